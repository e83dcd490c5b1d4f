//! Independent random numbers keyed by (seed, pixel, sample, dimension).
//!
//! Every number is a hash of its key, not the next state of a generator shared by a thread, so
//! an image does not depend on how pixels are divided among threads: one thread and many give
//! bit-identical results. The hash is the SplitMix64 finaliser (Steele et al. 2014), which
//! passes BigCrush when fed a counter.

/// SplitMix64's finaliser: a bijective 64-bit mixer.
#[inline]
pub fn mix64(mut x: u64) -> u64 {
    x ^= x >> 30;
    x = x.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x ^= x >> 27;
    x = x.wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// The random stream of one (pixel, sample) pair; `next` walks its dimensions.
pub struct Sampler {
    key: u64,
    dim: u64,
}

impl Sampler {
    pub fn new(seed: u64, pixel: u64, sample: u64) -> Sampler {
        Sampler { key: mix64(seed ^ mix64(pixel ^ mix64(sample.wrapping_add(0x5851_f42d)))), dim: 0 }
    }

    /// A uniform number in [0, 1).
    #[inline]
    pub fn next(&mut self) -> f32 {
        let h = mix64(self.key.wrapping_add(self.dim.wrapping_mul(0x9e37_79b9_7f4a_7c15)));
        self.dim += 1;
        (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    pub fn next2(&mut self) -> (f32, f32) {
        (self.next(), self.next())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_mean_and_range() {
        let mut s = Sampler::new(7, 3, 1);
        let n = 100_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let u = s.next();
            assert!((0.0..1.0).contains(&u));
            sum += u as f64;
        }
        // Mean of n uniforms: σ = 1/√(12n) ≈ 0.0009; allow 5σ.
        assert!((sum / n as f64 - 0.5).abs() < 0.0046);
    }
}
