//! Levenberg–Marquardt for dense non-linear least squares, min ½‖r(p)‖², with Marquardt's
//! scaling (Marquardt 1963): each step solves
//!
//!   (JᵀJ + μ·diag(JᵀJ)) δ = −Jᵀr
//!
//! by Cholesky, and is taken when the cost does not rise (μ shrinks), else μ grows and the
//! step is solved again. The parameters are any type with an update rule, so rotations can
//! be updated on the manifold (R ← exp([ω]×)·R) rather than as three numbers.
//!
//! Written here rather than taken from argmin: the calibration and the homography refinement
//! need the normal equations at the optimum for their covariance, a manifold update, and a
//! stopping rule on the relative change of the cost, and the loop is thirty lines. The
//! Blinn-Phong fit has its own loop (`photometric::blinn_phong`): its normal equations are
//! summed in lanes without a Jacobian matrix, and one pass at the trial point gives both the
//! cost that accepts the step and the next step's system.
//! Sparse problems (bundle adjustment) need the Schur complement and belong elsewhere.

use nalgebra::{DMatrix, DVector};

/// How the iteration runs and stops.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Outer iterations (Jacobian evaluations) at most.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction of it.
    pub rel_tolerance: f64,
    /// Starting damping μ; μ is divided by `mu_down` after an accepted step and multiplied by
    /// `mu_up` after a rejected one.
    pub mu_start: f64,
    pub mu_down: f64,
    pub mu_up: f64,
    /// Damped solves tried per iteration before giving up.
    pub max_tries: usize,
    /// Floor under each diagonal entry of JᵀJ in the damping, so a parameter the data do not
    /// touch is still damped.
    pub diag_floor: f64,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            max_iterations: 100,
            rel_tolerance: 1e-16,
            mu_start: 1e-3,
            mu_down: 3.0,
            mu_up: 4.0,
            max_tries: 20,
            diag_floor: 1e-12,
        }
    }
}

/// The minimiser, its cost ‖r‖² and the iterations taken.
pub struct Solution<P> {
    pub params: P,
    pub cost: f64,
    pub iterations: usize,
}

/// Minimises ‖r(p)‖² from `start`. `residuals(p)` gives r and J at p (None where they cannot
/// be evaluated); `cost(p)` gives ‖r(p)‖² alone (non-finite where p is not admissible);
/// `update(p, δ)` applies a step; `observe(k, p, cost)` sees the start (k = 0) and the
/// parameters after each accepted step k, so a caller can keep a trace of the iteration.
pub fn minimize<P: Clone>(
    start: P,
    mut residuals: impl FnMut(&P) -> Option<(DVector<f64>, DMatrix<f64>)>,
    cost: impl FnMut(&P) -> f64,
    update: impl FnMut(&P, &DVector<f64>) -> P,
    observe: impl FnMut(usize, &P, f64),
    opts: &Options,
) -> Solution<P> {
    let normal = |p: &P| residuals(p).map(|(r, j)| (j.transpose() * &j, j.transpose() * &r));
    minimize_normal(start, normal, cost, update, observe, opts)
}

/// `minimize`, given the normal equations' JᵀJ and Jᵀr at p (`normal(p)`) rather than r and
/// J: for a problem whose Jacobian is mostly zeros, whose caller sums them block by block.
pub fn minimize_normal<P: Clone>(
    start: P,
    mut normal: impl FnMut(&P) -> Option<(DMatrix<f64>, DVector<f64>)>,
    mut cost: impl FnMut(&P) -> f64,
    mut update: impl FnMut(&P, &DVector<f64>) -> P,
    mut observe: impl FnMut(usize, &P, f64),
    opts: &Options,
) -> Solution<P> {
    let mut p = start;
    let mut c = cost(&p);
    observe(0, &p, c);
    let mut mu = opts.mu_start;
    let mut iterations = 0;
    for it in 0..opts.max_iterations {
        iterations = it + 1;
        let Some((jtj, jtr)) = normal(&p) else { break };
        let n = jtj.nrows();
        let mut accepted = false;
        for _ in 0..opts.max_tries {
            let mut a = jtj.clone();
            for d in 0..n {
                a[(d, d)] += mu * jtj[(d, d)].max(opts.diag_floor);
            }
            let Some(chol) = a.cholesky() else {
                mu *= 10.0;
                continue;
            };
            let step = chol.solve(&(-&jtr));
            let q = update(&p, &step);
            let cq = cost(&q);
            if cq.is_finite() && cq <= c {
                let small = c - cq <= opts.rel_tolerance * c;
                p = q;
                c = cq;
                observe(iterations, &p, c);
                mu = (mu / opts.mu_down).max(1e-15);
                accepted = !small;
                break;
            }
            mu *= opts.mu_up;
        }
        if !accepted {
            break;
        }
    }
    Solution { params: p, cost: c, iterations }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock's valley as least squares, r = (10(y − x²), 1 − x): from (−1.2, 1) to (1, 1).
    #[test]
    fn rosenbrock() {
        let res = |p: &[f64; 2]| {
            let r = DVector::from_vec(vec![10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]]);
            let j = DMatrix::from_row_slice(2, 2, &[-20.0 * p[0], 10.0, -1.0, 0.0]);
            Some((r, j))
        };
        let cost = |p: &[f64; 2]| res(p).map_or(f64::INFINITY, |(r, _)| r.norm_squared());
        let mut costs = Vec::new();
        let s = minimize(
            [-1.2, 1.0],
            res,
            cost,
            |p, d| [p[0] + d[0], p[1] + d[1]],
            |k, _, c| costs.push((k, c)),
            &Options::default(),
        );
        assert!((s.params[0] - 1.0).abs() < 1e-9 && (s.params[1] - 1.0).abs() < 1e-9, "{:?}", s.params);
        assert!(s.cost < 1e-20 && s.iterations < 100);
        // The trace starts at the start and never rises.
        // r(−1.2, 1) = (−4.4, 2.2): cost 24.2.
        assert!(costs[0].0 == 0 && (costs[0].1 - 24.2).abs() < 1e-12, "{:?}", costs[0]);
        assert!(costs.windows(2).all(|w| w[1].1 <= w[0].1 && w[1].0 > w[0].0));
    }
}
