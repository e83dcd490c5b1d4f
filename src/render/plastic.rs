//! Smooth plastic, as Mitsuba 3's `plastic`: a diffuse base of albedo ρ under a smooth,
//! clear dielectric coat of relative index η (a layered model after Weidlich & Wilkie 2007,
//! without absorption in the coat).
//!
//! - The coat reflects as a mirror with the Fresnel reflectance F(θi) (`specular::
//!   fresnel_dielectric`), tinted by the specular colour.
//! - The rest, 1 − F(θi), enters, is scattered diffusely by the base, and leaves with
//!   1 − F(θo). On the way out the coat sends the share F_dr of diffuse light back (its
//!   hemispherical reflectance seen from inside), which the base reflects again; summing the
//!   series,
//!
//!     f(wo, wi) = ρ / (1 − F_dr) · (1 − F(θi))·(1 − F(θo)) / (π η²),
//!
//!   or ρ / (1 − ρ·F_dr) when `nonlinear` (the base's colour taken at every bounce inside,
//!   which darkens and saturates it). 1/η² is the change of solid angle across the coat.
//! - F_dr = 2∫₀¹ F(μ, 1/η) μ dμ is integrated here in f64 (`diffuse_reflectance_inside`,
//!   a midpoint rule past the critical angle, below which F = 1), exact to float precision;
//!   Mitsuba uses polynomial fits (Egan & Hilgeman 1973 for η < 1, d'Eon & Irving 2011
//!   otherwise), which differ from it by about 0.1 % (unit test). With the exact F_dr a
//!   white base (ρ = 1) under the coat reflects all the light it receives, which the white
//!   furnace checks.
//! - Sampling: the mirror with probability P = F·w / (F·w + (1 − F)·(1 − w)), w = s̄/(ρ̄ + s̄)
//!   from the means of the specular and diffuse colours (Mitsuba's choice), else a cosine-
//!   weighted direction for the base.
//!
//! Rough plastic (Mitsuba's `roughplastic`) puts a microfacet coat (`render::microfacet`,
//! GGX or Beckmann, roughness α) over the base: the coat reflects glossily, F·D·G/(4 cos θo
//! cos θi), and the base's light crosses it twice, weighted each way by the coat's directional
//! transmittance T(μ) (the refracted share, G1 and Fresnel included):
//!
//!   f = s·F·D·G/(4 cos θo cos θi) + ρ/(1 − F_int)·T(θo)·T(θi)/(π η²),
//!
//! F_int = 2∫R(μ, 1/η)μ dμ with R the rough interface's reflectance. T is integrated over
//! visible microfacet normals into a 64-entry table in cos θ, linearly interpolated, and F_int
//! by a midpoint rule (`RoughCoat`), as Mitsuba tabulates them. Sampling picks the glossy lobe
//! (visible normals) with probability (1 − T)·w / ((1 − T)·w + T·(1 − w)), else the cosine-
//! weighted base, and weighs by the mixture's density. The model is not energy conserving at high roughness (the coat's
//! single-scattering loss), as Mitsuba's is not.

use super::microfacet::{self, Distribution};
use super::specular::{fresnel_dielectric, reflect};
use glam::Vec3A;
use rayon::prelude::*;
use std::f32::consts::PI;

/// The coat's reflectance for diffuse light arriving from inside, 2∫₀¹ F(μ, 1/η) μ dμ, for a
/// coat of index `eta` relative to the outside.
pub fn diffuse_reflectance_inside(eta: f64) -> f64 {
    // From inside the relative index is 1/η: total internal reflection (F = 1) for μ below
    // the critical cosine √(1 − 1/η²) when η > 1.
    let mu_c = (1.0 - 1.0 / (eta * eta)).max(0.0).sqrt();
    const N: usize = 1 << 16;
    let h = (1.0 - mu_c) / N as f64;
    let mut sum = 0.0;
    for k in 0..N {
        let mu = mu_c + (k as f64 + 0.5) * h;
        sum += fresnel64(mu, 1.0 / eta) * mu;
    }
    mu_c * mu_c + 2.0 * sum * h
}

