//! Reflectance models: Lambertian, normalised Blinn-Phong, rough conductors with GGX or
//! Beckmann microfacets (`render::microfacet`), the smooth mirror, dielectric and thin
//! dielectric (`render::specular`), rough glass (`render::rough_dielectric`) and smooth and
//! rough plastic (`render::plastic`).
//!
//! Blinn-Phong, the form photometric stereo fits:
//!
//!   f(wo, wi) = kd/π + ks·(e + 8)/(8π)·cosᵉθh,   h = (wo + wi)/|wo + wi|,
//!
//! (e + 8)/(8π) is the usual approximate normalisation of the lobe. Its directional albedo
//! (by quadrature) is 1.024 at e = 1, 1.075 at e = 10 (the peak), 1.018 at e = 100 for normal
//! incidence and falls off the normal (0.86 at 30°, 0.43 at 60° for e = 10), so a material with
//! kd + 1.075·ks ≤ 1 never reflects more light than it receives.
//! zero when either direction is below the surface. Sampling mixes a cosine-weighted lobe for
//! the diffuse term with the half-vector lobe p(h) = (e + 1)/(2π)·cosᵉθh for the specular one
//! (the reflected direction's density is p(h)/(4 wo·h)), choosing between them in proportion
//! to the luminance of kd and ks; the density of a direction is the mixture's, so either lobe
//! may have produced it. Directions are in world space around the shading normal n, which the
//! caller has turned to the side wo is on (surfaces are two-sided).

pub use super::geometry::basis;
use super::microfacet::{self, Distribution};
use super::plastic;
use super::rough_dielectric;
use super::specular;
pub use super::transport::{cosine_hemisphere, unit_circle};
use glam::Vec3A;
use std::f32::consts::{FRAC_1_PI, PI};

/// The model of a material (its diffuse colour kd is the material's albedo texture).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bsdf {
    Lambertian,
    BlinnPhong {
        specular: Vec3A,
        exponent: f32,
    },
    /// A rough conductor of complex index η + ik (per channel) with roughness α; the
    /// material's colour multiplies it (Mitsuba's `specular_reflectance`).
    Conductor {
        distribution: Distribution,
        alpha: f32,
        eta: Vec3A,
        k: Vec3A,
    },
    /// A smooth conductor (`render::specular`): the conductor's Fresnel reflectance for the
    /// complex index (η, k) per channel, or 1 (a perfect mirror) when `fresnel` is `None`;
    /// the material's colour multiplies it.
    Mirror {
        fresnel: Option<(Vec3A, Vec3A)>,
    },
    /// A smooth dielectric interface (`render::specular`), `eta` = η_inside / η_outside for
    /// light arriving on the side the surface normal points to; the material's colour tints
    /// reflection and transmission alike.
    Dielectric {
        eta: f32,
    },
    /// No surface at all, only where a medium begins or ends (Mitsuba's `null`): the path goes
    /// on straight through, unweighted.
    Null,
    /// Rough plastic (`render::plastic`, Mitsuba's `roughplastic`): the diffuse base of the
    /// material's colour under a microfacet coat of roughness α and index `eta`, whose glossy
    /// reflection `specular` tints; `coat` holds its tabulated transmittance.
    RoughPlastic {
        distribution: Distribution,
        alpha: f32,
        eta: f32,
        specular: Vec3A,
        nonlinear: bool,
        coat: &'static plastic::RoughCoat,
    },
    /// Rough glass (`render::rough_dielectric`, Mitsuba's `roughdielectric`): a dielectric
    /// interface of relative index `eta` (as `Dielectric`'s) made of microfacets of roughness
    /// α; the material's colour tints reflection and transmission alike.
    RoughDielectric {
        distribution: Distribution,
        alpha: f32,
        eta: f32,
    },
    /// A thin pane of a dielectric of index `eta` relative to the medium on both sides
    /// (Mitsuba's `thindielectric`, `render::specular::thin_dielectric`): it reflects, or lets
    /// light through undeviated; the material's colour tints both.
    ThinDielectric {
        eta: f32,
    },
    /// Smooth plastic (Mitsuba's `plastic`, `render::plastic`): a diffuse base of
    /// the material's colour under a smooth dielectric coat of relative index `eta`, whose
    /// mirror reflection `specular` tints; `fdr_int` is the coat's reflectance for diffuse
    /// light from inside, and `nonlinear` lets light reflected back into the base take its
    /// colour each time.
    Plastic {
        eta: f32,
        fdr_int: f32,
        specular: Vec3A,
        nonlinear: bool,
    },
}

/// A direction sampled from a model: wi, the weight f·cos/pdf, and whether a delta lobe
/// (a mirror, refraction or a pass through) produced it, so that the emitter the ray reaches
/// counts in full.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub wi: Vec3A,
    pub weight: Vec3A,
    pub delta: bool,
}

/// Rec. 709 luminance of linear RGB.
pub fn luminance(c: Vec3A) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

impl Bsdf {
    /// Whether the model scatters into single directions (f and pdf are Dirac deltas).
    #[inline]
    pub fn is_delta(&self) -> bool {
        matches!(
            self,
            Bsdf::Mirror { .. } | Bsdf::Dielectric { .. } | Bsdf::Null | Bsdf::ThinDielectric { .. }
        )
    }

