//! Microfacet distributions for rough conductors, in the forms Mitsuba 3 uses (so that images
//! compare with its `roughconductor`): Walter et al. 2007, "Microfacet Models for Refraction
//! through Rough Surfaces".
//!
//!   GGX:       D(h) = α² / (π·cos⁴θh·(α² + tan²θh)²),  G1(v) = 2 / (1 + √(1 + α²·tan²θv))
//!   Beckmann:  D(h) = exp(−tan²θh/α²) / (π·α²·cos⁴θh), G1(v) from Walter's rational fit in
//!              a = 1/(α·tanθv): (3.535a + 2.181a²)/(1 + 2.276a + 2.577a²) for a < 1.6, else 1
//!
//! Shadowing-masking is Smith's separable form G = G1(wo)·G1(wi), each G1 zero when v·h and
//! n·v differ in sign. The conductor's reflectance is
//!
//!   f(wo, wi) = R·F(wi·h)·D(h)·G / (4·cosθo·cosθi),   h = (wo + wi)/|wo + wi|,
//!
//! with F the exact unpolarised Fresnel reflectance of a conductor of complex index η + ik
//! (per RGB channel) and R the material's colour (Mitsuba's `specular_reflectance`, 1 by
//! default). Sampling reflects wo about a microfacet normal h drawn from the normals visible
//! from wo, as Mitsuba does by default (`sample_visible_ggx`, `sample_visible_beckmann`):
//! p(wi) = G1(wo)·D(h) / (4·cos θo) with Smith's exact G1 (for Beckmann the erf form, not
//! Walter's fit, which only `eval` uses so that images match Mitsuba's), and the sample's
//! weight f·cos/p ≈ R·F·G1(wi) never much exceeds R. `sample_h` (D(h)·cos θh) is kept for
//! tests of D.

use super::geometry::basis;
use glam::Vec3A;
use std::f32::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Distribution {
    Ggx,
    Beckmann,
}