/// Unpolarised Fresnel reflectance in f64 for incident cosine `cos_i` and relative index
/// `eta` = η_t/η_i (1 under total internal reflection).
fn fresnel64(cos_i: f64, eta: f64) -> f64 {
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// The diffuse part f(wo, wi) for cosines `co`, `ci` > 0 (the mirror part is a delta).
#[inline]
pub fn diffuse(kd: Vec3A, eta: f32, fdr_int: f32, nonlinear: bool, co: f32, ci: f32) -> Vec3A {
    let (fi, _) = fresnel_dielectric(co, eta);
    let (fo, _) = fresnel_dielectric(ci, eta);
    let base = if nonlinear { kd / (Vec3A::ONE - kd * fdr_int) } else { kd / (1.0 - fdr_int) };
    base * ((1.0 - fi) * (1.0 - fo) / (eta * eta * PI))
}

/// Probability of sampling the coat's mirror reflection for `co` = cos θo.
#[inline]
pub fn specular_probability(kd: Vec3A, specular: Vec3A, eta: f32, co: f32) -> f32 {
    let (f, _) = fresnel_dielectric(co, eta);
    coat_lobe_probability(kd, specular, f, 1.0 - f)
}

/// The share of samples for a coat's reflection when the coat reflects R of the light and
/// lets T through: R·w / (R·w + T·(1 − w)), w = s̄/(ρ̄ + s̄) from the colours' means (Mitsuba's
/// choice for both plastics).
#[inline]
fn coat_lobe_probability(kd: Vec3A, specular: Vec3A, reflected: f32, transmitted: f32) -> f32 {
    let (d, s) = (kd.element_sum() / 3.0, specular.element_sum() / 3.0);
    if !(d + s > 0.0) {
        return 0.0;
    }
    let w = s / (d + s);
    let (ps, pd) = (reflected * w, transmitted * (1.0 - w));
    if ps + pd > 0.0 {
        ps / (ps + pd)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// F_dr against reciprocity: for diffuse light from outside, F_dr,ext = 2∫F(μ, η)μ dμ, and
    /// 1 − F_dr,ext = η²·(1 − F_dr,int) (what crosses the coat either way, radiance/η² being
    /// conserved); η = 1 reflects nothing.
    #[test]
    fn internal_diffuse_reflectance_obeys_reciprocity() {
        for eta in [1.0f64, 1.1, 1.33, 1.49, 1.5, 2.0, 2.5] {
            let n = 200_000;
            let h = 1.0 / n as f64;
            let outside: f64 =
                (0..n).map(|k| (k as f64 + 0.5) * h).map(|mu| 2.0 * fresnel64(mu, eta) * mu * h).sum();
            let inside = diffuse_reflectance_inside(eta);
            assert!(
                ((1.0 - outside) - eta * eta * (1.0 - inside)).abs() < 1e-7,
                "η {eta}: {outside} {inside}"
            );
        }
        assert!(diffuse_reflectance_inside(1.0).abs() < 1e-12);
    }

    /// Against the fit Mitsuba uses for F_dr,int (Egan & Hilgeman 1973, in 1/η), within the
    /// accuracy its authors state: 0.1 % for indices 1–1.5, 0.6 % for 1.5–2.
    #[test]
    fn internal_diffuse_reflectance_matches_the_published_fit() {
        let fit = |e: f64| -1.4399 * e * e + 0.7099 * e + 0.6681 + 0.0636 / e;
        for (eta, tol) in [(1.2, 1e-3), (1.33, 1.1e-3), (1.49, 1e-3), (1.8, 6e-3), (2.0, 6e-3)] {
            let exact = diffuse_reflectance_inside(eta);
            let rel = (fit(1.0 / eta) - exact).abs() / exact;
            assert!(rel <= tol, "η {eta}: {exact} against the fit's {}: {rel}", fit(1.0 / eta));
        }
    }
}

/// A rough coat's tables (`RoughCoat::of`): the share of light the coat lets through at each
/// incidence, and its reflectance for diffuse light from inside.
#[derive(Debug, PartialEq)]
pub struct RoughCoat {
    /// T(μ) at μ = i/(N − 1), the rough interface's directional transmittance (N = 64).
    transmittance: [f32; COAT_TABLE],
    /// 2∫₀¹ R(μ, 1/η) μ dμ: what the coat sends back of diffuse light from the base.
    pub internal: f32,
}

/// Entries of a rough coat's transmittance table, over cos θ from 0 to 1 (as Mitsuba's
/// `roughplastic`, whose model this is).
pub const COAT_TABLE: usize = 64;

impl RoughCoat {
    /// The tables of a coat of roughness α and index η, computed once per (distribution, α, η)
    /// in a process and kept for its life (a few hundred bytes each), so that a `Bsdf` holding
    /// a reference stays `Copy`.
    pub fn of(dist: Distribution, alpha: f32, eta: f32) -> &'static RoughCoat {
        use std::sync::{Mutex, OnceLock};
        type Key = (bool, u32, u32);
        static COATS: OnceLock<Mutex<Vec<(Key, &'static RoughCoat)>>> = OnceLock::new();
        let key = (dist == Distribution::Ggx, alpha.to_bits(), eta.to_bits());
        let mut coats =
            COATS.get_or_init(|| Mutex::new(Vec::new())).lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, c)) = coats.iter().find(|(k, _)| *k == key) {
            return c;
        }
        let mut transmittance = [0.0; COAT_TABLE];
        transmittance.par_iter_mut().enumerate().for_each(|(i, t)| {
            let mu = (i as f32 / (COAT_TABLE - 1) as f32).max(1e-6);
            *t = rough_interface(dist, alpha, eta, mu).1;
        });
        // Midpoint rule in μ over 256 steps (R is smooth but for the kink at the critical angle).
        let steps = 256;
        let internal = (0..steps)
            .into_par_iter()
            .map(|k| {
                let mu = (k as f32 + 0.5) / steps as f32;
                2.0 * rough_interface(dist, alpha, 1.0 / eta, mu).0 * mu / steps as f32
            })
            .collect::<Vec<f32>>()
            .iter()
            .sum(); // in order: the same sum whatever the thread count
        let coat: &'static RoughCoat = Box::leak(Box::new(RoughCoat { transmittance, internal }));
        coats.push((key, coat));
        coat
    }

    /// T(cos θ), linearly interpolated in the table.
    #[inline]
    pub fn transmittance(&self, c: f32) -> f32 {
        let x = c.clamp(0.0, 1.0) * (COAT_TABLE - 1) as f32;
        let i = (x as usize).min(COAT_TABLE - 2);
        let f = x - i as f32;
        self.transmittance[i] * (1.0 - f) + self.transmittance[i + 1] * f
    }
}

