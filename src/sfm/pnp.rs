//! A camera's pose from 3D points and their pixels (perspective-n-point), intrinsics known.
//!
//! - **Minimal solver.** P3P (`p3p`, Grunert's solution): up to four poses from three points
//!   and their rays x̂ = K⁻¹x.
//! - **Robust fit.** `math::ransac` with the reprojection error in pixels; each new best is
//!   refitted on its inliers by the direct linear transform on the rays: [R | t] (12 numbers)
//!   from x̂ × ([R | t] X) = 0 over ≥ 6 points (the points centred and scaled first), then the
//!   left 3 × 3 block projected onto the rotations (R = UVᵀ of its SVD, the scale the mean of
//!   its singular values, the sign that puts the points in front). The DLT was the minimal
//!   solver first: six-point samples need (1/w)³ times the iterations of three-point ones at
//!   inlier ratio w.
//! - **Refinement.** The pose minimising the inliers' squared reprojection errors, by
//!   Levenberg–Marquardt (`math::lm`) with `bundle`'s analytic Jacobian.

use super::bundle::{linearise, Pose};
use super::p3p;
use crate::math::ransac;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// Pose of one camera by DLT from ≥ 6 correspondences at `idx`.
pub fn dlt(
    k_inv: &Matrix3<f64>,
    points: &[Vector3<f64>],
    pixels: &[[f64; 2]],
    idx: &[usize],
) -> Option<Pose> {
    if idx.len() < 6 {
        return None;
    }
    let n = idx.len() as f64;
    let centre = idx.iter().map(|&i| points[i]).sum::<Vector3<f64>>() / n;
    let scale = idx.iter().map(|&i| (points[i] - centre).norm()).sum::<f64>() / n;
    if scale <= 0.0 {
        return None;
    }
    let s = 3f64.sqrt() / scale;
    let mut ata = nalgebra::SMatrix::<f64, 12, 12>::zeros();
    for &i in idx {
        let x = (points[i] - centre) * s;
        let r = k_inv * Vector3::new(pixels[i][0], pixels[i][1], 1.0);
        let (u, v) = (r[0] / r[2], r[1] / r[2]);
        let xh = [x[0], x[1], x[2], 1.0];
        let mut row1 = [0.0; 12];
        let mut row2 = [0.0; 12];
        for k in 0..4 {
            row1[k] = xh[k];
            row1[8 + k] = -u * xh[k];
            row2[4 + k] = xh[k];
            row2[8 + k] = -v * xh[k];
        }
        for row in [row1, row2] {
            let a = nalgebra::SVector::<f64, 12>::from_row_slice(&row);
            ata += a * a.transpose();
        }
    }
    let p = crate::math::linear::least_eigenvector(DMatrix::from_column_slice(12, 12, ata.as_slice()))?;
    let m = Matrix3::new(p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10]);
    let tv = Vector3::new(p[3], p[7], p[11]);
    let svd = nalgebra::SVD::try_new(m, true, true, 1e-12, 200)?;
    let (u, vt) = (svd.u?, svd.v_t?);
    // In the normalised frame X′ = s(X − c) the camera is ∝ [R | s(R c + t)]: M = λR with
    // |λ| the mean singular value and λ's sign det M's (p and −p are the same solution).
    let d = m.determinant().signum();
    let lambda = d * svd.singular_values.mean();
    if lambda.abs() < 1e-300 {
        return None;
    }
    let r = (u * vt) * d;
    let t = tv / (lambda * s) - r * centre;
    // A sample that puts most of its points behind the camera is degenerate.
    let front = idx.iter().filter(|&&i| (r * points[i] + t)[2] > 0.0).count();
    if 2 * front < idx.len() {
        return None;
    }
    Some(Pose { r, t })
}

/// Pixel reprojection error of one correspondence (infinite behind the camera).
pub fn reprojection_error(k: &Matrix3<f64>, pose: &Pose, x: &Vector3<f64>, px: [f64; 2]) -> f64 {
    linearise(k, pose, x, px).map_or(f64::INFINITY, |(r, ..)| r.norm())
}

