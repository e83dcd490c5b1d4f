//! Bounding volume hierarchy: a binned surface-area-heuristic build (Wald 2007), collapsed to
//! four or eight children per node for traversal.
//!
//! Build: at each node, primitive centroids are binned into 16 buckets along each axis and the
//! split with the lowest SAH cost C = C_trav + Σ (A_child / A_node)·N_child is taken, or a leaf
//! is made when that is not cheaper than intersecting every primitive (or there are no more
//! than one block's worth). The binary tree is then collapsed to a wide one by repeatedly
//! opening the largest interior child, so one SIMD slab test checks all child boxes; children
//! are visited nearest first and a popped node farther than the best hit is skipped.
//!
//! Leaves of triangles are stored again as structure-of-arrays blocks and tested by one SIMD
//! Möller–Trumbore per block. Leaves with spheres are tested one primitive at a time.
//!
//! Width: eight (AVX2, `avx2` module) where the processor has it, checked at run time, else
//! four (SSE through glam). Both compute the same per-lane arithmetic, so they find the same
//! hits. Eight is worth its code: the Cornell box's 36 triangles become one node of seven
//! leaves, and bigger meshes need half the node visits.
//!
//! Written here rather than taken from a crate so that leaves hold lumen's own primitive enum
//! (triangles and spheres) in place, and shadow rays get an any-hit traversal. Measured against
//! obvhs 0.4 (a PLOC-built, compressed 8-wide BVH; `cargo run --release --example
//! bvh_vs_obvhs`: same triangles, 2 M incoherent rays from inside the scene's box, one thread,
//! all three agreeing on every hit), in one run on the 2-core development machine, M rays/s:
//!
//! | scene                          | triangles | lumen 4-wide | lumen 8-wide | obvhs CWBVH | lumen any-hit 4 / 8 |
//! |--------------------------------|----------:|-------------:|-------------:|------------:|--------------------:|
//! | Cornell box                    |        36 |         6.39 |         9.46 |        4.41 |        6.90 / 13.96 |
//! | icosphere, subdivided 6 times  |    81 920 |         0.53 |         1.70 |        0.72 |         2.06 / 2.91 |
//!
//! lumen's 8-wide tree is 2.1–2.4× as fast as obvhs on both, so obvhs is not used. (The
//! machine's speed moves all figures by up to a factor of two between runs; the columns of a
//! row come from the same run.)

use super::geometry::{Hit, Prim, Ray};
use glam::{Vec3A, Vec4};

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(not(target_arch = "x86_64"))]
mod avx2 {
    pub fn available() -> bool {
        false
    }
}

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
/// Deepest level of the binary tree; deeper subtrees become (large) leaves.
const MAX_DEPTH: u32 = 60;

pub struct Bvh {
    /// The binary SAH tree the wide one is collapsed from (kept for its statistics).
    nodes: Vec<Node>,
    /// The same tree collapsed to 4 or 8 children per node, which traversal uses.
    tree: Tree,
    /// Primitives in leaf order.
    pub prims: Vec<Prim>,
    /// `order[i]` is the index, in the caller's list, of `prims[i]`.
    pub order: Vec<u32>,
}

/// How many children a node of the traversed tree has (and how many triangles one leaf test
/// checks at once).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Width {
    /// SSE: every x86-64 and (through glam's scalar fallback) every other target.
    Four,
    /// AVX2, chosen at run time where the processor has it.
    Eight,
}

enum Tree {
    /// Leaf triangles in blocks of four, for the 4-wide triangle test.
    Four { nodes: Vec<Node4>, blocks: Vec<Tri4> },
    #[cfg(target_arch = "x86_64")]
    Eight(avx2::Tree8),
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
    /// Builds the widest tree this processor can traverse.
    pub fn build(prims: &[Prim]) -> Bvh {
        Bvh::build_width(prims, Width::Eight)
    }

    /// Builds a tree of the given width, or of width four where the processor lacks AVX2.
    pub fn build_width(prims: &[Prim], width: Width) -> Bvh {
        Bvh::build_capped(prims, MAX_DEPTH, width)
    }

    /// The width traversal uses.
    pub fn width(&self) -> Width {
        match self.tree {
            Tree::Four { .. } => Width::Four,
            #[cfg(target_arch = "x86_64")]
            Tree::Eight(_) => Width::Eight,
        }
    }

