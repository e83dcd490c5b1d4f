//! Two-view geometry of calibrated cameras: the essential matrix by RANSAC, its decomposition
//! into a relative pose, and triangulation.
//!
//! - **Essential matrix.** The normalised 8-point algorithm (Hartley, "In defense of the
//!   eight-point algorithm", PAMI 19(6), 1997) on camera rays x̂ = K⁻¹x: the least-squares
//!   solution of x̂₂ᵀ E x̂₁ = 0 after an isotropic normalisation of each view's points, then
//!   projected onto the essential matrices (singular values 1, 1, 0). In the RANSAC driver
//!   of `math::ransac` (MSAC scoring, adaptive iterations, a refit on each new best's inliers)
//!   with the Sampson distance in pixels, through F = K₂⁻ᵀ E K₁⁻¹.
//! - **Pose.** E = U diag(1, 1, 0) Vᵀ gives R ∈ {U W Vᵀ, U Wᵀ Vᵀ} and t = ±u₃ (Hartley &
//!   Zisserman, 2nd ed., §9.6.2); the one of the four that puts the most inliers in front of
//!   both cameras (cheirality) is kept.
//! - **Triangulation.** The linear (DLT) solution of x̂ × (P X) = 0 for both views.
//!
//! Frames: a pose (R, t) maps view-1 camera coordinates to view 2's, X₂ = R X₁ + t, with
//! |t| = 1 (two views fix the baseline only up to scale).

use crate::math::ransac::{self, Found};
use nalgebra::{DMatrix, Matrix3, Vector3, SVD};

/// A relative pose: X₂ = R·X₁ + t.
#[derive(Clone, Copy, Debug)]
pub struct RelativePose {
    pub r: Matrix3<f64>,
    pub t: Vector3<f64>,
}

/// The estimated geometry of a pair.
#[derive(Clone, Debug)]
pub struct TwoView {
    pub essential: Matrix3<f64>,
    pub pose: RelativePose,
    /// Indices of the correspondences consistent with E and in front of both cameras.
    pub inliers: Vec<usize>,
    pub iterations: usize,
}

/// Isotropic normalisation: centroid to the origin, mean distance √2.
fn normalizer(p: &[[f64; 2]], idx: &[usize]) -> Matrix3<f64> {
    let n = idx.len() as f64;
    let (cx, cy) = idx.iter().fold((0.0, 0.0), |(a, b), &i| (a + p[i][0], b + p[i][1]));
    let (cx, cy) = (cx / n, cy / n);
    let mean = idx.iter().map(|&i| ((p[i][0] - cx).powi(2) + (p[i][1] - cy).powi(2)).sqrt()).sum::<f64>() / n;
    let s = if mean > 0.0 { std::f64::consts::SQRT_2 / mean } else { 1.0 };
    Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0)
}

/// The closest essential matrix (singular values 1, 1, 0).
fn to_essential(e: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let svd = SVD::try_new(*e, true, true, 1e-12, 200)?;
    let (u, vt) = (svd.u?, svd.v_t?);
    Some(u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.0)) * vt)
}

/// The normalised 8-point estimate from rays `x1`, `x2` (K⁻¹ applied) at `idx` (≥ 8).
pub fn essential_8pt(x1: &[[f64; 2]], x2: &[[f64; 2]], idx: &[usize]) -> Option<Matrix3<f64>> {
    if idx.len() < 8 {
        return None;
    }
    let (t1, t2) = (normalizer(x1, idx), normalizer(x2, idx));
    let mut a = DMatrix::<f64>::zeros(idx.len().max(9), 9);
    for (r, &i) in idx.iter().enumerate() {
        let p = t1 * Vector3::new(x1[i][0], x1[i][1], 1.0);
        let q = t2 * Vector3::new(x2[i][0], x2[i][1], 1.0);
        let row = [q[0] * p[0], q[0] * p[1], q[0], q[1] * p[0], q[1] * p[1], q[1], p[0], p[1], 1.0];
        for (c, v) in row.iter().enumerate() {
            a[(r, c)] = *v;
        }
    }
    // The right singular vector of the smallest singular value, from AᵀA's eigenvectors
    // (9 × 9, cheap at any number of points).
    let ata = a.tr_mul(&a);
    let eig = nalgebra::SymmetricEigen::try_new(ata, 1e-14, 500)?;
    let k = eig.eigenvalues.iter().enumerate().min_by(|p, q| p.1.total_cmp(q.1))?.0;
    let v = eig.eigenvectors.column(k);
    let en = Matrix3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]);
    let e = t2.transpose() * en * t1;
    let e = to_essential(&e)?;
    let norm = e.norm();
    (norm > 0.0 && norm.is_finite()).then(|| e / norm)
}

