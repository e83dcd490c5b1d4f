//! Two-view geometry of calibrated cameras: the essential matrix by RANSAC, its decomposition
//! into a relative pose, and triangulation.
//!
//! - **Essential matrix.** Samples of five correspondences on camera rays x̂ = K⁻¹x, each
//!   giving up to ten essential matrices (Nistér 2004, `five_point`), in the RANSAC driver of
//!   `math::ransac` (MSAC scoring, adaptive iterations) with the Sampson distance in pixels,
//!   through F = K₂⁻ᵀ E K₁⁻¹; each new best is refitted on its inliers by the normalised
//!   8-point algorithm (Hartley, "In defense of the eight-point algorithm", PAMI 19(6), 1997:
//!   the least-squares solution of x̂₂ᵀ E x̂₁ = 0 after an isotropic normalisation of each
//!   view's points, projected onto the essential matrices, singular values 1, 1, 0). Eight-point
//!   samples were the first choice: on Herz-Jesu-P8 with half the matches wrong, the pair whose
//!   matches lie mostly on the façade ended 13° off, its samples from the plane degenerate;
//!   five-point samples are not, and need about 250 iterations there instead of 7800.
//! - **Pose.** E = U diag(1, 1, 0) Vᵀ gives R ∈ {U W Vᵀ, U Wᵀ Vᵀ} and t = ±u₃ (Hartley &
//!   Zisserman, 2nd ed., §9.6.2); the one of the four that puts the most inliers in front of
//!   both cameras (cheirality) is kept.
//! - **Refinement.** The pose (3 rotation + 2 direction parameters, updated on their
//!   manifolds: R ← exp([ω]×)·R, t on the unit sphere) minimising the inliers' Sampson
//!   distances under Huber's loss (δ = 1 px) by Levenberg–Marquardt (`math::lm`, forward-difference Jacobian); inliers
//!   and the cheirality check are then taken again under the refined E.
//! - **Triangulation.** The linear (DLT) solution of x̂ × (P X) = 0 for both views.
//! - **Model selection.** A homography is fitted as well (normalised 4-point DLT in RANSAC,
//!   transfer error in pixels). When it explains more than 80 % as many correspondences as E
//!   (COLMAP's `max_H_inlier_ratio`), the pair is planar or a pure rotation, and E's pose is
//!   not to be trusted (the 8-point algorithm is degenerate on a plane; a rotation leaves t
//!   undetermined): `Configuration::PureRotation` when the rotation closest to K₂⁻¹HK₁
//!   (R̂ = UVᵀ of its SVD) alone, as K₂R̂K₁⁻¹, explains 80 % of the homography's inliers within
//!   the threshold (no parallax above the noise), else `Planar`. The caller decides what to do
//!   with such a pair; its pose is reported, never silently used.
//!
//! Frames: a pose (R, t) maps view-1 camera coordinates to view 2's, X₂ = R X₁ + t, with
//! |t| = 1 (two views fix the baseline only up to scale).

use super::five_point;
use crate::math::linear::least_eigenvector;
use crate::math::ransac::{self, Found};
use nalgebra::{DMatrix, Matrix3, Vector3, SVD};

/// A relative pose: X₂ = R·X₁ + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativePose {
    pub r: Matrix3<f64>,
    pub t: Vector3<f64>,
}

/// What a pair's correspondences say about its geometry (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Configuration {
    /// A baseline and depth: E's pose holds.
    General,
    /// A homography explains the pair as well: a plane seen from two places.
    Planar,
    /// A homography explains the pair and rays barely diverge: the camera only turned.
    PureRotation,
}

/// The estimated geometry of a pair.
#[derive(Clone, Debug)]
pub struct TwoView {
    pub essential: Matrix3<f64>,
    pub pose: RelativePose,
    /// Indices of the correspondences consistent with E and in front of both cameras.
    pub inliers: Vec<usize>,
    pub iterations: usize,
    /// Correspondences a homography explains within the same threshold.
    pub homography_inliers: usize,
    /// The median angle between the two rays of E's inliers, degrees.
    pub median_triangulation_angle_deg: f64,
    pub configuration: Configuration,
}