    /// Builds with the binary tree at most `max_depth` (≤ MAX_DEPTH) levels below the root.
    fn build_capped(prims: &[Prim], max_depth: u32, width: Width) -> Bvh {
        let width = if width == Width::Eight && avx2::available() { Width::Eight } else { Width::Four };
        let leaf_size = match width {
            Width::Four => 4,
            Width::Eight => 8,
        };
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
            build_node(&mut items, 0, max_depth.min(MAX_DEPTH), leaf_size, &mut nodes);
        }
        let order: Vec<u32> = items.iter().map(|b| b.index).collect();
        let prims: Vec<Prim> = order.iter().map(|&i| prims[i as usize]).collect();
        let tree = match width {
            #[cfg(target_arch = "x86_64")]
            Width::Eight => Tree::Eight(avx2::Tree8::collapse(&nodes, &prims)),
            _ => {
                let mut wide = Vec::with_capacity(nodes.len() / 2 + 1);
                let mut blocks = Vec::new();
                if !nodes.is_empty() {
                    collapse(&nodes, 0, &prims, &mut wide, &mut blocks);
                }
                Tree::Four { nodes: wide, blocks }
            }
        };
        Bvh { nodes, tree, prims, order }
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

/// Reciprocal direction with infinities clamped to ±1e30, so that (bound − origin)·inv is never
/// ∞·0 = NaN for a ray travelling inside a box's face plane.
#[inline(always)]
fn safe_recip(dir: Vec3A) -> Vec3A {
    dir.recip().clamp(Vec3A::splat(-1e30), Vec3A::splat(1e30))
}

/// A node of the 4-wide tree: the boxes of up to four children as structure-of-arrays lanes,
/// so one SIMD slab test checks all four.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Node4 {
    lo: [Vec4; 3],
    hi: [Vec4; 3],
    /// Interior child: index into `wide`. Leaf child: first primitive.
    child: [u32; 4],
    /// Leaf child: primitive count (> 0). Interior child: 0.
    count: [u32; 4],
    /// Leaf child of triangles only: its first block in `Bvh::blocks` (⌈count/4⌉ blocks);
    /// `NO_BLOCK` where the leaf holds a sphere and is tested one primitive at a time.
    block: [u32; 4],
    /// Bit mask of the lanes in use.
    lanes: u32,
}

const NO_BLOCK: u32 = u32::MAX;

/// Four triangles as structure-of-arrays lanes (vertex 0 and the two edges). Unused lanes
/// have zero edges, so their determinant is 0 and they never hit.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Tri4 {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
}

/// Vertex 0 and the edges e1 = v1 − v0, e2 = v2 − v0 of up to N triangles as lanes,
/// indexed [vector][axis][lane]: the layout of the 4- and 8-wide blocks. Unused lanes stay
/// zero. `None` when a primitive is not a triangle.
fn tri_lanes<const N: usize>(tris: &[Prim]) -> Option<[[[f32; N]; 3]; 3]> {
    let mut b = [[[0.0; N]; 3]; 3];
    for (lane, p) in tris.iter().enumerate() {
        let Prim::Triangle { v0, e1, e2 } = *p else { return None };
        for (k, v) in [v0, e1, e2].into_iter().enumerate() {
            for a in 0..3 {
                b[k][a][lane] = v[a];
            }
        }
    }
    Some(b)
}

impl Tri4 {
    fn new(tris: &[Prim]) -> Option<Tri4> {
        let [v0, e1, e2] = tri_lanes::<4>(tris)?.map(|v| v.map(Vec4::from_array));
        Some(Tri4 { v0, e1, e2 })
    }

