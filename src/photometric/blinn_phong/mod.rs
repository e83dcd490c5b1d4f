//! Blinn-Phong photometric stereo: per pixel, the normal n, diffuse albedo ρ (per channel),
//! specular albedo σ and shininess e of the renderer's Blinn-Phong form (`render::bsdf`),
//! fitted by non-linear least squares to the observations (divided by the light intensity):
//!
//!   Iⱼ,c = (ρ_c + σ·(e + 8)/8·(n·hⱼ)ᵉ)·max(0, n·lⱼ),   hⱼ = (lⱼ + v)/|lⱼ + v|,
//!
//! with v the direction towards the camera. In the renderer's terms ρ = kd/π and σ = ks/π, so
//! ρ is the same quantity the Lambertian models call albedo.
//!
//! Method: non-linear least squares with analytic Jacobians, hand-written on the 7×7 normal
//! equations, whose sums over the observations run eight observations at a time (`lanes`).
//! Parameters: two offsets (a, b) of the normal in the tangent plane of the robust Lambertian
//! normal n₀ (n = (n₀ + a·t + b·s)/|…|, so the normal stays a unit vector without a
//! constraint), ρ_r, ρ_g, ρ_b, σ and ln e (clamped to [0, ln 10⁴]). Seven tiny prior residuals
//! √μ·(p − p₀), μ = 10⁻¹⁰, keep JᵀJ invertible where the data leave a parameter free (no
//! highlight seen: σ ≈ 0 and e undetermined) without pulling where the data determine it.
//!
//! Starts: the robust Lambertian normal (`lambertian::solve_robust`) and the plain
//! least-squares one (where the two lie more than the narrowest lobe's half width apart,
//! `SAME_START_COS`), each with shininess 4 and 64 and the linear least squares for (ρ, σ) at
//! that normal; 8 Gauss-Newton iterations (`photometric::Config::start_iterations`) with a
//! backtracking line search from each
//! (`gauss_newton`), all over the same observations (every unsaturated one except clear cast
//! shadows: n₀·l > 0.1 yet darker than half the Lambertian prediction), and the lowest cost
//! goes on. One start is not enough: where a Lambertian normal leans towards a highlight, a
//! very narrow lobe on that one observation fits better there than the true lobe, and the
//! iteration stays in that basin; with 12 lights the robust start can be 20° off. The
//! starts need their eight iterations (ranked after fewer, the renders' errors grow several
//! times), and Gauss-Newton's halved steps keep each start near its own basin, where
//! Levenberg-Marquardt from the same starts, though faster, ends in other basins on the
//! ball's real photographs (docs/measurements.md, "Photometric stereo"). More shininess starts (16, 256)
//! double the time for no better answer; shininess 4 alone misses narrow lobes.
//! Then up to three rounds over the observations that are lit (n·l > 0.02 under the current
//! normal) and within max(3·1.4826·MAD, 2 % of the prediction + 10⁻⁴) of the model, which
//! drops cast shadows and light the model has no term for (interreflections); each by
//! Levenberg-Marquardt (`levenberg_marquardt`) with at most 15 passes over the observations,
//! stopping when ‖r‖ changes by less than 10⁻⁶.
//!
//! A pixel whose fit fails, ends with σ < 0 or a negative albedo, or has fewer than 7 usable
//! observations keeps the robust Lambertian solution (σ = e = 0). Where no used observation
//! lies where the lobe reaches 1 % of its peak, σ and e are reported as 0: the data say
//! nothing about them (the normal and ρ still come from the fit).

mod lanes;

use super::lambertian;
use crate::math::stats::upper_median;
use glam::DVec3;
use nalgebra::{Matrix4, SMatrix, SVector, Vector4};

/// Levenberg-Marquardt evaluations per round, and rounds of observation selection.
pub const MAX_ITERATIONS: u64 = 15;
const ROUNDS: usize = 3;
/// Shininess values the starts take.
const START_SHININESS: [f64; 2] = [4.0, 64.0];
/// Two start normals whose cosine exceeds this are one start: cos θ½ = 2^(−1/e_max), the half
/// width at half maximum of the narrowest lobe the fit allows (e_max = 10⁴, θ½ = 0.67°). The
/// cost has no finer angular detail, so starts that close end in the same basin.
const SAME_START_COS: f64 = 0.999_930_687_684_153_6;
/// Gauss-Newton iterations from each of them before the best goes on (the default of
/// `photometric::Config::start_iterations`).
pub const START_ITERATIONS: u64 = 8;
const PRIOR: f64 = 1e-5; // √μ
const TOLERANCE: f64 = 1e-6;
const LN_E_MAX: f64 = 9.210_340_371_976_184; // ln 10⁴
/// Step halvings of the line search before it gives up.
const MAX_HALVINGS: usize = 40;

