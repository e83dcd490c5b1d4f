//! The 8-wide tree for processors with AVX2: one 256-bit slab test checks eight child boxes,
//! one 256-bit Möller–Trumbore checks eight leaf triangles. Same layout, traversal order and
//! arithmetic as the 4-wide tree (every lane computes exactly what the SSE lane would), only
//! twice as wide, so a small scene's whole top level is one node and each leaf one test.
//!
//! Written with `std::arch` intrinsics rather than a SIMD crate because traversal is the one
//! place where the width matters, and glam stops at four lanes.

use super::{wide_children, Hit, Node, Prim, Ray, Stack, NO_BLOCK};
use std::arch::x86_64::*;

/// Whether this processor runs the 8-wide tree.
pub fn available() -> bool {
    is_x86_feature_detected!("avx2")
}

/// The boxes of up to eight children as structure-of-arrays lanes.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct Node8 {
    lo: [[f32; 8]; 3],
    hi: [[f32; 8]; 3],
    /// Interior child: index into `Tree8::nodes`. Leaf child: first primitive.
    child: [u32; 8],
    /// Leaf child: primitive count (> 0). Interior child: 0.
    count: [u32; 8],
    /// Leaf child of triangles only: its first block (⌈count/8⌉ blocks); `NO_BLOCK` where the
    /// leaf holds a sphere and is tested one primitive at a time.
    block: [u32; 8],
    /// Bit mask of the lanes in use.
    lanes: u32,
}

/// Eight triangles as lanes (vertex 0 and the two edges); unused lanes have zero edges, so
/// their determinant is 0 and they never hit.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct Tri8 {
    v0: [[f32; 8]; 3],
    e1: [[f32; 8]; 3],
    e2: [[f32; 8]; 3],
}

impl Tri8 {
    fn new(tris: &[Prim]) -> Option<Tri8> {
        let [v0, e1, e2] = super::tri_lanes::<8>(tris)?;
        Some(Tri8 { v0, e1, e2 })
    }
}

pub struct Tree8 {
    nodes: Vec<Node8>,
    blocks: Vec<Tri8>,
}

impl Tree8 {
    /// Collapses the binary tree (`prims` in its leaf order) to eight children per node.
    pub fn collapse(binary: &[Node], prims: &[Prim]) -> Tree8 {
        let mut tree = Tree8 { nodes: Vec::with_capacity(binary.len() / 4 + 1), blocks: Vec::new() };
        if !binary.is_empty() {
            tree.collapse_node(binary, 0, prims);
        }
        tree
    }

    fn collapse_node(&mut self, binary: &[Node], i: usize, prims: &[Prim]) -> u32 {
        let kids = wide_children(binary, i, 8);
        let index = self.nodes.len();
        self.nodes.push(Node8 {
            lo: [[f32::INFINITY; 8]; 3],
            hi: [[f32::NEG_INFINITY; 8]; 3],
            child: [0; 8],
            count: [0; 8],
            block: [NO_BLOCK; 8],
            lanes: (1 << kids.len()) - 1,
        });
        for (lane, &k) in kids.iter().enumerate() {
            let n = binary[k];
            let (child, count) = match n.leaf() {
                Some(leaf) => leaf,
                None => (self.collapse_node(binary, k, prims), 0),
            };
            if count > 0 {
                let leaf = &prims[child as usize..(child + count) as usize];
                let made: Option<Vec<Tri8>> = leaf.chunks(8).map(Tri8::new).collect();
                if let Some(made) = made {
                    self.nodes[index].block[lane] = self.blocks.len() as u32;
                    self.blocks.extend(made);
                }
            }
            let w = &mut self.nodes[index];
            for axis in 0..3 {
                w.lo[axis][lane] = n.lo[axis];
                w.hi[axis][lane] = n.hi[axis];
            }
            w.child[lane] = child;
            w.count[lane] = count;
        }
        index as u32
    }

