//! Bounding volume hierarchy with a binned surface-area-heuristic build (Wald 2007).
//!
//! Written here rather than taken from a crate so that leaves hold our own primitive enum
//! (triangles and spheres) in place, reordered for locality, and traversal is one tight loop
//! over 32-byte nodes with front-to-back child order and an any-hit mode for shadow rays.
//!
//! Build: at each node, primitive centroids are binned into 16 buckets along each axis and the
//! split with the lowest SAH cost C = C_trav + Σ (A_child / A_node)·N_child is taken, or a leaf
//! is made when that is not cheaper than intersecting every primitive (or there are ≤ 2).

use super::geometry::{Hit, Prim, Ray};
use glam::Vec3A;

/// 32 bytes. An interior node's left child follows it directly; `offset` is the right child.
/// A leaf has `count > 0` primitives starting at `offset`.
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: [f32; 3],
    offset: u32,
    hi: [f32; 3],
    /// Leaf: primitive count. Interior: 0, with the split axis in the top bits.
    count_axis: u32,
}

const AXIS_SHIFT: u32 = 30;
const COUNT_MASK: u32 = (1 << AXIS_SHIFT) - 1;
const BINS: usize = 16;

pub struct Bvh {
    nodes: Vec<Node>,
    /// Primitives in leaf order.
    pub prims: Vec<Prim>,
    /// `order[i]` is the index, in the caller's list, of `prims[i]`.
    pub order: Vec<u32>,
}

#[derive(Clone, Copy)]
struct Aabb {
    lo: Vec3A,
    hi: Vec3A,
}