    /// Whether the model has a lobe that is neither delta nor Lambertian, so that light and
    /// BSDF samples are weighed against each other by multiple importance sampling. Named by
    /// the glossy variants: written as "neither Lambertian nor delta", the test let LLVM call
    /// `Bsdf::pdf` on every Lambertian vertex and throw the result away (6 % of a Cornell
    /// path's instructions).
    #[inline]
    pub fn is_glossy(&self) -> bool {
        matches!(
            self,
            Bsdf::BlinnPhong { .. }
                | Bsdf::Conductor { .. }
                | Bsdf::RoughDielectric { .. }
                | Bsdf::RoughPlastic { .. }
        )
    }

    /// Whether `sample` uses its third number (a rough dielectric's choice of lobe).
    #[inline]
    pub fn needs_third_number(&self) -> bool {
        matches!(self, Bsdf::RoughDielectric { .. })
    }

    /// Whether light reaching the surface from behind (through it) is evaluated by `eval`, so
    /// that light sampling must look below the surface too.
    #[inline]
    pub fn transmits(&self) -> bool {
        matches!(self, Bsdf::RoughDielectric { .. })
    }

    /// The model with roughness α (rough conductors and glass; others are returned as they
    /// are).
    #[inline]
    pub fn with_alpha(self, a: f32) -> Bsdf {
        match self {
            Bsdf::Conductor { distribution, eta, k, .. } => {
                Bsdf::Conductor { distribution, alpha: a, eta, k }
            }
            Bsdf::RoughDielectric { distribution, eta, .. } => {
                Bsdf::RoughDielectric { distribution, alpha: a, eta }
            }
            b => b,
        }
    }

    /// The model for a path arriving on the front (`true`, the side the surface normal points
    /// to) or back of the surface: a dielectric seen from inside has the inverse index.
    #[inline]
    pub fn facing(self, front: bool) -> Bsdf {
        match self {
            Bsdf::Dielectric { eta } if !front => Bsdf::Dielectric { eta: 1.0 / eta },
            Bsdf::RoughDielectric { distribution, alpha, eta } if !front => {
                Bsdf::RoughDielectric { distribution, alpha, eta: 1.0 / eta }
            }
            b => b,
        }
    }

    /// Probability of sampling the specular lobe.
    fn specular_probability(&self, kd: Vec3A) -> f32 {
        match *self {
            Bsdf::Lambertian => 0.0,
            Bsdf::Conductor { .. }
            | Bsdf::RoughDielectric { .. }
            | Bsdf::Mirror { .. }
            | Bsdf::Dielectric { .. }
            | Bsdf::Null
            | Bsdf::ThinDielectric { .. } => 1.0,
            // Depends on the direction too: `plastic::specular_probability`.
            Bsdf::Plastic { .. } | Bsdf::RoughPlastic { .. } => 0.0,
            Bsdf::BlinnPhong { specular, .. } => {
                let (d, s) = (luminance(kd), luminance(specular));
                if s <= 0.0 {
                    0.0
                } else if d <= 0.0 {
                    1.0
                } else {
                    s / (d + s)
                }
            }
        }
    }

    /// f(wo, wi) (without the cosine); 0 for the delta models. The Lambertian case inlines
    /// into the path loop; the others stay a call.
    #[inline(always)]
    pub fn eval(&self, kd: Vec3A, n: Vec3A, wo: Vec3A, wi: Vec3A) -> Vec3A {
        match self {
            Bsdf::Lambertian => super::transport::lambert(kd, n, wo, wi),
            _ => self.eval_other(kd, n, wo, wi),
        }
    }

    #[inline(never)]
    fn eval_other(&self, kd: Vec3A, n: Vec3A, wo: Vec3A, wi: Vec3A) -> Vec3A {
        if let Bsdf::RoughDielectric { distribution, alpha, eta } = *self {
            return kd * rough_dielectric::eval(distribution, alpha, eta, n, wo, wi);
        }
        let (co, ci) = (n.dot(wo), n.dot(wi));
        if co <= 0.0 || ci <= 0.0 {
            return Vec3A::ZERO;
        }
        match *self {
            Bsdf::Mirror { .. }
            | Bsdf::Dielectric { .. }
            | Bsdf::Null
            | Bsdf::ThinDielectric { .. }
            | Bsdf::RoughDielectric { .. } => Vec3A::ZERO,
            Bsdf::Lambertian => kd * FRAC_1_PI,
            Bsdf::Plastic { eta, fdr_int, nonlinear, .. } => {
                plastic::diffuse(kd, eta, fdr_int, nonlinear, co, ci)
            }
            Bsdf::RoughPlastic { distribution, alpha, eta, specular, nonlinear, coat } => {
                plastic::rough_eval(kd, specular, distribution, alpha, eta, nonlinear, coat, n, wo, wi)
            }
            Bsdf::BlinnPhong { specular, exponent } => {
                let h = (wo + wi).normalize();
                let ch = n.dot(h).max(0.0);
                kd / PI + specular * ((exponent + 8.0) / (8.0 * PI) * ch.powf(exponent))
            }
            Bsdf::Conductor { distribution, alpha, eta, k } => {
                let h = (wo + wi).normalize();
                let ih = wi.dot(h);
                let dg = microfacet::d(distribution, alpha, n.dot(h))
                    * microfacet::g1(distribution, alpha, co, wo.dot(h))
                    * microfacet::g1(distribution, alpha, ci, ih);
                if !(dg > 0.0) {
                    return Vec3A::ZERO;
                }
                let f = Vec3A::new(
                    microfacet::fresnel_conductor(ih, eta.x, k.x),
                    microfacet::fresnel_conductor(ih, eta.y, k.y),
                    microfacet::fresnel_conductor(ih, eta.z, k.z),
                );
                kd * f * (dg / (4.0 * co * ci))
            }
        }
    }

