//! The implicit function whose zero set is the point-set surface, evaluated at any point x
//! from the points within the local radius of x, weighted by wᵢ = (1 − dᵢ²/r²)⁴ (compact, C²),
//! and only those whose normal agrees with the nearest point's (nᵢ·n₀ > ½), so two sheets
//! closer than the radius but facing apart (the two sides of a thin wall) are not averaged
//! into one.
//!
//! - `Mls` (Alexa et al. 2001/2003): a reference plane through the weighted centroid a, its
//!   normal n the smallest axis of the weighted covariance (turned to the points' normals);
//!   then a quadratic height field g(u, v) over that plane fitted to the neighbours by
//!   weighted least squares. f(x) = n·(x − a) − g(u(x), v(x)).
//! - `Apss` (Guennebaud & Gross 2007): the algebraic sphere s(x) = u₀ + u·x + u₄|x|² fitted
//!   in closed form to positions and normals (their eq. 7–9 with β = 1):
//!   u₄ = ½ (Σwᵢ pᵢ·nᵢ − p̄·Σwᵢnᵢ) / (Σwᵢ|pᵢ|² − p̄·Σwᵢpᵢ), u = n̄ − 2u₄p̄,
//!   u₀ = −u·p̄ − u₄ Σw̃ᵢ|pᵢ|² (p̄, n̄ the normalised weighted means); f(x) is the signed
//!   Euclidean distance to that sphere (to the plane where u₄ ≈ 0). A sphere keeps the detail
//!   a plane would flatten.
//!
//! f > 0 outside (where the normals point). With fewer than `MIN_NEIGHBOURS` points in reach,
//! f is undefined (`None`): no surface is made there.

use super::{Cloud, Method};
use glam::DVec3;

/// Fewest neighbours for a fit.
pub const MIN_NEIGHBOURS: usize = 6;
/// Fewest neighbours for `Mls`'s quadratic height field (fewer: the plane alone).
const MIN_POLYNOMIAL: usize = 20;
/// Ridge on the height field's curvature terms, relative to the total weight.
const RIDGE: f64 = 0.05;

/// f(x) (module docs), or `None` where too few points are in reach or x is farther than 0.7 of
/// the radius from every point.
pub fn value(cloud: &Cloud, method: Method, x: DVec3) -> Option<f64> {
    fit(cloud, method, x).map(|(f, _)| f)
}

/// f(x) and its gradient there, the local fit held fixed (the sphere's or the height field's
/// own gradient, as MLS projections take it): one fit where finite differences take seven.
pub fn fit(cloud: &Cloud, method: Method, x: DVec3) -> Option<(f64, DVec3)> {
    let nearest = cloud.nearest(x, 1).first().copied()? as usize;
    let r = cloud.radius[nearest].max(cloud.floor);
    // Farther than 0.7 of the radius from every point is off the surface's band: a fit there
    // sees only the edge of its neighbourhood, and a plane through a small cap of points
    // can cross zero where no surface is.
    if cloud.points[nearest].distance_squared(x) > 0.49 * r * r {
        return None;
    }
    let n0 = cloud.normals[nearest];
    let mut idx = Vec::new();
    let mut w = Vec::new();
    cloud.within(x, r, |i, d2| {
        if cloud.normals[i as usize].dot(n0) > 0.5 {
            let t = 1.0 - d2 / (r * r);
            if t > 0.0 {
                idx.push(i as usize);
                w.push(t * t * t * t);
            }
        }
    });
    if idx.len() < MIN_NEIGHBOURS {
        return None;
    }
    match method {
        Method::Apss => apss(cloud, &idx, &w, x),
        Method::Mls => mls(cloud, &idx, &w, x, n0),
    }
}

