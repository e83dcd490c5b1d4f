//! Rough glass, as Mitsuba 3's `roughdielectric`: Walter et al. 2007, "Microfacet Models for
//! Refraction through Rough Surfaces", with the microfacet distributions of
//! `render::microfacet` (GGX or Beckmann, roughness α).
//!
//! For wo on the side of the normal n (cos θo > 0) and η = η on wi's far side / η on wo's
//! side (`Bsdf::facing` inverts it for a path inside):
//!
//! - reflection (cos θi > 0), h = (wo + wi)/|wo + wi|:
//!     f = F(wo·h)·D(h)·G1(wo)·G1(wi) / (4·cos θo·cos θi);
//! - refraction (cos θi < 0), h = ±(wo + η·wi)/|wo + η·wi| turned to n's side, wo and wi on
//!   the sides of h their cosines say:
//!     f = (1 − F(wo·h))·D(h)·G1(wo)·G1(wi)·|wo·h|·|wi·h| / (cos θo·|cos θi|·(wo·h + η·wi·h)²),
//!   which carries radiance (the 1/η² of crossing the interface and the η² of the half-vector
//!   Jacobian cancel, as in Mitsuba's radiance mode).
//!
//! F is the dielectric's exact Fresnel reflectance (`specular::fresnel_dielectric`), 1 past
//! the critical angle. Sampling draws h from the normals visible from wo (Heitz 2018; Heitz &
//! d'Eon 2014 for Beckmann), then reflects with probability F(wo·h), else refracts, so that
//!
//!   p(wi) = D_wo(h)·F / (4·wo·h)   or   D_wo(h)·(1 − F)·η²·|wi·h| / (wo·h + η·wi·h)²,
//!
//! with D_wo(h) = G1(wo)·D(h)·(wo·h)/cos θo, and the sample's weight is G1(wi) (reflection)
//! or G1(wi)/η² (refraction). The material's colour tints both (Mitsuba's
//! `specular_reflectance` = `specular_transmittance`).

use super::microfacet::{self, Distribution};
use super::specular::{fresnel_dielectric, reflect};
use glam::Vec3A;

/// The microfacet normal of a pair (wo, wi) and whether it is a reflection; `None` where the
/// pair cannot arise (grazing, or a side the microfacet and the macro-surface disagree on).
#[inline]
fn half_vector(n: Vec3A, wo: Vec3A, wi: Vec3A, eta: f32) -> Option<(Vec3A, bool)> {
    let (co, ci) = (n.dot(wo), n.dot(wi));
    if co <= 0.0 || ci == 0.0 {
        return None;
    }
    let reflection = ci > 0.0;
    let h = if reflection { wo + wi } else { wo + wi * eta };
    let len = h.length();
    if !(len > 0.0) {
        return None;
    }
    let h = h / len;
    let h = if n.dot(h) < 0.0 { -h } else { h };
    (wo.dot(h) > 0.0 && wi.dot(h) * ci > 0.0).then_some((h, reflection))
}

/// f(wo, wi) without the colour, for wo on n's side; wi on either side.
#[inline]
pub fn eval(dist: Distribution, alpha: f32, eta: f32, n: Vec3A, wo: Vec3A, wi: Vec3A) -> f32 {
    let Some((h, reflection)) = half_vector(n, wo, wi, eta) else { return 0.0 };
    let (co, ci) = (n.dot(wo), n.dot(wi));
    let (oh, ih) = (wo.dot(h), wi.dot(h));
    let (f, _) = fresnel_dielectric(oh, eta);
    let dg = microfacet::d(dist, alpha, n.dot(h))
        * microfacet::g1(dist, alpha, co, oh)
        * microfacet::g1(dist, alpha, ci, ih);
    let v = if reflection {
        f * dg / (4.0 * co * ci)
    } else {
        let denom = oh + eta * ih;
        (1.0 - f) * dg * (oh * ih).abs() / (co * ci.abs() * denom * denom)
    };
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// The density (solid angle) with which `sample` returns wi.
#[inline]
pub fn pdf(dist: Distribution, alpha: f32, eta: f32, n: Vec3A, wo: Vec3A, wi: Vec3A) -> f32 {
    let Some((h, reflection)) = half_vector(n, wo, wi, eta) else { return 0.0 };
    let (oh, ih) = (wo.dot(h), wi.dot(h));
    // D_wo(h) = G1(wo)·D(h)·(wo·h)/cos θo; `visible_pdf` is that over 4·(wo·h).
    let visible = microfacet::visible_pdf(dist, alpha, n.dot(wo), n.dot(h)) * 4.0 * oh;
    let (f, _) = fresnel_dielectric(oh, eta);
    let p = if reflection {
        visible * f / (4.0 * oh)
    } else {
        let denom = oh + eta * ih;
        visible * (1.0 - f) * eta * eta * ih.abs() / (denom * denom)
    };
    if p.is_finite() {
        p
    } else {
        0.0
    }
}

/// Samples wi for wo on n's side: a visible microfacet normal from (u1, u2), the lobe from
/// u3. Returns wi and the weight f·|cos θi|/p without the colour.
#[inline]
pub fn sample(
    dist: Distribution,
    alpha: f32,
    eta: f32,
    n: Vec3A,
    wo: Vec3A,
    u: [f32; 3],
) -> Option<(Vec3A, f32)> {
    let co = n.dot(wo);
    if co <= 0.0 {
        return None;
    }
    let h = microfacet::sample_visible(dist, alpha, n, wo, u[0], u[1]);
    let oh = wo.dot(h);
    if oh <= 0.0 {
        return None;
    }
    let (f, cos_t) = fresnel_dielectric(oh, eta);
    let wi = if u[2] < f {
        reflect(wo, h)
    } else {
        // Refraction about h: the tangential part scales by 1/η, the normal part is −cos θt.
        (-wo / eta + h * (oh / eta - cos_t)).normalize()
    };
    let ci = n.dot(wi);
    // A reflection below the surface or a refraction above it: the microfacet sends the
    // path where the macro-surface says it cannot go (the single-scattering model's loss).
    if (u[2] < f) != (ci > 0.0) || ci == 0.0 {
        return None;
    }
    let p = pdf(dist, alpha, eta, n, wo, wi);
    if !(p > 0.0) {
        return None;
    }
    let w = eval(dist, alpha, eta, n, wo, wi) * ci.abs() / p;
    w.is_finite().then_some((wi, w))
}