    /// Möller–Trumbore on four triangles at once, dividing by the determinant only for lanes
    /// hit (as `avx2`): the mask of lanes hit within (t_min, t_max), and per lane the
    /// determinant and the numerators of b1, b2, t.
    #[inline(always)]
    fn hits(&self, q: &Query4, t_min: f32, t_max: f32) -> (u32, [Vec4; 4]) {
        let [dx, dy, dz] = q.dir;
        let [e1x, e1y, e1z] = self.e1;
        let [e2x, e2y, e2z] = self.e2;
        // p = d × e2, det = e1 · p
        let (px, py, pz) = (dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x);
        let det = e1x * px + e1y * py + e1z * pz;
        let (sx, sy, sz) = (q.origin[0] - self.v0[0], q.origin[1] - self.v0[1], q.origin[2] - self.v0[2]);
        let n1 = sx * px + sy * py + sz * pz;
        // q = s × e1
        let (qx, qy, qz) = (sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x);
        let n2 = dx * qx + dy * qy + dz * qz;
        let nt = e2x * qx + e2y * qy + e2z * qz;
        // Multiplying by ±1 is exact: the numerators' signs become those of b1, b2, t.
        let sign = Vec4::ONE.copysign(det);
        let abs_det = det.abs();
        let (u, v, t) = (n1 * sign, n2 * sign, nt * sign);
        let ok = abs_det.cmpge(Vec4::splat(1e-12))
            & u.cmpge(Vec4::ZERO)
            & v.cmpge(Vec4::ZERO)
            & (u + v).cmple(abs_det)
            & t.cmpgt(Vec4::splat(t_min) * abs_det)
            & t.cmplt(Vec4::splat(t_max) * abs_det);
        (ok.bitmask(), [det, n1, n2, nt])
    }

    /// The nearest of the four triangles hit within (t_min, t_max), as (lane, t, b1, b2).
    #[inline(always)]
    fn intersect(&self, q: &Query4, t_min: f32, t_max: f32) -> Option<(usize, f32, f32, f32)> {
        let (mask, [det, n1, n2, nt]) = self.hits(q, t_min, t_max);
        if mask == 0 {
            return None;
        }
        nearest_lane(mask, [det, n1, n2, nt].map(|v| v.to_array()), t_min, t_max)
    }
}

/// Among the lanes of `mask` (triangles a 4-wide block test found hit), the nearest, as (lane,
/// t, b1, b2): the divisions the block test saved, done for these lanes only, and t checked
/// against the range once more as the divided value (the block compared t·|det| with it).
#[inline(always)]
fn nearest_lane(
    mut mask: u32,
    [det, n1, n2, nt]: [[f32; 4]; 4],
    t_min: f32,
    t_max: f32,
) -> Option<(usize, f32, f32, f32)> {
    let mut best: Option<(usize, f32, f32, f32)> = None;
    while mask != 0 {
        let lane = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let inv = 1.0 / det[lane];
        let t = nt[lane] * inv;
        if t > t_min && t < best.map_or(t_max, |b| b.1) {
            best = Some((lane, t, n1[lane] * inv, n2[lane] * inv));
        }
    }
    best
}

impl Node {
    fn is_leaf(&self) -> bool {
        self.count_axis & COUNT_MASK > 0
    }

    /// Leaf: (first primitive, count).
    fn leaf(&self) -> Option<(u32, u32)> {
        self.is_leaf().then_some((self.offset, self.count_axis & COUNT_MASK))
    }
}

/// The up to `width` binary nodes that become the children of one wide node standing for the
/// binary subtree at `i` (an interior node, or the root): its two children, with the interior
/// one of largest surface area opened until there are `width` or only leaves.
fn wide_children(nodes: &[Node], i: usize, width: usize) -> Vec<usize> {
    let area = |k: usize| {
        let n = &nodes[k];
        Aabb { lo: n.lo.into(), hi: n.hi.into() }.half_area()
    };
    let mut kids: Vec<usize> =
        if nodes[i].is_leaf() { vec![i] } else { vec![i + 1, nodes[i].offset as usize] };
    while kids.len() < width {
        let open = kids
            .iter()
            .enumerate()
            .filter(|(_, &k)| !nodes[k].is_leaf())
            .max_by(|a, b| area(*a.1).total_cmp(&area(*b.1)));
        let Some((slot, &k)) = open else { break };
        kids.swap_remove(slot);
        kids.push(k + 1);
        kids.push(nodes[k].offset as usize);
    }
    kids
}