/// [a, b, ρ_r, ρ_g, ρ_b, σ, ln e] (module docs).
type Param = SVector<f64, 7>;

/// One pixel's Blinn-Phong solution.
#[derive(Clone, Debug)]
pub struct Pixel {
    pub normal: DVec3,
    /// Diffuse albedo ρ per channel.
    pub albedo: [f64; 3],
    /// Specular albedo σ and shininess e; both 0 when the pixel kept the Lambertian solution
    /// or no used observation lies where the lobe reaches 1 % of its peak (σ and e are then
    /// not determined by the data).
    pub specular: f64,
    pub exponent: f64,
    pub used: usize,
    /// The normal after each iteration, the start first.
    pub history: Vec<DVec3>,
}

/// The residuals of one pixel over the used observations.
struct Fit {
    /// The observations in lanes, for the cost, the normal equations and the residuals.
    lanes: lanes::Observations,
    n0: DVec3,
    t: DVec3,
    s: DVec3,
}

impl Fit {
    fn new(
        lights: &[DVec3],
        halves: &[DVec3],
        obs: &[[f32; 3]],
        used: &[usize],
        (n0, t, s): (DVec3, DVec3, DVec3),
    ) -> Fit {
        Fit { lanes: lanes::Observations::new(lights, halves, obs, used), n0, t, s }
    }

    fn normal(&self, p: &Param) -> (DVec3, f64) {
        let m = self.n0 + self.t * p[0] + self.s * p[1];
        let len = m.length();
        (m / len, len)
    }

    /// The model's quantities at `p` for the lanes.
    fn point(&self, p: &Param) -> lanes::Point {
        let (n, len) = self.normal(p);
        lanes::Point {
            n,
            // ∂n/∂a and ∂n/∂b.
            dna: (self.t - n * n.dot(self.t)) / len,
            dnb: (self.s - n * n.dot(self.s)) / len,
            rho: [p[2], p[3], p[4]],
            sigma: p[5],
            e: p[6].clamp(0.0, LN_E_MAX).exp(),
            ln_e_free: p[6] > 0.0 && p[6] < LN_E_MAX,
        }
    }

    /// The residuals, three per used observation.
    fn residuals(&self, p: &Param) -> Vec<f64> {
        lanes::residuals(&self.lanes, &self.point(p))
    }

    /// ‖r‖ with the prior's seven residuals √μ·(p − p₀).
    fn cost(&self, p: &Param, p0: &Param) -> f64 {
        (lanes::squares(&self.lanes, &self.point(p)) + ((p - p0) * PRIOR).norm_squared()).sqrt()
    }

    /// ‖r‖, JᵀJ and Jᵀr with the prior (no Jacobian matrix is formed).
    fn normal_equations(&self, p: &Param, p0: &Param) -> (f64, SMatrix<f64, 7, 7>, Param) {
        let (sum, mut jtj, mut jtr) = lanes::normal_equations(&self.lanes, &self.point(p));
        let prior = (p - p0) * PRIOR;
        for i in 0..7 {
            jtj[(i, i)] += PRIOR * PRIOR;
        }
        jtr += prior * PRIOR;
        ((sum + prior.norm_squared()).sqrt(), jtj, jtr)
    }
}