/// D(h) for cos θh = `c` (0 below the surface).
#[inline]
pub fn d(dist: Distribution, alpha: f32, c: f32) -> f32 {
    if c <= 0.0 {
        return 0.0;
    }
    let c2 = c * c;
    let tan2 = (1.0 - c2).max(0.0) / c2;
    let a2 = alpha * alpha;
    let v = match dist {
        Distribution::Ggx => {
            let s = a2 + tan2;
            a2 / (PI * c2 * c2 * s * s)
        }
        Distribution::Beckmann => (-tan2 / a2).exp() / (PI * a2 * c2 * c2),
    };
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// Smith's G1 for direction v (cos θv = `cv`) and microfacet normal with v·h = `vh`.
#[inline]
pub fn g1(dist: Distribution, alpha: f32, cv: f32, vh: f32) -> f32 {
    if vh * cv <= 0.0 {
        return 0.0;
    }
    let c2 = cv * cv;
    let tan2 = (1.0 - c2).max(0.0) / c2;
    if tan2 == 0.0 {
        return 1.0;
    }
    match dist {
        Distribution::Ggx => 2.0 / (1.0 + (1.0 + alpha * alpha * tan2).sqrt()),
        Distribution::Beckmann => {
            let a = 1.0 / (alpha * tan2.sqrt());
            if a >= 1.6 {
                1.0
            } else {
                (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
            }
        }
    }
}

/// A microfacet normal around `n` drawn from D(h)·cos θh.
#[inline]
pub fn sample_h(dist: Distribution, alpha: f32, n: Vec3A, u1: f32, u2: f32) -> Vec3A {
    let u1 = u1.min(1.0 - 1e-7);
    let tan2 = match dist {
        Distribution::Ggx => alpha * alpha * u1 / (1.0 - u1),
        Distribution::Beckmann => -alpha * alpha * (1.0 - u1).ln(),
    };
    let c = 1.0 / (1.0 + tan2).sqrt();
    let s = (1.0 - c * c).max(0.0).sqrt();
    let phi = 2.0 * PI * u2;
    let (t, b) = basis(n);
    (t * (s * phi.cos()) + b * (s * phi.sin()) + n * c).normalize()
}

/// A GGX microfacet normal around `n` drawn from the distribution of normals visible from
/// `wo`, D_wo(h) = G1(wo)·max(0, wo·h)·D(h) / cos θo (Heitz 2018, "Sampling the GGX
/// Distribution of Visible Normals"): the view is stretched by α into the configuration of
/// roughness 1, a point is drawn on the projected hemisphere, and the normal stretched back.
#[inline]
pub fn sample_visible_ggx(alpha: f32, n: Vec3A, wo: Vec3A, u1: f32, u2: f32) -> Vec3A {
    let (t, b) = basis(n);
    let v = Vec3A::new(alpha * wo.dot(t), alpha * wo.dot(b), wo.dot(n).max(0.0)).normalize();
    let len2 = v.x * v.x + v.y * v.y;
    let t1 = if len2 > 0.0 { Vec3A::new(-v.y, v.x, 0.0) / len2.sqrt() } else { Vec3A::X };
    let t2 = v.cross(t1);
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let (p1, p2) = (r * phi.cos(), r * phi.sin());
    let s = 0.5 * (1.0 + v.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
    let nh = t1 * p1 + t2 * p2 + v * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    let h = Vec3A::new(alpha * nh.x, alpha * nh.y, nh.z.max(1e-6)).normalize();
    (t * h.x + b * h.y + n * h.z).normalize()
}

/// A microfacet normal around `n` drawn from the normals of `dist` visible from `wo`
/// (`sample_visible_ggx`, `sample_visible_beckmann`).
#[inline]
pub fn sample_visible(dist: Distribution, alpha: f32, n: Vec3A, wo: Vec3A, u1: f32, u2: f32) -> Vec3A {
    match dist {
        Distribution::Ggx => sample_visible_ggx(alpha, n, wo, u1, u2),
        Distribution::Beckmann => sample_visible_beckmann(alpha, n, wo, u1, u2),
    }
}

/// erf(x), from the f64 complementary error function.
#[inline]
fn erf(x: f32) -> f32 {
    (1.0 - crate::math::stats::erfc(x as f64)) as f32
}

/// erf⁻¹(x) for x in (−1, 1) (Giles 2010, "Approximating the erfinv function", single
/// precision).
#[inline]
fn erfinv(x: f32) -> f32 {
    let w = -((1.0 - x) * (1.0 + x)).ln();
    let p = if w < 5.0 {
        let w = w - 2.5;
        [
            2.810_226_4e-8,
            3.432_739_4e-7,
            -3.523_387_7e-6,
            -4.391_506_5e-6,
            2.185_808_7e-4,
            -1.253_725e-3,
            -4.177_681_6e-3,
            0.246_640_73,
            1.501_409_4,
        ]
        .iter()
        .fold(0.0f32, |p, &c| p * w + c)
    } else {
        let w = w.sqrt() - 3.0;
        [
            -2.002_142_6e-4,
            1.009_505_6e-4,
            1.349_343_2e-3,
            -3.673_428_4e-3,
            5.739_507_7e-3,
            -7.622_461_3e-3,
            9.438_870_5e-3,
            1.001_674,
            2.832_976_8,
        ]
        .iter()
        .fold(0.0f32, |p, &c| p * w + c)
    };
    p * x
}

/// Smith's exact G1 for Beckmann, 1/(1 + Λ) with Λ = (erf(a) − 1)/2 + exp(−a²)/(2a√π),
/// a = 1/(α·tan θv): the normalisation of the visible-normal density.
#[inline]
fn g1_beckmann_exact(alpha: f32, cv: f32) -> f32 {
    let tan = (1.0 - cv * cv).max(0.0).sqrt() / cv;
    if !(tan > 0.0) {
        return 1.0;
    }
    let a = 1.0 / (alpha * tan);
    let lambda = 0.5 * (erf(a) - 1.0) + (-a * a).exp() / (2.0 * a * PI.sqrt());
    1.0 / (1.0 + lambda)
}

/// Density of the visible-normal sampler (`sample_visible`) for wi, per solid angle:
/// G1(wo)·D(h) / (4·cos θo), with Smith's exact G1 of the distribution.
#[inline]
pub fn visible_pdf(dist: Distribution, alpha: f32, co: f32, ch: f32) -> f32 {
    let g1 = match dist {
        Distribution::Ggx => g1(dist, alpha, co, 1.0),
        Distribution::Beckmann => g1_beckmann_exact(alpha, co),
    };
    g1 * d(dist, alpha, ch) / (4.0 * co)
}

/// A Beckmann microfacet normal around `n` drawn from the normals visible from `wo` (Heitz &
/// d'Eon 2014's stretch–sample–unstretch, with Jakob 2014's sampling of the visible slope
/// distribution of roughness 1 by three Newton steps in the erf domain, as Mitsuba 3 does).
#[inline]
pub fn sample_visible_beckmann(alpha: f32, n: Vec3A, wo: Vec3A, u1: f32, u2: f32) -> Vec3A {
    let (t, b) = basis(n);
    let v = Vec3A::new(alpha * wo.dot(t), alpha * wo.dot(b), wo.dot(n).max(0.0)).normalize();
    let sin_t = (v.x * v.x + v.y * v.y).sqrt();
    let (u1, u2) = (u1.clamp(1e-6, 1.0 - 1e-6), u2.clamp(1e-6, 1.0 - 1e-6));
    let (sx, sy) = if sin_t < 1e-4 * v.z {
        // Normal incidence: the slopes are Gaussian.
        let r = (-(1.0 - u1).ln()).sqrt();
        let phi = 2.0 * PI * u2;
        (r * phi.cos(), r * phi.sin())
    } else {
        let tan_t = sin_t / v.z;
        let cot_t = 1.0 / tan_t;
        let max = erf(cot_t);
        let mut x = max - (max + 1.0) * erf((-u1.ln()).sqrt());
        let target = u1 * (1.0 + max + tan_t * (-cot_t * cot_t).exp() / PI.sqrt());
        for _ in 0..3 {
            let slope = erfinv(x);
            let value = 1.0 + x + tan_t * (-slope * slope).exp() / PI.sqrt() - target;
            x -= value / (1.0 - slope * tan_t);
        }
        (erfinv(x.clamp(-1.0 + 1e-6, 1.0 - 1e-6)), erfinv(2.0 * u2 - 1.0))
    };
    // Rotate to the stretched view's azimuth, unstretch, and turn the slope into a normal.
    let (cos_p, sin_p) = if sin_t > 0.0 { (v.x / sin_t, v.y / sin_t) } else { (1.0, 0.0) };
    let (mx, my) = (alpha * (cos_p * sx - sin_p * sy), alpha * (sin_p * sx + cos_p * sy));
    let h = Vec3A::new(-mx, -my, 1.0).normalize();
    (t * h.x + b * h.y + n * h.z).normalize()
}

/// Unpolarised Fresnel reflectance of a conductor with index η + ik at incidence cos θ = `c`
/// (Mitsuba 3's `fresnel_conductor`).
#[inline]
pub fn fresnel_conductor(c: f32, eta: f32, k: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    let (c2, s2) = (c * c, 1.0 - c * c);
    let t1 = eta * eta - k * k - s2;
    let a2b2 = (t1 * t1 + 4.0 * k * k * eta * eta).sqrt();
    let a = (0.5 * (a2b2 + t1)).max(0.0).sqrt();
    let term1 = a2b2 + c2;
    let term2 = 2.0 * c * a;
    let rs = (term1 - term2) / (term1 + term2);
    let term3 = a2b2 * c2 + s2 * s2;
    let term4 = term2 * s2;
    let rp = rs * (term3 - term4) / (term3 + term4);
    let f = 0.5 * (rs + rp);
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quadrature over the hemisphere of directions around +z in (cos θ, φ).
    fn integrate(f: impl Fn(Vec3A) -> f64, nt: usize) -> f64 {
        let np = 64;
        let mut sum = 0.0;
        for i in 0..nt {
            // Cells denser near the pole, where narrow lobes live: cos θ = 1 − x².
            let (x0, x1) = (i as f64 / nt as f64, (i + 1) as f64 / nt as f64);
            let x = 0.5 * (x0 + x1);
            let ct = 1.0 - x * x;
            let dct = 2.0 * x * (x1 - x0);
            let st = (1.0 - ct * ct).max(0.0).sqrt();
            for j in 0..np {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
                let v = Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                sum += f(v) * dct * 2.0 * std::f64::consts::PI / np as f64;
            }
        }
        sum
    }

    /// erf⁻¹ inverts erf to single precision, and the exact Beckmann G1 normalises the visible
    /// normals: ∫ G1(v)·max(0, v·h)·D(h) dh = cos θv to quadrature accuracy (unlike Walter's
    /// fit, which `eval` keeps for agreement with Mitsuba's images).
    #[test]
    fn erfinv_and_exact_beckmann_g1() {
        for k in -999..=999 {
            let x = k as f32 / 1000.0;
            let y = erfinv(x);
            assert!(
                (erf(y) - x).abs() < 2e-6 * (1.0 + 1.0 / (1.0 - x.abs())),
                "erf(erfinv({x})) = {}",
                erf(y)
            );
        }
        for alpha in [0.05f32, 0.3, 1.0] {
            for theta in [0.0f32, 40.0, 75.0, 85.0] {
                let v = Vec3A::new(theta.to_radians().sin(), 0.0, theta.to_radians().cos());
                let g = g1_beckmann_exact(alpha, v.z);
                let vis = integrate(
                    |h| (g * v.dot(h).max(0.0) * d(Distribution::Beckmann, alpha, h.z)) as f64,
                    20000,
                );
                assert!((vis / v.z as f64 - 1.0).abs() < 2e-3, "α {alpha}, {theta}°: {vis} vs {}", v.z);
            }
        }
    }

    /// ∫ D(h) cos θh dh = 1 (D is a distribution of projected area), and the visible normals
    /// integrate to the projected area: ∫ G1(v, h)·max(0, v·h)·D(h) dh = cos θv.
    #[test]
    fn distributions_normalised() {
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.05f32, 0.2, 0.6, 1.0] {
                let norm = integrate(|h| (d(dist, alpha, h.z) * h.z) as f64, 20000);
                assert!((norm - 1.0).abs() < 2e-3, "{dist:?} α {alpha}: ∫D cos = {norm}");
                for theta in [0.0f32, 40.0, 75.0] {
                    let v = Vec3A::new(theta.to_radians().sin(), 0.0, theta.to_radians().cos());
                    let vis = integrate(
                        |h| (g1(dist, alpha, v.z, v.dot(h)) * v.dot(h).max(0.0) * d(dist, alpha, h.z)) as f64,
                        20000,
                    );
                    // Walter's Beckmann G1 is a fit, good to about 0.5 %.
                    let tol = if dist == Distribution::Ggx { 3e-3 } else { 8e-3 };
                    assert!(
                        (vis / v.z as f64 - 1.0).abs() < tol,
                        "{dist:?} α {alpha} θ {theta}: ∫G1·(v·h)·D = {vis}, cos θ = {}",
                        v.z
                    );
                }
            }
        }
    }

    /// Fresnel: normal incidence ((η−1)² + k²)/((η+1)² + k²), grazing 1, dielectric limit
    /// (k = 0) equal to the dielectric formula.
    #[test]
    fn fresnel_closed_form() {
        let (eta, k) = (0.2f32, 3.9f32);
        let r0 = ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k);
        assert!((fresnel_conductor(1.0, eta, k) - r0).abs() < 1e-5);
        assert!((fresnel_conductor(1e-4, eta, k) - 1.0).abs() < 1e-3);
        // k = 0, η = 1.5 at 45°: Rs, Rp from Snell's law.
        let (ci, n) = (std::f32::consts::FRAC_1_SQRT_2, 1.5f32);
        let ct = (1.0 - (1.0 - ci * ci) / (n * n)).sqrt();
        let rs = ((ci - n * ct) / (ci + n * ct)).powi(2);
        let rp = ((n * ci - ct) / (n * ci + ct)).powi(2);
        assert!((fresnel_conductor(ci, n, 0.0) - 0.5 * (rs + rp)).abs() < 1e-5);
    }

    /// Sampled half vectors follow D·cos: the mean of a test function over samples equals its
    /// integral against D·cos.
    #[test]
    fn sampled_h_follows_d_cos() {
        use crate::render::sampler::{Sampler, SamplerKind};
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            let alpha = 0.3;
            let f = |h: Vec3A| (h.x * h.x + 0.5 * h.z) as f64;
            let exact = integrate(|h| f(h) * (d(dist, alpha, h.z) * h.z) as f64, 20000);
            let m = 200_000;
            let mut sum = 0.0;
            for k in 0..m {
                let (u1, u2) = Sampler::with_kind(SamplerKind::Independent, 5, k, 0).next2();
                sum += f(sample_h(dist, alpha, Vec3A::Z, u1, u2));
            }
            let mc = sum / m as f64;
            assert!((mc - exact).abs() < 3e-3, "{dist:?}: {mc} vs {exact}");
        }
    }
}