fn apss(cloud: &Cloud, idx: &[usize], w: &[f64], x: DVec3) -> Option<(f64, DVec3)> {
    let sw: f64 = w.iter().sum();
    // Work relative to x: the fit is translation-invariant, and small coordinates keep
    // |p|² from swamping the sums far from the origin.
    let (mut sp, mut sn, mut spn, mut spp) = (DVec3::ZERO, DVec3::ZERO, 0.0, 0.0);
    for (&i, &wi) in idx.iter().zip(w) {
        let p = cloud.points[i] - x;
        let n = cloud.normals[i];
        sp += wi * p;
        sn += wi * n;
        spn += wi * p.dot(n);
        spp += wi * p.dot(p);
    }
    let (pm, nm) = (sp / sw, sn / sw);
    let den = spp - pm.dot(sp);
    let u4 = if den.abs() > 1e-300 { 0.5 * (spn - pm.dot(sn)) / den } else { 0.0 };
    let u = nm - 2.0 * u4 * pm;
    let u0 = -u.dot(pm) - u4 * spp / sw;
    // x is the origin here: s(x) = u0, ∇s(x) = u.
    let grad = u.length();
    if !(grad.is_finite() && u0.is_finite()) {
        return None;
    }
    if u4.abs() * (spp / sw).sqrt() < 1e-6 * grad {
        // A plane: the distance is s / |∇s|.
        return (grad > 0.0).then(|| (u0 / grad, u / grad));
    }
    let c = -u / (2.0 * u4);
    let r2 = c.length_squared() - u0 / u4;
    if r2 <= 0.0 {
        return (grad > 0.0).then(|| (u0 / grad, u / grad));
    }
    // x is the origin: the distance is sign(u₄)(|c| − R), its gradient sign(u₄)·(x − c)/|x − c|.
    let dir = -c / c.length();
    (c.length() > 0.0).then(|| (u4.signum() * (c.length() - r2.sqrt()), u4.signum() * dir))
}

fn mls(cloud: &Cloud, idx: &[usize], w: &[f64], x: DVec3, n0: DVec3) -> Option<(f64, DVec3)> {
    let sw: f64 = w.iter().sum();
    let a = idx.iter().zip(w).map(|(&i, &wi)| wi * cloud.points[i]).sum::<DVec3>() / sw;
    let mut cov = nalgebra::Matrix3::<f64>::zeros();
    let mut nsum = DVec3::ZERO;
    for (&i, &wi) in idx.iter().zip(w) {
        let d = cloud.points[i] - a;
        let v = nalgebra::Vector3::new(d.x, d.y, d.z);
        cov += wi * v * v.transpose();
        nsum += wi * cloud.normals[i];
    }
    let mut n = super::normals::smallest_axis(&cov)?;
    let toward = if nsum.length() > 0.0 { nsum.normalize() } else { n0 };
    if n.dot(toward) < 0.0 {
        n = -n;
    }
    // Where the points in reach are too few or too flat across to fix a plane by themselves
    // (a small cap at the edge of the neighbourhood), the plane tilts away from the normals
    // they carry: their mean normal stands in for it.
    if n.dot(toward) < 0.8 {
        n = toward;
    }
    let t1 = n.any_orthonormal_vector();
    let t2 = n.cross(t1);
    // Heights over the plane, in coordinates scaled by the neighbourhood's spread.
    let scale = (idx.iter().zip(w).map(|(&i, &wi)| wi * (cloud.points[i] - a).length_squared()).sum::<f64>()
        / sw)
        .sqrt();
    let s = if scale > 0.0 { 1.0 / scale } else { 1.0 };
    let basis = |u: f64, v: f64| [1.0, u, v, u * u, u * v, v * v];
    let mut g = [0.0; 6];
    // The height field needs points spread across the plane: at least `MIN_POLYNOMIAL`, and a
    // small ridge on the curvature terms (in units of the neighbourhood's spread) keeps a
    // lopsided cap of points from bending it where no point is.
    if idx.len() >= MIN_POLYNOMIAL {
        let mut ata = nalgebra::SMatrix::<f64, 6, 6>::zeros();
        let mut atb = nalgebra::SVector::<f64, 6>::zeros();
        for (&i, &wi) in idx.iter().zip(w) {
            let d = cloud.points[i] - a;
            let b = nalgebra::SVector::<f64, 6>::from(basis(s * d.dot(t1), s * d.dot(t2)));
            ata += wi * b * b.transpose();
            atb += wi * b * d.dot(n);
        }
        for k in 3..6 {
            ata[(k, k)] += RIDGE * sw;
        }
        if let Some(inv) = ata.try_inverse() {
            let c = inv * atb;
            if c.iter().all(|v| v.is_finite()) {
                g.copy_from_slice(c.as_slice());
            }
        }
    }
    let d = x - a;
    let b = basis(s * d.dot(t1), s * d.dot(t2));
    let height: f64 = b.iter().zip(&g).map(|(p, q)| p * q).sum();
    let f = d.dot(n) - height;
    // ∂g/∂u and ∂g/∂v at x, through the scaled coordinates.
    let (u, v) = (s * d.dot(t1), s * d.dot(t2));
    let (gu, gv) = (g[1] + 2.0 * g[3] * u + g[4] * v, g[2] + g[4] * u + 2.0 * g[5] * v);
    let grad = n - s * (gu * t1 + gv * t2);
    (f.is_finite() && grad.is_finite()).then_some((f, grad))
}
