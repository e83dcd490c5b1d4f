//! Phase functions: how a medium scatters light at a point, as a density over the sphere of
//! directions.
//!
//! Henyey & Greenstein (1941), with θ the angle between the direction light travelled before
//! and after scattering (g > 0 forward, g < 0 back, g = 0 isotropic, 1/4π):
//!
//!   p(θ) = (1 − g²) / (4π (1 + g² − 2g cos θ)^{3/2})
//!
//! Sampled exactly by inverting its distribution in cos θ,
//!
//!   cos θ = (1 + g² − ((1 − g²)/(1 − g + 2gξ))²) / 2g,
//!
//! so the sample's weight p/pdf is 1. Mitsuba 3's `hg` uses the same g, and its `isotropic` is
//! g = 0. Below |g| = 10⁻³ both are the isotropic ones (the inversion divides by g; the
//! density differs from 1/4π by at most 3|g|).

use crate::render::transport::{basis, unit_circle};
use glam::Vec3A;
use std::f32::consts::PI;

/// Henyey–Greenstein with asymmetry `g` in (−1, 1); 0 is isotropic.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Phase {
    pub g: f32,
}

const ISOTROPIC: f32 = 1e-3;

impl Phase {
    /// The density of scattering from travelling along `dir` into `wi` (both unit), per
    /// steradian; it is also the density `sample` draws `wi` with.
    #[inline]
    pub fn eval(&self, dir: Vec3A, wi: Vec3A) -> f32 {
        let g = self.g;
        if g.abs() < ISOTROPIC {
            return 1.0 / (4.0 * PI);
        }
        let denom = 1.0 + g * g - 2.0 * g * dir.dot(wi);
        (1.0 - g * g) / (4.0 * PI * denom * denom.max(0.0).sqrt())
    }

    /// A direction scattered from `dir`, drawn with density `eval` (weight 1).
    #[inline]
    pub fn sample(&self, dir: Vec3A, u1: f32, u2: f32) -> Vec3A {
        let g = self.g;
        let cos = if g.abs() < ISOTROPIC {
            1.0 - 2.0 * u1
        } else {
            let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u1);
            ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
        };
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let (c, s) = unit_circle(u2);
        let (t, b) = basis(dir);
        (t * (sin * c) + b * (sin * s) + dir * cos).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::stats::{chi2_test, sidak_alpha};
    use crate::render::sampler::Sampler;

    /// The density integrates to 1 over the sphere (midpoint rule in cos θ, where it depends
    /// on nothing else).
    #[test]
    fn normalised() {
        for g in [-0.9f32, -0.3, 0.0, 0.5, 0.95] {
            let p = Phase { g };
            let n = 200_000;
            let total: f64 = (0..n)
                .map(|i| {
                    let c = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
                    let wi = Vec3A::new((1.0 - c * c).sqrt() as f32, 0.0, c as f32);
                    p.eval(Vec3A::Z, wi) as f64 * 2.0 * std::f64::consts::PI * 2.0 / n as f64
                })
                .sum();
            assert!((total - 1.0).abs() < 1e-3, "g {g}: ∫p = {total}");
        }
    }

    /// Pearson's χ² test of `sample` against `eval`, as the BSDFs' (`render::bsdf`): 10⁶
    /// directions per case into 20 × 32 cells over (cos θ, φ) round a tilted axis, cells
    /// expecting fewer than 5 pooled, every case passing at 0.01 after Šidák's correction.
    #[test]
    fn chi_square_sampling() {
        let gs = [-0.9f32, -0.5, 0.0, 0.0005, 0.3, 0.7, 0.95];
        let alpha = sidak_alpha(0.01, gs.len());
        let (nt, np) = (20usize, 32usize);
        let samples = 1_000_000u64;
        let dir = Vec3A::new(0.3, -0.5, 0.8).normalize();
        let (t, b) = basis(dir);
        for (case, &g) in gs.iter().enumerate() {
            let phase = Phase { g };
            let cell = |wi: Vec3A| {
                let c = ((wi.dot(dir).clamp(-1.0, 1.0) + 1.0) / 2.0 * nt as f32) as usize;
                let phi = wi.dot(b).atan2(wi.dot(t)).rem_euclid(2.0 * PI);
                c.min(nt - 1) * np + ((phi / (2.0 * PI) * np as f32) as usize).min(np - 1)
            };
            let mut observed = vec![0.0f64; nt * np];
            for k in 0..samples {
                let (u1, u2) = Sampler::new(11 + case as u64, k, 0).next2();
                observed[cell(phase.sample(dir, u1, u2))] += 1.0;
            }
            // The density depends on cos θ alone (`eval` sees only dir·wi): each cell expects
            // its φ share of the integral over its band of cos θ, by 4096 midpoints (a band
            // holds all of a strong lobe's peak).
            let mut expected = vec![0.0f64; nt * np];
            let fine = 4096;
            for ci in 0..nt {
                let band: f64 = (0..fine)
                    .map(|a| {
                        let c = -1.0 + 2.0 * (ci as f64 + (a as f64 + 0.5) / fine as f64) / nt as f64;
                        let wi = t * (1.0 - c * c).max(0.0).sqrt() as f32 + dir * c as f32;
                        phase.eval(dir, wi) as f64 * 2.0 * std::f64::consts::PI * (2.0 / nt as f64)
                            / fine as f64
                    })
                    .sum();
                for pi in 0..np {
                    expected[ci * np + pi] = samples as f64 * band / np as f64;
                }
            }
            let p = chi2_test(&observed, &expected).expect("enough cells");
            assert!(p >= alpha, "g {g}: χ² p-value {p:.3e} below {alpha:.3e}");
        }
    }
}