/// Sampson distance (pixels) of a correspondence under the fundamental matrix `f`.
pub fn sampson(f: &Matrix3<f64>, p1: [f64; 2], p2: [f64; 2]) -> f64 {
    let a = Vector3::new(p1[0], p1[1], 1.0);
    let b = Vector3::new(p2[0], p2[1], 1.0);
    let fa = f * a;
    let ftb = f.transpose() * b;
    let num = b.dot(&fa);
    let den = fa[0] * fa[0] + fa[1] * fa[1] + ftb[0] * ftb[0] + ftb[1] * ftb[1];
    if den <= 0.0 {
        return f64::INFINITY;
    }
    (num * num / den).sqrt()
}

/// DLT triangulation of one correspondence of rays for P₁ = [I | 0], P₂ = [R | t]; the point
/// in view 1's frame, or None at infinity.
pub fn triangulate(pose: &RelativePose, x1: [f64; 2], x2: [f64; 2]) -> Option<Vector3<f64>> {
    let p2 = pose.r.insert_column(3, 0.0);
    let mut p2 = p2;
    p2.set_column(3, &pose.t);
    let p1 = Matrix3::<f64>::identity().insert_column(3, 0.0);
    let mut a = nalgebra::Matrix4::<f64>::zeros();
    for k in 0..4 {
        a[(0, k)] = x1[0] * p1[(2, k)] - p1[(0, k)];
        a[(1, k)] = x1[1] * p1[(2, k)] - p1[(1, k)];
        a[(2, k)] = x2[0] * p2[(2, k)] - p2[(0, k)];
        a[(3, k)] = x2[1] * p2[(2, k)] - p2[(1, k)];
    }
    let svd = SVD::try_new(a, false, true, 1e-14, 200)?;
    let vt = svd.v_t?;
    let k = svd.singular_values.iter().enumerate().min_by(|p, q| p.1.total_cmp(q.1))?.0;
    let x = vt.row(k);
    if x[3].abs() < 1e-12 {
        return None;
    }
    Some(Vector3::new(x[0] / x[3], x[1] / x[3], x[2] / x[3]))
}

/// The four poses of E, and the one with the most of `idx` in front of both cameras, with
/// those indices.
pub fn decompose(
    e: &Matrix3<f64>,
    x1: &[[f64; 2]],
    x2: &[[f64; 2]],
    idx: &[usize],
) -> Option<(RelativePose, Vec<usize>)> {
    let svd = SVD::try_new(*e, true, true, 1e-12, 200)?;
    let (mut u, mut vt) = (svd.u?, svd.v_t?);
    if u.determinant() < 0.0 {
        u = -u;
    }
    if vt.determinant() < 0.0 {
        vt = -vt;
    }
    let w = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let t: Vector3<f64> = u.column(2).into_owned();
    let mut best: Option<(RelativePose, Vec<usize>)> = None;
    for r in [u * w * vt, u * w.transpose() * vt] {
        for t in [t, -t] {
            let pose = RelativePose { r, t };
            let front: Vec<usize> = idx
                .iter()
                .copied()
                .filter(|&i| {
                    triangulate(&pose, x1[i], x2[i]).is_some_and(|x| x[2] > 0.0 && (r * x + t)[2] > 0.0)
                })
                .collect();
            if best.as_ref().is_none_or(|b| front.len() > b.1.len()) {
                best = Some((pose, front));
            }
        }
    }
    best
}