/// The least squares of (ρ_r, ρ_g, ρ_b, σ) at normal n and shininess e over the fit's
/// observations, as a start [a, b, ρ_r, ρ_g, ρ_b, σ, ln e] (a and b left 0); `None` when the
/// system is singular. Rows (j, c): c_j·ρ_c + g_j·σ with g = c·lobe·dᵉ; negative values are
/// set to 0.
fn start_at(fit: &Fit, n: DVec3, e: f64) -> Option<Param> {
    let at = lanes::Point {
        n,
        dna: DVec3::ZERO,
        dnb: DVec3::ZERO,
        rho: [0.0; 3],
        sigma: 0.0,
        e,
        ln_e_free: false,
    };
    let [cc, cg, gg, ci0, ci1, ci2, gi] = lanes::linear_sums(&fit.lanes, &at);
    #[rustfmt::skip]
    let a = Matrix4::new(
        cc, 0.0, 0.0, cg,
        0.0, cc, 0.0, cg,
        0.0, 0.0, cc, cg,
        cg, cg, cg, 3.0 * gg,
    );
    let x = a.cholesky()?.solve(&Vector4::new(ci0, ci1, ci2, gi));
    x.iter()
        .all(|v| v.is_finite())
        .then(|| Param::from([0.0, 0.0, x[0].max(0.0), x[1].max(0.0), x[2].max(0.0), x[3].max(0.0), e.ln()]))
}

/// Whether some used observation lies where the lobe is at least 1 % of its peak.
fn lobe_seen(n: DVec3, e: f64, halves: &[DVec3], used: &[usize]) -> bool {
    used.iter().any(|&j| n.dot(halves[j]).max(0.0).powf(e) >= 0.01)
}

/// Gauss-Newton from `p` over the `used` observations, with a backtracking (Armijo, step
/// halving) line search on ‖r‖ along the Gauss-Newton step, the Armijo slope taken as
/// Jᵀr·step, stopping after `iterations` or when ‖r‖ changes by less than `TOLERANCE`, as
/// argmin's `GaussNewtonLS` with `BacktrackingLineSearch` does: the solution, its cost ‖r‖,
/// and the normal after each iteration. The first iteration tries α = 1 first; each later one
/// starts from twice the step the one before accepted (at most 1), the warm start Nocedal &
/// Wright (2006, §3.5) suggest where steps are badly scaled: a start whose steps are cut to ⅛
/// iteration after iteration no longer spends three passes over the observations finding
/// that out again (docs/measurements.md, "Photometric stereo", for what it saved). Hand-written on the 7×7 normal equations summed in
/// lanes, so an iteration allocates nothing; argmin builds the (3m + 7) × 7 Jacobian and JᵀJ
/// as dynamic matrices each time, which was most of the fit's time.
fn gauss_newton(fit: &Fit, p0: &Param, iterations: u64) -> Option<(Param, f64, Vec<DVec3>)> {
    let mut p = *p0;
    let mut history = Vec::with_capacity(iterations as usize);
    let mut previous = f64::INFINITY;
    let mut cost = f64::INFINITY;
    let mut first_alpha = 1.0;
    for _ in 0..iterations {
        let (c0, jtj, jtr) = fit.normal_equations(&p, p0);
        let step = jtj.cholesky().map(|ch| ch.solve(&-jtr)).or_else(|| jtj.lu().solve(&-jtr))?;
        // Armijo: ‖r(p + α·step)‖ ≤ c₀ + 10⁻⁴·α·(Jᵀr)·step, α halved from 1.
        let slope = jtr.dot(&step);
        let mut alpha = first_alpha;
        let mut accepted = None;
        for _ in 0..MAX_HALVINGS {
            let q = p + step * alpha;
            let c = fit.cost(&q, p0);
            if c <= c0 + 1e-4 * alpha * slope {
                accepted = Some((q, c));
                break;
            }
            alpha *= 0.5;
        }
        let Some((q, c)) = accepted else { break };
        first_alpha = (alpha * 2.0).min(1.0);
        p = q;
        cost = c;
        history.push(fit.normal(&p).0);
        if (previous - cost).abs() < TOLERANCE {
            break;
        }
        previous = cost;
    }
    if !cost.is_finite() {
        cost = fit.cost(&p, p0);
    }
    (cost.is_finite() && p.iter().all(|v| v.is_finite())).then_some((p, cost, history))
}

