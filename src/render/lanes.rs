//! Eight paths at once: `Scene::trace` for scenes of Lambertian surfaces lit by triangle area
//! lights, point lights and directional lights (the Cornell box, the calibration and
//! photometric scenes), with the shading between hits done for eight paths in the lanes of
//! AVX2 registers.
//!
//! Rays are still traced one at a time (the BVH's 8-wide tests already use the lanes for one
//! ray), and so are a hit's surface look-ups and a new path's camera ray. What the lanes take
//! over is the rest of a vertex: the light pick (a branch-free binary search over the power
//! CDF) and the light sample, the shadow ray's set-up, the Lambertian contribution, the
//! cosine-weighted bounce (Malley's method with `bsdf::unit_circle`'s polynomials), the
//! throughput, Russian roulette, and the random numbers themselves: PCG32 with 64-bit products
//! built from 32-bit ones, and Owen-scrambled Sobol points with the scramble seeds looked up
//! per pixel (they do not depend on the sample). A lane whose path ends takes the next
//! (pixel, sample) of its group of pixels at once, so the lanes stay full while paths of
//! different lengths run side by side.
//!
//! Every lane performs the scalar loop's floating-point and integer operations in the same
//! order, draws the same numbers from its own (pixel, sample) stream, and the film sums each
//! pixel's samples in sample order, so the image is bit-identical to the scalar loop's
//! (tested on both samplers, a thin lens, spheres, textures and every light kind taken).
//! Scenes with anything else (glossy or delta materials, textured roughness, spot, sphere or
//! environment lights) and processors without AVX2 take the scalar loop.
//!
//! Written with `std::arch` intrinsics behind small operator types rather than a SIMD crate,
//! for the reason the BVH's 8-wide module gives: glam stops at four lanes, and the lanes must
//! reproduce the scalar code's rounding exactly. On the Cornell box (callgrind, `lumen bench
//! render --spp 8 --threads 1`, instructions per path; alternating runs at 64 spp on 2
//! threads for time):
//!
//! | sampler | one path at a time | eight lanes | speed |
//! |---|---:|---:|---:|
//! | independent | 4210 | 3395 (−19 %) | 1.21× |
//! | Sobol | 4686 | 3569 (−24 %) | 1.32× |
//!
//! Of the 3395 instructions left, closest-hit traversal takes about 1680 and shadow rays 620.
//! Tried and not kept: gathering the hit's normal, material and albedo for the lanes from
//! per-primitive tables (−1.9 % instructions, no faster: the gathers cost what the scalar
//! loads did).

use super::bsdf::Bsdf;
use super::camera_ray::{camera_direction, camera_ray, needs_lens_sample};
use super::film::{pixel_stats, Settings, RR_START};
use super::geometry::{Prim, Ray};
use super::sampler::{self, Sampler, SamplerKind};
use super::scene::{Light, Scene};
use glam::Vec3A;

/// Whether `render` may draw this scene eight paths at a time.
pub fn supported(scene: &Scene, settings: &Settings) -> bool {
    simd::available()
        && settings.max_depth >= 1
        // The light pick gathers from the light table: a scene without a light (or whose
        // emitters are all black) takes the one-path loop, which renders it black.
        && !scene.lights.is_empty()
        && scene.environment_light.is_none()
        && scene.materials.iter().all(|m| matches!(m.bsdf, Bsdf::Lambertian) && m.roughness.is_none())
        && scene.lights.iter().all(|l| match *l {
            Light::Point { .. } | Light::Directional { .. } => true,
            Light::Area { prim, .. } => matches!(scene.bvh.prims[prim as usize], Prim::Triangle { .. }),
            _ => false,
        })
}

/// Samples per group of pixels whose paths share the lanes: enough that the group's last,
/// longest paths leave the lanes idle for a small share of the time.
const GROUP_SAMPLES: usize = 4096;

/// A scene `supported` accepts, with its lights laid out for the lanes (once per render).
pub struct Tracer<'a> {
    scene: &'a Scene,
    lights: LightTable,
}

