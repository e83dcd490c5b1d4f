//! A simple linear sensor: exposure, photon (Poisson) noise, read (Gaussian) noise, and
//! quantisation with clipping to 8 or 16 bits.
//!
//! electrons e = Poisson(L · exposure · full_well) + Normal(0, read_noise²)
//! code value  = clamp(round(e / full_well · (2^bits − 1)), 0, 2^bits − 1)
//!
//! so a radiance of 1/exposure reaches full scale. Noise is drawn from a generator seeded by
//! (seed, pixel), so it does not depend on the thread count. A non-linear response curve is
//! not modelled here.

use crate::image::Image;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal, Poisson};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Sensor {
    /// Radiance → fraction of full scale (default 1).
    #[serde(default = "one")]
    pub exposure: f64,
    /// Electrons at full scale, which sets the photon noise (default 20000).
    #[serde(default = "full_well")]
    pub full_well: f64,
    /// Whether photon (shot) noise is drawn (default true).
    #[serde(default = "yes")]
    pub photon_noise: bool,
    /// Standard deviation of the read noise in electrons (default 0).
    #[serde(default)]
    pub read_noise: f64,
    /// Bits per sample of the output PNG: 8 or 16 (default 8).
    #[serde(default = "eight")]
    pub bits: u8,
}

fn one() -> f64 {
    1.0
}
fn full_well() -> f64 {
    20000.0
}
fn yes() -> bool {
    true
}
fn eight() -> u8 {
    8
}

impl Default for Sensor {
    fn default() -> Self {
        Sensor { exposure: 1.0, full_well: full_well(), photon_noise: true, read_noise: 0.0, bits: 8 }
    }
}

impl Sensor {
    pub fn validate(&self) -> Result<(), String> {
        if !(self.exposure.is_finite() && self.exposure > 0.0) {
            return Err(format!("exposure = {} must be positive", self.exposure));
        }
        if !(self.full_well.is_finite() && self.full_well >= 1.0) {
            return Err(format!("full_well = {} must be at least 1 electron", self.full_well));
        }
        if !(self.read_noise.is_finite() && self.read_noise >= 0.0) {
            return Err(format!("read_noise = {} must be non-negative", self.read_noise));
        }
        if self.bits != 8 && self.bits != 16 {
            return Err(format!("bits = {} must be 8 or 16", self.bits));
        }
        Ok(())
    }

    pub fn max_code(&self) -> u16 {
        ((1u32 << self.bits) - 1) as u16
    }

    /// Exposes a radiance image: integer code values, same layout. Photon counts above
    /// `LARGE_MEAN` electrons are drawn from the normal approximation.
    pub fn expose(&self, radiance: &Image, seed: u64) -> Vec<u16> {
        let max = self.max_code() as f64;
        let c = radiance.channels as usize;
        let read = Normal::new(0.0, self.read_noise.max(0.0)).ok();
        radiance
            .data
            .chunks_exact(c)
            .enumerate()
            .flat_map(|(pixel, px)| {
                let key = super::sampler::mix64(seed ^ 0x5e45_0a11 ^ super::sampler::mix64(pixel as u64));
                let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(key);
                px.iter()
                    .map(|&l| {
                        let mean_e = (l.max(0.0) as f64) * self.exposure * self.full_well;
                        let mut e = if self.photon_noise && mean_e > LARGE_MEAN {
                            // The Poisson sampler's rejection loop does not end for means near
                            // f64's range; this far out the normal approximation is exact to
                            // any precision a 16-bit code can show.
                            Normal::new(mean_e, mean_e.sqrt()).map(|n| n.sample(&mut rng)).unwrap_or(mean_e)
                        } else if self.photon_noise && mean_e > 0.0 {
                            Poisson::new(mean_e).map(|p| p.sample(&mut rng)).unwrap_or(mean_e)
                        } else {
                            mean_e
                        };
                        if let Some(n) = &read {
                            e += n.sample(&mut rng);
                        }
                        (e / self.full_well * max).round().clamp(0.0, max) as u16
                    })
                    .collect::<Vec<_>>()
            })
            .collect()
    }
}

/// Mean electron count above which photon noise is drawn as Normal(μ, √μ) instead of Poisson.
const LARGE_MEAN: f64 = 1e12;

#[cfg(test)]
mod tests {
    use super::*;

    /// An absurd exposure saturates every code at once instead of looping in the sampler.
    #[test]
    fn huge_exposure_saturates_without_hanging() {
        let s = Sensor { exposure: 1e300, full_well: 4e4, read_noise: 2.0, bits: 16, photon_noise: true };
        let img = Image { width: 16, height: 16, channels: 3, data: vec![0.5; 768] };
        let t = std::time::Instant::now();
        let codes = s.expose(&img, 1);
        assert!(codes.iter().all(|&c| c == 65535));
        assert!(t.elapsed().as_secs_f64() < 5.0);
    }

    /// Photon noise has variance = mean in electrons; read noise adds in quadrature; values
    /// above full scale clip.
    #[test]
    fn noise_statistics_and_clipping() {
        let mut img = Image::new(200, 100, 3);
        img.data.iter_mut().for_each(|v| *v = 0.5);
        let s = Sensor { exposure: 1.0, full_well: 10_000.0, photon_noise: true, read_noise: 30.0, bits: 16 };
        let codes = s.expose(&img, 3);
        let n = codes.len() as f64;
        let mean = codes.iter().map(|&c| c as f64).sum::<f64>() / n;
        let var = codes.iter().map(|&c| (c as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let dn_per_e = 65535.0 / 10_000.0;
        let expected_sd = (5000.0f64 + 900.0).sqrt() * dn_per_e;
        assert!((mean / (0.5 * 65535.0) - 1.0).abs() < 1e-3, "mean {mean}");
        // The sample SD of 60000 draws is within 2 % of the truth with overwhelming odds.
        assert!((var.sqrt() / expected_sd - 1.0).abs() < 0.02, "sd {} vs {expected_sd}", var.sqrt());
        img.data.iter_mut().for_each(|v| *v = 3.0);
        let s8 = Sensor { bits: 8, ..s };
        assert!(s8.expose(&img, 3).iter().all(|&c| c == 255));
        // Same seed, same noise; another seed, other noise.
        img.data.iter_mut().for_each(|v| *v = 0.5);
        assert_eq!(s.expose(&img, 3), codes);
        assert_ne!(s.expose(&img, 4), codes);
    }
}
