//! What a render hands back: the film (mean and variance of the mean per pixel), and the
//! per-pixel statistics the integrators fill it with.

use crate::image::Image;
use glam::Vec3A;

/// The film after rendering: mean radiance and the variance of that mean, per pixel.
pub struct Film {
    pub mean: Image,
    pub variance: Image,
    /// Pixel offset of the film in the full image (non-zero for a crop).
    pub origin: [u32; 2],
    /// Samples whose value was not finite and was dropped (should be 0).
    pub dropped_samples: u64,
    /// Samples per pixel (passes, for integrators that render in passes) it holds: the
    /// settings' `spp`, or what a time budget reached.
    pub samples: u32,
}

/// Segments after which Russian roulette starts (`integrators::path` docs).
pub const RR_START: u32 = 5;

/// Mean and variance of the mean of a pixel's samples, in sample order, and the number of
/// non-finite samples dropped.
pub fn pixel_stats(samples: impl Iterator<Item = Vec3A>) -> ([f32; 3], [f32; 3], u64) {
    let mut sums = PixelSums::default();
    let dropped = samples.filter(|&l| !sums.add(l)).count() as u64;
    let (mean, var) = sums.stats();
    (mean, var, dropped)
}

/// A pixel's sums over its finite samples, in the order they are added.
#[derive(Clone, Copy, Debug, Default)]
pub struct PixelSums {
    sum: [f64; 3],
    sum2: [f64; 3],
    n: u64,
}

impl PixelSums {
    /// Adds a sample; returns false, adding nothing, where it is not finite.
    pub fn add(&mut self, l: Vec3A) -> bool {
        if !l.is_finite() {
            return false;
        }
        for c in 0..3 {
            let v = l[c] as f64;
            self.sum[c] += v;
            self.sum2[c] += v * v;
        }
        self.n += 1;
        true
    }

    /// The mean, and the variance of that mean (the samples' unbiased variance over n; 0 for
    /// one sample, and all 0 for none).
    pub fn stats(&self) -> ([f32; 3], [f32; 3]) {
        let n = self.n.max(1) as f64;
        let mut mean = [0.0f32; 3];
        let mut var = [0.0f32; 3];
        for c in 0..3 {
            let m = self.sum[c] / n;
            mean[c] = m as f32;
            var[c] = if n > 1.0 { ((self.sum2[c] - n * m * m).max(0.0) / (n - 1.0) / n) as f32 } else { 0.0 };
        }
        (mean, var)
    }
}