impl<'a> Tracer<'a> {
    /// `None` where the scene or the processor needs the one-path loop.
    pub fn new(scene: &'a Scene, settings: &Settings) -> Option<Tracer<'a>> {
        supported(scene, settings).then(|| Tracer { scene, lights: LightTable::new(scene) })
    }

    /// Mean, variance of the mean and dropped samples of the pixels x0..x1 of row y, as
    /// `integrator::render_pixel` gives them.
    pub fn render_row(
        &self,
        settings: &Settings,
        y: u32,
        x0: u32,
        x1: u32,
    ) -> Vec<([f32; 3], [f32; 3], u64)> {
        let spp = settings.spp as usize;
        if spp == 0 {
            return (x0..x1).map(|_| pixel_stats(std::iter::empty())).collect();
        }
        let group = (GROUP_SAMPLES / spp).max(1) as u32;
        let mut out = Vec::with_capacity((x1 - x0) as usize);
        let mut radiance = Vec::new();
        let mut gx = x0;
        while gx < x1 {
            let gx1 = (gx + group).min(x1);
            radiance.clear();
            radiance.resize((gx1 - gx) as usize * spp, Vec3A::ZERO);
            // SAFETY: `supported` checked that the processor has AVX2.
            unsafe { simd::trace_group(self.scene, &self.lights, settings, y, gx, gx1, &mut radiance) };
            out.extend(radiance.chunks(spp).map(|c| pixel_stats(c.iter().copied())));
            gx = gx1;
        }
        out
    }
}

/// The lights as the lanes gather them by index, one array per component: a triangle (v0,
/// e1, e2, unit normal, area), a point (position in v0) or a direction (towards the light, in
/// v0), and `power`: radiance, intensity or irradiance.
struct LightTable {
    v0: [Vec<f32>; 3],
    e1: [Vec<f32>; 3],
    e2: [Vec<f32>; 3],
    n: [Vec<f32>; 3],
    power: [Vec<f32>; 3],
    area: Vec<f32>,
    kind: Vec<i32>,
}

const TRIANGLE: i32 = 0;
const POINT: i32 = 1;
const DIRECTIONAL: i32 = 2;

impl LightTable {
    fn new(scene: &Scene) -> LightTable {
        let none = || [Vec::new(), Vec::new(), Vec::new()];
        let mut t = LightTable {
            v0: none(),
            e1: none(),
            e2: none(),
            n: none(),
            power: none(),
            area: Vec::new(),
            kind: Vec::new(),
        };
        for light in &scene.lights {
            let z = Vec3A::ZERO;
            let (kind, v0, e1, e2, n, power, area) = match *light {
                Light::Point { position, intensity } => (POINT, position, z, z, z, intensity, 0.0),
                Light::Directional { to_light, irradiance } => {
                    (DIRECTIONAL, to_light, z, z, z, irradiance, 0.0)
                }
                Light::Area { prim, radiance, area } => match scene.bvh.prims[prim as usize] {
                    Prim::Triangle { v0, e1, e2 } => {
                        (TRIANGLE, v0, e1, e2, scene.info[prim as usize].normal, radiance, area)
                    }
                    Prim::Sphere { .. } => (TRIANGLE, z, z, z, z, z, 0.0),
                },
                _ => (TRIANGLE, z, z, z, z, z, 0.0),
            };
            for (table, v) in
                [(&mut t.v0, v0), (&mut t.e1, e1), (&mut t.e2, e2), (&mut t.n, n), (&mut t.power, power)]
            {
                for a in 0..3 {
                    table[a].push(v[a]);
                }
            }
            t.area.push(area);
            t.kind.push(kind);
        }
        t
    }
}

#[cfg(not(target_arch = "x86_64"))]
mod simd {
    pub fn available() -> bool {
        false
    }
    pub unsafe fn trace_group(
        _: &super::Scene,
        _: &super::LightTable,
        _: &super::Settings,
        _: u32,
        _: u32,
        _: u32,
        _: &mut [super::Vec3A],
    ) {
        unreachable!("supported() is false without AVX2")
    }
}

#[cfg(target_arch = "x86_64")]
mod simd {
    use super::*;
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

    pub fn available() -> bool {
        is_x86_feature_detected!("avx2")
    }

    /// Eight f32 lanes. The operators are IEEE single operations lane by lane, as the scalar
    /// code's; they are inlined into the AVX2 function that uses them.
    #[derive(Clone, Copy)]
    struct F(__m256);

    /// A lane mask: all bits set where true.
    #[derive(Clone, Copy)]
    struct M(__m256);

    macro_rules! binop {
        ($trait:ident, $f:ident, $intr:ident) => {
            impl $trait for F {
                type Output = F;
                #[inline(always)]
                fn $f(self, o: F) -> F {
                    // SAFETY: only reached inside `trace_group`, which requires AVX2.
                    F(unsafe { $intr(self.0, o.0) })
                }
            }
        };
    }
    binop!(Add, add, _mm256_add_ps);
    binop!(Sub, sub, _mm256_sub_ps);
    binop!(Mul, mul, _mm256_mul_ps);
    binop!(Div, div, _mm256_div_ps);

    impl Neg for F {
        type Output = F;
        #[inline(always)]
        fn neg(self) -> F {
            // SAFETY: as in `binop`.
            F(unsafe { _mm256_xor_ps(self.0, _mm256_set1_ps(-0.0)) })
        }
    }

    impl BitAnd for M {
        type Output = M;
        #[inline(always)]
        fn bitand(self, o: M) -> M {
            // SAFETY: as in `binop`.
            M(unsafe { _mm256_and_ps(self.0, o.0) })
        }
    }

    impl BitOr for M {
        type Output = M;
        #[inline(always)]
        fn bitor(self, o: M) -> M {
            // SAFETY: as in `binop`.
            M(unsafe { _mm256_or_ps(self.0, o.0) })
        }
    }

