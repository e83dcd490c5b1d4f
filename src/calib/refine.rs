//! Joint refinement of intrinsics, distortion and every view's pose by Levenberg–Marquardt
//! on the reprojection error (Zhang 2000, §3.3; the same cost as OpenCV's `calibrateCamera`):
//!
//!   min Σ_views Σ_corners ‖ π(K, d, R_v X + t_v) − x ‖²
//!
//! with analytic Jacobians, by `math::lm`. Rotations are updated on the manifold, R ← exp([ω]×)·R, for which
//! ∂(R X)/∂ω = −[R X]×. Standard deviations come from σ²·(JᵀJ)⁻¹ at the optimum with
//! σ² = cost / (residuals − free parameters), as OpenCV's `calibrateCameraExtended` reports.

use super::Error;
use crate::math::{CameraModel, Distortion, Intrinsics};
use glam::{DMat3, DVec2, DVec3};
use nalgebra::{DMatrix, DVector};

/// Which parameters stay fixed (OpenCV's CALIB_FIX_ASPECT_RATIO, CALIB_FIX_PRINCIPAL_POINT,
/// CALIB_ZERO_TANGENT_DIST, CALIB_FIX_K3).
#[derive(Clone, Copy, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Flags {
    pub fix_aspect_ratio: bool,
    pub fix_principal_point: bool,
    pub zero_tangential: bool,
    pub fix_k3: bool,
}

pub struct Problem<'a> {
    /// Board points (Z = 0) per view and their detected image points.
    pub board: &'a [DVec3],
    pub image: &'a [Vec<DVec2>],
}

pub struct Solution {
    pub camera: CameraModel,
    /// Board-to-camera rotation and translation per view.
    pub poses: Vec<(DMat3, DVec3)>,
    /// Residuals (projected − observed) per view.
    pub residuals: Vec<Vec<DVec2>>,
    /// Standard deviations of (fx, fy, cx, cy, k1, k2, p1, p2, k3); 0 for a fixed one.
    pub std_intrinsics: [f64; 9],
    /// The same for corners with 1 px of noise per coordinate: how well the views' geometry
    /// determines each parameter, whatever the residuals happen to be.
    pub unit_std_intrinsics: [f64; 9],
    /// Standard deviations of each view's rotation (small-angle, radians) and translation.
    pub std_views: Vec<[f64; 6]>,
    pub iterations: usize,
    /// The intrinsics at the start and after each accepted step.
    pub trace: Vec<TraceStep>,
}

/// One point of the refinement's trace: elapsed time, iteration, cost and the intrinsics
/// (fx, fy, cx, cy, k1, k2, p1, p2, k3) at that point.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct TraceStep {
    pub seconds: f64,
    pub iteration: usize,
    pub cost: f64,
    pub intrinsics: [f64; 9],
}

const NI: usize = 9;

fn skew(q: DVec3) -> DMat3 {
    DMat3::from_cols(DVec3::new(0.0, q.z, -q.y), DVec3::new(-q.z, 0.0, q.x), DVec3::new(q.y, -q.x, 0.0))
}

/// Projects and returns the 2×(9 + 6) Jacobian rows: intrinsics, then (ω, t) of the view.
fn project(cam: &CameraModel, r: &DMat3, t: DVec3, x: DVec3) -> (DVec2, [[f64; NI + 6]; 2]) {
    let q = *r * x;
    let pc = q + t;
    let (iz, xn, yn) = (1.0 / pc.z, pc.x / pc.z, pc.y / pc.z);
    let d = &cam.distortion;
    let (pd, jd) = d.distort_with_jacobian(DVec2::new(xn, yn));
    let k = &cam.intrinsics;
    let uv = DVec2::new(k.fx * pd.x + k.cx, k.fy * pd.y + k.cy);
    let r2 = xn * xn + yn * yn;
    let (r4, r6) = (r2 * r2, r2 * r2 * r2);
    let mut j = [[0.0; NI + 6]; 2];
    j[0][0] = pd.x;
    j[1][1] = pd.y;
    j[0][2] = 1.0;
    j[1][3] = 1.0;
    let dxd = [xn * r2, xn * r4, 2.0 * xn * yn, r2 + 2.0 * xn * xn, xn * r6];
    let dyd = [yn * r2, yn * r4, r2 + 2.0 * yn * yn, 2.0 * xn * yn, yn * r6];
    for c in 0..5 {
        j[0][4 + c] = k.fx * dxd[c];
        j[1][4 + c] = k.fy * dyd[c];
    }
    // ∂(u, v)/∂pc = diag(fx, fy) · J_d · ∂(xn, yn)/∂pc
    let dn = [[iz, 0.0, -xn * iz], [0.0, iz, -yn * iz]];
    let mut duv_dpc = [[0.0; 3]; 2];
    for a in 0..2 {
        let f = if a == 0 { k.fx } else { k.fy };
        for c in 0..3 {
            duv_dpc[a][c] = f * (jd[a][0] * dn[0][c] + jd[a][1] * dn[1][c]);
        }
    }
    let dpc_dw = -skew(q); // columns: ∂pc/∂ω_c
    for a in 0..2 {
        for c in 0..3 {
            let col = dpc_dw.col(c);
            j[a][NI + c] = duv_dpc[a][0] * col.x + duv_dpc[a][1] * col.y + duv_dpc[a][2] * col.z;
            j[a][NI + 3 + c] = duv_dpc[a][c];
        }
    }
    (uv, j)
}