/// Collapses the binary subtree at `i` (an interior node, or the root) into 4-wide nodes
/// (`wide_children`), and returns the new node's index.
fn collapse(nodes: &[Node], i: usize, prims: &[Prim], wide: &mut Vec<Node4>, blocks: &mut Vec<Tri4>) -> u32 {
    let kids = wide_children(nodes, i, 4);
    let index = wide.len();
    let inf = Vec4::splat(f32::INFINITY);
    wide.push(Node4 {
        lo: [inf; 3],
        hi: [-inf; 3],
        child: [0; 4],
        count: [0; 4],
        block: [NO_BLOCK; 4],
        lanes: (1 << kids.len()) - 1,
    });
    for (lane, &k) in kids.iter().enumerate() {
        let n = nodes[k];
        let (child, count) = match n.leaf() {
            Some(leaf) => leaf,
            None => (collapse(nodes, k, prims, wide, blocks), 0),
        };
        if count > 0 {
            let leaf = &prims[child as usize..(child + count) as usize];
            let made: Option<Vec<Tri4>> = leaf.chunks(4).map(Tri4::new).collect();
            if let Some(made) = made {
                wide[index].block[lane] = blocks.len() as u32;
                blocks.extend(made);
            }
        }
        let w = &mut wide[index];
        for axis in 0..3 {
            w.lo[axis][lane] = n.lo[axis];
            w.hi[axis][lane] = n.hi[axis];
        }
        w.child[lane] = child;
        w.count[lane] = count;
    }
    index as u32
}

/// The traversal stack of a tree `W` wide. Left uninitialised: zeroing a few hundred bytes per
/// ray costs more than a shadow ray's whole box tests in small scenes. The binary tree is at
/// most MAX_DEPTH + 1 levels deep, so its W-wide collapse pushes at most W − 1 entries for each
/// of ≤ MAX_DEPTH + 1 levels, plus the root.
struct Stack<T: Copy, const W: usize> {
    items: [[std::mem::MaybeUninit<T>; W]; MAX_DEPTH as usize + 2],
    len: usize,
}

impl<T: Copy, const W: usize> Stack<T, W> {
    #[inline(always)]
    fn new() -> Self {
        Stack { items: [[std::mem::MaybeUninit::uninit(); W]; MAX_DEPTH as usize + 2], len: 0 }
    }

    #[inline(always)]
    fn push(&mut self, v: T) {
        self.items[self.len / W][self.len % W] = std::mem::MaybeUninit::new(v);
        self.len += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: every slot below `len` was written by `push`.
        Some(unsafe { self.items[self.len / W][self.len % W].assume_init() })
    }
}

/// A ray splatted across four lanes for the 4-wide box and triangle tests.
struct Query4 {
    origin: [Vec4; 3],
    inv: [Vec4; 3],
    dir: [Vec4; 3],
}

impl Query4 {
    #[inline(always)]
    fn new(ray: &Ray) -> Query4 {
        let inv = safe_recip(ray.dir);
        let o = ray.origin;
        let d = ray.dir;
        Query4 {
            origin: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            dir: [Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z)],
            inv: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
        }
    }

    /// Entry distances of the four child boxes and the mask of those met within the range.
    #[inline(always)]
    fn enter(&self, n: &Node4, t_min: f32, t_max: f32) -> (Vec4, u32) {
        let mut near = Vec4::splat(t_min);
        let mut far = Vec4::splat(t_max);
        for a in 0..3 {
            let t0 = (n.lo[a] - self.origin[a]) * self.inv[a];
            let t1 = (n.hi[a] - self.origin[a]) * self.inv[a];
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
        }
        (near, near.cmple(far).bitmask() & n.lanes)
    }
}

impl Bvh {
    /// Closest hit within (t_min, t_max). `Hit::prim` indexes `self.prims` (leaf order).
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        match &self.tree {
            Tree::Four { nodes, blocks } => intersect4(nodes, blocks, &self.prims, ray, t_min, t_max),
            // SAFETY: an 8-wide tree is only built where the processor has AVX2.
            #[cfg(target_arch = "x86_64")]
            Tree::Eight(tree) => unsafe { tree.intersect(&self.prims, ray, t_min, t_max) },
        }
    }

    /// Whether anything lies within (t_min, t_max): the shadow-ray query.
    #[inline(always)]
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        match &self.tree {
            Tree::Four { nodes, blocks } => occluded4(nodes, blocks, &self.prims, ray, t_min, t_max),
            // SAFETY: as in `intersect`.
            #[cfg(target_arch = "x86_64")]
            Tree::Eight(tree) => unsafe { tree.occluded(&self.prims, ray, t_min, t_max) },
        }
    }
}