/// The directional reflectance and transmittance (R, T) of a rough dielectric interface of
/// index η at incidence cos θ = μ: the means of F(wi·h)·G1(wo) and (1 − F(wi·h))·G1(wt) over
/// microfacet normals h visible from wi (wo reflected, wt refracted about h), on a 128 × 128
/// stratified grid of the visible-normal sampler. R + T < 1: the single-scattering loss.
fn rough_interface(dist: Distribution, alpha: f32, eta: f32, mu: f32) -> (f32, f32) {
    let n = Vec3A::Z;
    let wi = Vec3A::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let k = 128;
    let (mut r, mut t) = (0.0f64, 0.0f64);
    for a in 0..k {
        for b in 0..k {
            let (u1, u2) = ((a as f32 + 0.5) / k as f32, (b as f32 + 0.5) / k as f32);
            let h = microfacet::sample_visible(dist, alpha, n, wi, u1, u2);
            let ih = wi.dot(h);
            if ih <= 0.0 {
                continue;
            }
            let (f, cos_t) = fresnel_dielectric(ih, eta);
            let wo = reflect(wi, h);
            if wo.z > 0.0 {
                r += (f * microfacet::g1(dist, alpha, wo.z, wo.dot(h))) as f64;
            }
            if f < 1.0 {
                let wt = (-wi / eta + h * (ih / eta - cos_t)).normalize();
                if wt.z < 0.0 {
                    t += ((1.0 - f) * microfacet::g1(dist, alpha, wt.z, wt.dot(h))) as f64;
                }
            }
        }
    }
    let m = (k * k) as f64;
    ((r / m) as f32, (t / m) as f32)
}

/// Rough plastic's f(wo, wi) for cosines `co`, `ci` > 0: the coat's glossy reflection tinted by
/// `specular` plus the base under it, ρ/(1 − F_int)·T(θo)·T(θi)/(π η²) (ρ/(1 − ρ·F_int) when
/// `nonlinear`).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn rough_eval(
    kd: Vec3A,
    specular: Vec3A,
    dist: Distribution,
    alpha: f32,
    eta: f32,
    nonlinear: bool,
    coat: &RoughCoat,
    n: Vec3A,
    wo: Vec3A,
    wi: Vec3A,
) -> Vec3A {
    let (co, ci) = (n.dot(wo), n.dot(wi));
    let h = (wo + wi).normalize();
    let oh = wo.dot(h);
    let (f, _) = fresnel_dielectric(oh, eta);
    let dg = microfacet::d(dist, alpha, n.dot(h))
        * microfacet::g1(dist, alpha, co, oh)
        * microfacet::g1(dist, alpha, ci, wi.dot(h));
    let glossy = if dg.is_finite() { f * dg / (4.0 * co * ci) } else { 0.0 };
    let base = if nonlinear { kd / (Vec3A::ONE - kd * coat.internal) } else { kd / (1.0 - coat.internal) };
    specular * glossy + base * (coat.transmittance(co) * coat.transmittance(ci) / (PI * eta * eta))
}

/// Probability of sampling rough plastic's glossy lobe for cos θo = `co` (Mitsuba's choice:
/// the coat's reflectance 1 − T(θo) against its transmittance, weighted by the colours' means).
#[inline]
pub fn rough_specular_probability(kd: Vec3A, specular: Vec3A, coat: &RoughCoat, co: f32) -> f32 {
    let t = coat.transmittance(co);
    coat_lobe_probability(kd, specular, 1.0 - t, t)
}