impl Aabb {
    const EMPTY: Aabb = Aabb { lo: Vec3A::splat(f32::INFINITY), hi: Vec3A::splat(f32::NEG_INFINITY) };
    fn grow(&mut self, lo: Vec3A, hi: Vec3A) {
        self.lo = self.lo.min(lo);
        self.hi = self.hi.max(hi);
    }
    fn half_area(&self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

struct BuildPrim {
    lo: Vec3A,
    hi: Vec3A,
    centroid: Vec3A,
    index: u32,
}

impl Bvh {
    pub fn build(prims: &[Prim]) -> Bvh {
        let mut items: Vec<BuildPrim> = prims
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let (lo, hi) = p.bounds();
                BuildPrim { lo, hi, centroid: (lo + hi) * 0.5, index: i as u32 }
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * prims.len().max(1));
        if !items.is_empty() {
            build_node(&mut items, 0, &mut nodes);
        }
        let order: Vec<u32> = items.iter().map(|b| b.index).collect();
        Bvh { nodes, prims: order.iter().map(|&i| prims[i as usize]).collect(), order }
    }

    /// Closest hit within (t_min, t_max). `Hit::prim` indexes `self.prims` (leaf order).
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, mut t_max: f32) -> Option<Hit> {
        let q = Query::new(ray, t_min);
        let mut best: Option<Hit> = None;
        let Some(root) = self.nodes.first() else {
            return None;
        };
        if q.enter(root, t_max).is_none() {
            return None;
        }
        // Stack of (node, entry distance): a far child is skipped when popped if a closer hit
        // was found meanwhile.
        let mut stack = [(0u32, 0.0f32); 64];
        let mut sp = 0usize;
        let mut index = 0u32;
        loop {
            let node = &self.nodes[index as usize];
            let count = node.count_axis & COUNT_MASK;
            if count > 0 {
                let first = node.offset as usize;
                for (k, prim) in self.prims[first..first + count as usize].iter().enumerate() {
                    if let Some((t, b1, b2)) = prim.intersect(ray, t_min, t_max) {
                        t_max = t;
                        best = Some(Hit { t, prim: (first + k) as u32, b1, b2 });
                    }
                }
            } else {
                let (a, b) = (index + 1, node.offset);
                let ta = q.enter(&self.nodes[a as usize], t_max);
                let tb = q.enter(&self.nodes[b as usize], t_max);
                match (ta, tb) {
                    (Some(ta), Some(tb)) => {
                        let (near, far, tfar) = if ta <= tb { (a, b, tb) } else { (b, a, ta) };
                        stack[sp] = (far, tfar);
                        sp += 1;
                        index = near;
                        continue;
                    }
                    (Some(_), None) => {
                        index = a;
                        continue;
                    }
                    (None, Some(_)) => {
                        index = b;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                let (next, t_enter) = stack[sp];
                if t_enter <= t_max {
                    index = next;
                    break;
                }
            }
        }
    }

    /// Whether anything lies within (t_min, t_max): the shadow-ray query.
    #[inline]
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        let q = Query::new(ray, t_min);
        let Some(root) = self.nodes.first() else {
            return false;
        };
        if q.enter(root, t_max).is_none() {
            return false;
        }
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        let mut index = 0u32;
        loop {
            let node = &self.nodes[index as usize];
            let count = node.count_axis & COUNT_MASK;
            if count > 0 {
                let first = node.offset as usize;
                if self.prims[first..first + count as usize]
                    .iter()
                    .any(|p| p.intersect(ray, t_min, t_max).is_some())
                {
                    return true;
                }
            } else {
                let (a, b) = (index + 1, node.offset);
                let ha = q.enter(&self.nodes[a as usize], t_max).is_some();
                let hb = q.enter(&self.nodes[b as usize], t_max).is_some();
                if ha || hb {
                    if ha && hb {
                        stack[sp] = b;
                        sp += 1;
                    }
                    index = if ha { a } else { b };
                    continue;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            index = stack[sp];
        }
    }

    pub fn depth(&self) -> usize {
        fn walk(nodes: &[Node], i: usize) -> usize {
            let n = &nodes[i];
            if n.count_axis & COUNT_MASK > 0 {
                1
            } else {
                1 + walk(nodes, i + 1).max(walk(nodes, n.offset as usize))
            }
        }
        if self.nodes.is_empty() {
            0
        } else {
            walk(&self.nodes, 0)
        }
    }
}

/// A ray prepared for box tests: t = (bound − origin)·inv = bound·inv − origin·inv.
struct Query {
    inv: Vec3A,
    origin_inv: Vec3A,
    t_min: f32,
}

impl Query {
    #[inline(always)]
    fn new(ray: &Ray, t_min: f32) -> Query {
        let inv = ray.dir.recip();
        Query { inv, origin_inv: ray.origin * inv, t_min }
    }

    /// Entry distance into the node's box if the ray meets it within (t_min, t_max).
    #[inline(always)]
    fn enter(&self, node: &Node, t_max: f32) -> Option<f32> {
        let t0 = Vec3A::from(node.lo) * self.inv - self.origin_inv;
        let t1 = Vec3A::from(node.hi) * self.inv - self.origin_inv;
        let near = t0.min(t1).max_element().max(self.t_min);
        let far = t0.max(t1).min_element().min(t_max);
        (near <= far).then_some(near)
    }
}

/// Builds the subtree for `items` (which it reorders) and returns its node index.
fn build_node(items: &mut [BuildPrim], first: usize, nodes: &mut Vec<Node>) -> u32 {
    let mut bounds = Aabb::EMPTY;
    let mut cbounds = Aabb::EMPTY;
    for it in items.iter() {
        bounds.grow(it.lo, it.hi);
        cbounds.grow(it.centroid, it.centroid);
    }
    let index = nodes.len() as u32;
    nodes.push(Node {
        lo: bounds.lo.into(),
        offset: first as u32,
        hi: bounds.hi.into(),
        count_axis: items.len() as u32,
    });
    // The 64-entry traversal stack bounds the depth; a leaf is forced well before that.
    if items.len() <= 2 || nodes.len() > 1 << 29 {
        return index;
    }
    let leaf_cost = items.len() as f32;
    let mut best: Option<(f32, usize, f32)> = None; // (cost, axis, split position)
    for axis in 0..3 {
        let (lo, hi) = (cbounds.lo[axis], cbounds.hi[axis]);
        if !(hi > lo) {
            continue;
        }
        let scale = BINS as f32 / (hi - lo);
        let bin_of = |c: f32| (((c - lo) * scale) as usize).min(BINS - 1);
        let mut bins = [(Aabb::EMPTY, 0u32); BINS];
        for it in items.iter() {
            let b = &mut bins[bin_of(it.centroid[axis])];
            b.0.grow(it.lo, it.hi);
            b.1 += 1;
        }
        // Sweep from the right to get suffix areas and counts, then from the left.
        let mut right = [(0.0f32, 0u32); BINS];
        let mut acc = Aabb::EMPTY;
        let mut n = 0;
        for i in (1..BINS).rev() {
            acc.grow(bins[i].0.lo, bins[i].0.hi);
            n += bins[i].1;
            right[i] = (acc.half_area(), n);
        }
        let mut acc = Aabb::EMPTY;
        let mut n = 0;
        for i in 0..BINS - 1 {
            acc.grow(bins[i].0.lo, bins[i].0.hi);
            n += bins[i].1;
            let (ra, rn) = right[i + 1];
            if n == 0 || rn == 0 {
                continue;
            }
            let cost = 0.125 + (acc.half_area() * n as f32 + ra * rn as f32) / bounds.half_area().max(1e-30);
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, lo + (i + 1) as f32 / scale));
            }
        }
    }
    let Some((cost, axis, split)) = best else {
        return index;
    };
    if cost >= leaf_cost && items.len() <= 8 {
        return index;
    }
    let mut mid = partition(items, |it| it.centroid[axis] < split);
    if mid == 0 || mid == items.len() {
        mid = items.len() / 2; // all centroids fell in one bin by rounding: split by count
    }
    let (left, right) = items.split_at_mut(mid);
    build_node(left, first, nodes);
    let right_index = build_node(right, first + mid, nodes);
    nodes[index as usize].offset = right_index;
    nodes[index as usize].count_axis = (axis as u32) << AXIS_SHIFT;
    index
}