/// Levenberg-Marquardt from `p0` over the fit's observations: Marquardt's scaling,
/// (JᵀJ + λ·diag JᵀJ)·δ = −Jᵀr, and Nielsen's update of λ (÷ max(3, 1/(1 − (2g − 1)³)) after a
/// step of gain ratio g > 0, else × 2, 4, 8 …). Each step evaluates the normal equations at
/// the trial point, which become the next iterate's when the trial lowers ‖r‖, so a step
/// costs one pass over the observations where Gauss-Newton with a line search spends one and
/// then one per tried step length. At most `evaluations` passes (the one at p₀ included);
/// stops when an accepted step changes ‖r‖ by less than `TOLERANCE`. The solution, its cost
/// ‖r‖, and the normal after each accepted step. Not `math::lm`, which forms J as a matrix
/// and evaluates the cost apart from it.
fn levenberg_marquardt(fit: &Fit, p0: &Param, evaluations: u64) -> Option<(Param, f64, Vec<DVec3>)> {
    let mut p = *p0;
    let (mut cost, mut jtj, mut jtr) = fit.normal_equations(&p, p0);
    let mut history = Vec::with_capacity(evaluations as usize);
    let (mut lambda, mut nu) = (1e-3, 2.0);
    for _ in 1..evaluations {
        let mut a = jtj;
        for i in 0..7 {
            a[(i, i)] += lambda * jtj[(i, i)];
        }
        let Some(step) = a.cholesky().map(|ch| ch.solve(&-jtr)) else { break };
        let q = p + step;
        let (c, jtj_q, jtr_q) = fit.normal_equations(&q, p0);
        // The decrease of ½‖r‖² the linear model predicts: ½·δᵀ(λ·diag(JᵀJ)·δ − Jᵀr).
        let predicted =
            0.5 * (0..7).map(|i| step[i] * (lambda * jtj[(i, i)] * step[i] - jtr[i])).sum::<f64>();
        let gain = 0.5 * (cost * cost - c * c) / predicted;
        if c.is_finite() && gain > 0.0 && q.iter().all(|v| v.is_finite()) {
            let change = cost - c;
            (p, cost, jtj, jtr) = (q, c, jtj_q, jtr_q);
            history.push(fit.normal(&p).0);
            lambda *= (1.0 - (2.0 * gain - 1.0).powi(3)).max(1.0 / 3.0);
            nu = 2.0;
            if change < TOLERANCE {
                break;
            }
        } else {
            lambda *= nu;
            nu *= 2.0;
        }
    }
    (cost.is_finite() && p.iter().all(|v| v.is_finite())).then_some((p, cost, history))
}

