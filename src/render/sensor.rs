//! A sensor: exposure, photon (Poisson) noise, read (Gaussian) noise, a camera response curve,
//! and quantisation with clipping to 8, 10, 12 or 16 bits.
//!
//! electrons e = Poisson(L · exposure · full_well) + Normal(0, read_noise²)
//! code value  = clamp(round(f(clamp(e / full_well, 0, 1)) · (2^bits − 1)), 0, 2^bits − 1)
//!
//! so a radiance of 1/exposure reaches full scale. f is the response (`Response`): linear
//! by default, or a gamma, the sRGB curve, a film-like S-curve, a measured film curve
//! (`Memorial`) or a sensor's S-curve with a steep toe, per channel (`Sigmoid`), each increasing from
//! f(0) = 0 to f(1) = 1; `Response::inverse` gives the truth a response recovery is judged
//! against. Noise is drawn from a generator seeded by (seed, pixel), so it does not depend on
//! the thread count.

use crate::error::Invalid;
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
    /// Bits per sample: 8, 10, 12 or 16 (default 8); above 8 the PNG holds 16-bit samples.
    #[serde(default = "eight")]
    pub bits: u8,
    /// The camera response between exposure and code value (default linear).
    #[serde(default)]
    pub response: Response,
}

/// A camera response curve f: [0, 1] → [0, 1], increasing, f(0) = 0, f(1) = 1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case", tag = "type", deny_unknown_fields)]
pub enum Response {
    #[default]
    Linear,
    /// f(x) = x^(1/gamma).
    Gamma { gamma: f64 },
    /// IEC 61966-2-1's encoding.
    Srgb,
    /// A film-like curve with a toe and a shoulder: Narkowicz's fit of the ACES filmic curve,
    /// x(2.51x + 0.03)/(x(2.43x + 0.59) + 0.14), on exposures scaled by `stops` stops above full
    /// scale (so full scale maps to f(1) = 1, more stops put more of the range in the toe).
    Film { stops: f64 },
    /// A measured curve: the green channel of the response recovered from the Memorial
    /// Church photographs (`data/responses/memorial-green.csv`: film scanned to 8 bits, with a
    /// long toe and a soft shoulder), f linear in ln x between its values 0 to 254 (the
    /// measured ones: 255 is the scan's clip), 0 below the first, full scale at 254.
    Memorial,
    /// A sensor's S-shaped curve with a steep toe, per channel c (R, G, B):
    /// f(x) = x^γ_c·(1 + a_c)/(x^γ_c + a_c), so f(0) = 0, f(1) = 1, steepest near black.
    Sigmoid { gamma: [f64; 3], a: [f64; 3] },
}

/// `data/responses/memorial-green.csv`: ln exposure (full scale 0) of each of 255 values.
fn memorial() -> &'static [f64] {
    static TABLE: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        include_str!("../../data/responses/memorial-green.csv")
            .lines()
            .filter(|l| l.starts_with(|c: char| c.is_ascii_digit()))
            .filter_map(|l| l.split(',').nth(1)?.trim().parse().ok())
            .collect()
    })
}