fn partition<T>(items: &mut [T], pred: impl Fn(&T) -> bool) -> usize {
    let mut i = 0;
    for j in 0..items.len() {
        if pred(&items[j]) {
            items.swap(i, j);
            i += 1;
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Sampler;

    /// The BVH must find exactly the hits a brute-force loop finds.
    #[test]
    fn matches_brute_force() {
        let mut s = Sampler::new(1, 2, 3);
        let mut r = || Vec3A::new(s.next(), s.next(), s.next());
        let mut prims = Vec::new();
        for i in 0..500 {
            let v0 = r() * 4.0 - 2.0;
            if i % 7 == 0 {
                prims.push(Prim::Sphere { center: v0, radius: 0.05 + 0.1 * r().x });
            } else {
                prims.push(Prim::Triangle { v0, e1: (r() - 0.5) * 0.5, e2: (r() - 0.5) * 0.5 });
            }
        }
        let bvh = Bvh::build(&prims);
        for _ in 0..2000 {
            let ray = Ray { origin: r() * 6.0 - 3.0, dir: (r() - 0.5).normalize() };
            let brute = prims
                .iter()
                .filter_map(|p| p.intersect(&ray, 1e-4, f32::INFINITY).map(|h| h.0))
                .fold(f32::INFINITY, f32::min);
            let got = bvh.intersect(&ray, 1e-4, f32::INFINITY).map_or(f32::INFINITY, |h| h.t);
            assert_eq!(brute, got);
            assert_eq!(brute.is_finite(), bvh.occluded(&ray, 1e-4, f32::INFINITY));
        }
    }
}