/// The normalised DLT homography p₂ ~ H p₁ from ≥ 4 correspondences at `idx`.
pub fn homography_dlt(p1: &[[f64; 2]], p2: &[[f64; 2]], idx: &[usize]) -> Option<Matrix3<f64>> {
    if idx.len() < 4 {
        return None;
    }
    let (t1, t2) = (normalizer(p1, idx), normalizer(p2, idx));
    let mut ata = nalgebra::SMatrix::<f64, 9, 9>::zeros();
    for &i in idx {
        let a = t1 * Vector3::new(p1[i][0], p1[i][1], 1.0);
        let b = t2 * Vector3::new(p2[i][0], p2[i][1], 1.0);
        let rows = [
            [-a[0], -a[1], -1.0, 0.0, 0.0, 0.0, b[0] * a[0], b[0] * a[1], b[0]],
            [0.0, 0.0, 0.0, -a[0], -a[1], -1.0, b[1] * a[0], b[1] * a[1], b[1]],
        ];
        for r in rows {
            let v = nalgebra::SVector::<f64, 9>::from_row_slice(&r);
            ata += v * v.transpose();
        }
    }
    let v = least_eigenvector(DMatrix::from_column_slice(9, 9, ata.as_slice()))?;
    let hn = Matrix3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]);
    let h = t2.try_inverse()? * hn * t1;
    let norm = h.norm();
    (norm > 0.0 && norm.is_finite()).then(|| h / norm)
}

/// Distance (pixels) from p₂ to H p₁.
pub fn transfer_error(h: &Matrix3<f64>, p1: [f64; 2], p2: [f64; 2]) -> f64 {
    let v = h * Vector3::new(p1[0], p1[1], 1.0);
    if v[2].abs() < 1e-300 {
        return f64::INFINITY;
    }
    ((v[0] / v[2] - p2[0]).powi(2) + (v[1] / v[2] - p2[1]).powi(2)).sqrt()
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
    let v = least_eigenvector(a.tr_mul(&a))?;
    let en = Matrix3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]);
    let e = t2.transpose() * en * t1;
    let e = to_essential(&e)?;
    let norm = e.norm();
    (norm > 0.0 && norm.is_finite()).then(|| e / norm)
}

/// E = [t]×·R.
pub fn essential_of(pose: &RelativePose) -> Matrix3<f64> {
    pose.t.cross_matrix() * pose.r
}

/// Signed Sampson distance (pixels): x₂ᵀF x₁ over the norm of its gradient.
fn sampson_signed(f: &Matrix3<f64>, p1: [f64; 2], p2: [f64; 2]) -> f64 {
    let a = Vector3::new(p1[0], p1[1], 1.0);
    let b = Vector3::new(p2[0], p2[1], 1.0);
    let fa = f * a;
    let ftb = f.transpose() * b;
    let den = fa[0] * fa[0] + fa[1] * fa[1] + ftb[0] * ftb[0] + ftb[1] * ftb[1];
    if den <= 0.0 {
        return f64::INFINITY;
    }
    b.dot(&fa) / den.sqrt()
}