fn intrinsic_vector(cam: &CameraModel) -> [f64; NI] {
    let (k, d) = (&cam.intrinsics, &cam.distortion);
    [k.fx, k.fy, k.cx, k.cy, d.k1, d.k2, d.p1, d.p2, d.k3]
}

fn camera_from(v: &[f64; NI], w: u32, h: u32) -> CameraModel {
    CameraModel {
        width: w,
        height: h,
        intrinsics: Intrinsics { fx: v[0], fy: v[1], cx: v[2], cy: v[3] },
        distortion: Distortion { k1: v[4], k2: v[5], p1: v[6], p2: v[7], k3: v[8] },
    }
}

/// Levenberg–Marquardt from an initial camera and poses. `max_iterations` bounds the work;
/// it stops when the cost changes by less than `1e-16` relative.
pub fn refine(
    problem: &Problem,
    init: CameraModel,
    init_poses: Vec<(DMat3, DVec3)>,
    flags: Flags,
    max_iterations: usize,
) -> Result<Solution, Error> {
    let nv = problem.image.len();
    let (w, h) = (init.width, init.height);
    let mut intr = intrinsic_vector(&init);
    if flags.zero_tangential {
        intr[6] = 0.0;
        intr[7] = 0.0;
    }
    let aspect = intr[1] / intr[0];
    // Free intrinsic columns; with a fixed aspect ratio fy follows fx.
    let mut free: Vec<usize> = vec![0];
    if !flags.fix_aspect_ratio {
        free.push(1);
    }
    if !flags.fix_principal_point {
        free.extend([2, 3]);
    }
    free.extend([4, 5]);
    if !flags.zero_tangential {
        free.extend([6, 7]);
    }
    if !flags.fix_k3 {
        free.push(8);
    }
    let nf = free.len();
    let np = nf + 6 * nv;
    let m: usize = 2 * problem.image.iter().map(|v| v.len()).sum::<usize>();
    if m <= np {
        return Err(Error::Numerical(format!("{} residuals cannot determine {np} parameters", m)));
    }
    let poses = init_poses;

    // The residuals, and with `normal` the normal equations JᵀJ, Jᵀr. Each corner's two rows
    // of J are nonzero only in the free intrinsics and its view's six pose columns, so the
    // sums are taken over those alone: (nf + 6)² products a row instead of np², and no m × np
    // matrix (1404 × 93 for 13 views, 99 % of the time of a dense JᵀJ).
    let evaluate = |intr: &[f64; NI],
                    poses: &[(DMat3, DVec3)],
                    normal: bool|
     -> (f64, DVector<f64>, Option<(DMatrix<f64>, DVector<f64>)>) {
        let cam = camera_from(intr, w, h);
        let mut r = DVector::zeros(m);
        let mut ne = normal.then(|| (DMatrix::zeros(np, np), DVector::zeros(np)));
        let mut row = 0;
        let (mut cols, mut vals) =
            (Vec::with_capacity(nf + 6), [Vec::with_capacity(nf + 6), Vec::with_capacity(nf + 6)]);
        for (v, (pts, (rot, t))) in problem.image.iter().zip(poses).enumerate() {
            for (x, obs) in problem.board.iter().zip(pts) {
                let (uv, jr) = project(&cam, rot, *t, *x);
                let res = uv - *obs;
                r[row] = res.x;
                r[row + 1] = res.y;
                row += 2;
                let Some((jtj, jtr)) = ne.as_mut() else { continue };
                cols.clear();
                cols.extend((0..nf).chain((0..6).map(|c| nf + 6 * v + c)));
                for (a, vals) in vals.iter_mut().enumerate() {
                    vals.clear();
                    vals.extend(free.iter().map(|&p| {
                        if p == 0 && flags.fix_aspect_ratio {
                            jr[a][0] + aspect * jr[a][1]
                        } else {
                            jr[a][p]
                        }
                    }));
                    vals.extend((0..6).map(|c| jr[a][NI + c]));
                }
                for (i, &ci) in cols.iter().enumerate() {
                    jtr[ci] += vals[0][i] * res.x + vals[1][i] * res.y;
                    for (k, &ck) in cols.iter().enumerate().take(i + 1) {
                        jtj[(ci, ck)] += vals[0][i] * vals[0][k] + vals[1][i] * vals[1][k];
                    }
                }
            }
        }
        if let Some((jtj, _)) = ne.as_mut() {
            jtj.fill_upper_triangle_with_lower_triangle();
        }
        (r.norm_squared(), r, ne)
    };

    let opts = crate::math::lm::Options { max_iterations, ..Default::default() };
    let started = std::time::Instant::now();
    let mut trace = Vec::new();
    let solved = crate::math::lm::minimize_normal(
        (intr, poses),
        |(intr, poses)| evaluate(intr, poses, true).2,
        |(intr, poses)| evaluate(intr, poses, false).0,
        |(intr, poses), step| {
            let mut ni = *intr;
            for (col, &p) in free.iter().enumerate() {
                ni[p] += step[col];
            }
            if flags.fix_aspect_ratio {
                ni[1] = aspect * ni[0];
            }
            let np_: Vec<(DMat3, DVec3)> = poses
                .iter()
                .enumerate()
                .map(|(v, (rot, t))| {
                    let wv = DVec3::new(step[nf + 6 * v], step[nf + 6 * v + 1], step[nf + 6 * v + 2]);
                    let dt = DVec3::new(step[nf + 6 * v + 3], step[nf + 6 * v + 4], step[nf + 6 * v + 5]);
                    (crate::math::Pose::rotation_from_rvec(wv) * *rot, *t + dt)
                })
                .collect();
            (ni, np_)
        },
        |k, (intr, _), cost| {
            trace.push(TraceStep {
                seconds: started.elapsed().as_secs_f64(),
                iteration: k,
                cost,
                intrinsics: *intr,
            })
        },
        &opts,
    );
    let ((intr, poses), iterations) = (solved.params, solved.iterations);

    let (cost, r, ne) = evaluate(&intr, &poses, true);
    let (jtj, _) = ne.ok_or_else(|| Error::Numerical("no Jacobian".into()))?;
    let sigma2 = cost / (m - np) as f64;
    let cov = jtj.try_inverse().ok_or_else(|| {
        Error::Numerical(
            "the calibration is degenerate: the normal equations are singular at the optimum".into(),
        )
    })?;
    let sd = |k: usize| (sigma2 * cov[(k, k)]).max(0.0).sqrt();
    let mut std_intrinsics = [0.0; NI];
    let mut unit_std_intrinsics = [0.0; NI];
    for (col, &p) in free.iter().enumerate() {
        std_intrinsics[p] = sd(col);
        // A negative variance is the inverse of numerically singular normal equations: the
        // parameter is not determined at all.
        let v = cov[(col, col)];
        unit_std_intrinsics[p] = if v >= 0.0 { v.sqrt() } else { f64::INFINITY };
    }
    if flags.fix_aspect_ratio {
        std_intrinsics[1] = aspect * std_intrinsics[0];
        unit_std_intrinsics[1] = aspect * unit_std_intrinsics[0];
    }
    let std_views = (0..nv).map(|v| std::array::from_fn(|c| sd(nf + 6 * v + c))).collect();
    let mut residuals = Vec::with_capacity(nv);
    let mut row = 0;
    for pts in problem.image {
        residuals.push((0..pts.len()).map(|k| DVec2::new(r[row + 2 * k], r[row + 2 * k + 1])).collect());
        row += 2 * pts.len();
    }
    Ok(Solution {
        camera: camera_from(&intr, w, h),
        poses,
        residuals,
        std_intrinsics,
        unit_std_intrinsics,
        std_views,
        iterations,
        trace,
    })
}