/// Two-view geometry from pixel correspondences `p1`, `p2` of cameras with intrinsics `k1`,
/// `k2` (undistorted pixels): E by RANSAC with a Sampson threshold of `threshold_px`, then the
/// pose. None when fewer than 8 correspondences or no sample gives a model.
pub fn estimate(
    p1: &[[f64; 2]],
    p2: &[[f64; 2]],
    k1: &Matrix3<f64>,
    k2: &Matrix3<f64>,
    threshold_px: f64,
    seed: u64,
) -> Option<TwoView> {
    let n = p1.len().min(p2.len());
    if n < 8 {
        return None;
    }
    let (k1i, k2i) = (k1.try_inverse()?, k2.try_inverse()?);
    let ray = |k: &Matrix3<f64>, p: [f64; 2]| {
        let v = k * Vector3::new(p[0], p[1], 1.0);
        [v[0] / v[2], v[1] / v[2]]
    };
    let x1: Vec<[f64; 2]> = p1.iter().map(|&p| ray(&k1i, p)).collect();
    let x2: Vec<[f64; 2]> = p2.iter().map(|&p| ray(&k2i, p)).collect();
    let to_f = |e: &Matrix3<f64>| k2i.transpose() * e * k1i;
    let opts = ransac::Options { threshold: threshold_px, seed, ..ransac::Options::default() };
    let found: Found<Matrix3<f64>> = ransac::ransac(
        n,
        8,
        |s| essential_8pt(&x1, &x2, s).into_iter().collect(),
        |e, i| sampson(&to_f(e), p1[i], p2[i]),
        |inl| essential_8pt(&x1, &x2, inl),
        &opts,
    )?;
    let (pose, inliers) = decompose(&found.model, &x1, &x2, &found.inliers)?;
    Some(TwoView { essential: found.model, pose, inliers, iterations: found.iterations })
}

/// The angle of a rotation matrix, in degrees.
pub fn rotation_angle_deg(r: &Matrix3<f64>) -> f64 {
    (((r.trace() - 1.0) / 2.0).clamp(-1.0, 1.0)).acos().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points in front of two cameras with a known relative pose, projected exactly, with a
    /// quarter of the correspondences replaced by random ones: the pose comes back to
    /// machine precision and the outliers are left out.
    #[test]
    fn recovers_a_known_pose_with_outliers() {
        let k = Matrix3::new(800.0, 0.0, 319.5, 0.0, 800.0, 239.5, 0.0, 0.0, 1.0);
        let axis = Vector3::new(0.2, 1.0, -0.1).normalize();
        let r = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), 0.15).into_inner();
        let t = Vector3::new(-1.0, 0.1, 0.2).normalize();
        let pose = RelativePose { r, t };
        let mut s = 99u64;
        let mut next = || {
            s = crate::render::sampler::mix64(s);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let project = |x: Vector3<f64>| {
            let v = k * x;
            [v[0] / v[2], v[1] / v[2]]
        };
        let (mut p1, mut p2) = (Vec::new(), Vec::new());
        for i in 0..200 {
            let x = Vector3::new(next() * 4.0 - 2.0, next() * 3.0 - 1.5, 4.0 + next() * 4.0);
            p1.push(project(x));
            if i % 4 == 0 {
                p2.push([next() * 640.0, next() * 480.0]);
            } else {
                p2.push(project(pose.r * x + pose.t));
            }
        }
        let tv = estimate(&p1, &p2, &k, &k, 1.0, 5).unwrap();
        let dr = rotation_angle_deg(&(tv.pose.r * r.transpose()));
        assert!(dr < 1e-6, "rotation off by {dr}°");
        assert!((tv.pose.t - t).norm() < 1e-6, "{:?}", tv.pose.t);
        assert!(tv.inliers.iter().all(|&i| i % 4 != 0));
        assert!(tv.inliers.len() >= 145, "{}", tv.inliers.len());
    }
}
