//! Smooth (delta) interfaces: the mirror and the smooth dielectric, as Mitsuba 3's `conductor`
//! and `dielectric`.
//!
//! Both scatter into single directions, so their f and pdf are Dirac deltas: light sampling
//! cannot find the reflected light (the path tracer counts the emitter a sampled ray reaches
//! in full instead) and `Bsdf::eval`/`Bsdf::pdf` return 0 for them.
//!
//! - Mirror: wi = 2(wo·n)n − wo, weight R·F(wo·n) with F the conductor Fresnel reflectance
//!   (`microfacet::fresnel_conductor`) or 1 for a perfect mirror.
//! - Dielectric of relative index η = η_inside/η_outside: the exact unpolarised Fresnel
//!   reflectance F(cos θi, η); reflection is chosen with probability F and refraction
//!   (Snell: η_i sin θi = η_t sin θt) with 1 − F, so the weight is R in both cases, divided by
//!   η_ti² = (η_t/η_i)² on refraction because radiance is carried (L/η² is invariant along a
//!   path; Veach 1997, §5.2). Beyond the critical angle F = 1: total internal reflection.
//! - Thin dielectric (Mitsuba's `thindielectric`), a pane whose two faces reflect in turn:
//!   summing the light bounced between them, R' = R + T²R + T²R³ + … = 2R/(1 + R) with
//!   R = F(cos θi, η), T = 1 − R; reflected with probability R', else through undeviated
//!   (wi = −wo, the pane's refractions cancel), weight R in both cases.

use glam::Vec3A;

/// Mirror direction of `wo` about `n`.
#[inline]
pub fn reflect(wo: Vec3A, n: Vec3A) -> Vec3A {
    2.0 * wo.dot(n) * n - wo
}

/// Unpolarised Fresnel reflectance of a smooth dielectric interface for an incident cosine
/// `cos_i` > 0 measured on the side the light arrives from, with `eta` = η_t/η_i. Returns
/// (F, cos θt); F = 1 and cos θt = 0 under total internal reflection.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> (f32, f32) {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return (1.0, 0.0);
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    (0.5 * (rs * rs + rp * rp), cos_t)
}

/// Samples a smooth dielectric for `wo` on the side of `n` (n·wo > 0), with `eta` = η on the
/// far side / η on wo's side: (wi, weight / R) with wi below the surface on refraction.
#[inline]
pub fn sample_dielectric(n: Vec3A, wo: Vec3A, eta: f32, u: f32) -> (Vec3A, f32) {
    let cos_i = n.dot(wo);
    let (f, cos_t) = fresnel_dielectric(cos_i, eta);
    if u < f {
        return (reflect(wo, n), 1.0);
    }
    // Refracted direction: the tangential part scales by 1/η, the normal part is −cos θt.
    let wi = (-wo / eta + n * (cos_i / eta - cos_t)).normalize();
    (wi, 1.0 / (eta * eta))
}

/// Samples a thin dielectric pane of index `eta` for `wo` on the side of `n`: the mirror
/// direction with probability 2R/(1 + R), else straight through.
#[inline]
pub fn thin_dielectric(n: Vec3A, wo: Vec3A, eta: f32, u: f32) -> Vec3A {
    let (r, _) = fresnel_dielectric(n.dot(wo), eta);
    if u < 2.0 * r / (1.0 + r) {
        reflect(wo, n)
    } else {
        -wo
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_matches_closed_forms() {
        // Normal incidence: ((η − 1)/(η + 1))².
        let (f, c) = fresnel_dielectric(1.0, 1.5);
        assert!((f - 0.04).abs() < 1e-6 && (c - 1.0).abs() < 1e-6, "{f} {c}");
        // Brewster's angle tan θB = η: the p-polarised part vanishes, F = rs²/2.
        let tb = 1.5f32.atan();
        let (f, ct) = fresnel_dielectric(tb.cos(), 1.5);
        let st = tb.sin() / 1.5;
        assert!((ct - (1.0 - st * st).sqrt()).abs() < 1e-6);
        let rs = (tb.cos() - 1.5 * ct) / (tb.cos() + 1.5 * ct);
        assert!((f - 0.5 * rs * rs).abs() < 1e-6, "{f}");
        // Reciprocity across the interface: F(θi, η) = F(θt, 1/η).
        for deg in [0.0f32, 20.0, 40.0, 60.0, 80.0, 89.0] {
            let ci = deg.to_radians().cos();
            let (f1, ct) = fresnel_dielectric(ci, 1.33);
            let (f2, ci2) = fresnel_dielectric(ct, 1.0 / 1.33);
            assert!((f1 - f2).abs() < 1e-5 && (ci2 - ci).abs() < 1e-5, "{deg}: {f1} {f2}");
        }
        // Total internal reflection beyond the critical angle sin θc = 1/η, grazing F → 1.
        let crit = (1.0f32 / 1.5).asin();
        assert_eq!(fresnel_dielectric((crit + 0.01).cos(), 1.0 / 1.5).0, 1.0);
        assert!(fresnel_dielectric((crit - 0.01).cos(), 1.0 / 1.5).0 < 1.0);
        assert!(fresnel_dielectric(1e-4, 1.5).0 > 0.999);
    }

    #[test]
    fn dielectric_sampling_obeys_snell_and_fresnel() {
        let n = Vec3A::Z;
        for (deg, eta) in [(0.0f32, 1.5f32), (30.0, 1.5), (75.0, 1.5), (30.0, 1.0 / 1.5), (50.0, 1.0 / 1.5)] {
            let t = deg.to_radians();
            let wo = Vec3A::new(t.sin(), 0.0, t.cos());
            let (f, _) = fresnel_dielectric(t.cos(), eta);
            // Reflection for u < F, mirror direction, weight 1.
            if f > 0.0 {
                let (wi, w) = sample_dielectric(n, wo, eta, 0.5 * f);
                assert!((wi - Vec3A::new(-t.sin(), 0.0, t.cos())).length() < 1e-6 && w == 1.0);
            }
            if f < 1.0 {
                let (wi, w) = sample_dielectric(n, wo, eta, f + 0.5 * (1.0 - f));
                // Snell: η_i sin θi = η_t sin θt, wi on the far side, in the plane of incidence
                // and on the other side of the normal from wo.
                assert!(wi.z < 0.0 && wi.y.abs() < 1e-7 && wi.x <= 0.0);
                assert!((t.sin() - eta * (-wi.x)).abs() < 1e-5, "{deg} {eta}: {wi}");
                assert!((wi.length() - 1.0).abs() < 1e-6);
                assert!((w - 1.0 / (eta * eta)).abs() < 1e-6);
            }
        }
        // Beyond the critical angle every sample reflects.
        let t = 60f32.to_radians();
        let wo = Vec3A::new(t.sin(), 0.0, t.cos());
        assert!(sample_dielectric(n, wo, 1.0 / 1.5, 0.999).0.z > 0.0);
    }
}
