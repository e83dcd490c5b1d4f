//! Participating media: fog, smoke, murky water, the inside of a translucent object.
//!
//! A medium absorbs and scatters light everywhere along a ray, not only at surfaces. Per unit
//! length it has an extinction coefficient σt (per channel) of which the share α (the single-
//! scattering albedo) scatters, σs = α·σt, and the rest, σa = σt − σs, is absorbed; where light
//! scatters, the phase function (`phase`) says where to. Light crossing a length d of it keeps
//! the fraction T = exp(−σt·d) (Beer–Lambert).
//!
//! Where a medium is lies in the scene, not here: shapes bound media (their `interior` and
//! `exterior`, as Mitsuba 3's), and the camera may sit in one (`[camera] medium`), which then
//! fills space up to the first boundary. `integrators::volpath` walks the boundaries.
//!
//! Distances are drawn in proportion to the transmittance of one channel, the path's hero,
//! picked at random when the path starts; the estimate is combined over the three choices of
//! hero by the balance heuristic on whole paths (single-sample spectral MIS, as pbrt-v4's and
//! Mitsuba's `volpathmis`): a path of throughput f per channel, which hero c would have drawn
//! with density p_c, counts f / mean_c(p_c). The integrator keeps that ratio as the throughput β
//! and the densities' ratios r = p_c / mean(p) (mean 1); a collision at t multiplies f by
//! σs·e^(−σt·t) and p by σt·e^(−σt·t), going through a length d multiplies both by e^(−σt·d).
//! Each channel's weight stays below 3α however the channels' σt differ (drawing by one channel
//! alone, as Mitsuba's `volpath`, weights the others by transmittance ratios, without bound),
//! and is exactly α per collision in a grey medium. Transmittance along a shadow ray is
//! Beer–Lambert's closed form.

pub mod phase;

pub use phase::Phase;

use glam::Vec3A;

/// A homogeneous medium.
#[derive(Clone, Debug)]
pub struct Medium {
    pub name: String,
    /// σt per unit of scene length, per channel, ≥ 0.
    pub sigma_t: Vec3A,
    /// The single-scattering albedo α = σs/σt per channel, in [0, 1].
    pub albedo: Vec3A,
    pub phase: Phase,
}

/// Where a ray's flight through a medium ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Flight {
    /// Scattered at distance t along the ray.
    Scatter(f32),
    /// Reached the end of the segment.
    Through,
    /// Absorbed: nothing comes back along the path.
    Absorbed,
}

fn mean(v: Vec3A) -> f32 {
    (v.x + v.y + v.z) / 3.0
}

impl Medium {
    /// σs per channel.
    pub fn sigma_s(&self) -> Vec3A {
        self.sigma_t * self.albedo
    }

    /// Samples where a ray first collides within [0, t_max) by the transmittance of channel
    /// `hero` (the path's, module docs), with the uniform number `u`; updates the path's
    /// throughput `beta` and its channels' relative densities `r` (mean 1).
    pub fn sample_flight(&self, t_max: f32, hero: usize, u: f32, beta: &mut Vec3A, r: &mut Vec3A) -> Flight {
        let sigma_t = self.sigma_t;
        if sigma_t.max_element() <= 0.0 {
            return Flight::Through;
        }
        // 1 − u lies in (0, 1]: the logarithm is finite; a channel with σt = 0 never collides.
        let h = sigma_t[hero];
        let t = if h > 0.0 { -(1.0 - u).ln() / h } else { f32::INFINITY };
        let (flight, f, p) = if t < t_max {
            let tr = self.transmittance(t);
            (Flight::Scatter(t), self.sigma_s() * tr, sigma_t * tr)
        } else {
            let tr = self.transmittance(t_max);
            (Flight::Through, tr, tr)
        };
        let k = mean(*r * p);
        if !(k > 0.0) || f == Vec3A::ZERO {
            return Flight::Absorbed;
        }
        *beta *= f / k;
        *r *= p / k;
        flight
    }

    /// The fraction of light a length `d` of the medium lets through, per channel:
    /// exp(−σt·d), 1 where σt = 0 (also for an infinite d).
    pub fn transmittance(&self, d: f32) -> Vec3A {
        let f = |s: f32| if s > 0.0 { (-s * d).exp() } else { 1.0 };
        Vec3A::new(f(self.sigma_t.x), f(self.sigma_t.y), f(self.sigma_t.z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Sampler;

    /// The mean weight of getting through a length d is exp(−σt·d) per channel, in a
    /// chromatic medium (heroes picked at random) as in a grey one.
    #[test]
    fn flight_passes_with_beer_lambert_probability() {
        for sigma_t in [Vec3A::splat(1.5), Vec3A::new(0.2, 1.0, 3.0), Vec3A::new(0.0, 0.5, 4.0)] {
            let m = Medium { name: "m".into(), sigma_t, albedo: Vec3A::splat(0.5), phase: Phase { g: 0.0 } };
            let (d, n) = (0.8f32, 400_000u64);
            let mut sum = [0.0f64; 3];
            let mut sq = [0.0f64; 3];
            for k in 0..n {
                let (u_hero, u) = Sampler::new(5, k, 0).next2();
                let (mut beta, mut r) = (Vec3A::ONE, Vec3A::ONE);
                let hero = ((u_hero * 3.0) as usize).min(2);
                if m.sample_flight(d, hero, u, &mut beta, &mut r) == Flight::Through {
                    assert!((r.x + r.y + r.z - 3.0).abs() < 1e-5, "r = {r} has mean 1");
                    for c in 0..3 {
                        sum[c] += beta[c] as f64;
                        sq[c] += (beta[c] as f64).powi(2);
                    }
                }
            }
            let truth = m.transmittance(d);
            for c in 0..3 {
                let mean = sum[c] / n as f64;
                let se = ((sq[c] / n as f64 - mean * mean) / n as f64).sqrt();
                assert!(
                    (mean - truth[c] as f64).abs() < 4.0 * se + 1e-6,
                    "σt {sigma_t:?}, channel {c}: {mean} ± {se} against exp(−σt·d) = {}",
                    truth[c]
                );
            }
        }
    }
}