/// The pose minimising the squared reprojection errors of `idx`, from `start`.
pub fn refine(
    k: &Matrix3<f64>,
    start: &Pose,
    points: &[Vector3<f64>],
    pixels: &[[f64; 2]],
    idx: &[usize],
) -> Pose {
    let residuals = |p: &Pose| -> Option<(DVector<f64>, DMatrix<f64>)> {
        let mut r = DVector::<f64>::zeros(2 * idx.len());
        let mut j = DMatrix::<f64>::zeros(2 * idx.len(), 6);
        for (row, &i) in idx.iter().enumerate() {
            let (res, d_omega, d_t, _) = linearise(k, p, &points[i], pixels[i])?;
            r.fixed_rows_mut::<2>(2 * row).copy_from(&res);
            j.fixed_view_mut::<2, 3>(2 * row, 0).copy_from(&d_omega);
            j.fixed_view_mut::<2, 3>(2 * row, 3).copy_from(&d_t);
        }
        Some((r, j))
    };
    let cost =
        |p: &Pose| idx.iter().map(|&i| reprojection_error(k, p, &points[i], pixels[i]).powi(2)).sum::<f64>();
    let update = |p: &Pose, d: &DVector<f64>| {
        let rot = nalgebra::Rotation3::new(Vector3::new(d[0], d[1], d[2])).into_inner();
        Pose { r: rot * p.r, t: p.t + Vector3::new(d[3], d[4], d[5]) }
    };
    let opts = crate::math::lm::Options { max_iterations: 30, rel_tolerance: 1e-12, ..Default::default() };
    crate::math::lm::minimize(*start, residuals, cost, update, |_, _, _| {}, &opts).params
}

/// A registered pose and its inliers.
#[derive(Clone, Debug)]
pub struct Registered {
    pub pose: Pose,
    pub inliers: Vec<usize>,
}

/// The pose of a camera with intrinsics `k` from 3D `points` and their `pixels`: P3P in
/// RANSAC with DLT refits (reprojection threshold `threshold_px`), refined on the inliers,
/// inliers taken again.
pub fn estimate(
    k: &Matrix3<f64>,
    points: &[Vector3<f64>],
    pixels: &[[f64; 2]],
    threshold_px: f64,
    seed: u64,
) -> Option<Registered> {
    let k_inv = k.try_inverse()?;
    let n = points.len().min(pixels.len());
    let opts = ransac::Options { threshold: threshold_px, seed, ..ransac::Options::default() };
    let rays: Vec<Vector3<f64>> = pixels.iter().map(|p| k_inv * Vector3::new(p[0], p[1], 1.0)).collect();
    let found = ransac::ransac(
        n,
        3,
        |s| p3p::solve(&[points[s[0]], points[s[1]], points[s[2]]], &[rays[s[0]], rays[s[1]], rays[s[2]]]),
        |p, i| reprojection_error(k, p, &points[i], pixels[i]),
        |inl| dlt(&k_inv, points, pixels, inl),
        &opts,
    )?;
    let pose = refine(k, &found.model, points, pixels, &found.inliers);
    let inliers: Vec<usize> =
        (0..n).filter(|&i| reprojection_error(k, &pose, &points[i], pixels[i]) <= threshold_px).collect();
    Some(Registered { pose, inliers })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 100 points in front of a camera, a fifth of their pixels random: the pose to machine
    /// precision, the outliers left out.
    #[test]
    fn recovers_a_pose_with_outliers() {
        let k = Matrix3::new(900.0, 0.0, 639.5, 0.0, 900.0, 359.5, 0.0, 0.0, 1.0);
        let axis = nalgebra::Unit::new_normalize(Vector3::new(0.3, -1.0, 0.2));
        let r = nalgebra::Rotation3::from_axis_angle(&axis, 0.4).into_inner();
        let pose = Pose { r, t: Vector3::new(0.3, -0.2, 5.0) };
        let mut s = 3u64;
        let mut next = || {
            s = crate::render::sampler::mix64(s);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let points: Vec<Vector3<f64>> = (0..100)
            .map(|_| Vector3::new(next() * 4.0 - 2.0, next() * 3.0 - 1.5, next() * 2.0 - 1.0))
            .collect();
        let pixels: Vec<[f64; 2]> = points
            .iter()
            .enumerate()
            .map(|(i, x)| {
                if i % 5 == 0 {
                    [next() * 1280.0, next() * 720.0]
                } else {
                    let p = k * (pose.r * x + pose.t);
                    [p[0] / p[2], p[1] / p[2]]
                }
            })
            .collect();
        let reg = estimate(&k, &points, &pixels, 1.0, 1).unwrap();
        assert!((reg.pose.r - r).norm() < 1e-9 && (reg.pose.t - pose.t).norm() < 1e-8, "{reg:?}");
        assert!(reg.inliers.iter().all(|&i| i % 5 != 0) && reg.inliers.len() >= 78);
    }
}