    impl Not for M {
        type Output = M;
        #[inline(always)]
        fn not(self) -> M {
            // SAFETY: as in `binop`.
            M(unsafe { _mm256_xor_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(-1))) })
        }
    }

    macro_rules! cmp {
        ($f:ident, $pred:ident) => {
            #[inline(always)]
            fn $f(self, o: F) -> M {
                // SAFETY: as in `binop`.
                M(unsafe { _mm256_cmp_ps::<$pred>(self.0, o.0) })
            }
        };
    }

    impl F {
        #[inline(always)]
        fn splat(v: f32) -> F {
            // SAFETY: as in `binop`.
            F(unsafe { _mm256_set1_ps(v) })
        }
        #[inline(always)]
        fn load(v: &[f32; 8]) -> F {
            // SAFETY: reads the eight floats of `v`; as in `binop` otherwise.
            F(unsafe { _mm256_loadu_ps(v.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, v: &mut [f32; 8]) {
            // SAFETY: writes the eight floats of `v`; as in `binop` otherwise.
            unsafe { _mm256_storeu_ps(v.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn sqrt(self) -> F {
            // SAFETY: as in `binop`.
            F(unsafe { _mm256_sqrt_ps(self.0) })
        }
        /// `f32::min` / `max` for numbers (SSE's operand order, which glam's `max_element`
        /// also uses).
        #[inline(always)]
        fn min(self, o: F) -> F {
            // SAFETY: as in `binop`.
            F(unsafe { _mm256_min_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn max(self, o: F) -> F {
            // SAFETY: as in `binop`.
            F(unsafe { _mm256_max_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn abs(self) -> F {
            // SAFETY: as in `binop`.
            F(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) })
        }
        #[inline(always)]
        fn bits(self) -> __m256i {
            // SAFETY: as in `binop`.
            unsafe { _mm256_castps_si256(self.0) }
        }
        #[inline(always)]
        fn from_bits(v: __m256i) -> F {
            // SAFETY: as in `binop`.
            F(unsafe { _mm256_castsi256_ps(v) })
        }
        /// Lane i gets `table[index[i]]`; every index must be in bounds.
        #[inline(always)]
        fn gather(table: &[f32], index: __m256i) -> F {
            // SAFETY: the callers' indices are in 0..table.len(); as in `binop` otherwise.
            F(unsafe { _mm256_i32gather_ps::<4>(table.as_ptr(), index) })
        }
        cmp!(le, _CMP_LE_OQ);
        cmp!(gt, _CMP_GT_OQ);
        cmp!(ge, _CMP_GE_OQ);
        cmp!(eq, _CMP_EQ_OQ);
    }

    impl M {
        /// `a` where true, `b` elsewhere.
        #[inline(always)]
        fn select(self, a: F, b: F) -> F {
            // SAFETY: as in `binop`.
            F(unsafe { _mm256_blendv_ps(b.0, a.0, self.0) })
        }
        #[inline(always)]
        fn bits(self) -> u32 {
            // SAFETY: as in `binop`.
            unsafe { _mm256_movemask_ps(self.0) as u32 }
        }
        #[inline(always)]
        fn from_bits(bits: u32) -> M {
            // SAFETY: as in `binop`.
            unsafe {
                let lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
                let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bit);
                M(_mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane_bit)))
            }
        }
    }

    /// Eight 3-vectors, one per lane.
    #[derive(Clone, Copy)]
    struct V {
        x: F,
        y: F,
        z: F,
    }

    impl V {
        #[inline(always)]
        fn load(v: &[[f32; 8]; 3]) -> V {
            V { x: F::load(&v[0]), y: F::load(&v[1]), z: F::load(&v[2]) }
        }
        #[inline(always)]
        fn store(self, v: &mut [[f32; 8]; 3]) {
            self.x.store(&mut v[0]);
            self.y.store(&mut v[1]);
            self.z.store(&mut v[2]);
        }
        #[inline(always)]
        fn gather(table: &[Vec<f32>; 3], index: __m256i) -> V {
            V {
                x: F::gather(&table[0], index),
                y: F::gather(&table[1], index),
                z: F::gather(&table[2], index),
            }
        }
        /// glam's `Vec3A::dot` order: (x·x' + y·y') + z·z'.
        #[inline(always)]
        fn dot(self, o: V) -> F {
            self.x * o.x + self.y * o.y + self.z * o.z
        }
        #[inline(always)]
        fn add(self, o: V) -> V {
            V { x: self.x + o.x, y: self.y + o.y, z: self.z + o.z }
        }
        #[inline(always)]
        fn sub(self, o: V) -> V {
            V { x: self.x - o.x, y: self.y - o.y, z: self.z - o.z }
        }
        #[inline(always)]
        fn mul(self, o: V) -> V {
            V { x: self.x * o.x, y: self.y * o.y, z: self.z * o.z }
        }
        #[inline(always)]
        fn scale(self, s: F) -> V {
            V { x: self.x * s, y: self.y * s, z: self.z * s }
        }
        #[inline(always)]
        fn div(self, s: F) -> V {
            V { x: self.x / s, y: self.y / s, z: self.z / s }
        }
        #[inline(always)]
        fn neg(self) -> V {
            V { x: -self.x, y: -self.y, z: -self.z }
        }
        #[inline(always)]
        fn select(m: M, a: V, b: V) -> V {
            V { x: m.select(a.x, b.x), y: m.select(a.y, b.y), z: m.select(a.z, b.z) }
        }
        /// glam's `Vec3A::max_element` order: max(max(x, z), y).
        #[inline(always)]
        fn max_element(self) -> F {
            self.x.max(self.z).max(self.y)
        }
    }

    /// Lane i gets `table[index[i]]`; every index must be in bounds.
    #[inline(always)]
    fn gather_i(table: &[i32], index: __m256i) -> __m256i {
        // SAFETY: the callers' indices are in 0..table.len(); as in `binop` otherwise.
        unsafe { _mm256_i32gather_epi32::<4>(table.as_ptr(), index) }
    }

    /// `Scene::pick_light`, lane by lane: (light index, pick probability, the pick number
    /// stretched over the light's share). The index is a branch-free binary search for the
    /// partition point that `partition_point` finds; the probability is 0 where the scalar
    /// pick gives `None` (no light, or one of zero power).
    #[inline(always)]
    fn pick_light(cdf: &[f32], u: F) -> (__m256i, F, F) {
        let n = cdf.len().saturating_sub(1);
        // SAFETY: indices stay within cdf (see below); as in `binop` otherwise.
        unsafe {
            let zero = F::splat(0.0);
            if n == 0 {
                return (_mm256_setzero_si256(), zero, zero);
            }
            // The partition point P of cdf[1..=n] under c ≤ u lies in [base, base + size].
            let upper = &cdf[1..];
            let mut base = _mm256_setzero_si256();
            let mut size = n;
            while size > 1 {
                let half = size / 2;
                let mid = _mm256_add_epi32(base, _mm256_set1_epi32(half as i32));
                let below = F::gather(upper, mid).le(u);
                base = _mm256_castps_si256(_mm256_blendv_ps(
                    _mm256_castsi256_ps(base),
                    _mm256_castsi256_ps(mid),
                    below.0,
                ));
                size -= half;
            }
            let below = F::gather(upper, base).le(u);
            // P = base + 1 where cdf[1 + base] ≤ u (the mask is −1 there), then min(P, n − 1).
            let p = _mm256_sub_epi32(base, _mm256_castps_si256(below.0));
            let i = _mm256_min_epi32(p, _mm256_set1_epi32(n as i32 - 1));
            let lo = F::gather(cdf, i);
            let prob = F::gather(cdf, _mm256_add_epi32(i, _mm256_set1_epi32(1))) - lo;
            let ok = prob.gt(zero);
            let reused = ((u - lo) / prob).max(zero).min(F::splat(1.0 - f32::EPSILON / 2.0));
            (i, ok.select(prob, zero), reused)
        }
    }

    /// `bsdf::unit_circle`, lane by lane.
    #[inline(always)]
    fn unit_circle(u: F) -> (F, F) {
        let v = F::splat(4.0) * u;
        let shifted = v + F::splat(8_388_608.0);
        let q = shifted.bits();
        let t = (v - (shifted - F::splat(8_388_608.0))) * F::splat(std::f32::consts::FRAC_PI_2);
        let t2 = t * t;
        let c = |x: f32| F::splat(x);
        let sin = t
            * (c(1.0)
                + t2 * (c(-1.0 / 6.0)
                    + t2 * (c(1.0 / 120.0) + t2 * (c(-1.0 / 5040.0) + t2 * c(1.0 / 362_880.0)))));
        let cos =
            c(1.0) + t2 * (c(-0.5) + t2 * (c(1.0 / 24.0) + t2 * (c(-1.0 / 720.0) + t2 * c(1.0 / 40_320.0))));
        // SAFETY: as in `binop`.
        unsafe {
            let one = _mm256_set1_epi32(1);
            let two = _mm256_set1_epi32(2);
            let swap = M(_mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(q, one), one)));
            let (cb, sb) = (swap.select(sin, cos).bits(), swap.select(cos, sin).bits());
            let c_sign = _mm256_slli_epi32::<30>(_mm256_and_si256(_mm256_add_epi32(q, one), two));
            let s_sign = _mm256_slli_epi32::<30>(_mm256_and_si256(q, two));
            (F::from_bits(_mm256_xor_si256(cb, c_sign)), F::from_bits(_mm256_xor_si256(sb, s_sign)))
        }
    }

    /// `bsdf::basis`, lane by lane.
    #[inline(always)]
    fn basis(n: V) -> (V, V) {
        // SAFETY: as in `binop`.
        let s = F(unsafe { _mm256_or_ps(_mm256_and_ps(n.z.0, _mm256_set1_ps(-0.0)), _mm256_set1_ps(1.0)) });
        let a = F::splat(-1.0) / (s + n.z);
        let b = n.x * n.y * a;
        (
            V { x: F::splat(1.0) + s * n.x * n.x * a, y: s * b, z: -s * n.x },
            V { x: b, y: s + n.y * n.y * a, z: -n.y },
        )
    }

    /// Eight unsigned 64-bit lanes, as two registers (lanes 0–3, 4–7).
    #[derive(Clone, Copy)]
    struct U64([__m256i; 2]);

    impl U64 {
        #[inline(always)]
        fn load(v: &[u64; 8]) -> U64 {
            // SAFETY: reads the eight integers of `v`; as in `binop` otherwise.
            unsafe {
                U64([_mm256_loadu_si256(v.as_ptr().cast()), _mm256_loadu_si256(v[4..].as_ptr().cast())])
            }
        }
        #[inline(always)]
        fn store(self, v: &mut [u64; 8]) {
            // SAFETY: writes the eight integers of `v`; as in `binop` otherwise.
            unsafe {
                _mm256_storeu_si256(v.as_mut_ptr().cast(), self.0[0]);
                _mm256_storeu_si256(v[4..].as_mut_ptr().cast(), self.0[1]);
            }
        }
        #[inline(always)]
        fn map(self, f: impl Fn(__m256i) -> __m256i) -> U64 {
            U64([f(self.0[0]), f(self.0[1])])
        }
        #[inline(always)]
        fn zip(self, o: U64, f: impl Fn(__m256i, __m256i) -> __m256i) -> U64 {
            U64([f(self.0[0], o.0[0]), f(self.0[1], o.0[1])])
        }
        #[inline(always)]
        fn xor(self, o: U64) -> U64 {
            // SAFETY: as in `binop`.
            self.zip(o, |a, b| unsafe { _mm256_xor_si256(a, b) })
        }
        #[inline(always)]
        fn add(self, c: u64) -> U64 {
            // SAFETY: as in `binop`.
            self.map(|a| unsafe { _mm256_add_epi64(a, _mm256_set1_epi64x(c as i64)) })
        }
        #[inline(always)]
        fn shr<const S: i32>(self) -> U64 {
            // SAFETY: as in `binop`.
            self.map(|a| unsafe { _mm256_srli_epi64::<S>(a) })
        }
        /// The low 64 bits of the product with c (`u64::wrapping_mul`), from 32-bit products.
        #[inline(always)]
        fn mul(self, c: u64) -> U64 {
            // SAFETY: as in `binop`.
            self.map(|a| unsafe {
                let (lo, hi) =
                    (_mm256_set1_epi64x((c & 0xffff_ffff) as i64), _mm256_set1_epi64x((c >> 32) as i64));
                let cross = _mm256_add_epi64(
                    _mm256_mul_epu32(_mm256_srli_epi64::<32>(a), lo),
                    _mm256_mul_epu32(a, hi),
                );
                _mm256_add_epi64(_mm256_mul_epu32(a, lo), _mm256_slli_epi64::<32>(cross))
            })
        }
        /// The low 32 bits of the eight lanes (`as u32`), as eight 32-bit lanes.
        #[inline(always)]
        fn low_halves(self) -> __m256i {
            // SAFETY: as in `binop`.
            unsafe {
                let (a, b) = (_mm256_castsi256_ps(self.0[0]), _mm256_castsi256_ps(self.0[1]));
                // Per 128-bit half: a's two low dwords, then b's; then the 64-bit pairs in order.
                let mixed = _mm256_shuffle_ps::<0b10_00_10_00>(a, b);
                _mm256_permute4x64_epi64::<0b11_01_10_00>(_mm256_castps_si256(mixed))
            }
        }
        /// `m` (eight 32-bit lanes, all bits or none) as the mask of the matching 64-bit lanes.
        #[inline(always)]
        fn widen(m: __m256i) -> U64 {
            // SAFETY: as in `binop`.
            unsafe {
                U64([
                    _mm256_cvtepi32_epi64(_mm256_castsi256_si128(m)),
                    _mm256_cvtepi32_epi64(_mm256_extracti128_si256::<1>(m)),
                ])
            }
        }
        /// `a` where the 32-bit lane mask `m` is set, `b` elsewhere.
        #[inline(always)]
        fn select(m: __m256i, a: U64, b: U64) -> U64 {
            let w = U64::widen(m);
            // SAFETY: as in `binop`.
            U64([0, 1].map(|h| unsafe { _mm256_blendv_epi8(b.0[h], a.0[h], w.0[h]) }))
        }
    }

    /// `sampler::lk_hash`, lane by lane.
    #[inline(always)]
    fn lk_hash(x: __m256i, seed: __m256i) -> __m256i {
        // SAFETY: as in `binop`.
        unsafe {
            let mul = |a, c: u32| _mm256_mullo_epi32(a, _mm256_set1_epi32(c as i32));
            let x = _mm256_xor_si256(x, mul(x, sampler::LK_MUL[0]));
            let x = _mm256_add_epi32(x, seed);
            let x =
                _mm256_mullo_epi32(x, _mm256_or_si256(_mm256_srli_epi32::<16>(seed), _mm256_set1_epi32(1)));
            let x = _mm256_xor_si256(x, mul(x, sampler::LK_MUL[1]));
            _mm256_xor_si256(x, mul(x, sampler::LK_MUL[2]))
        }
    }

    /// `u32::reverse_bits`, lane by lane: the bytes swapped, then each byte's nibbles looked up
    /// reversed and swapped.
    #[inline(always)]
    fn reverse_bits(x: __m256i) -> __m256i {
        // SAFETY: as in `binop`.
        unsafe {
            let bytes = _mm256_setr_epi8(
                3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8,
                15, 14, 13, 12,
            );
            let x = _mm256_shuffle_epi8(x, bytes);
            let nibble = _mm256_setr_epi8(
                0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15, 0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13,
                3, 11, 7, 15,
            );
            let low = _mm256_set1_epi8(0x0f);
            let lo = _mm256_shuffle_epi8(nibble, _mm256_and_si256(x, low));
            let hi = _mm256_shuffle_epi8(nibble, _mm256_and_si256(_mm256_srli_epi16::<4>(x), low));
            _mm256_or_si256(_mm256_slli_epi16::<4>(lo), hi)
        }
    }

    /// `sampler::sobol_dim1_reversed`, lane by lane.
    #[inline(always)]
    fn sobol_dim1_reversed(i: __m256i) -> __m256i {
        let mut v = i;
        for (shift, mask) in sampler::SUPERSET_STEPS {
            // SAFETY: as in `binop`.
            v = unsafe {
                let shifted = _mm256_srl_epi32(v, _mm_cvtsi32_si128(shift as i32));
                _mm256_xor_si256(v, _mm256_and_si256(shifted, _mm256_set1_epi32(mask as i32)))
            };
        }
        v
    }

    /// `sampler::to_unit` (the top 24 bits as a float in [0, 1)), lane by lane.
    #[inline(always)]
    fn to_unit(bits: __m256i) -> F {
        // SAFETY: as in `binop`.
        let value = unsafe { F(_mm256_cvtepi32_ps(_mm256_srli_epi32::<8>(bits))) };
        value * F::splat(1.0 / (1u32 << 24) as f32)
    }

    /// The eight lanes' `Sampler`s, structure of arrays, drawn from together, and the Sobol
    /// scramble seeds of the group's pixels.
    #[derive(Default)]
    struct Samplers {
        pcg: [u64; 8],
        sobol_left: [u32; 8],
        index_reversed: [u32; 8],
        dim: [u32; 8],
        /// Per lane, where its pixel's rows of `seeds` start.
        seed_row: [u32; 8],
        /// (index shuffle, x, y) seeds per pixel of the group and Sobol dimension
        /// (`sampler::sobol_seeds`), pixel-major; empty without Sobol points.
        seeds: [Vec<u32>; 3],
    }

    const DIMS: u32 = sampler::SOBOL_DIMENSIONS as u32;

    impl Samplers {
        fn new(settings: &Settings, y: u32, gx0: u32, gx1: u32, width: u32) -> Samplers {
            let mut s = Samplers::default();
            if settings.sampler == SamplerKind::Sobol {
                for x in gx0..gx1 {
                    let pixel = y as u64 * width as u64 + x as u64;
                    for (hi, hx, hy) in sampler::sobol_seeds(settings.seed, pixel) {
                        s.seeds[0].push(hi);
                        s.seeds[1].push(hx);
                        s.seeds[2].push(hy);
                    }
                }
            }
            s
        }

        /// Lane `lane` continues `s`, a sampler of the group's pixel `x_local`.
        fn set(&mut self, lane: usize, s: &Sampler, x_local: u32) {
            let dim;
            (self.pcg[lane], self.sobol_left[lane], self.index_reversed[lane], dim) = s.parts();
            self.dim[lane] = dim.min(DIMS as u64) as u32;
            self.seed_row[lane] = x_local * DIMS;
        }

        /// `Sampler::next2` (or `next` when `two` is false, the second number then 0) for the
        /// lanes of `want`; the other lanes' streams do not move.
        #[inline(always)]
        fn next(&mut self, want: u32, two: bool) -> (F, F) {
            let zero = F::splat(0.0);
            if want == 0 {
                return (zero, zero);
            }
            // SAFETY: as in `binop`.
            unsafe {
                let want_m = M::from_bits(want);
                let left = _mm256_loadu_si256(self.sobol_left.as_ptr().cast());
                let sobol_m = _mm256_and_si256(
                    _mm256_cmpgt_epi32(left, _mm256_setzero_si256()),
                    _mm256_castps_si256(want_m.0),
                );
                let sobol = _mm256_movemask_ps(_mm256_castsi256_ps(sobol_m)) as u32;
                let (mut x, mut y) = (zero, zero);
                let pcg = want & !sobol;
                if pcg != 0 {
                    let old = U64::load(&self.pcg);
                    let (a, state) = pcg_step(old);
                    let (b, state) = if two { pcg_step(state) } else { (zero, state) };
                    let m = _mm256_castps_si256(M::from_bits(pcg).0);
                    U64::select(m, state, old).store(&mut self.pcg);
                    (x, y) = (a, b);
                }
                if sobol != 0 {
                    // `Sobol::seeds` (looked up), then `Sobol::next2` / `next`. A lane with
                    // Sobol requests left is at a dimension below DIMS; the others' look-ups
                    // are clamped into the table and not used.
                    let dim = _mm256_loadu_si256(self.dim.as_ptr().cast());
                    let row = _mm256_add_epi32(
                        _mm256_loadu_si256(self.seed_row.as_ptr().cast()),
                        _mm256_min_epu32(dim, _mm256_set1_epi32(DIMS as i32 - 1)),
                    );
                    let seed = |k: usize| _mm256_i32gather_epi32::<4>(self.seeds[k].as_ptr().cast(), row);
                    _mm256_storeu_si256(self.dim.as_mut_ptr().cast(), _mm256_sub_epi32(dim, sobol_m));
                    _mm256_storeu_si256(self.sobol_left.as_mut_ptr().cast(), _mm256_add_epi32(left, sobol_m));
                    let (hi, hx) = (seed(0), seed(1));
                    let index = _mm256_loadu_si256(self.index_reversed.as_ptr().cast());
                    let i = reverse_bits(lk_hash(index, hi));
                    let sm = M(_mm256_castsi256_ps(sobol_m));
                    x = sm.select(to_unit(reverse_bits(lk_hash(i, hx))), x);
                    if two {
                        let hy = seed(2);
                        y = sm.select(to_unit(reverse_bits(lk_hash(sobol_dim1_reversed(i), hy))), y);
                    }
                }
                (x, y)
            }
        }
    }

    /// One PCG32 step (`Sampler::pcg`) on eight streams: the number and the next state.
    #[inline(always)]
    fn pcg_step(old: U64) -> (F, U64) {
        let state = old.mul(sampler::PCG_MUL).add(sampler::PCG_INC);
        let xorshifted = old.shr::<18>().xor(old).shr::<27>().low_halves();
        let rot = old.shr::<59>().low_halves();
        // SAFETY: as in `binop`.
        unsafe {
            // Rotate right by rot (a left shift by 32 gives 0, so rot = 0 is the value itself).
            let left = _mm256_sub_epi32(_mm256_set1_epi32(32), rot);
            let out =
                _mm256_or_si256(_mm256_srlv_epi32(xorshifted, rot), _mm256_sllv_epi32(xorshifted, left));
            (to_unit(out), state)
        }
    }

    /// The state of the eight lanes' paths, structure of arrays.
    struct Lanes {
        origin: [[f32; 8]; 3],
        dir: [[f32; 8]; 3],
        beta: [[f32; 8]; 3],
        l: [[f32; 8]; 3],
        depth: [u32; 8],
        /// Index of the lane's sample in the group's radiance buffer, and its pixel's column.
        slot: [usize; 8],
        x: [u32; 8],
        samplers: Samplers,
        active: u32,
    }

    /// What a vertex's shading needs from the hit and the sampler, per lane.
    #[derive(Default)]
    struct Vertex {
        p: [[f32; 8]; 3],
        n: [[f32; 8]; 3],
        albedo: [[f32; 8]; 3],
    }

    #[inline(always)]
    fn put(a: &mut [[f32; 8]; 3], lane: usize, v: Vec3A) {
        a[0][lane] = v.x;
        a[1][lane] = v.y;
        a[2][lane] = v.z;
    }

    #[inline(always)]
    fn get(a: &[[f32; 8]; 3], lane: usize) -> Vec3A {
        Vec3A::new(a[0][lane], a[1][lane], a[2][lane])
    }

    /// Traces every sample of the pixels gx0..gx1 of row y into `radiance` (pixel-major,
    /// sample order within a pixel).
    ///
    /// # Safety
    /// The processor must have AVX2 (`available()`).
    #[target_feature(enable = "avx2")]
    pub unsafe fn trace_group(
        scene: &Scene,
        lights: &LightTable,
        settings: &Settings,
        y: u32,
        gx0: u32,
        gx1: u32,
        radiance: &mut [Vec3A],
    ) {
        let spp = settings.spp;
        let max_depth = settings.max_depth;
        let jobs = (gx1 - gx0) as usize * spp as usize;
        let mut next_job = 0;
        let mut lanes = Lanes {
            origin: [[0.0; 8]; 3],
            dir: [[0.0; 8]; 3],
            beta: [[0.0; 8]; 3],
            l: [[0.0; 8]; 3],
            depth: [0; 8],
            slot: [0; 8],
            x: [0; 8],
            samplers: Samplers::new(settings, y, gx0, gx1, scene.camera.width),
            active: 0,
        };
        let mut v = Vertex::default();
        loop {
            // Empty lanes take the next samples (`integrator::camera_path`, with the pixel
            // position and a thin lens's sample drawn for the new lanes together).
            let mut fresh = 0u32;
            let mut empty = !lanes.active & 0xff;
            while empty != 0 && next_job < jobs {
                let lane = empty.trailing_zeros() as usize;
                empty &= empty - 1;
                let slot = next_job;
                next_job += 1;
                let (x, k) = (gx0 + (slot / spp as usize) as u32, (slot % spp as usize) as u32);
                let pixel = y as u64 * scene.camera.width as u64 + x as u64;
                let s = Sampler::with_kind(settings.sampler, settings.seed, pixel, k as u64);
                lanes.samplers.set(lane, &s, x - gx0);
                lanes.slot[lane] = slot;
                lanes.x[lane] = x;
                fresh |= 1 << lane;
            }
            if lanes.active == 0 && fresh == 0 {
                return;
            }
            if fresh != 0 {
                let mut jitter = ([0.0f32; 8], [0.0f32; 8]);
                let (jx, jy) = lanes.samplers.next(fresh, true);
                jx.store(&mut jitter.0);
                jy.store(&mut jitter.1);
                let mut dirs = [glam::DVec3::ZERO; 8];
                let (mut seen, mut lens) = (0u32, 0u32);
                let mut mask = fresh;
                while mask != 0 {
                    let lane = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    // Beyond the fold of the distortion the sample is black, as the buffer is.
                    if let Some(d) =
                        camera_direction(scene, lanes.x[lane], y, (jitter.0[lane], jitter.1[lane]))
                    {
                        dirs[lane] = d;
                        seen |= 1 << lane;
                        lens |= (needs_lens_sample(scene, d) as u32) << lane;
                    }
                }
                let mut lens_u = ([0.0f32; 8], [0.0f32; 8]);
                if lens != 0 {
                    let (lx, ly) = lanes.samplers.next(lens, true);
                    lx.store(&mut lens_u.0);
                    ly.store(&mut lens_u.1);
                }
                let mut mask = seen;
                while mask != 0 {
                    let lane = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let u = (lens & (1 << lane) != 0).then_some((lens_u.0[lane], lens_u.1[lane]));
                    let ray = camera_ray(scene, dirs[lane], u);
                    lanes.depth[lane] = 1;
                    put(&mut lanes.origin, lane, ray.origin);
                    put(&mut lanes.dir, lane, ray.dir);
                    put(&mut lanes.beta, lane, Vec3A::ONE);
                    put(&mut lanes.l, lane, Vec3A::ZERO);
                }
                lanes.active |= seen;
                if lanes.active == 0 {
                    continue;
                }
            }
            // Hits, emission seen from the camera, and what shading needs, lane by lane.
            let mut shade = 0u32;
            let mut mask = lanes.active;
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let ray = Ray { origin: get(&lanes.origin, lane), dir: get(&lanes.dir, lane) };
                let depth = lanes.depth[lane];
                let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) else {
                    radiance[lanes.slot[lane]] = get(&lanes.l, lane);
                    lanes.active &= !(1 << lane);
                    continue;
                };
                let surf = scene.surface(&ray, &hit);
                let mat = &scene.materials[surf.material as usize];
                if let Some(le) = mat.emission {
                    if depth == 1 && surf.n.dot(-ray.dir) > 0.0 {
                        let l = get(&lanes.l, lane) + get(&lanes.beta, lane) * le;
                        put(&mut lanes.l, lane, l);
                    }
                }
                if depth == max_depth {
                    radiance[lanes.slot[lane]] = get(&lanes.l, lane);
                    lanes.active &= !(1 << lane);
                    continue;
                }
                shade |= 1 << lane;
                put(&mut v.p, lane, surf.p);
                put(&mut v.n, lane, surf.n);
                put(&mut v.albedo, lane, scene.albedo(surf.material, &hit, surf.p));
            }
            if shade == 0 {
                continue;
            }
            let shading = M::from_bits(shade);
            // The vertex's numbers, in the scalar loop's order: light, bounce, roulette.
            let roulette: u32 = (0..8).filter(|&i| lanes.depth[i] >= RR_START).fold(0, |m, i| m | 1 << i);
            let u_light = lanes.samplers.next(shade, true);
            let u_bsdf = lanes.samplers.next(shade, true);
            let u_rr = lanes.samplers.next(shade & roulette, false).0;

            // The light sample and its shadow ray (`Scene::sample_light`, `unoccluded`).
            let p = V::load(&v.p);
            let wo = V::load(&lanes.dir).neg();
            let surf_n = V::load(&v.n);
            let front = surf_n.dot(wo).ge(F::splat(0.0));
            let n = V::select(front, surf_n, surf_n.neg());
            let eps = F::splat(1e-4) * (F::splat(1.0) + p.x.abs().max(p.z.abs()).max(p.y.abs()));
            let zero = F::splat(0.0);
            let (light, p_pick, u_pick) = pick_light(&scene.light_cdf, u_light.0);
            let kind = gather_i(&lights.kind, light);
            let is = |k: i32| M(_mm256_castsi256_ps(_mm256_cmpeq_epi32(kind, _mm256_set1_epi32(k))));
            let (point, directional) = (is(POINT), is(DIRECTIONAL));
            // Triangle: y = v0 + b1·e1 + b2·e2 with b1 = √u(1 − v), b2 = √u·v.
            let su = u_pick.sqrt();
            let uv = u_light.1;
            let (b1, b2) = (su * (F::splat(1.0) - uv), su * uv);
            let v0 = V::gather(&lights.v0, light);
            let tri_y =
                v0.add(V::gather(&lights.e1, light).scale(b1)).add(V::gather(&lights.e2, light).scale(b2));
            let d = V::select(point, v0, tri_y).sub(p);
            let r2 = d.dot(d);
            let r = r2.sqrt();
            let wi = V::select(directional, v0, d.div(r));
            let cos_light = -V::gather(&lights.n, light).dot(wi);
            let power = V::gather(&lights.power, light);
            // Point: intensity / (r²·p_pick). Triangle: radiance / pdf, pdf = p_pick·r² / (A·cos θ_light).
            let li_point = power.div(r2 * p_pick);
            let pdf = p_pick * r2 / (F::gather(&lights.area, light) * cos_light);
            let li_tri = power.div(pdf);
            // Directional: irradiance / p_pick, along the direction itself.
            let li_directional = power.div(p_pick);
            let li = V::select(point, li_point, V::select(directional, li_directional, li_tri));
            let tri_ok = !(cos_light.le(zero) | r2.eq(zero));
            let cos = n.dot(wi);
            let origin = p.add(n.scale(eps));
            let to = p.add(wi.scale(r)).sub(origin);
            let len = to.dot(to).sqrt();
            let sdir = V::select(directional, wi, to.div(len));
            let t_max = directional.select(F::splat(f32::INFINITY), len * F::splat(1.0 - 1e-4) - eps);
            let lit = shading
                & p_pick.gt(zero)
                & (point | directional | tri_ok)
                & cos.gt(zero)
                & (directional | len.gt(zero));
            let mut ray_o = [[0.0f32; 8]; 3];
            let mut ray_d = [[0.0f32; 8]; 3];
            let mut ray_t = [0.0f32; 8];
            origin.store(&mut ray_o);
            sdir.store(&mut ray_d);
            t_max.store(&mut ray_t);
            let mut visible = 0u32;
            let mut mask = lit.bits();
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let ray = Ray { origin: get(&ray_o, lane), dir: get(&ray_d, lane) };
                if !scene.bvh.occluded(&ray, 0.0, ray_t[lane]) {
                    visible |= 1 << lane;
                }
            }

            // Lambertian: f = kd/π where n·wo > 0 and n·wi > 0.
            let albedo = V::load(&v.albedo);
            let beta = V::load(&lanes.beta);
            let f_on = n.dot(wo).gt(zero) & cos.gt(zero);
            let none = V { x: zero, y: zero, z: zero };
            let f = V::select(f_on, albedo.scale(F::splat(std::f32::consts::FRAC_1_PI)), none);
            let l = V::load(&lanes.l);
            let l = V::select(M::from_bits(visible), l.add(beta.mul(f).scale(cos).mul(li)), l);
            l.store(&mut lanes.l);

            // The bounce (`bsdf::cosine_hemisphere`): weight kd.
            let u1 = u_bsdf.0;
            let radius = u1.sqrt();
            let (c, s) = unit_circle(u_bsdf.1);
            let (t, b) = basis(n);
            let z = (F::splat(1.0) - u1).max(zero).sqrt();
            let wi = t.scale(radius * c).add(b.scale(radius * s)).add(n.scale(z));
            let mut beta = beta.mul(albedo);
            // Russian roulette after RR_START segments: survive with q = min(max β, 0.95).
            let roulette = M::from_bits(roulette);
            let q = beta.max_element().min(F::splat(0.95));
            let killed = roulette & u_rr.ge(q);
            beta = V::select(roulette, beta.div(q), beta);
            let black = beta.x.eq(zero) & beta.y.eq(zero) & beta.z.eq(zero);
            let alive = shading & !killed & !black;
            let away = n.dot(wi).ge(zero);
            let off = n.scale(eps);
            let origin = p.add(V::select(away, off, off.neg()));
            beta.store(&mut lanes.beta);
            origin.store(&mut lanes.origin);
            wi.store(&mut lanes.dir);
            let alive = alive.bits();
            let mut ended = shade & !alive;
            while ended != 0 {
                let lane = ended.trailing_zeros() as usize;
                ended &= ended - 1;
                radiance[lanes.slot[lane]] = get(&lanes.l, lane);
                lanes.active &= !(1 << lane);
            }
            for lane in 0..8 {
                lanes.depth[lane] += (alive >> lane) & 1;
            }
        }
    }
}