impl Response {
    pub fn validate(&self) -> Result<(), Invalid> {
        match *self {
            Response::Gamma { gamma } if !(gamma.is_finite() && (0.1..=10.0).contains(&gamma)) => {
                Err(format!("response gamma = {gamma}: expected 0.1 to 10").into())
            }
            Response::Film { stops } if !(stops.is_finite() && (0.0..=10.0).contains(&stops)) => {
                Err(format!("response stops = {stops}: expected 0 to 10").into())
            }
            Response::Sigmoid { gamma, a } => {
                if let Some(g) = gamma.iter().find(|g| !(g.is_finite() && (0.1..=10.0).contains(*g))) {
                    return Err(format!("response gamma = {g} (of {gamma:?}): expected 0.1 to 10").into());
                }
                if let Some(v) = a.iter().find(|v| !(v.is_finite() && (1e-3..=1e3).contains(*v))) {
                    return Err(format!("response a = {v} (of {a:?}): expected 0.001 to 1000").into());
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// Whether channels have curves of their own (else `apply` is every channel's).
    pub fn per_channel(&self) -> bool {
        matches!(self, Response::Sigmoid { .. })
    }

    /// f(x) for x in [0, 1], for the green channel where channels differ.
    pub fn apply(&self, x: f64) -> f64 {
        self.apply_channel(1, x)
    }

    /// f⁻¹(y) for y in [0, 1], for the green channel where channels differ.
    pub fn inverse(&self, y: f64) -> f64 {
        self.inverse_channel(1, y)
    }

    /// Channel `c`'s f(x) for x in [0, 1].
    pub fn apply_channel(&self, c: usize, x: f64) -> f64 {
        let x = x.clamp(0.0, 1.0);
        match *self {
            Response::Sigmoid { gamma, a } => {
                let (g, a) = (gamma[c.min(2)], a[c.min(2)]);
                let p = x.powf(g);
                p * (1.0 + a) / (p + a)
            }
            Response::Linear => x,
            Response::Gamma { gamma } => x.powf(1.0 / gamma),
            Response::Srgb => {
                if x <= 0.003_130_8 {
                    12.92 * x
                } else {
                    1.055 * x.powf(1.0 / 2.4) - 0.055
                }
            }
            Response::Film { stops } => {
                let aces = |v: f64| v * (2.51 * v + 0.03) / (v * (2.43 * v + 0.59) + 0.14);
                let k = 2f64.powf(stops);
                aces(k * x) / aces(k)
            }
            Response::Memorial => {
                let table = memorial();
                let top = (table.len() - 1) as f64;
                let l = x.ln();
                if l <= table[0] {
                    return 0.0;
                }
                // The last value whose ln exposure is at most ln x, then linear in ln x.
                let k = table.partition_point(|&v| v <= l).clamp(1, table.len() - 1) - 1;
                let f = ((l - table[k]) / (table[k + 1] - table[k])).clamp(0.0, 1.0);
                (k as f64 + f) / top
            }
        }
    }

    /// Channel `c`'s f⁻¹(y) for y in [0, 1]: in closed form for the linear, gamma and sRGB
    /// curves, by bisection for the others (60 halvings reach f64's resolution).
    pub fn inverse_channel(&self, c: usize, y: f64) -> f64 {
        let y = y.clamp(0.0, 1.0);
        match *self {
            Response::Linear => return y,
            Response::Gamma { gamma } => return y.powf(gamma),
            // 0.040 45 = 12.92 × 0.003 130 8, where `apply`'s two pieces meet.
            Response::Srgb if y <= 0.040_45 => return y / 12.92,
            Response::Srgb => return ((y + 0.055) / 1.055).powf(2.4),
            _ => {}
        }
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if self.apply_channel(c, mid) < y {
                lo = mid
            } else {
                hi = mid
            }
        }
        0.5 * (lo + hi)
    }
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
        Sensor {
            exposure: 1.0,
            full_well: full_well(),
            photon_noise: true,
            read_noise: 0.0,
            bits: 8,
            response: Response::Linear,
        }
    }
}

impl Sensor {
    pub fn validate(&self) -> Result<(), Invalid> {
        if !(self.exposure.is_finite() && self.exposure > 0.0) {
            return Err(format!("exposure = {} must be positive", self.exposure).into());
        }
        if !(self.full_well.is_finite() && self.full_well >= 1.0) {
            return Err(format!("full_well = {} must be at least 1 electron", self.full_well).into());
        }
        if !(self.read_noise.is_finite() && self.read_noise >= 0.0) {
            return Err(format!("read_noise = {} must be non-negative", self.read_noise).into());
        }
        if ![8, 10, 12, 16].contains(&self.bits) {
            return Err(format!("bits = {} must be 8, 10, 12 or 16", self.bits).into());
        }
        self.response.validate()
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
                    .enumerate()
                    .map(|(ch, &l)| {
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
                        let x = (e / self.full_well).clamp(0.0, 1.0);
                        let y = if self.response == Response::Linear {
                            x
                        } else {
                            self.response.apply_channel(ch, x)
                        };
                        (y * max).round().clamp(0.0, max) as u16
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
        let s = Sensor {
            exposure: 1e300,
            full_well: 4e4,
            read_noise: 2.0,
            bits: 16,
            photon_noise: true,
            response: Response::Linear,
        };
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
        let s = Sensor {
            exposure: 1.0,
            full_well: 10_000.0,
            photon_noise: true,
            read_noise: 30.0,
            bits: 16,
            response: Response::Linear,
        };
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

    /// Every response is increasing from 0 to 1 and its inverse undoes it; a 10-bit sensor
    /// with the sRGB curve writes the codes the curve gives.
    #[test]
    fn responses_and_bit_depths() {
        for r in [
            Response::Linear,
            Response::Gamma { gamma: 2.2 },
            Response::Srgb,
            Response::Film { stops: 2.0 },
            Response::Memorial,
            Response::Sigmoid { gamma: [0.42, 0.46, 0.5], a: [0.25, 0.3, 0.35] },
        ] {
            for c in 0..3 {
                let f = |x: f64| r.apply_channel(c, x);
                assert!(f(0.0).abs() < 1e-12 && (f(1.0) - 1.0).abs() < 1e-12, "{r:?}");
                let ys: Vec<f64> = (0..=1000).map(|k| f(k as f64 / 1000.0)).collect();
                assert!(ys.windows(2).all(|w| w[1] > w[0]), "{r:?} is not increasing");
                for k in 1..100 {
                    let x = k as f64 / 100.0;
                    assert!((r.inverse_channel(c, f(x)) - x).abs() < 1e-9, "{r:?} at {x}");
                }
            }
        }
        let table = memorial();
        assert_eq!(table.len(), 255);
        assert!(table.windows(2).all(|w| w[1] > w[0]) && table[254] == 0.0);
        assert!(Response::Gamma { gamma: 0.0 }.validate().is_err());
        let img = Image { width: 4, height: 1, channels: 3, data: vec![0.25; 12] };
        let s = Sensor { bits: 10, photon_noise: false, response: Response::Srgb, ..Sensor::default() };
        s.validate().unwrap();
        let want = (Response::Srgb.apply(0.25) * 1023.0).round() as u16;
        assert!(s.expose(&img, 1).iter().all(|&c| c == want), "{want}");
        assert!(Sensor { bits: 9, ..Sensor::default() }.validate().is_err());
    }
}
