//! Eight f32 lanes of AVX2 for code that must compute exactly what a scalar loop computes:
//! `vector` holds the lane types (f32, masks, 3-vectors, u64) and their operators, each an
//! IEEE single operation lane by lane in the scalar code's order; `samplers` the lanes' random
//! numbers, bit-identical to `render::sampler`'s streams. The path integrator's eight-lane loop
//! (`integrators::path::lanes`) is built from them.
//!
//! Written with `std::arch` intrinsics behind small operator types rather than a SIMD crate,
//! for the reason the BVH's 8-wide module gives: glam stops at four lanes, and the lanes must
//! reproduce the scalar code's rounding exactly.

#[cfg(target_arch = "x86_64")]
pub(crate) mod samplers;
#[cfg(target_arch = "x86_64")]
pub(crate) mod vector;

/// Whether the processor has the lanes (AVX2).
pub fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    return is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

use glam::Vec3A;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// A number of the width code is written for: `f32` (one path) or a register of lanes, each
/// operation an IEEE single operation lane by lane. Code generic over it (`render::transport`)
/// is written once and computes the same bits at every width.
pub trait Real:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    /// One truth value per lane: `bool` for `f32`.
    type Mask: Copy + BitAnd<Output = Self::Mask> + BitOr<Output = Self::Mask> + Not<Output = Self::Mask>;
    fn splat(v: f32) -> Self;
    fn sqrt(self) -> Self;
    /// `f32::min` / `max` for numbers (which operand a NaN yields is not relied on).
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
    fn le(self, o: Self) -> Self::Mask;
    fn gt(self, o: Self) -> Self::Mask;
    fn ge(self, o: Self) -> Self::Mask;
    fn eq(self, o: Self) -> Self::Mask;
    /// `a` where `m` holds, `b` elsewhere.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// 1 with the sign bit of `self` (`1f32.copysign`).
    fn sign_one(self) -> Self;
    /// (cos, sin) turned by the quarter turns q held in the low bits of `shifted` (a float
    /// whose bits are 2²³'s plus q): bit operations, as `transport::unit_circle` explains.
    fn quarter_turn(shifted: Self, cos: Self, sin: Self) -> (Self, Self);
}

/// Three `Real`s: `Vec3A` (one path) or one 3-vector per lane.
pub trait Vector: Copy {
    type R: Real;
    fn new(x: Self::R, y: Self::R, z: Self::R) -> Self;
    fn x(self) -> Self::R;
    fn y(self) -> Self::R;
    fn z(self) -> Self::R;
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn scale(self, s: Self::R) -> Self;
    fn div(self, s: Self::R) -> Self;
    fn neg(self) -> Self;
    /// glam's `Vec3A::dot` order: (x·x' + y·y') + z·z'.
    fn dot(self, o: Self) -> Self::R;
    /// glam's `Vec3A::max_element` order: max(max(x, z), y).
    fn max_element(self) -> Self::R;
    /// Component magnitudes.
    fn abs(self) -> Self;
    fn select(m: <Self::R as Real>::Mask, a: Self, b: Self) -> Self;
}

impl Real for f32 {
    type Mask = bool;
    #[inline(always)]
    fn splat(v: f32) -> f32 {
        v
    }
    #[inline(always)]
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn min(self, o: f32) -> f32 {
        f32::min(self, o)
    }
    #[inline(always)]
    fn max(self, o: f32) -> f32 {
        f32::max(self, o)
    }
    #[inline(always)]
    fn le(self, o: f32) -> bool {
        self <= o
    }
    #[inline(always)]
    fn gt(self, o: f32) -> bool {
        self > o
    }
    #[inline(always)]
    fn ge(self, o: f32) -> bool {
        self >= o
    }
    #[inline(always)]
    fn eq(self, o: f32) -> bool {
        self == o
    }
    #[inline(always)]
    fn select(m: bool, a: f32, b: f32) -> f32 {
        if m {
            a
        } else {
            b
        }
    }
    #[inline(always)]
    fn sign_one(self) -> f32 {
        1.0f32.copysign(self)
    }
    #[inline(always)]
    fn quarter_turn(shifted: f32, cos: f32, sin: f32) -> (f32, f32) {
        let q = shifted.to_bits();
        let swap = 0u32.wrapping_sub(q & 1);
        let (cb, sb) = (cos.to_bits(), sin.to_bits());
        let c = (cb & !swap) | (sb & swap);
        let s = (sb & !swap) | (cb & swap);
        (f32::from_bits(c ^ (((q + 1) & 2) << 30)), f32::from_bits(s ^ ((q & 2) << 30)))
    }
}

impl Vector for Vec3A {
    type R = f32;
    #[inline(always)]
    fn new(x: f32, y: f32, z: f32) -> Vec3A {
        Vec3A::new(x, y, z)
    }
    #[inline(always)]
    fn x(self) -> f32 {
        self.x
    }
    #[inline(always)]
    fn y(self) -> f32 {
        self.y
    }
    #[inline(always)]
    fn z(self) -> f32 {
        self.z
    }
    #[inline(always)]
    fn add(self, o: Vec3A) -> Vec3A {
        self + o
    }
    #[inline(always)]
    fn sub(self, o: Vec3A) -> Vec3A {
        self - o
    }
    #[inline(always)]
    fn mul(self, o: Vec3A) -> Vec3A {
        self * o
    }
    #[inline(always)]
    fn scale(self, s: f32) -> Vec3A {
        self * s
    }
    #[inline(always)]
    fn div(self, s: f32) -> Vec3A {
        self / s
    }
    #[inline(always)]
    fn neg(self) -> Vec3A {
        -self
    }
    #[inline(always)]
    fn dot(self, o: Vec3A) -> f32 {
        Vec3A::dot(self, o)
    }
    #[inline(always)]
    fn max_element(self) -> f32 {
        Vec3A::max_element(self)
    }
    #[inline(always)]
    fn abs(self) -> Vec3A {
        Vec3A::abs(self)
    }
    #[inline(always)]
    fn select(m: bool, a: Vec3A, b: Vec3A) -> Vec3A {
        if m {
            a
        } else {
            b
        }
    }
}