/// Closest hit in a 4-wide tree. Not inlined, like the 8-wide traversal (which cannot be:
/// it is compiled for AVX2), so that `Bvh::intersect` inlines into its callers as one branch
/// and a call.
#[inline(never)]
fn intersect4(
    wide: &[Node4],
    blocks: &[Tri4],
    prims: &[Prim],
    ray: &Ray,
    t_min: f32,
    mut t_max: f32,
) -> Option<Hit> {
    if wide.is_empty() {
        return None;
    }
    let q = Query4::new(ray);
    let mut best: Option<Hit> = None;
    // (node, entry distance): popped nodes farther than the best hit so far are skipped.
    let mut stack = Stack::<(u32, f32), 4>::new();
    stack.push((0, t_min));
    while let Some((index, t_enter)) = stack.pop() {
        if t_enter > t_max {
            continue;
        }
        let node = &wide[index as usize];
        let (near, mut mask) = q.enter(node, t_min, t_max);
        // Interior children are pushed farthest first, so the nearest is popped next.
        let mut pending = [(0u32, 0.0f32); 4];
        let mut np = 0;
        while mask != 0 {
            let lane = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let count = node.count[lane];
            if count > 0 {
                let first = node.child[lane] as usize;
                let block = node.block[lane];
                if block != NO_BLOCK {
                    let nb = count.div_ceil(4);
                    for (k, b) in blocks[block as usize..(block + nb) as usize].iter().enumerate() {
                        if let Some((l, t, b1, b2)) = b.intersect(&q, t_min, t_max) {
                            t_max = t;
                            best = Some(Hit { t, prim: (first + 4 * k + l) as u32, b1, b2 });
                        }
                    }
                } else {
                    for (k, prim) in prims[first..first + count as usize].iter().enumerate() {
                        if let Some((t, b1, b2)) = prim.intersect(ray, t_min, t_max) {
                            t_max = t;
                            best = Some(Hit { t, prim: (first + k) as u32, b1, b2 });
                        }
                    }
                }
            } else {
                let entry = (node.child[lane], near[lane]);
                let mut j = np;
                while j > 0 && pending[j - 1].1 < entry.1 {
                    pending[j] = pending[j - 1];
                    j -= 1;
                }
                pending[j] = entry;
                np += 1;
            }
        }
        for &e in &pending[..np] {
            stack.push(e);
        }
    }
    best
}

/// Any hit in a 4-wide tree (not inlined, as `intersect4`).
#[inline(never)]
fn occluded4(wide: &[Node4], blocks: &[Tri4], prims: &[Prim], ray: &Ray, t_min: f32, t_max: f32) -> bool {
    if wide.is_empty() {
        return false;
    }
    let q = Query4::new(ray);
    let mut stack = Stack::<u32, 4>::new();
    stack.push(0);
    while let Some(index) = stack.pop() {
        let node = &wide[index as usize];
        let (_, mut mask) = q.enter(node, t_min, t_max);
        while mask != 0 {
            let lane = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let count = node.count[lane];
            if count > 0 {
                let first = node.child[lane] as usize;
                let block = node.block[lane];
                let hit = if block != NO_BLOCK {
                    let nb = count.div_ceil(4);
                    blocks[block as usize..(block + nb) as usize]
                        .iter()
                        .any(|b| b.hits(&q, t_min, t_max).0 != 0)
                } else {
                    prims[first..first + count as usize]
                        .iter()
                        .any(|p| p.intersect(ray, t_min, t_max).is_some())
                };
                if hit {
                    return true;
                }
            } else {
                stack.push(node.child[lane]);
            }
        }
    }
    false
}

