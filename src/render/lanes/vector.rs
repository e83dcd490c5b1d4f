//! Eight f32, mask, 3-vector and u64 lanes over AVX2, with the operators the path loop uses
//! (each an IEEE single operation lane by lane, as the scalar code's), the light pick on
//! lanes, and the `Real` and `Vector` implementations that let `render::transport` run on them.

use std::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Eight f32 lanes. The operators are IEEE single operations lane by lane, as the scalar
/// code's; they are inlined into the AVX2 function that uses them.
#[derive(Clone, Copy)]
pub(crate) struct F(pub(crate) __m256);

/// A lane mask: all bits set where true.
#[derive(Clone, Copy)]
pub(crate) struct M(pub(crate) __m256);

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
        pub(crate) fn $f(self, o: F) -> M {
            // SAFETY: as in `binop`.
            M(unsafe { _mm256_cmp_ps::<$pred>(self.0, o.0) })
        }
    };
}

impl F {
    #[inline(always)]
    pub(crate) fn splat(v: f32) -> F {
        // SAFETY: as in `binop`.
        F(unsafe { _mm256_set1_ps(v) })
    }
    #[inline(always)]
    pub(crate) fn load(v: &[f32; 8]) -> F {
        // SAFETY: reads the eight floats of `v`; as in `binop` otherwise.
        F(unsafe { _mm256_loadu_ps(v.as_ptr()) })
    }
    #[inline(always)]
    pub(crate) fn store(self, v: &mut [f32; 8]) {
        // SAFETY: writes the eight floats of `v`; as in `binop` otherwise.
        unsafe { _mm256_storeu_ps(v.as_mut_ptr(), self.0) }
    }
    #[inline(always)]
    pub(crate) fn sqrt(self) -> F {
        // SAFETY: as in `binop`.
        F(unsafe { _mm256_sqrt_ps(self.0) })
    }
    /// `f32::min` / `max` for numbers (SSE's operand order, which glam's `max_element`
    /// also uses).
    #[inline(always)]
    pub(crate) fn min(self, o: F) -> F {
        // SAFETY: as in `binop`.
        F(unsafe { _mm256_min_ps(self.0, o.0) })
    }
    #[inline(always)]
    pub(crate) fn max(self, o: F) -> F {
        // SAFETY: as in `binop`.
        F(unsafe { _mm256_max_ps(self.0, o.0) })
    }
    #[inline(always)]
    pub(crate) fn abs(self) -> F {
        // SAFETY: as in `binop`.
        F(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) })
    }
    #[inline(always)]
    pub(crate) fn bits(self) -> __m256i {
        // SAFETY: as in `binop`.
        unsafe { _mm256_castps_si256(self.0) }
    }
    #[inline(always)]
    pub(crate) fn from_bits(v: __m256i) -> F {
        // SAFETY: as in `binop`.
        F(unsafe { _mm256_castsi256_ps(v) })
    }
    /// Lane i gets `table[index[i]]`; every index must be in bounds.
    #[inline(always)]
    pub(crate) fn gather(table: &[f32], index: __m256i) -> F {
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
    pub(crate) fn select(self, a: F, b: F) -> F {
        // SAFETY: as in `binop`.
        F(unsafe { _mm256_blendv_ps(b.0, a.0, self.0) })
    }
    #[inline(always)]
    pub(crate) fn bits(self) -> u32 {
        // SAFETY: as in `binop`.
        unsafe { _mm256_movemask_ps(self.0) as u32 }
    }
    #[inline(always)]
    pub(crate) fn from_bits(bits: u32) -> M {
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
pub(crate) struct V {
    pub(crate) x: F,
    pub(crate) y: F,
    pub(crate) z: F,
}

impl V {
    #[inline(always)]
    pub(crate) fn load(v: &[[f32; 8]; 3]) -> V {
        V { x: F::load(&v[0]), y: F::load(&v[1]), z: F::load(&v[2]) }
    }
    #[inline(always)]
    pub(crate) fn store(self, v: &mut [[f32; 8]; 3]) {
        self.x.store(&mut v[0]);
        self.y.store(&mut v[1]);
        self.z.store(&mut v[2]);
    }
    #[inline(always)]
    pub(crate) fn gather(table: &[Vec<f32>; 3], index: __m256i) -> V {
        V { x: F::gather(&table[0], index), y: F::gather(&table[1], index), z: F::gather(&table[2], index) }
    }
}

/// Lane i gets `table[index[i]]`; every index must be in bounds.
#[inline(always)]
pub(crate) fn gather_i(table: &[i32], index: __m256i) -> __m256i {
    // SAFETY: the callers' indices are in 0..table.len(); as in `binop` otherwise.
    unsafe { _mm256_i32gather_epi32::<4>(table.as_ptr(), index) }
}

/// `Scene::pick_light`, lane by lane: (light index, pick probability, the pick number
/// stretched over the light's share). The index is a branch-free binary search for the
/// partition point that `partition_point` finds; the probability is 0 where the scalar
/// pick gives `None` (no light, or one of zero power).
#[inline(always)]
pub(crate) fn pick_light(cdf: &[f32], u: F) -> (__m256i, F, F) {
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

/// Eight unsigned 64-bit lanes, as two registers (lanes 0–3, 4–7).
#[derive(Clone, Copy)]
pub(crate) struct U64(pub(crate) [__m256i; 2]);

impl U64 {
    #[inline(always)]
    pub(crate) fn load(v: &[u64; 8]) -> U64 {
        // SAFETY: reads the eight integers of `v`; as in `binop` otherwise.
        unsafe { U64([_mm256_loadu_si256(v.as_ptr().cast()), _mm256_loadu_si256(v[4..].as_ptr().cast())]) }
    }
    #[inline(always)]
    pub(crate) fn store(self, v: &mut [u64; 8]) {
        // SAFETY: writes the eight integers of `v`; as in `binop` otherwise.
        unsafe {
            _mm256_storeu_si256(v.as_mut_ptr().cast(), self.0[0]);
            _mm256_storeu_si256(v[4..].as_mut_ptr().cast(), self.0[1]);
        }
    }
    #[inline(always)]
    pub(crate) fn map(self, f: impl Fn(__m256i) -> __m256i) -> U64 {
        U64([f(self.0[0]), f(self.0[1])])
    }
    #[inline(always)]
    pub(crate) fn zip(self, o: U64, f: impl Fn(__m256i, __m256i) -> __m256i) -> U64 {
        U64([f(self.0[0], o.0[0]), f(self.0[1], o.0[1])])
    }
    #[inline(always)]
    pub(crate) fn xor(self, o: U64) -> U64 {
        // SAFETY: as in `binop`.
        self.zip(o, |a, b| unsafe { _mm256_xor_si256(a, b) })
    }
    #[inline(always)]
    pub(crate) fn add(self, c: u64) -> U64 {
        // SAFETY: as in `binop`.
        self.map(|a| unsafe { _mm256_add_epi64(a, _mm256_set1_epi64x(c as i64)) })
    }
    #[inline(always)]
    pub(crate) fn shr<const S: i32>(self) -> U64 {
        // SAFETY: as in `binop`.
        self.map(|a| unsafe { _mm256_srli_epi64::<S>(a) })
    }
    /// The low 64 bits of the product with c (`u64::wrapping_mul`), from 32-bit products.
    #[inline(always)]
    pub(crate) fn mul(self, c: u64) -> U64 {
        // SAFETY: as in `binop`.
        self.map(|a| unsafe {
            let (lo, hi) =
                (_mm256_set1_epi64x((c & 0xffff_ffff) as i64), _mm256_set1_epi64x((c >> 32) as i64));
            let cross =
                _mm256_add_epi64(_mm256_mul_epu32(_mm256_srli_epi64::<32>(a), lo), _mm256_mul_epu32(a, hi));
            _mm256_add_epi64(_mm256_mul_epu32(a, lo), _mm256_slli_epi64::<32>(cross))
        })
    }
    /// The low 32 bits of the eight lanes (`as u32`), as eight 32-bit lanes.
    #[inline(always)]
    pub(crate) fn low_halves(self) -> __m256i {
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
    pub(crate) fn widen(m: __m256i) -> U64 {
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
    pub(crate) fn select(m: __m256i, a: U64, b: U64) -> U64 {
        let w = U64::widen(m);
        // SAFETY: as in `binop`.
        U64([0, 1].map(|h| unsafe { _mm256_blendv_epi8(b.0[h], a.0[h], w.0[h]) }))
    }
}

impl super::Real for F {
    type Mask = M;
    #[inline(always)]
    fn splat(v: f32) -> F {
        F::splat(v)
    }
    #[inline(always)]
    fn sqrt(self) -> F {
        F::sqrt(self)
    }
    #[inline(always)]
    fn min(self, o: F) -> F {
        F::min(self, o)
    }
    #[inline(always)]
    fn max(self, o: F) -> F {
        F::max(self, o)
    }
    #[inline(always)]
    fn le(self, o: F) -> M {
        F::le(self, o)
    }
    #[inline(always)]
    fn gt(self, o: F) -> M {
        F::gt(self, o)
    }
    #[inline(always)]
    fn ge(self, o: F) -> M {
        F::ge(self, o)
    }
    #[inline(always)]
    fn eq(self, o: F) -> M {
        F::eq(self, o)
    }
    #[inline(always)]
    fn select(m: M, a: F, b: F) -> F {
        m.select(a, b)
    }
    #[inline(always)]
    fn sign_one(self) -> F {
        // SAFETY: as in `binop`.
        F(unsafe { _mm256_or_ps(_mm256_and_ps(self.0, _mm256_set1_ps(-0.0)), _mm256_set1_ps(1.0)) })
    }
    #[inline(always)]
    fn quarter_turn(shifted: F, cos: F, sin: F) -> (F, F) {
        // SAFETY: as in `binop`.
        unsafe {
            let q = shifted.bits();
            let one = _mm256_set1_epi32(1);
            let two = _mm256_set1_epi32(2);
            let swap = M(_mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(q, one), one)));
            let (cb, sb) = (swap.select(sin, cos).bits(), swap.select(cos, sin).bits());
            let c_sign = _mm256_slli_epi32::<30>(_mm256_and_si256(_mm256_add_epi32(q, one), two));
            let s_sign = _mm256_slli_epi32::<30>(_mm256_and_si256(q, two));
            (F::from_bits(_mm256_xor_si256(cb, c_sign)), F::from_bits(_mm256_xor_si256(sb, s_sign)))
        }
    }
}

impl super::Vector for V {
    type R = F;
    #[inline(always)]
    fn new(x: F, y: F, z: F) -> V {
        V { x, y, z }
    }
    #[inline(always)]
    fn x(self) -> F {
        self.x
    }
    #[inline(always)]
    fn y(self) -> F {
        self.y
    }
    #[inline(always)]
    fn z(self) -> F {
        self.z
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
    fn dot(self, o: V) -> F {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline(always)]
    fn max_element(self) -> F {
        self.x.max(self.z).max(self.y)
    }
    #[inline(always)]
    fn abs(self) -> V {
        V { x: self.x.abs(), y: self.y.abs(), z: self.z.abs() }
    }
    #[inline(always)]
    fn select(m: M, a: V, b: V) -> V {
        V { x: m.select(a.x, b.x), y: m.select(a.y, b.y), z: m.select(a.z, b.z) }
    }
}