    /// Density (solid angle) with which `sample` returns wi.
    pub fn pdf(&self, kd: Vec3A, n: Vec3A, wo: Vec3A, wi: Vec3A) -> f32 {
        if let Bsdf::RoughDielectric { distribution, alpha, eta } = *self {
            return rough_dielectric::pdf(distribution, alpha, eta, n, wo, wi);
        }
        let (co, ci) = (n.dot(wo), n.dot(wi));
        if co <= 0.0 || ci <= 0.0 {
            return 0.0;
        }
        let ps = self.specular_probability(kd);
        let diffuse = ci / PI;
        match *self {
            Bsdf::Mirror { .. }
            | Bsdf::Dielectric { .. }
            | Bsdf::Null
            | Bsdf::ThinDielectric { .. }
            | Bsdf::RoughDielectric { .. } => 0.0,
            Bsdf::Lambertian => diffuse,
            Bsdf::Plastic { eta, specular, .. } => {
                (1.0 - plastic::specular_probability(kd, specular, eta, co)) * diffuse
            }
            Bsdf::RoughPlastic { distribution, alpha, specular, coat, .. } => {
                let ps = plastic::rough_specular_probability(kd, specular, coat, co);
                let h = (wo + wi).normalize();
                let glossy = if wo.dot(h) > 0.0 {
                    microfacet::visible_pdf(distribution, alpha, co, n.dot(h))
                } else {
                    0.0
                };
                ps * glossy + (1.0 - ps) * diffuse
            }
            Bsdf::Conductor { distribution, alpha, .. } => {
                let h = (wo + wi).normalize();
                let oh = wo.dot(h);
                let ch = n.dot(h);
                if oh <= 0.0 {
                    0.0
                } else {
                    // Visible normals: G1(wo)·D(h)·(wo·h)/cos θo, times 1/(4 wo·h).
                    microfacet::visible_pdf(distribution, alpha, co, ch)
                }
            }
            Bsdf::BlinnPhong { exponent, .. } => {
                let h = (wo + wi).normalize();
                let (ch, oh) = (n.dot(h).max(0.0), wo.dot(h));
                let spec = if oh > 0.0 {
                    (exponent + 1.0) / (2.0 * PI) * ch.powf(exponent) / (4.0 * oh)
                } else {
                    0.0
                };
                (1.0 - ps) * diffuse + ps * spec
            }
        }
    }