    /// Closest hit within (t_min, t_max), as `Bvh::intersect`.
    ///
    /// # Safety
    /// The processor must have AVX2 (`available()`).
    #[target_feature(enable = "avx2")]
    pub unsafe fn intersect(&self, prims: &[Prim], ray: &Ray, t_min: f32, mut t_max: f32) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let q = Query8::new(ray);
        let mut best: Option<Hit> = None;
        // (node, entry distance): popped nodes farther than the best hit so far are skipped.
        let mut stack = Stack::<(u32, f32), 8>::new();
        stack.push((0, t_min));
        while let Some((index, t_enter)) = stack.pop() {
            if t_enter > t_max {
                continue;
            }
            let node = &self.nodes[index as usize];
            let (near, mut mask) = q.enter(node, t_min, t_max);
            // Interior children are pushed farthest first, so the nearest is popped next.
            let mut pending = [(0u32, 0.0f32); 8];
            let mut np = 0;
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let count = node.count[lane];
                if count > 0 {
                    let first = node.child[lane] as usize;
                    let block = node.block[lane];
                    if block != NO_BLOCK {
                        let nb = count.div_ceil(8);
                        for (k, b) in self.blocks[block as usize..(block + nb) as usize].iter().enumerate() {
                            if let Some((l, t, b1, b2)) = q.nearest(b, t_min, t_max) {
                                t_max = t;
                                best = Some(Hit { t, prim: (first + 8 * k + l) as u32, b1, b2 });
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

    /// Whether anything lies within (t_min, t_max), as `Bvh::occluded`.
    ///
    /// # Safety
    /// The processor must have AVX2 (`available()`).
    #[target_feature(enable = "avx2")]
    pub unsafe fn occluded(&self, prims: &[Prim], ray: &Ray, t_min: f32, t_max: f32) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let q = Query8::new(ray);
        let mut stack = Stack::<u32, 8>::new();
        stack.push(0);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            let (_, mut mask) = q.enter(node, t_min, t_max);
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let count = node.count[lane];
                if count > 0 {
                    let first = node.child[lane] as usize;
                    let block = node.block[lane];
                    let hit = if block != NO_BLOCK {
                        let nb = count.div_ceil(8);
                        self.blocks[block as usize..(block + nb) as usize]
                            .iter()
                            .any(|b| _mm256_movemask_ps(q.hits(b, t_min, t_max).0) != 0)
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
}

/// A ray splatted across eight lanes.
struct Query8 {
    origin: [__m256; 3],
    inv: [__m256; 3],
    dir: [__m256; 3],
}

#[inline(always)]
fn load(v: &[f32; 8]) -> __m256 {
    // SAFETY: reads exactly the eight floats of `v`; unaligned loads are allowed.
    unsafe { _mm256_loadu_ps(v.as_ptr()) }
}

#[inline(always)]
fn lanes(v: __m256) -> [f32; 8] {
    let mut out = [0.0f32; 8];
    // SAFETY: writes exactly the eight floats of `out`.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
    out
}

impl Query8 {
    #[target_feature(enable = "avx2")]
    #[inline]
    fn new(ray: &Ray) -> Query8 {
        let inv = super::safe_recip(ray.dir);
        let splat = |v: glam::Vec3A| [_mm256_set1_ps(v.x), _mm256_set1_ps(v.y), _mm256_set1_ps(v.z)];
        Query8 { origin: splat(ray.origin), inv: splat(inv), dir: splat(ray.dir) }
    }

    /// Entry distances of the eight child boxes and the mask of those met within the range.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn enter(&self, n: &Node8, t_min: f32, t_max: f32) -> ([f32; 8], u32) {
        let mut near = _mm256_set1_ps(t_min);
        let mut far = _mm256_set1_ps(t_max);
        for a in 0..3 {
            let t0 = _mm256_mul_ps(_mm256_sub_ps(load(&n.lo[a]), self.origin[a]), self.inv[a]);
            let t1 = _mm256_mul_ps(_mm256_sub_ps(load(&n.hi[a]), self.origin[a]), self.inv[a]);
            near = _mm256_max_ps(near, _mm256_min_ps(t0, t1));
            far = _mm256_min_ps(far, _mm256_max_ps(t0, t1));
        }
        let met = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(near, far)) as u32 & n.lanes;
        (lanes(near), met)
    }

    /// Möller–Trumbore on eight triangles, without dividing by the determinant until a lane is
    /// known to be hit (the division is the slowest instruction of the test): the lanes hit
    /// within (t_min, t_max) (all bits set), and per lane the determinant and the numerators
    /// of b1, b2, t.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn hits(&self, b: &Tri8, t_min: f32, t_max: f32) -> (__m256, [__m256; 4]) {
        let [dx, dy, dz] = self.dir;
        let [e1x, e1y, e1z] = [load(&b.e1[0]), load(&b.e1[1]), load(&b.e1[2])];
        let [e2x, e2y, e2z] = [load(&b.e2[0]), load(&b.e2[1]), load(&b.e2[2])];
        let (mul, sub, add) = (_mm256_mul_ps, _mm256_sub_ps, _mm256_add_ps);
        let cross = |ax, ay, az, bx, by, bz| {
            (sub(mul(ay, bz), mul(az, by)), sub(mul(az, bx), mul(ax, bz)), sub(mul(ax, by), mul(ay, bx)))
        };
        let dot = |ax, ay, az, bx, by, bz| add(add(mul(ax, bx), mul(ay, by)), mul(az, bz));
        // p = d × e2, det = e1 · p
        let (px, py, pz) = cross(dx, dy, dz, e2x, e2y, e2z);
        let det = dot(e1x, e1y, e1z, px, py, pz);
        let sx = sub(self.origin[0], load(&b.v0[0]));
        let sy = sub(self.origin[1], load(&b.v0[1]));
        let sz = sub(self.origin[2], load(&b.v0[2]));
        let n1 = dot(sx, sy, sz, px, py, pz);
        // q = s × e1
        let (qx, qy, qz) = cross(sx, sy, sz, e1x, e1y, e1z);
        let n2 = dot(dx, dy, dz, qx, qy, qz);
        let nt = dot(e2x, e2y, e2z, qx, qy, qz);
        // With the determinant's sign moved onto the numerators, b1 ≥ 0 ⇔ n1·sign ≥ 0, and so on.
        let sign = _mm256_and_ps(det, _mm256_set1_ps(-0.0));
        let abs_det = _mm256_xor_ps(det, sign);
        let (u, v, t) = (_mm256_xor_ps(n1, sign), _mm256_xor_ps(n2, sign), _mm256_xor_ps(nt, sign));
        let zero = _mm256_setzero_ps();
        let and = _mm256_and_ps;
        let ok = and(
            and(
                and(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(abs_det, _mm256_set1_ps(1e-12)),
                    _mm256_cmp_ps::<_CMP_GE_OQ>(u, zero),
                ),
                and(_mm256_cmp_ps::<_CMP_GE_OQ>(v, zero), _mm256_cmp_ps::<_CMP_LE_OQ>(add(u, v), abs_det)),
            ),
            and(
                _mm256_cmp_ps::<_CMP_GT_OQ>(t, mul(_mm256_set1_ps(t_min), abs_det)),
                _mm256_cmp_ps::<_CMP_LT_OQ>(t, mul(_mm256_set1_ps(t_max), abs_det)),
            ),
        );
        (ok, [det, n1, n2, nt])
    }

    /// The nearest of the eight triangles hit within (t_min, t_max), as (lane, t, b1, b2):
    /// the same numbers `nearest_lane` computes lane by lane (t = n_t · (1/det), and so on),
    /// here for all eight lanes at once and reduced to the smallest t without a branch per
    /// lane, whose count is as unpredictable as the ray.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn nearest(&self, b: &Tri8, t_min: f32, t_max: f32) -> Option<(usize, f32, f32, f32)> {
        let (ok, [det, n1, n2, nt]) = self.hits(b, t_min, t_max);
        if _mm256_movemask_ps(ok) == 0 {
            return None;
        }
        let inv = _mm256_div_ps(_mm256_set1_ps(1.0), det);
        let t = _mm256_mul_ps(nt, inv);
        let inside = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(t, _mm256_set1_ps(t_min)),
            _mm256_cmp_ps::<_CMP_LT_OQ>(t, _mm256_set1_ps(t_max)),
        );
        let valid = _mm256_and_ps(ok, inside);
        let mask = _mm256_movemask_ps(valid) as u32;
        if mask == 0 {
            return None;
        }
        // Lanes not hit become +∞, then the minimum is spread to every lane.
        let tm = _mm256_blendv_ps(_mm256_set1_ps(f32::INFINITY), t, valid);
        let m = _mm256_min_ps(tm, _mm256_permute2f128_ps::<1>(tm, tm));
        let m = _mm256_min_ps(m, _mm256_permute_ps::<0b0100_1110>(m));
        let m = _mm256_min_ps(m, _mm256_permute_ps::<0b1011_0001>(m));
        let lane =
            (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(tm, m)) as u32 & mask).trailing_zeros() as usize;
        let (inv, n1, n2) = (lanes(inv), lanes(n1), lanes(n2));
        Some((lane, _mm256_cvtss_f32(m), n1[lane] * inv[lane], n2[lane] * inv[lane]))
    }
}