/// The pose minimising the squared Sampson distances of `idx` (module docs).
pub fn refine(
    pose: &RelativePose,
    p1: &[[f64; 2]],
    p2: &[[f64; 2]],
    k1i: &Matrix3<f64>,
    k2i: &Matrix3<f64>,
    idx: &[usize],
) -> RelativePose {
    use nalgebra::{DMatrix, DVector};
    // Huber's loss with δ = 1 px, as the residual sign(e)·√ρ(e²): an inlier within the RANSAC
    // threshold but far from the rest (a wrong match near its epipolar line) pulls linearly,
    // not quadratically.
    const DELTA: f64 = 1.0;
    let robust = |e: f64| {
        let a = e.abs();
        let rho = if a <= DELTA { a * a } else { 2.0 * DELTA * a - DELTA * DELTA };
        rho.sqrt().copysign(e)
    };
    let residuals_at = |q: &RelativePose| -> DVector<f64> {
        let f = k2i.transpose() * essential_of(q) * k1i;
        DVector::from_iterator(idx.len(), idx.iter().map(|&i| robust(sampson_signed(&f, p1[i], p2[i]))))
    };
    let update = |q: &RelativePose, d: &DVector<f64>| -> RelativePose {
        let rot = nalgebra::Rotation3::new(Vector3::new(d[0], d[1], d[2])).into_inner();
        // Two directions orthogonal to t span its tangent plane.
        let helper = if q.t[0].abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let b1 = q.t.cross(&helper).normalize();
        let b2 = q.t.cross(&b1);
        RelativePose { r: rot * q.r, t: (q.t + b1 * d[3] + b2 * d[4]).normalize() }
    };
    let residuals = |q: &RelativePose| -> Option<(DVector<f64>, DMatrix<f64>)> {
        let r0 = residuals_at(q);
        if !r0.iter().all(|v| v.is_finite()) {
            return None;
        }
        let mut j = DMatrix::<f64>::zeros(idx.len(), 5);
        for k in 0..5 {
            let h = 1e-7;
            let mut d = DVector::<f64>::zeros(5);
            d[k] = h;
            let rk = residuals_at(&update(q, &d));
            j.set_column(k, &((rk - &r0) / h));
        }
        Some((r0, j))
    };
    let cost = |q: &RelativePose| {
        let r = residuals_at(q);
        if r.iter().all(|v| v.is_finite()) {
            r.norm_squared()
        } else {
            f64::INFINITY
        }
    };
    let opts = crate::math::lm::Options { max_iterations: 30, rel_tolerance: 1e-10, ..Default::default() };
    crate::math::lm::minimize(*pose, residuals, cost, update, |_, _, _| {}, &opts).params
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

/// The normalised image point of pixel `p` through the inverse intrinsics `k_inv`.
fn ray(k_inv: &Matrix3<f64>, p: [f64; 2]) -> [f64; 2] {
    let v = k_inv * Vector3::new(p[0], p[1], 1.0);
    [v[0] / v[2], v[1] / v[2]]
}

/// A pair is planar or a rotation when a homography explains more than this fraction of
/// E's inliers (COLMAP's default).
pub const MAX_H_INLIER_RATIO: f64 = 0.8;

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
    let x1: Vec<[f64; 2]> = p1.iter().map(|&p| ray(&k1i, p)).collect();
    let x2: Vec<[f64; 2]> = p2.iter().map(|&p| ray(&k2i, p)).collect();
    let to_f = |e: &Matrix3<f64>| k2i.transpose() * e * k1i;
    let opts = ransac::Options { threshold: threshold_px, seed, ..ransac::Options::default() };
    let found: Found<Matrix3<f64>> = ransac::ransac(
        n,
        5,
        |s| five_point::essentials(&x1, &x2, s),
        |e, i| sampson(&to_f(e), p1[i], p2[i]),
        |inl| essential_8pt(&x1, &x2, inl),
        &opts,
    )?;
    let (pose, front) = decompose(&found.model, &x1, &x2, &found.inliers)?;
    let pose = refine(&pose, p1, p2, &k1i, &k2i, &front);
    // Inliers again under the refined E: within the threshold and in front of both cameras.
    let e = essential_of(&pose);
    let inliers = consistent(&pose, p1, p2, k1, k2, threshold_px);
    // The homography, and the rays' divergence, for the model selection (module docs).
    let h_found = ransac::ransac(
        n,
        4,
        |s| homography_dlt(p1, p2, s).into_iter().collect(),
        |h, i| transfer_error(h, p1[i], p2[i]),
        |inl| homography_dlt(p1, p2, inl),
        &opts,
    );
    let homography_inliers = h_found.as_ref().map_or(0, |h| h.inliers.len());
    let mut angles: Vec<f64> = inliers
        .iter()
        .filter_map(|&i| {
            // The angle at the triangulated point between the directions to both centres.
            let c2 = -(pose.r.transpose() * pose.t);
            triangulate(&pose, x1[i], x2[i])
                .map(|x| x.normalize().dot(&(x - c2).normalize()).clamp(-1.0, 1.0).acos().to_degrees())
        })
        .collect();
    angles.sort_by(f64::total_cmp);
    let median_triangulation_angle_deg = angles.get(angles.len() / 2).copied().unwrap_or(0.0);
    let configuration = match &h_found {
        Some(h) if (h.inliers.len() as f64) > MAX_H_INLIER_RATIO * inliers.len() as f64 => {
            // Does a rotation alone explain the homography's inliers?
            // H's sign is arbitrary: make K₂⁻¹HK₁ a positive multiple of a rotation.
            let m = k2i * h.model * k1;
            let m = if m.determinant() < 0.0 { -m } else { m };
            let rotation_only = SVD::try_new(m, true, true, 1e-12, 200).and_then(|svd| {
                let (u, vt) = (svd.u?, svd.v_t?);
                let d = (u * vt).determinant().signum();
                let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
                Some(k2 * r * k1i)
            });
            let explained = rotation_only.map_or(0, |hr| {
                h.inliers.iter().filter(|&&i| transfer_error(&hr, p1[i], p2[i]) <= threshold_px).count()
            });
            if explained as f64 >= MAX_H_INLIER_RATIO * h.inliers.len() as f64 {
                Configuration::PureRotation
            } else {
                Configuration::Planar
            }
        }
        _ => Configuration::General,
    };
    Some(TwoView {
        essential: e,
        pose,
        inliers,
        iterations: found.iterations,
        homography_inliers,
        median_triangulation_angle_deg,
        configuration,
    })
}

/// The correspondences `p1`, `p2` (pixels of cameras with intrinsics `k1`, `k2`) that `pose`
/// explains: Sampson distance within `threshold_px` and in front of both cameras.
pub fn consistent(
    pose: &RelativePose,
    p1: &[[f64; 2]],
    p2: &[[f64; 2]],
    k1: &Matrix3<f64>,
    k2: &Matrix3<f64>,
    threshold_px: f64,
) -> Vec<usize> {
    let (Some(k1i), Some(k2i)) = (k1.try_inverse(), k2.try_inverse()) else {
        return Vec::new();
    };
    let f = k2i.transpose() * essential_of(pose) * k1i;
    (0..p1.len().min(p2.len()))
        .filter(|&i| sampson(&f, p1[i], p2[i]) <= threshold_px)
        .filter(|&i| {
            triangulate(pose, ray(&k1i, p1[i]), ray(&k2i, p2[i]))
                .is_some_and(|x| x[2] > 0.0 && (pose.r * x + pose.t)[2] > 0.0)
        })
        .collect()
}