/// Builds the subtree for `items` (which it reorders) and returns its node index.
/// `levels` is how many more levels may be split below this node.
/// Leaves hold at most `leaf_size` primitives, or up to twice that when splitting them costs
/// more than testing them all.
fn build_node(
    items: &mut [BuildPrim],
    first: usize,
    levels: u32,
    leaf_size: usize,
    nodes: &mut Vec<Node>,
) -> u32 {
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
    // Traversal stacks are sized for depth ≤ 64: a leaf is forced before that.
    if items.len() <= leaf_size || levels == 0 {
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
    if cost >= leaf_cost && items.len() <= 2 * leaf_size {
        return index;
    }
    let mut mid = partition(items, |it| it.centroid[axis] < split);
    if mid == 0 || mid == items.len() {
        mid = items.len() / 2; // all centroids fell in one bin by rounding: split by count
    }
    let (left, right) = items.split_at_mut(mid);
    build_node(left, first, levels - 1, leaf_size, nodes);
    let right_index = build_node(right, first + mid, levels - 1, leaf_size, nodes);
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

    /// Spheres at 4^i drive a binned SAH build deep (each split peels off the largest few); a
    /// depth cap must hold, and traversal must still find every hit in the large leaves it
    /// leaves behind.
    #[test]
    fn depth_is_capped() {
        for width in [Width::Four, Width::Eight] {
            depth_is_capped_at(width);
        }
    }

    fn depth_is_capped_at(width: Width) {
        let prims: Vec<Prim> = (0..64)
            .map(|i| Prim::Sphere { center: Vec3A::new(4f32.powi(i), 0.0, 0.0), radius: 1e-3 * 4f32.powi(i) })
            .collect();
        assert!(Bvh::build_width(&prims, width).depth() > 20, "the case is not deep enough to test the cap");
        let bvh = Bvh::build_capped(&prims, 8, width);
        assert_eq!(bvh.depth(), 9);
        // Up to 4^27, where r² still fits in an f32.
        for i in 0..28 {
            let x = 4f32.powi(i);
            // Axis-aligned rays: the reciprocal direction has infinite components.
            let ray = Ray { origin: Vec3A::new(x, -0.01 * x, 0.0), dir: Vec3A::Y };
            assert!(bvh.intersect(&ray, 0.0, f32::INFINITY).is_some(), "missed sphere {i}");
            assert!(bvh.occluded(&ray, 0.0, f32::INFINITY));
        }
        // A ray running inside the plane of a box face (0 · ∞ in the slab test).
        let tri = [Prim::Triangle { v0: Vec3A::ZERO, e1: Vec3A::X, e2: Vec3A::Y }];
        let flat = Bvh::build_width(&tri, width);
        let ray = Ray { origin: Vec3A::new(0.2, -1.0, 0.0), dir: Vec3A::Y };
        assert!(flat.intersect(&ray, 0.0, f32::INFINITY).is_none()); // parallel: no hit, no NaN trap
        let ray = Ray { origin: Vec3A::new(0.2, 0.2, 1.0), dir: -Vec3A::Z };
        assert!(flat.intersect(&ray, 0.0, f32::INFINITY).is_some());
    }

    /// The BVH must find exactly the hits a brute-force loop finds, at either width.
    #[test]
    fn matches_brute_force() {
        assert!(!avx2::available() || Bvh::build(&[]).width() == Width::Eight);
        for width in [Width::Four, Width::Eight] {
            matches_brute_force_at(width);
        }
    }

    fn matches_brute_force_at(width: Width) {
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
        // 12 triangles tilted by different amounts about one point, far from the rest: their
        // boxes share a centre, so no split separates them and they stay one leaf of more
        // triangles than one block tests at once.
        let c = Vec3A::splat(10.0);
        for k in 0..12 {
            let h = 0.1 * (k + 1) as f32;
            let v0 = c + Vec3A::new(-2.0, -2.0, -h);
            let (v1, v2) = (c + Vec3A::new(2.0, -2.0, h), c + Vec3A::new(0.0, 2.0, 0.0));
            prims.push(Prim::Triangle { v0, e1: v1 - v0, e2: v2 - v0 });
        }
        let bvh = Bvh::build_width(&prims, width);
        for i in 0..3000 {
            let ray = if i < 2000 {
                Ray { origin: r() * 6.0 - 3.0, dir: (r() - 0.5).normalize() }
            } else {
                // Down into the stack or up into it from below, at a slant.
                let p = c + (r() - 0.5) * Vec3A::new(4.0, 4.0, 0.5);
                Ray {
                    origin: p,
                    dir: (Vec3A::new(0.5, 0.5, 0.0) - r() + Vec3A::Z * (i % 2) as f32 * 2.0).normalize(),
                }
            };
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
