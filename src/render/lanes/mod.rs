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
