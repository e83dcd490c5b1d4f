//! Lambertian photometric stereo (Woodham 1980): with unit light directions lⱼ and
//! observations Iⱼ (divided by the light's intensity), I = ρ·max(0, lⱼ·n); least squares over
//! the lights gives b = ρn = (LᵀL)⁻¹LᵀI, n = b/|b|, and per channel ρ_c = Σ I_c,ⱼ sⱼ / Σ sⱼ²
//! with sⱼ = lⱼ·n.
//!
//! `solve_plain` is that recipe over every light, on the mean of the three channels.
//! `solve_robust` fits only the observations the Lambertian model explains: it drops lights
//! that graze or face away from the current normal (attached shadow, sⱼ ≤ 0.05), observations
//! far darker than the model predicts (cast shadow) and far brighter (specular highlights,
//! saturation), judged against the median absolute residual (threshold 3·1.4826·MAD, at least
//! 2 % of the pixel's predicted brightness), and refits until the set settles (≤ 10 rounds).
//! Saturated observations (any channel at the top code value) are never used by it.
//! Black observations (≤ 1 % of the pixel's brightest) are never used while three others
//! remain: ρ·max(0, l·n) = 0 says only l·n ≤ 0. A refit whose set cannot be solved keeps the
//! fit before it.
//! A pixel with fewer than 3 usable observations, or whose used lights are nearly coplanar
//! (condition number of the 3×3 normal matrix above 10⁶), gets no normal.

use crate::math::stats::upper_median;
use glam::DVec3;
use nalgebra::{Matrix3, Vector3};

/// One pixel's solution.
#[derive(Clone, Copy, Debug)]
pub struct Pixel {
    pub normal: DVec3,
    pub albedo: [f64; 3],
    /// Observations used.
    pub used: usize,
}

/// Least squares of b over the selected lights; `None` when fewer than 3 are used or the
/// normal matrix is ill-conditioned.
fn fit(lights: &[DVec3], grey: &[f64], use_it: &[bool]) -> Option<DVec3> {
    // The six distinct entries of Σ l·lᵀ and Σ g·l, summed apart (nalgebra's outer product
    // per light was most of a robust fit's time).
    let (mut xx, mut xy, mut xz, mut yy, mut yz, mut zz) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let mut rhs = DVec3::ZERO;
    let mut n = 0;
    for ((l, &g), &u) in lights.iter().zip(grey).zip(use_it) {
        if !u {
            continue;
        }
        (xx, xy, xz) = (xx + l.x * l.x, xy + l.x * l.y, xz + l.x * l.z);
        (yy, yz, zz) = (yy + l.y * l.y, yz + l.y * l.z, zz + l.z * l.z);
        rhs += *l * g;
        n += 1;
    }
    if n < 3 {
        return None;
    }
    let a = Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz);
    let rhs = Vector3::new(rhs.x, rhs.y, rhs.z);
    let eig = a.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    if !(lo > hi * 1e-6) {
        return None;
    }
    let b = a.cholesky()?.solve(&rhs);
    let b = DVec3::new(b.x, b.y, b.z);
    (b.length() > 0.0 && b.is_finite()).then_some(b)
}

/// Per-channel albedo for a normal over the selected observations.
fn albedo(lights: &[DVec3], obs: &[[f32; 3]], n: DVec3, use_it: &[bool]) -> [f64; 3] {
    let mut num = [0.0; 3];
    let mut den = 0.0;
    for ((l, o), &u) in lights.iter().zip(obs).zip(use_it) {
        if u {
            let s = l.dot(n);
            for c in 0..3 {
                num[c] += o[c] as f64 * s;
            }
            den += s * s;
        }
    }
    if den > 0.0 {
        num.map(|v| (v / den).max(0.0))
    } else {
        [0.0; 3]
    }
}

fn grey(obs: &[[f32; 3]]) -> Vec<f64> {
    obs.iter().map(|o| (o[0] as f64 + o[1] as f64 + o[2] as f64) / 3.0).collect()
}

/// The plain least-squares recipe over every light.
pub fn solve_plain(lights: &[DVec3], obs: &[[f32; 3]]) -> Option<Pixel> {
    let all = vec![true; lights.len()];
    let b = fit(lights, &grey(obs), &all)?;
    let n = b.normalize();
    Some(Pixel { normal: n, albedo: albedo(lights, obs, n, &all), used: lights.len() })
}