    /// Samples wi for wo: wi, the weight f·|cos|/pdf and whether a delta lobe produced it, or
    /// `None` when the sample leaves below the surface (the path ends there). Only a
    /// dielectric's refracted direction (smooth or rough) and a thin dielectric's or null
    /// surface's direction through go below n. `u3` picks a rough dielectric's lobe (the
    /// others need two numbers; `needs_third_number`).
    #[inline]
    pub fn sample(&self, kd: Vec3A, n: Vec3A, wo: Vec3A, u1: f32, u2: f32, u3: f32) -> Option<Sample> {
        let delta = |wi: Vec3A, weight: Vec3A| Some(Sample { wi, weight, delta: true });
        let smooth = |wi: Vec3A, weight: Vec3A| Some(Sample { wi, weight, delta: false });
        match *self {
            Bsdf::Mirror { fresnel } => {
                let c = n.dot(wo);
                let f = match fresnel {
                    None => Vec3A::ONE,
                    Some((eta, k)) => Vec3A::new(
                        microfacet::fresnel_conductor(c, eta.x, k.x),
                        microfacet::fresnel_conductor(c, eta.y, k.y),
                        microfacet::fresnel_conductor(c, eta.z, k.z),
                    ),
                };
                if c > 0.0 {
                    delta(specular::reflect(wo, n), kd * f)
                } else {
                    None
                }
            }
            Bsdf::Null => delta(-wo, Vec3A::ONE),
            Bsdf::Dielectric { eta } => {
                if n.dot(wo) <= 0.0 {
                    return None;
                }
                let (wi, w) = specular::sample_dielectric(n, wo, eta, u1);
                delta(wi, kd * w)
            }
            Bsdf::RoughDielectric { distribution, alpha, eta } => {
                let (wi, w) = rough_dielectric::sample(distribution, alpha, eta, n, wo, [u1, u2, u3])?;
                smooth(wi, kd * w)
            }
            Bsdf::ThinDielectric { eta } => {
                if n.dot(wo) <= 0.0 {
                    return None;
                }
                delta(specular::thin_dielectric(n, wo, eta, u1), kd)
            }
            Bsdf::Plastic { eta, specular, .. } => {
                let co = n.dot(wo);
                if co <= 0.0 {
                    return None;
                }
                let (fi, _) = specular::fresnel_dielectric(co, eta);
                let ps = plastic::specular_probability(kd, specular, eta, co);
                if u1 < ps {
                    return delta(specular::reflect(wo, n), specular * (fi / ps));
                }
                let u = ((u1 - ps) / (1.0 - ps)).min(1.0 - f32::EPSILON);
                let wi = cosine_hemisphere(n, u, u2);
                let ci = n.dot(wi);
                if ci <= 0.0 {
                    return None;
                }
                // f·cos/pdf with pdf = (1 − ps)·cos/π.
                smooth(wi, self.eval(kd, n, wo, wi) * (PI / (1.0 - ps)))
            }
            Bsdf::RoughPlastic { distribution, alpha, specular, coat, .. } => {
                let co = n.dot(wo);
                if co <= 0.0 {
                    return None;
                }
                let ps = plastic::rough_specular_probability(kd, specular, coat, co);
                let wi = if u1 < ps {
                    let u = (u1 / ps).min(1.0 - f32::EPSILON);
                    let h = microfacet::sample_visible(distribution, alpha, n, wo, u, u2);
                    specular::reflect(wo, h)
                } else {
                    cosine_hemisphere(n, ((u1 - ps) / (1.0 - ps)).min(1.0 - f32::EPSILON), u2)
                };
                let ci = n.dot(wi);
                let pdf = self.pdf(kd, n, wo, wi);
                if ci <= 0.0 || !(pdf > 0.0) {
                    return None;
                }
                smooth(wi, self.eval(kd, n, wo, wi) * (ci / pdf))
            }
            // f·cos/pdf = (kd/π)·cos/(cos/π) = kd.
            Bsdf::Lambertian => smooth(cosine_hemisphere(n, u1, u2), kd),
            Bsdf::Conductor { distribution, alpha, .. } => {
                let h = microfacet::sample_visible(distribution, alpha, n, wo, u1, u2);
                let wi = specular::reflect(wo, h);
                let ci = n.dot(wi);
                let pdf = self.pdf(kd, n, wo, wi);
                if ci <= 0.0 || !(pdf > 0.0) {
                    return None;
                }
                smooth(wi, self.eval(kd, n, wo, wi) * (ci / pdf))
            }
            Bsdf::BlinnPhong { exponent, .. } => {
                let ps = self.specular_probability(kd);
                let wi = if u1 < ps {
                    // Reuse u1 within the chosen lobe.
                    let u = (u1 / ps).min(1.0);
                    let cos_h = u.powf(1.0 / (exponent + 1.0));
                    let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
                    let phi = 2.0 * PI * u2;
                    let (t, b) = basis(n);
                    let h = t * (sin_h * phi.cos()) + b * (sin_h * phi.sin()) + n * cos_h;
                    specular::reflect(wo, h)
                } else {
                    let u = ((u1 - ps) / (1.0 - ps)).min(1.0 - f32::EPSILON);
                    cosine_hemisphere(n, u, u2)
                };
                let ci = n.dot(wi);
                if ci <= 0.0 {
                    return None;
                }
                let pdf = self.pdf(kd, n, wo, wi);
                if !(pdf > 0.0) {
                    return None;
                }
                smooth(wi, self.eval(kd, n, wo, wi) * (ci / pdf))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::{Sampler, SamplerKind};

    /// Cosine-weighted directions come out unit length (they are not renormalised) and in the
    /// upper hemisphere, for normals all over the sphere, the poles included.
    #[test]
    fn cosine_directions_are_unit() {
        let mut s = Sampler::new(4, 5, 6);
        for k in 0..20_000 {
            let n = match k {
                0 => Vec3A::Z,
                1 => -Vec3A::Z,
                _ => Vec3A::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5).normalize(),
            };
            let (u1, u2) = s.next2();
            let wi = cosine_hemisphere(n, u1, u2);
            assert!((wi.length() - 1.0).abs() < 1e-6 && n.dot(wi) >= 0.0, "n {n}, wi {wi}");
        }
    }

    /// `unit_circle` against f64 sine and cosine on a fine grid of [0, 1], both ends included.
    #[test]
    fn unit_circle_is_accurate() {
        let mut worst = 0.0f64;
        for k in 0..=1_000_000u32 {
            let u = k as f32 / 1_000_000.0;
            let (c, s) = unit_circle(u);
            let phi = 2.0 * std::f64::consts::PI * u as f64;
            worst = worst.max((c as f64 - phi.cos()).abs()).max((s as f64 - phi.sin()).abs());
        }
        assert!(worst < 1.5e-7, "worst error {worst}");
    }

    fn dir(theta_deg: f32, phi_deg: f32) -> Vec3A {
        let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
        Vec3A::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
    }

    fn gold(distribution: Distribution, alpha: f32) -> Bsdf {
        Bsdf::Conductor {
            distribution,
            alpha,
            eta: Vec3A::new(0.143, 0.374, 1.442),
            k: Vec3A::new(3.983, 2.385, 1.603),
        }
    }

    /// Conductors: at normal incidence and reflection h = n, so D = 1/(πα²) for either
    /// distribution, G = 1, F = ((η−1)² + k²)/((η+1)² + k²), f = R·F/(4πα²).
    #[test]
    fn conductor_eval_closed_form() {
        for distribution in [Distribution::Ggx, Distribution::Beckmann] {
            let bsdf = gold(distribution, 0.2);
            let tint = Vec3A::new(1.0, 0.5, 0.25);
            let f = bsdf.eval(tint, Vec3A::Z, Vec3A::Z, Vec3A::Z);
            for (c, (eta, k)) in
                [(0.143f32, 3.983f32), (0.374, 2.385), (1.442, 1.603)].into_iter().enumerate()
            {
                let r0 = ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k);
                let want = tint[c] * r0 / (4.0 * PI * 0.04);
                assert!(
                    (f[c] - want).abs() < 1e-4 * want,
                    "{distribution:?} channel {c}: {} vs {want}",
                    f[c]
                );
            }
            assert_eq!(bsdf.eval(tint, Vec3A::Z, dir(30.0, 0.0), dir(100.0, 0.0)), Vec3A::ZERO);
        }
    }

    /// Gold conductors, GGX and Beckmann, α 0.05–1, incidence 0°–85°: the mean sampled weight
    /// equals ∫ f cos dω by quadrature (sampling is consistent with eval and pdf), the density
    /// integrates to at most 1, and the directional albedo stays ≤ 1 (Smith's single-scattering
    /// model loses energy, never creates it).
    #[test]
    fn conductor_sampling_consistent_and_lossy() {
        let n = Vec3A::Z;
        for distribution in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.05f32, 0.3, 1.0] {
                for theta_o in [0.0f32, 60.0, 85.0] {
                    let bsdf = gold(distribution, alpha);
                    let wo = dir(theta_o, 0.0);
                    // Fine in φ: a narrow lobe reflected at grazing incidence is thin in azimuth.
                    let (nt, np) = (1500, 4000);
                    let mut albedo = 0.0f64;
                    let mut pdf_sum = 0.0f64;
                    for i in 0..nt {
                        // cos θ = 1 − x²: denser near the pole for narrow lobes.
                        let (x0, x1) = (i as f64 / nt as f64, (i + 1) as f64 / nt as f64);
                        let x = 0.5 * (x0 + x1);
                        let ct = 1.0 - x * x;
                        let st = (1.0 - ct * ct).max(0.0).sqrt();
                        for j in 0..np {
                            let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
                            let wi = Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                            let dw = 2.0 * x * (x1 - x0) * 2.0 * std::f64::consts::PI / np as f64;
                            albedo += bsdf.eval(Vec3A::ONE, n, wo, wi).x as f64 * ct * dw;
                            pdf_sum += bsdf.pdf(Vec3A::ONE, n, wo, wi) as f64 * dw;
                        }
                    }
                    let m = 400_000;
                    let mut sum = 0.0f64;
                    for k in 0..m {
                        let (u1, u2) = Sampler::with_kind(SamplerKind::Independent, 17, k, 0).next2();
                        if let Some(Sample { wi, weight: w, .. }) =
                            bsdf.sample(Vec3A::ONE, n, wo, u1, u2, 0.5)
                        {
                            assert!(w.is_finite() && n.dot(wi) > 0.0);
                            sum += w.x as f64;
                        }
                    }
                    let mc = sum / m as f64;
                    let case = format!("{distribution:?} α {alpha} θo {theta_o}");
                    assert!(pdf_sum <= 1.0 + 3e-3, "{case}: ∫pdf = {pdf_sum}");
                    assert!(albedo <= 1.0, "{case}: albedo {albedo}");
                    assert!(
                        (mc - albedo).abs() < 0.01 * albedo.max(0.1),
                        "{case}: sampled {mc} vs quadrature {albedo}"
                    );
                }
            }
        }
    }

    /// f at fixed directions against the formula worked by hand.
    #[test]
    fn eval_closed_form() {
        let bp = Bsdf::BlinnPhong { specular: Vec3A::splat(0.4), exponent: 20.0 };
        let kd = Vec3A::splat(0.5);
        let (wo, wi) = (dir(30.0, 0.0), dir(30.0, 180.0));
        // Mirror pair: h = n, cos θh = 1.
        let want = 0.5 / PI + 0.4 * 28.0 / (8.0 * PI);
        assert!((bp.eval(kd, Vec3A::Z, wo, wi).x - want).abs() < 1e-6);
        // θh = 15° for wo at 30°, wi at 0°.
        let want = 0.5 / PI + 0.4 * 28.0 / (8.0 * PI) * 15f32.to_radians().cos().powf(20.0);
        assert!((bp.eval(kd, Vec3A::Z, wo, Vec3A::Z).x - want).abs() < 1e-6);
        assert_eq!(bp.eval(kd, Vec3A::Z, wo, dir(100.0, 0.0)), Vec3A::ZERO);
        assert!((Bsdf::Lambertian.eval(kd, Vec3A::Z, wo, wi).x - 0.5 / PI).abs() < 1e-7);
    }

    /// For several exponents and incident angles (grazing included): the density integrates to
    /// at most 1 over the hemisphere (exactly 1 less what the specular lobe sends below the
    /// surface), and the mean sampled weight equals ∫ f cos dω computed by quadrature — so the
    /// samples follow `pdf` — and stays ≤ 1 for kd + ks = 1 (no energy is created).
    #[test]
    fn pdf_normalised_and_sampling_consistent() {
        let n = Vec3A::Z;
        for exponent in [1.0f32, 10.0, 100.0] {
            for theta_o in [0.0f32, 45.0, 80.0, 89.0] {
                let bp = Bsdf::BlinnPhong { specular: Vec3A::splat(0.6), exponent };
                let kd = Vec3A::splat(0.4);
                let wo = dir(theta_o, 0.0);
                // Quadrature over the hemisphere in (cos θ, φ), fine enough for e = 100.
                let (nt, np) = (2000, 1000);
                let (mut pdf_sum, mut albedo) = (0.0f64, 0.0f64);
                for i in 0..nt {
                    let ct = (i as f64 + 0.5) / nt as f64;
                    let st = (1.0 - ct * ct).sqrt();
                    for j in 0..np {
                        let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
                        let wi = Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                        let dw = (1.0 / nt as f64) * (2.0 * std::f64::consts::PI / np as f64);
                        pdf_sum += bp.pdf(kd, n, wo, wi) as f64 * dw;
                        albedo += bp.eval(kd, n, wo, wi).x as f64 * ct * dw;
                    }
                }
                assert!(
                    pdf_sum <= 1.0 + 2e-3 && pdf_sum > 0.5,
                    "e {exponent}, θo {theta_o}: ∫pdf = {pdf_sum}"
                );
                let m = 400_000;
                let mut sum = 0.0f64;
                for k in 0..m {
                    let mut s = Sampler::with_kind(SamplerKind::Independent, 11, k, 0);
                    let (u1, u2) = s.next2();
                    if let Some(Sample { wi, weight: w, .. }) = bp.sample(kd, n, wo, u1, u2, 0.5) {
                        assert!(w.is_finite() && n.dot(wi) > 0.0);
                        sum += w.x as f64;
                    }
                }
                let mc = sum / m as f64;
                // The lobe reflects at most 1.075 of the light (module docs).
                assert!(albedo <= 0.4 + 0.6 * 1.076, "e {exponent}, θo {theta_o}: albedo {albedo}");
                assert!(
                    (mc - albedo).abs() < 0.01 * albedo.max(0.1),
                    "e {exponent}, θo {theta_o}: sampled {mc} vs quadrature {albedo}"
                );
            }
        }
    }

    /// Pearson's χ² test of the sampled directions against `pdf`, as pbrt-v4 and Mitsuba 3 test
    /// their BSDFs: 10⁶ samples per case into a 16 × 32 grid over (cos θ, φ) of the upper
    /// hemisphere, expected counts from the pdf integrated over each cell (16 × 16 midpoints,
    /// 128 × 128 in the band next to the horizon),
    /// cells expecting fewer than 5 pooled; every case must pass at 0.01 after Šidák's
    /// correction over the cases. Blinn-Phong exponents 1–100, incidence 0°–89° (grazing);
    /// GGX and Beckmann conductors with α 0.1–0.8, incidence 0°–80°.
    #[test]
    fn chi_square_sampling() {
        use crate::math::stats::{chi2_test, sidak_alpha};
        let n = Vec3A::Z;
        let mut cases = vec![(Bsdf::Lambertian, Vec3A::splat(0.5), 30.0f32)];
        for e in [1.0f32, 10.0, 100.0] {
            for theta_o in [0.0f32, 45.0, 80.0, 89.0] {
                cases.push((
                    Bsdf::BlinnPhong { specular: Vec3A::splat(0.5), exponent: e },
                    Vec3A::splat(0.3),
                    theta_o,
                ));
            }
        }
        cases.push((Bsdf::BlinnPhong { specular: Vec3A::splat(0.7), exponent: 20.0 }, Vec3A::ZERO, 30.0));
        for distribution in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.1f32, 0.3, 0.8] {
                for theta_o in [0.0f32, 45.0, 80.0] {
                    cases.push((gold(distribution, alpha), Vec3A::ONE, theta_o));
                }
            }
        }
        let alpha = sidak_alpha(0.01, cases.len());
        let (nt, np, sub) = (16usize, 32usize, 16usize);
        let samples = 1_000_000u64;
        for (case, &(bsdf, kd, theta_o)) in cases.iter().enumerate() {
            let wo = dir(theta_o, 0.0);
            let cell = |wi: Vec3A| {
                let t = ((wi.z.clamp(0.0, 1.0) * nt as f32) as usize).min(nt - 1);
                let phi = wi.y.atan2(wi.x).rem_euclid(2.0 * PI);
                let p = ((phi / (2.0 * PI) * np as f32) as usize).min(np - 1);
                t * np + p
            };
            let mut observed = vec![0.0f64; nt * np];
            for k in 0..samples {
                let (u1, u2) = Sampler::with_kind(SamplerKind::Independent, 3 + case as u64, k, 0).next2();
                if let Some(Sample { wi, .. }) = bsdf.sample(kd, n, wo, u1, u2, 0.5) {
                    observed[cell(wi)] += 1.0;
                }
            }
            let mut expected = vec![0.0f64; nt * np];
            for t in 0..nt {
                // At the horizon the specular density of a grazing wo climbs steeply towards
                // wi = −wo (its 1/(4 wo·h) factor): finer quadrature in that band.
                let sub = if t == 0 { 8 * sub } else { sub };
                for p in 0..np {
                    let mut sum = 0.0f64;
                    for a in 0..sub {
                        let ct = (t as f64 + (a as f64 + 0.5) / sub as f64) / nt as f64;
                        let st = (1.0 - ct * ct).max(0.0).sqrt();
                        for b in 0..sub {
                            let phi = 2.0 * std::f64::consts::PI * (p as f64 + (b as f64 + 0.5) / sub as f64)
                                / np as f64;
                            let wi = Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                            sum += bsdf.pdf(kd, n, wo, wi) as f64;
                        }
                    }
                    let area = (1.0 / nt as f64) * (2.0 * std::f64::consts::PI / np as f64);
                    expected[t * np + p] = samples as f64 * sum / (sub * sub) as f64 * area;
                }
            }
            let p = chi2_test(&observed, &expected).expect("enough cells");
            assert!(
                p >= alpha,
                "case {case} ({bsdf:?}, θo {theta_o}°): χ² p-value {p:.3e} below {alpha:.3e}"
            );
        }
    }

    /// Smooth plastic's directional albedo in closed form against the mean sample weight
    /// (4·10⁵ samples, 4 SE): s·F(θo) + (1 − F(θo))·ρ, or with `nonlinear` the base's share
    /// ρ(1 − F_dr)/(1 − ρF_dr), since ∫(1 − F(θi))·cos/π dωi = η²(1 − F_dr). Every diffuse
    /// sample's weight is f·cos/pdf from `eval` and `pdf`.
    #[test]
    fn plastic_albedo_closed_form() {
        for (eta, kd, spec, nonlinear) in [
            (1.49f32, 0.5f32, 1.0f32, false),
            (1.33, 0.8, 0.6, true),
            (1.8, 0.2, 1.0, false),
            (1.49, 1.0, 1.0, false),
        ] {
            let fdr = plastic::diffuse_reflectance_inside(eta as f64) as f32;
            let bsdf = Bsdf::Plastic { eta, fdr_int: fdr, specular: Vec3A::splat(spec), nonlinear };
            let kd3 = Vec3A::splat(kd);
            for deg in [0.0f32, 30.0, 60.0, 85.0] {
                let wo = dir(deg, 20.0);
                let (fi, _) = specular::fresnel_dielectric(wo.z, eta);
                let base = if nonlinear { kd * (1.0 - fdr) / (1.0 - kd * fdr) } else { kd };
                let want = (spec * fi + (1.0 - fi) * base) as f64;
                let mut s = Sampler::new(7, deg as u64, 1);
                let n = 400_000;
                let (mut sum, mut sum2) = (0.0f64, 0.0f64);
                for _ in 0..n {
                    let (u1, u2) = s.next2();
                    let Some(smp) = bsdf.sample(kd3, Vec3A::Z, wo, u1, u2, 0.5) else { continue };
                    if !smp.delta {
                        let (f, pdf) =
                            (bsdf.eval(kd3, Vec3A::Z, wo, smp.wi), bsdf.pdf(kd3, Vec3A::Z, wo, smp.wi));
                        let direct = f.x * smp.wi.z / pdf;
                        assert!(
                            (smp.weight.x - direct).abs() <= 1e-4 * direct,
                            "{} vs {direct}",
                            smp.weight.x
                        );
                    }
                    let w = smp.weight.x as f64;
                    sum += w;
                    sum2 += w * w;
                }
                let mean = sum / n as f64;
                let se = ((sum2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt();
                assert!(
                    (mean - want).abs() < 4.0 * se + 1e-5,
                    "η {eta}, ρ {kd}, s {spec}, nonlinear {nonlinear}, θo {deg}°: {mean} ± {se} vs {want}"
                );
            }
        }
    }

    /// A thin pane reflects with probability 2R/(1 + R) (R the Fresnel reflectance, the light
    /// bounced between its faces summed) and otherwise passes light undeviated, weight 1.
    #[test]
    fn thin_dielectric_reflects_two_r_over_one_plus_r() {
        for (deg, eta) in [(0.0f32, 1.5f32), (45.0, 1.5), (80.0, 1.5), (60.0, 1.33)] {
            let wo = dir(deg, 0.0);
            let (r, _) = specular::fresnel_dielectric(wo.z, eta);
            let want = 2.0 * r as f64 / (1.0 + r as f64);
            let bsdf = Bsdf::ThinDielectric { eta };
            let mut s = Sampler::new(3, deg as u64, 2);
            let n = 200_000;
            let mut reflected = 0usize;
            for _ in 0..n {
                let (u1, u2) = s.next2();
                let smp = bsdf.sample(Vec3A::ONE, Vec3A::Z, wo, u1, u2, 0.5).expect("a pane always scatters");
                assert!(smp.delta && smp.weight == Vec3A::ONE);
                if smp.wi.z > 0.0 {
                    assert!((smp.wi - Vec3A::new(-wo.x, -wo.y, wo.z)).length() < 1e-6);
                    reflected += 1;
                } else {
                    assert_eq!(smp.wi, -wo);
                }
            }
            let p = reflected as f64 / n as f64;
            let se = (want * (1.0 - want) / n as f64).sqrt();
            assert!((p - want).abs() < 4.0 * se + 1e-6, "θ {deg}°, η {eta}: {p} vs {want}");
        }
    }

    /// Rough glass sampled over the whole sphere of directions (reflection and refraction,
    /// from outside η = 1.5 and from inside η = 1/1.5), Pearson's χ² against `pdf` as in
    /// `chi_square_sampling` (32 × 32 cells over cos θ ∈ [−1, 1] and φ); and the mean sample
    /// weight equal to ∫ f·|cos θi| dωi by the same quadrature, at most 1 from outside (the
    /// single-scattering model loses what microfacets send to the wrong side).
    #[test]
    fn rough_dielectric_sampling_over_the_sphere() {
        use crate::math::stats::{chi2_test, sidak_alpha};
        let n = Vec3A::Z;
        let mut cases = Vec::new();
        for (distribution, alpha) in
            [(Distribution::Ggx, 0.2f32), (Distribution::Ggx, 0.5), (Distribution::Beckmann, 0.3)]
        {
            for eta in [1.5f32, 1.0 / 1.5] {
                for theta_o in [0.0f32, 40.0, 75.0] {
                    cases.push((Bsdf::RoughDielectric { distribution, alpha, eta }, theta_o));
                }
            }
        }
        let level = sidak_alpha(0.01, cases.len());
        let (nt, np, sub) = (32usize, 32usize, 16usize);
        let samples = 1_000_000u64;
        for (case, &(bsdf, theta_o)) in cases.iter().enumerate() {
            let wo = dir(theta_o, 0.0);
            let cell = |wi: Vec3A| {
                let t = (((wi.z.clamp(-1.0, 1.0) + 1.0) * 0.5 * nt as f32) as usize).min(nt - 1);
                let phi = wi.y.atan2(wi.x).rem_euclid(2.0 * PI);
                t * np + ((phi / (2.0 * PI) * np as f32) as usize).min(np - 1)
            };
            let (mut observed, mut weight) = (vec![0.0f64; nt * np], 0.0f64);
            for k in 0..samples {
                let mut s = Sampler::with_kind(SamplerKind::Independent, 40 + case as u64, k, 0);
                let (u1, u2) = s.next2();
                if let Some(Sample { wi, weight: w, delta }) =
                    bsdf.sample(Vec3A::ONE, n, wo, u1, u2, s.next())
                {
                    assert!(!delta && w.is_finite() && w.x >= 0.0);
                    observed[cell(wi)] += 1.0;
                    weight += w.x as f64;
                }
            }
            let (mut expected, mut albedo) = (vec![0.0f64; nt * np], 0.0f64);
            for t in 0..nt {
                // Refraction near normal incidence squeezes the lobe into a sliver around −n
                // (and reflection around +n): finer steps in cos θ in the bands at the poles.
                let st_sub = match t.min(nt - 1 - t) {
                    0 => 64 * sub,
                    1 => 4 * sub,
                    _ => sub,
                };
                let area =
                    (2.0 / nt as f64) * (2.0 * std::f64::consts::PI / np as f64) / (st_sub * sub) as f64;
                for p in 0..np {
                    let mut sum = 0.0f64;
                    for a in 0..st_sub {
                        let ct = -1.0 + 2.0 * (t as f64 + (a as f64 + 0.5) / st_sub as f64) / nt as f64;
                        let st = (1.0 - ct * ct).max(0.0).sqrt();
                        for b in 0..sub {
                            let phi = 2.0 * std::f64::consts::PI * (p as f64 + (b as f64 + 0.5) / sub as f64)
                                / np as f64;
                            let wi = Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                            sum += bsdf.pdf(Vec3A::ONE, n, wo, wi) as f64;
                            albedo += bsdf.eval(Vec3A::ONE, n, wo, wi).x as f64 * ct.abs() * area;
                        }
                    }
                    expected[t * np + p] = samples as f64 * sum * area;
                }
            }
            let p = chi2_test(&observed, &expected).expect("enough cells");
            assert!(
                p >= level,
                "case {case} ({bsdf:?}, θo {theta_o}°): χ² p-value {p:.3e} below {level:.3e}"
            );
            let mc = weight / samples as f64;
            // Radiance entering a denser medium grows by 1/η² (L/η² is conserved), so from
            // inside (η < 1) the bound is 1/η².
            let Bsdf::RoughDielectric { eta, .. } = bsdf else { unreachable!() };
            assert!(albedo <= (1.0 / (eta * eta) as f64).max(1.0) + 1e-3, "case {case}: ∫f|cos| = {albedo}");
            assert!(
                (mc - albedo).abs() < 0.01 * albedo,
                "case {case} ({bsdf:?}, θo {theta_o}°): sampled {mc} vs quadrature {albedo}"
            );
        }
    }

    /// Rough plastic: the mean sample weight equals ∫ f·cos θi dωi by quadrature (1 %), so
    /// the two lobes are sampled as `pdf` says, for GGX and Beckmann coats, linear and nonlinear,
    /// from normal to grazing incidence; and its coat tables behave: T(1) ≈ 1 − F(1) for a
    /// nearly smooth coat, and the internal reflectance near the smooth coat's exact one.
    #[test]
    fn rough_plastic_sampling_consistent() {
        let n = Vec3A::Z;
        let smooth = plastic::RoughCoat::of(Distribution::Ggx, 0.001, 1.5);
        let f0 = specular::fresnel_dielectric(1.0, 1.5).0;
        assert!((smooth.transmittance(1.0) - (1.0 - f0)).abs() < 2e-3, "T(1) {}", smooth.transmittance(1.0));
        let exact = plastic::diffuse_reflectance_inside(1.5) as f32;
        assert!((smooth.internal - exact).abs() < 0.01 * exact, "F_int {} vs {exact}", smooth.internal);
        for (distribution, alpha, nonlinear) in
            [(Distribution::Ggx, 0.1f32, false), (Distribution::Beckmann, 0.4, true)]
        {
            let eta = 1.49f32;
            let coat = plastic::RoughCoat::of(distribution, alpha, eta);
            let bsdf = Bsdf::RoughPlastic { distribution, alpha, eta, specular: Vec3A::ONE, nonlinear, coat };
            let kd = Vec3A::new(0.7, 0.4, 0.2);
            for theta_o in [0.0f32, 45.0, 80.0] {
                let wo = dir(theta_o, 0.0);
                let (nt, np) = (1000, 500);
                let mut albedo = 0.0f64;
                for i in 0..nt {
                    let ct = (i as f64 + 0.5) / nt as f64;
                    let st = (1.0 - ct * ct).sqrt();
                    for j in 0..np {
                        let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
                        let wi = Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                        albedo +=
                            bsdf.eval(kd, n, wo, wi).x as f64 * ct / nt as f64 * 2.0 * std::f64::consts::PI
                                / np as f64;
                    }
                }
                let m = 400_000;
                let mut sum = 0.0f64;
                for k in 0..m {
                    let mut s = Sampler::with_kind(SamplerKind::Independent, 60, k, 0);
                    let (u1, u2) = s.next2();
                    if let Some(Sample { wi, weight, delta }) = bsdf.sample(kd, n, wo, u1, u2, 0.5) {
                        assert!(!delta && weight.is_finite() && n.dot(wi) > 0.0);
                        sum += weight.x as f64;
                    }
                }
                let mc = sum / m as f64;
                assert!(
                    (mc - albedo).abs() < 0.01 * albedo,
                    "{distribution:?} α {alpha}, θo {theta_o}: sampled {mc} vs quadrature {albedo}"
                );
            }
        }
    }
}