/// Fits one pixel (module docs). `view` points from the surface towards the camera; `valid`
/// flags the unsaturated observations; `start_iterations` Gauss-Newton iterations run from
/// each start.
pub fn solve(
    lights: &[DVec3],
    view: DVec3,
    obs: &[[f32; 3]],
    valid: &[bool],
    start_iterations: u64,
) -> Option<Pixel> {
    let start = lambertian::solve_robust(lights, obs, valid)?;
    let lambertian = || Pixel {
        normal: start.normal,
        albedo: start.albedo,
        specular: 0.0,
        exponent: 0.0,
        used: start.used,
        history: vec![start.normal],
    };
    let halves: Vec<DVec3> = lights.iter().map(|&l| (l + view).normalize_or_zero()).collect();
    let n0 = start.normal;
    let (t, s) = n0.any_orthonormal_pair();
    let lit = |n: DVec3| -> Vec<usize> {
        (0..lights.len()).filter(|&j| valid[j] && n.dot(lights[j]) > 0.02).collect()
    };
    let basis = (n0, t, s);
    // The starts all fit the same observations, so that their costs compare: every
    // unsaturated one except clear cast shadows, lit under n₀ yet far darker than the
    // Lambertian solution predicts (a highlight only adds light to that floor).
    let rho = (start.albedo[0] + start.albedo[1] + start.albedo[2]) / 3.0;
    let shadowed = |j: usize| {
        let c = n0.dot(lights[j]);
        let grey = obs[j].iter().map(|&v| v as f64).sum::<f64>() / 3.0;
        c > 0.1 && grey < 0.5 * rho * c
    };
    let mut used: Vec<usize> = (0..lights.len()).filter(|&j| valid[j] && !shadowed(j)).collect();
    if used.len() < 7 {
        return Some(lambertian());
    }
    // A few iterations from each start (module docs); the lowest cost goes on.
    // The plain least-squares normal is a start of its own only where it differs from n₀ by
    // more than the narrowest lobe's half width (`SAME_START_COS`).
    let plain = lambertian::solve_plain(lights, obs)
        .map(|p| p.normal)
        .filter(|n| n.dot(n0) > 0.5 && n.dot(n0) < SAME_START_COS);
    let starts = std::iter::once(n0).chain(plain);
    let mut fit = Fit::new(lights, &halves, obs, &used, basis);
    let Some((mut p, _, steps)) = starts
        .flat_map(|n| START_SHININESS.iter().map(move |&e| (n, e)))
        .filter_map(|(n, e)| {
            let mut p = start_at(&fit, n, e)?;
            // n in the (a, b) parameters around n₀.
            (p[0], p[1]) = (n.dot(t) / n.dot(n0), n.dot(s) / n.dot(n0));
            gauss_newton(&fit, &p, start_iterations)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
    else {
        return Some(lambertian());
    };
    let mut history = vec![n0];
    history.extend(steps);
    for round in 0..ROUNDS {
        let Some((q, _, steps)) = levenberg_marquardt(&fit, &p, MAX_ITERATIONS) else {
            return Some(lambertian());
        };
        p = q;
        history.extend(steps);
        if round + 1 == ROUNDS {
            break;
        }
        // Keep the observations the fit explains.
        let lit_now = lit(normal_of(n0, t, s, &p));
        let r = Fit::new(lights, &halves, obs, &lit_now, basis).residuals(&p);
        // Per observation: the largest channel residual, and the mean prediction.
        let judged: Vec<(f64, f64)> = (0..lit_now.len())
            .map(|k| {
                let res = (0..3).map(|c| r[3 * k + c].abs()).fold(0.0, f64::max);
                let pred = (0..3).map(|c| r[3 * k + c] + obs[lit_now[k]][c] as f64).sum::<f64>() / 3.0;
                (res, pred)
            })
            .collect();
        let mut abs: Vec<f64> = judged.iter().map(|x| x.0).collect();
        let mad = upper_median(&mut abs).unwrap_or(0.0);
        let next: Vec<usize> = lit_now
            .iter()
            .zip(&judged)
            .filter(|&(_, &(res, pred))| res <= (3.0 * 1.4826 * mad).max(0.02 * pred + 1e-4))
            .map(|(&j, _)| j)
            .collect();
        if next == used {
            break;
        }
        used = next;
        if used.len() < 7 {
            return Some(lambertian());
        }
        fit = Fit::new(lights, &halves, obs, &used, basis);
    }
    let normal = normal_of(n0, t, s, &p);
    // The model reads ln e clamped to its range (a flat direction of the cost outside it).
    let (sigma, ln_e) = (p[5], p[6].clamp(0.0, LN_E_MAX));
    let ok = normal.is_finite() && sigma >= 0.0 && (2..5).all(|i| p[i].is_finite() && p[i] >= 0.0);
    if !ok {
        return Some(lambertian());
    }
    // A lobe no observation samples says nothing about σ and e.
    let (sigma, exponent) =
        if lobe_seen(normal, ln_e.exp(), &halves, &used) { (sigma, ln_e.exp()) } else { (0.0, 0.0) };
    if history.last() != Some(&normal) {
        history.push(normal);
    }
    Some(Pixel { normal, albedo: [p[2], p[3], p[4]], specular: sigma, exponent, used: used.len(), history })
}

fn normal_of(n0: DVec3, t: DVec3, s: DVec3, p: &Param) -> DVec3 {
    (n0 + t * p[0] + s * p[1]).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lights() -> Vec<DVec3> {
        (0..48)
            .map(|k| {
                let t = (k as f64 + 0.5) / 48.0;
                let (az, el) = (k as f64 * 2.399_963, (20.0 + 65.0 * t).to_radians());
                DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
            })
            .collect()
    }

    fn render(l: &[DVec3], v: DVec3, n: DVec3, rho: [f64; 3], sigma: f64, e: f64) -> Vec<[f32; 3]> {
        l.iter()
            .map(|&l| {
                let c = n.dot(l).max(0.0);
                let d = n.dot((l + v).normalize()).max(0.0);
                rho.map(|r| ((r + sigma * (e + 8.0) / 8.0 * d.powf(e)) * c) as f32)
            })
            .collect()
    }

    /// Noiseless Blinn-Phong observations: the fit recovers every parameter, where the
    /// Lambertian start is several degrees off.
    #[test]
    fn exact_on_blinn_phong_data() {
        let l = lights();
        let v = DVec3::new(0.1, 0.0, 1.0).normalize();
        for (n, e) in [(DVec3::new(0.2, -0.3, 1.0), 20.0), (DVec3::new(-0.5, 0.1, 0.8), 80.0)] {
            let n = n.normalize();
            let obs = render(&l, v, n, [0.15, 0.12, 0.1], 0.12, e);
            let valid = vec![true; l.len()];
            let start = lambertian::solve_robust(&l, &obs, &valid).unwrap();
            let p = solve(&l, v, &obs, &valid, START_ITERATIONS).unwrap();
            let err = p.normal.angle_between(n).to_degrees();
            assert!(
                err < 1e-3,
                "normal error {err}° (start {}°)",
                start.normal.angle_between(n).to_degrees()
            );
            assert!((p.specular - 0.12).abs() < 1e-4 && (p.exponent - e).abs() < 0.01 * e, "{p:?}");
            for (a, b) in p.albedo.iter().zip([0.15, 0.12, 0.1]) {
                assert!((a - b).abs() < 1e-4, "{a} vs {b}");
            }
            assert_eq!(p.history[0], start.normal);
        }
    }

    /// Calls `each(residuals, Jacobian rows)` for every used observation in order (the rows
    /// only when `jacobian` and the light reaches the surface: an unlit observation's rows are
    /// zero): the model and Jacobian written out once, observation by observation, as the
    /// reference the lanes are checked against.
    fn visit(
        fit: &Fit,
        (lights, halves, obs, used): (&[DVec3], &[DVec3], &[[f32; 3]], &[usize]),
        p: &Param,
        jacobian: bool,
        mut each: impl FnMut([f64; 3], Option<[[f64; 7]; 3]>),
    ) {
        let lanes::Point { n, dna, dnb, sigma, e, ln_e_free, .. } = fit.point(p);
        for &j in used {
            let (l, h) = (lights[j], halves[j]);
            let c = n.dot(l);
            let d = n.dot(h).max(0.0);
            let (ln_d, de) = if c > 0.0 && d > 0.0 {
                let ln = d.ln();
                (ln, (e * ln).exp())
            } else {
                (0.0, 0.0)
            };
            let lobe = if de > 0.0 { (e + 8.0) / 8.0 } else { 0.0 };
            let spec = sigma * lobe * de;
            let r: [f64; 3] = std::array::from_fn(|ch| {
                let pred = if c > 0.0 { (p[2 + ch] + spec) * c } else { 0.0 };
                pred - obs[j][ch] as f64
            });
            let rows = (jacobian && c > 0.0).then(|| {
                // ∂spec/∂n = σ·lobe·e·dᵉ⁻¹·h; ∂spec/∂ln e = e·σ·dᵉ·(1/8 + lobe·ln d).
                let dspec_dn = if d > 0.0 { h * (sigma * lobe * e * de / d) } else { DVec3::ZERO };
                let dspec_dt =
                    if d > 0.0 && ln_e_free { e * sigma * de * (0.125 + lobe * ln_d) } else { 0.0 };
                std::array::from_fn(|ch| {
                    let dn = l * (p[2 + ch] + spec) + dspec_dn * c;
                    let mut row = [0.0; 7];
                    row[0] = dn.dot(dna);
                    row[1] = dn.dot(dnb);
                    row[2 + ch] = c;
                    row[5] = lobe * de * c;
                    row[6] = dspec_dt * c;
                    row
                })
            });
            each(r, rows);
        }
    }

    /// The lanes' sums and residuals equal the model and Jacobian written out observation by
    /// observation (`visit`), with some lights unlit and ln e inside and outside its clamp.
    #[test]
    fn lanes_match_the_written_out_jacobian() {
        let l = lights();
        let v = DVec3::new(0.1, -0.05, 1.0).normalize();
        let halves: Vec<DVec3> = l.iter().map(|&x| (x + v).normalize()).collect();
        let n = DVec3::new(0.6, 0.3, 0.7).normalize();
        let obs = render(&l, v, n, [0.2, 0.15, 0.1], 0.1, 30.0);
        let used: Vec<usize> = (0..l.len()).filter(|j| j % 5 != 0).collect();
        let n0 = DVec3::new(0.5, 0.2, 0.8).normalize();
        let (t, s) = n0.any_orthonormal_pair();
        let fit = Fit::new(&l, &halves, &obs, &used, (n0, t, s));
        for ln_e in [3.2, -0.5, 12.0] {
            let p = Param::from([0.05, -0.03, 0.18, 0.16, 0.09, 0.12, ln_e]);
            let (mut sum, mut jtj, mut jtr) = (0.0, SMatrix::<f64, 7, 7>::zeros(), Param::zeros());
            let mut written_out = Vec::new();
            visit(&fit, (&l, &halves, &obs, &used), &p, true, |r, rows| {
                sum += r.iter().map(|x| x * x).sum::<f64>();
                written_out.extend(r);
                for (row, r) in rows.into_iter().flatten().zip(r) {
                    let row = Param::from(row);
                    jtj += row * row.transpose();
                    jtr += row * r;
                }
            });
            // Without the prior: p = p₀.
            let (cost, lanes_jtj, lanes_jtr) = fit.normal_equations(&p, &p);
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()));
            assert!(close(cost * cost, sum), "ln e {ln_e}: {} vs {sum}", cost * cost);
            let residuals = fit.residuals(&p);
            assert_eq!(residuals.len(), 3 * used.len());
            for (a, b) in residuals.iter().zip(&written_out) {
                assert!(close(*a, *b), "ln e {ln_e}: residual {a} vs {b}");
            }
            for i in 0..7 {
                assert!(close(lanes_jtr[i], jtr[i]), "ln e {ln_e}: Jᵀr[{i}] {} vs {}", lanes_jtr[i], jtr[i]);
                for k in 0..7 {
                    let prior = if i == k { PRIOR * PRIOR } else { 0.0 };
                    assert!(
                        close(lanes_jtj[(i, k)] - prior, jtj[(i, k)]),
                        "ln e {ln_e}: JᵀJ[{i},{k}] {} vs {}",
                        lanes_jtj[(i, k)] - prior,
                        jtj[(i, k)]
                    );
                }
            }
        }
    }

    /// `start_at`'s lane sums give the least squares written out row by row, with some lights
    /// unlit and the start normal off the true one.
    #[test]
    fn start_matches_the_written_out_least_squares() {
        let l = lights();
        let v = DVec3::new(0.1, -0.05, 1.0).normalize();
        let halves: Vec<DVec3> = l.iter().map(|&x| (x + v).normalize()).collect();
        let obs = render(&l, v, DVec3::new(0.6, 0.3, 0.7).normalize(), [0.2, 0.15, 0.1], 0.1, 30.0);
        let used: Vec<usize> = (0..l.len()).filter(|j| j % 5 != 0).collect();
        let n0 = DVec3::new(0.5, 0.2, 0.8).normalize();
        let fit = Fit::new(&l, &halves, &obs, &used, (n0, DVec3::X, DVec3::Y));
        for e in [4.0, 64.0] {
            let (mut a, mut b) = (Matrix4::<f64>::zeros(), Vector4::<f64>::zeros());
            for &j in &used {
                let c = n0.dot(l[j]).max(0.0);
                let g = c * (e + 8.0) / 8.0 * n0.dot(halves[j]).max(0.0).powf(e);
                for ch in 0..3 {
                    let mut row = Vector4::zeros();
                    (row[ch], row[3]) = (c, g);
                    a += row * row.transpose();
                    b += row * obs[j][ch] as f64;
                }
            }
            let x = a.cholesky().unwrap().solve(&b);
            let p = start_at(&fit, n0, e).unwrap();
            for k in 0..4 {
                assert!((p[2 + k] - x[k].max(0.0)).abs() < 1e-12, "e {e}: {p:?} vs {x:?}");
            }
            assert_eq!((p[0], p[1], p[6]), (0.0, 0.0, e.ln()));
        }
    }

    /// `SAME_START_COS` is cos θ½ of the narrowest lobe: (cos θ½)^e_max = ½.
    #[test]
    fn same_start_is_the_narrowest_lobes_half_width() {
        assert!((SAME_START_COS.powf(LN_E_MAX.exp()) - 0.5).abs() < 1e-12);
    }

    /// A Lambertian pixel stays Lambertian: σ near 0, normal exact.
    #[test]
    fn lambertian_data_stays_exact() {
        let l = lights();
        let n = DVec3::new(0.3, 0.2, 1.0).normalize();
        let obs = render(&l, DVec3::Z, n, [0.3, 0.2, 0.1], 0.0, 10.0);
        let p = solve(&l, DVec3::Z, &obs, &vec![true; l.len()], START_ITERATIONS).unwrap();
        assert!(p.normal.angle_between(n).to_degrees() < 1e-3);
        assert!(p.specular < 1e-4, "{p:?}");
    }
}
