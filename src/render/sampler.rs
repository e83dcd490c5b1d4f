//! Independent random numbers keyed by (seed, pixel, sample, dimension).
//!
//! Each (seed, pixel, sample) triple owns its own stream, started from a hash of the triple and
//! never shared with another pixel or thread; the dimension is the position in that stream. So
//! an image does not depend on how pixels are divided among threads: one thread and many give
//! bit-identical results. The hash is the SplitMix64 finaliser (Steele et al. 2014); the stream
//! is PCG32 (O'Neill 2014, XSH-RR output), one multiply-add per number.

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
    state: u64,
}

const PCG_MUL: u64 = 6_364_136_223_846_793_005;
const PCG_INC: u64 = 1_442_695_040_888_963_407;

impl Sampler {
    pub fn new(seed: u64, pixel: u64, sample: u64) -> Sampler {
        Sampler { state: mix64(seed ^ mix64(pixel ^ mix64(sample.wrapping_add(0x5851_f42d)))) }
    }

    /// A uniform number in [0, 1) with 24 random bits.
    #[inline]
    pub fn next(&mut self) -> f32 {
        let old = self.state;
        self.state = old.wrapping_mul(PCG_MUL).wrapping_add(PCG_INC);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let out = xorshifted.rotate_right((old >> 59) as u32);
        (out >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
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

    /// Neighbouring pixels' and samples' streams are uncorrelated in every early dimension
    /// (the ones a path uses most): |corr| < 5/√n.
    #[test]
    fn neighbouring_streams_are_uncorrelated() {
        let n = 20_000;
        for dim in 0..8 {
            for (dp, ds) in [(1u64, 0u64), (0, 1)] {
                let (mut sx, mut sy, mut sxy, mut sxx, mut syy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
                for i in 0..n as u64 {
                    let mut a = Sampler::new(5, i, 3);
                    let mut b = Sampler::new(5, i + dp, 3 + ds);
                    let (mut x, mut y) = (0.0, 0.0);
                    for _ in 0..=dim {
                        x = a.next() as f64;
                        y = b.next() as f64;
                    }
                    sx += x;
                    sy += y;
                    sxy += x * y;
                    sxx += x * x;
                    syy += y * y;
                }
                let nf = n as f64;
                let cov = sxy / nf - sx * sy / nf / nf;
                let corr = cov / ((sxx / nf - (sx / nf).powi(2)) * (syy / nf - (sy / nf).powi(2))).sqrt();
                assert!(
                    corr.abs() < 5.0 / nf.sqrt(),
                    "dimension {dim}, offset {dp}/{ds}: correlation {corr}"
                );
            }
        }
    }
}