/// The angle of a rotation matrix, in degrees: atan2(‖v‖, tr R − 1) with v the axial vector
/// of R − Rᵀ (2 sin θ and 2 cos θ), which keeps its precision for small angles where
/// acos((tr R − 1)/2) loses it (a 10⁻⁶ error in the trace is 0.06° there).
pub fn rotation_angle_deg(r: &Matrix3<f64>) -> f64 {
    let v = Vector3::new(r[(2, 1)] - r[(1, 2)], r[(0, 2)] - r[(2, 0)], r[(1, 0)] - r[(0, 1)]);
    v.norm().atan2(r.trace() - 1.0).to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    const K: Matrix3<f64> = Matrix3::new(800.0, 0.0, 319.5, 0.0, 800.0, 239.5, 0.0, 0.0, 1.0);

    /// 200 points from `point(u, v, w)` (three uniform numbers) seen by two cameras `pose`
    /// apart, projected exactly; every fourth correspondence replaced by a random one.
    fn pair(
        pose: &RelativePose,
        point: impl Fn(f64, f64, f64) -> Vector3<f64>,
    ) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let mut s = 99u64;
        let mut next = || {
            s = crate::render::sampler::mix64(s);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let project = |x: Vector3<f64>| {
            let v = K * x;
            [v[0] / v[2], v[1] / v[2]]
        };
        let (mut p1, mut p2) = (Vec::new(), Vec::new());
        for i in 0..200 {
            let x = point(next(), next(), next());
            p1.push(project(x));
            if i % 4 == 0 {
                p2.push([next() * 640.0, next() * 480.0]);
            } else {
                p2.push(project(pose.r * x + pose.t));
            }
        }
        (p1, p2)
    }

    fn rotation() -> Matrix3<f64> {
        let axis = nalgebra::Unit::new_normalize(Vector3::new(0.2, 1.0, -0.1));
        nalgebra::Rotation3::from_axis_angle(&axis, 0.15).into_inner()
    }

    /// Points at several depths with a known relative pose and a quarter of the
    /// correspondences random: the pose comes back to machine precision, the outliers are
    /// left out, and the pair is `General`.
    #[test]
    fn recovers_a_known_pose_with_outliers() {
        let (r, t) = (rotation(), Vector3::new(-1.0, 0.1, 0.2).normalize());
        let pose = RelativePose { r, t };
        let (p1, p2) = pair(&pose, |u, v, w| Vector3::new(u * 4.0 - 2.0, v * 3.0 - 1.5, 4.0 + w * 4.0));
        let tv = estimate(&p1, &p2, &K, &K, 1.0, 5).unwrap();
        let dr = rotation_angle_deg(&(tv.pose.r * r.transpose()));
        assert!(dr < 1e-6, "rotation off by {dr}°");
        assert!((tv.pose.t - t).norm() < 1e-6, "{:?}", tv.pose.t);
        assert!(tv.inliers.iter().all(|&i| i % 4 != 0));
        assert!(tv.inliers.len() >= 145, "{}", tv.inliers.len());
        assert_eq!(tv.configuration, Configuration::General, "{tv:?}");
    }

    /// A plane seen from two places is `Planar`; a camera that only turned (points far away,
    /// a baseline of a millionth of their distance) is `PureRotation`.
    #[test]
    fn recognises_a_plane_and_a_rotation() {
        let pose = RelativePose { r: rotation(), t: Vector3::new(-1.0, 0.1, 0.2).normalize() };
        let (p1, p2) = pair(&pose, |u, v, _| Vector3::new(u * 4.0 - 2.0, v * 3.0 - 1.5, 5.0 + 0.5 * u));
        let tv = estimate(&p1, &p2, &K, &K, 1.0, 5).unwrap();
        assert_eq!(tv.configuration, Configuration::Planar, "{tv:?}");
        let turn = RelativePose { r: rotation(), t: Vector3::new(1e-6, 0.0, 0.0) };
        let (p1, p2) = pair(&turn, |u, v, w| Vector3::new(u * 4.0 - 2.0, v * 3.0 - 1.5, 4.0 + w * 4.0));
        let tv = estimate(&p1, &p2, &K, &K, 1.0, 5).unwrap();
        assert_eq!(tv.configuration, Configuration::PureRotation, "{tv:?}");
    }
}