/// The robust variant (module docs). `valid` marks the observations that may be used at all
/// (not saturated).
pub fn solve_robust(lights: &[DVec3], obs: &[[f32; 3]], valid: &[bool]) -> Option<Pixel> {
    let g = grey(obs);
    // Black observations (≤ 1 % of the brightest) are left out: ρ·max(0, l·n) = 0 says only
    // l·n ≤ 0, so each is an attached shadow (never fitted anyway) or a cast shadow (an
    // outlier, and deep in a hole the majority, which the MAD test cannot reject). Unless
    // fewer than three others remain.
    let brightest = g.iter().zip(valid).filter(|(_, &ok)| ok).fold(0.0f64, |m, (&v, _)| m.max(v));
    let lit: Vec<bool> = g.iter().zip(valid).map(|(&v, &ok)| ok && v > 0.01 * brightest).collect();
    let valid: &[bool] = if lit.iter().filter(|&&u| u).count() >= 3 { &lit } else { valid };
    // Start from the middle of the pixel's brightness ranking: the darkest quarter (shadows)
    // and the brightest tenth (highlights) are the commonest outliers. The ranks lo..hi are
    // found by selection, ties broken by index as a stable sort would.
    let mut order: Vec<usize> = (0..g.len()).filter(|&j| valid[j]).collect();
    if order.len() < 3 {
        return None;
    }
    let (lo, hi) =
        (order.len() / 4, (order.len() * 9).div_ceil(10).max(order.len() / 4 + 3).min(order.len()));
    let rank = |a: &usize, b: &usize| g[*a].total_cmp(&g[*b]).then(a.cmp(b));
    order.select_nth_unstable_by(lo, rank);
    let upper = &mut order[lo..];
    if hi - lo < upper.len() {
        upper.select_nth_unstable_by(hi - lo, rank);
    }
    let mut use_it = vec![false; g.len()];
    for &j in &order[lo..hi] {
        use_it[j] = true;
    }
    let mut b = fit(lights, &g, &use_it).or_else(|| fit(lights, &g, valid))?;
    // l·n per light, the residuals of the lit ones and the next set, reused across rounds.
    let (mut s, mut res, mut next) = (vec![0.0; g.len()], Vec::with_capacity(g.len()), vec![false; g.len()]);
    for _ in 0..10 {
        let n = b.normalize();
        let rho = b.length();
        res.clear();
        for j in 0..g.len() {
            s[j] = lights[j].dot(n);
            if valid[j] && s[j] > 0.05 {
                res.push((g[j] - rho * s[j]).abs());
            }
        }
        if res.len() < 3 {
            return None;
        }
        let limit = 3.0 * 1.4826 * upper_median(&mut res)?;
        for j in 0..g.len() {
            let pred = rho * s[j];
            next[j] = valid[j] && s[j] > 0.05 && (g[j] - pred).abs() <= limit.max(0.02 * pred);
        }
        // A set the model cannot be fitted to (too few or coplanar lights) keeps the last fit.
        let Some(nb) = fit(lights, &g, &next) else { break };
        let settled = next == use_it;
        std::mem::swap(&mut use_it, &mut next);
        b = nb;
        if settled {
            break;
        }
    }
    let n = b.normalize();
    let used = use_it.iter().filter(|&&u| u).count();
    Some(Pixel { normal: n, albedo: albedo(lights, obs, n, &use_it), used })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lights() -> Vec<DVec3> {
        (0..24)
            .map(|k| {
                let (az, el) = (k as f64 * 0.9, 0.4 + 0.5 * ((k % 4) as f64 / 3.0));
                DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()).normalize()
            })
            .collect()
    }

    fn render(l: &[DVec3], n: DVec3, rho: [f64; 3]) -> Vec<[f32; 3]> {
        l.iter().map(|l| rho.map(|r| (r * l.dot(n).max(0.0)) as f32)).collect()
    }

    /// Noiseless Lambertian observations, all lit: both solvers recover n and ρ exactly.
    #[test]
    fn exact_on_lit_lambertian_data() {
        let l = lights();
        let n = DVec3::new(0.1, -0.2, 1.0).normalize();
        let obs = render(&l, n, [0.3, 0.5, 0.7]);
        let valid = vec![true; l.len()];
        for p in [solve_plain(&l, &obs).unwrap(), solve_robust(&l, &obs, &valid).unwrap()] {
            assert!(p.normal.angle_between(n) < 1e-5, "{:?}", p.normal);
            for (a, b) in p.albedo.iter().zip([0.3, 0.5, 0.7]) {
                assert!((a - b).abs() < 1e-5, "{a} vs {b}");
            }
        }
    }

    /// A tilted normal with attached shadows and two highlights: the plain fit is pulled
    /// away, the robust one is not.
    #[test]
    fn robust_ignores_shadows_and_highlights() {
        let l = lights();
        let n = DVec3::new(0.8, 0.1, 0.6).normalize();
        let mut obs = render(&l, n, [0.5, 0.5, 0.5]);
        let bright: Vec<usize> = (0..l.len()).filter(|&j| l[j].dot(n) > 0.3).take(2).collect();
        for &j in &bright {
            obs[j] = [3.0; 3];
        }
        let plain = solve_plain(&l, &obs).unwrap().normal.angle_between(n).to_degrees();
        let robust = solve_robust(&l, &obs, &vec![true; l.len()]).unwrap();
        let err = robust.normal.angle_between(n).to_degrees();
        assert!(plain > 5.0, "plain error {plain}°");
        assert!(err < 1e-3, "robust error {err}°");
        assert!((robust.albedo[0] - 0.5).abs() < 1e-4);
    }

    /// Deep in a hole most lights are cast in shadow: with 16 of 24 observations black, the
    /// start must not fit the zeros (a pixel like this once got no normal at all).
    #[test]
    fn mostly_black_pixel_keeps_its_normal() {
        let l = lights();
        let n = DVec3::new(0.2, -0.1, 1.0).normalize();
        let mut obs = render(&l, n, [0.4, 0.4, 0.4]);
        for (j, o) in obs.iter_mut().enumerate() {
            if j % 3 != 0 {
                *o = [0.0; 3];
            }
        }
        let p = solve_robust(&l, &obs, &vec![true; l.len()]).expect("a normal");
        let err = p.normal.angle_between(n).to_degrees();
        assert!(err < 1e-3, "error {err}°");
        assert_eq!(p.used, 8);
    }

    /// Too few or coplanar lights: no normal rather than a made-up one.
    #[test]
    fn degenerate_lights_give_none() {
        let l = vec![DVec3::X, DVec3::Y];
        assert!(solve_plain(&l, &[[0.5; 3], [0.5; 3]]).is_none());
        let coplanar: Vec<DVec3> =
            (0..8).map(|k| DVec3::new((k as f64).cos(), (k as f64).sin(), 0.0)).collect();
        assert!(solve_plain(&coplanar, &vec![[0.5; 3]; 8]).is_none());
        assert!(solve_robust(&coplanar, &vec![[0.5; 3]; 8], &[true; 8]).is_none());
    }
}
