//! Zhang's closed-form calibration (Z. Zhang, "A flexible new technique for camera
//! calibration", IEEE TPAMI 2000): homographies, intrinsics from the image of the absolute
//! conic, extrinsics, and a linear guess of radial distortion.
//!
//! For each view the board plane (Z = 0) maps to the image by H = λ·K·[r₁ r₂ t]. Since r₁, r₂
//! are orthonormal, with B = K⁻ᵀK⁻¹ (symmetric, 6 unknowns b):
//!
//!   h₁ᵀ B h₂ = 0,   h₁ᵀ B h₁ − h₂ᵀ B h₂ = 0
//!
//! two linear equations per view; b is the null vector of the stacked system (≥ 3 views, or 2
//! with zero skew added as an equation). K follows from B in closed form. Where B comes out
//! indefinite (slightly tilted boards through a distorting lens), the principal point is fixed
//! at the image centre and the focal lengths solved alone, as OpenCV's initIntrinsicParams2D
//! does; the refinement frees the principal point and reports how well the focal length is
//! determined (`calib::calibrate` refuses it beyond 10 %). Image coordinates are
//! first scaled to about ±1 so the system is well conditioned (Hartley 1997).

use super::Error;
use glam::{DMat3, DVec2, DVec3};
use nalgebra::{DMatrix, DVector, Matrix3, SVD};

/// A 3×3 homography mapping board (X, Y, 1) to image (u, v, 1), row-major.
pub type Homography = Matrix3<f64>;

/// Points normalised to zero mean and mean distance √2: returns the 3×3 normalising transform.
fn normaliser(pts: &[DVec2]) -> Matrix3<f64> {
    let n = pts.len().max(1) as f64;
    let c = pts.iter().fold(DVec2::ZERO, |a, &p| a + p) / n;
    let d = pts.iter().map(|p| p.distance(c)).sum::<f64>() / n;
    let s = if d > 0.0 { std::f64::consts::SQRT_2 / d } else { 1.0 };
    Matrix3::new(s, 0.0, -s * c.x, 0.0, s, -s * c.y, 0.0, 0.0, 1.0)
}

fn apply(h: &Matrix3<f64>, p: DVec2) -> DVec2 {
    let w = h[(2, 0)] * p.x + h[(2, 1)] * p.y + h[(2, 2)];
    DVec2::new(
        (h[(0, 0)] * p.x + h[(0, 1)] * p.y + h[(0, 2)]) / w,
        (h[(1, 0)] * p.x + h[(1, 1)] * p.y + h[(1, 2)]) / w,
    )
}

/// Condition numbers above this are reported as a warning. A homography's entries and Zhang's
/// b come out of their systems with relative errors up to the condition number times the
/// data's: corners good to 0.05 px on a board spanning 500 px give 10⁻⁴, so above 10³ the
/// intrinsics may be off by 10 % or more.
pub const CONDITION_WARNING: f64 = 1e3;

/// Homography from ≥ 4 correspondences: normalised DLT, then Levenberg–Marquardt on the
/// reprojection error in the image.
pub fn homography(board: &[DVec2], image: &[DVec2]) -> Option<Homography> {
    homography_conditioned(board, image).map(|(h, _)| h)
}

/// The homography and the condition number of its normalised DLT system (σ_max over the
/// second-smallest singular value: how well the solution is separated from other directions).
pub fn homography_conditioned(board: &[DVec2], image: &[DVec2]) -> Option<(Homography, f64)> {
    if board.len() < 4 || board.len() != image.len() {
        return None;
    }
    let (tb, ti) = (normaliser(board), normaliser(image));
    let mut a = DMatrix::<f64>::zeros(2 * board.len(), 9);
    for (k, (&b, &i)) in board.iter().zip(image).enumerate() {
        let (b, i) = (apply(&tb, b), apply(&ti, i));
        let row0 = [b.x, b.y, 1.0, 0.0, 0.0, 0.0, -i.x * b.x, -i.x * b.y, -i.x];
        let row1 = [0.0, 0.0, 0.0, b.x, b.y, 1.0, -i.y * b.x, -i.y * b.y, -i.y];
        for c in 0..9 {
            a[(2 * k, c)] = row0[c];
            a[(2 * k + 1, c)] = row1[c];
        }
    }
    let (h, cond) = null_vector(&a)?;
    let hn = Matrix3::from_row_slice(h.as_slice());
    let mut h = ti.try_inverse()? * hn * tb;
    h /= h[(2, 2)];
    refine_homography(&mut h, board, image);
    h.iter().all(|v| v.is_finite()).then_some((h, cond))
}

/// The right singular vector of the smallest singular value, and the system's condition
/// number for it: σ_max / σ₂, σ₂ the second-smallest singular value of A.
fn null_vector(a: &DMatrix<f64>) -> Option<(DVector<f64>, f64)> {
    // AᵀA is small (≤ 9×9); its eigenvector of the smallest eigenvalue is the null vector,
    // and its eigenvalues are A's singular values squared.
    let ata = a.transpose() * a;
    let svd = SVD::new(ata, false, true);
    let vt = svd.v_t?;
    let (k, _) = svd.singular_values.iter().enumerate().min_by(|x, y| x.1.total_cmp(y.1))?;
    let mut sv: Vec<f64> = svd.singular_values.iter().copied().collect();
    sv.sort_by(|x, y| x.total_cmp(y));
    let cond = match sv.as_slice() {
        [_, second, .., max] if *second > 0.0 => (max / second).sqrt(),
        _ => f64::INFINITY,
    };
    Some((vt.row(k).transpose(), cond))
}

/// Levenberg–Marquardt (`math::lm`) on the 8 free entries of H (H₃₃ = 1), minimising the
/// reprojection error in the image.
fn refine_homography(h: &mut Homography, board: &[DVec2], image: &[DVec2]) {
    let cost =
        |h: &Homography| board.iter().zip(image).map(|(&b, &i)| apply(h, b).distance_squared(i)).sum::<f64>();
    let residuals = |h: &Homography| {
        let mut r = DVector::zeros(2 * board.len());
        let mut j = DMatrix::zeros(2 * board.len(), 8);
        for (k, (&b, &i)) in board.iter().zip(image).enumerate() {
            let w = h[(2, 0)] * b.x + h[(2, 1)] * b.y + h[(2, 2)];
            let p = apply(h, b);
            let ju = [b.x / w, b.y / w, 1.0 / w, 0.0, 0.0, 0.0, -p.x * b.x / w, -p.x * b.y / w];
            let jv = [0.0, 0.0, 0.0, b.x / w, b.y / w, 1.0 / w, -p.y * b.x / w, -p.y * b.y / w];
            r[2 * k] = p.x - i.x;
            r[2 * k + 1] = p.y - i.y;
            for c in 0..8 {
                j[(2 * k, c)] = ju[c];
                j[(2 * k + 1, c)] = jv[c];
            }
        }
        Some((r, j))
    };
    let update = |h: &Homography, step: &DVector<f64>| {
        let mut hn = *h;
        for k in 0..8 {
            hn[(k / 3, k % 3)] += step[k];
        }
        hn
    };
    let opts = crate::math::lm::Options {
        max_iterations: 50,
        rel_tolerance: 1e-14,
        mu_down: 10.0,
        mu_up: 10.0,
        max_tries: 10,
        ..Default::default()
    };
    *h = crate::math::lm::minimize(*h, residuals, cost, update, |_, _, _| {}, &opts).params;
}

const UNOBSERVABLE: &str =
    "the views do not determine the intrinsics (the boards are parallel to each other \
     or to the image plane): tilt the board differently between views";

/// Intrinsics (fx, fy, cx, cy; zero skew) from ≥ 2 homographies, `size` = image (w, h).
pub fn intrinsics(hs: &[Homography], size: (u32, u32)) -> Result<DMat3, Error> {
    intrinsics_conditioned(hs, size).map(|(k, _)| k)
}

/// The intrinsics and the condition number of Zhang's system for b (as `null_vector`).
pub fn intrinsics_conditioned(hs: &[Homography], size: (u32, u32)) -> Result<(DMat3, f64), Error> {
    if hs.len() < 2 {
        return Err(Error::Numerical(format!("{} view(s): Zhang's method needs at least 2", hs.len())));
    }
    // Scale image coordinates to about ±1: H' = N·H, and K = N⁻¹·K'.
    let s = 0.5 * (size.0 + size.1) as f64;
    let (cx, cy) = ((size.0 as f64 - 1.0) / 2.0, (size.1 as f64 - 1.0) / 2.0);
    let n = Matrix3::new(1.0 / s, 0.0, -cx / s, 0.0, 1.0 / s, -cy / s, 0.0, 0.0, 1.0);
    let v = |h: &Matrix3<f64>, i: usize, j: usize| {
        [
            h[(0, i)] * h[(0, j)],
            h[(0, i)] * h[(1, j)] + h[(1, i)] * h[(0, j)],
            h[(1, i)] * h[(1, j)],
            h[(2, i)] * h[(0, j)] + h[(0, i)] * h[(2, j)],
            h[(2, i)] * h[(1, j)] + h[(1, i)] * h[(2, j)],
            h[(2, i)] * h[(2, j)],
        ]
    };
    // Two equations per view, plus zero skew (b₁₂ = 0) weighted like one view.
    let mut a = DMatrix::<f64>::zeros(2 * hs.len() + 1, 6);
    for (k, h) in hs.iter().enumerate() {
        let h = n * h;
        let h = h / h.column(0).norm().max(h.column(1).norm());
        let (v12, v11, v22) = (v(&h, 0, 1), v(&h, 0, 0), v(&h, 1, 1));
        for c in 0..6 {
            a[(2 * k, c)] = v12[c];
            a[(2 * k + 1, c)] = v11[c] - v22[c];
        }
    }
    a[(2 * hs.len(), 1)] = 1.0;
    // One null direction is expected; a second (near-)null one means the views do not
    // constrain K (for example every board parallel to the image plane).
    let sv = SVD::new(a.transpose() * &a, false, false).singular_values;
    let mut sv: Vec<f64> = sv.iter().copied().collect();
    sv.sort_by(|x, y| x.total_cmp(y));
    if sv[1] <= 1e-10 * sv[5] {
        return Err(Error::Numerical(UNOBSERVABLE.into()));
    }
    let (b, cond) =
        null_vector(&a).ok_or_else(|| Error::Numerical("the homographies give no solution".into()))?;
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let den = b11 * b22 - b12 * b12;
    let v0 = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let alpha2 = lambda / b11;
    let beta2 = lambda * b11 / den;
    let (kn, cond) =
        if alpha2 > 0.0 && beta2 > 0.0 && den.abs() > 0.0 && alpha2.is_finite() && beta2.is_finite() {
            let (alpha, beta) = (alpha2.sqrt(), beta2.sqrt());
            let u0 = -b13 * alpha2 / lambda;
            (Matrix3::new(alpha, 0.0, u0, 0.0, beta, v0, 0.0, 0.0, 1.0), cond)
        } else {
            // Slightly tilted boards seen through a distorting lens leave the principal point too
            // weakly determined for the full closed form (B comes out indefinite). Fix it at the
            // image centre and solve for the focal lengths alone, as OpenCV's
            // initIntrinsicParams2D does; the refinement frees it again.
            centred_focal(hs, &n)?
        };
    let k = n.try_inverse().ok_or_else(|| Error::Numerical("singular normaliser".into()))? * kn;
    let k = k / k[(2, 2)];
    Ok((DMat3::from_cols_array(&[k[(0, 0)], 0.0, 0.0, 0.0, k[(1, 1)], 0.0, k[(0, 2)], k[(1, 2)], 1.0]), cond))
}

/// Focal lengths with the principal point at the image centre (zero in the normalised
/// coordinates `n` gives): with B = diag(1/α², 1/β², 1), each view's two equations are linear
/// in (1/α², 1/β²): h₁₁h₁₂/α² + h₂₁h₂₂/β² = −h₃₁h₃₂ and (h₁₁² − h₁₂²)/α² + (h₂₁² − h₂₂²)/β²
/// = −(h₃₁² − h₃₂²). Returns K in normalised coordinates and the system's condition number.
fn centred_focal(hs: &[Homography], n: &Matrix3<f64>) -> Result<(Matrix3<f64>, f64), Error> {
    let mut a = DMatrix::<f64>::zeros(2 * hs.len(), 2);
    let mut rhs = DVector::<f64>::zeros(2 * hs.len());
    for (k, h) in hs.iter().enumerate() {
        let h = n * h;
        let h = h / h.column(0).norm().max(h.column(1).norm());
        a[(2 * k, 0)] = h[(0, 0)] * h[(0, 1)];
        a[(2 * k, 1)] = h[(1, 0)] * h[(1, 1)];
        rhs[2 * k] = -h[(2, 0)] * h[(2, 1)];
        a[(2 * k + 1, 0)] = h[(0, 0)] * h[(0, 0)] - h[(0, 1)] * h[(0, 1)];
        a[(2 * k + 1, 1)] = h[(1, 0)] * h[(1, 0)] - h[(1, 1)] * h[(1, 1)];
        rhs[2 * k + 1] = -(h[(2, 0)] * h[(2, 0)] - h[(2, 1)] * h[(2, 1)]);
    }
    let svd = SVD::new(a.clone(), true, true);
    let sv = &svd.singular_values;
    let cond = if sv.min() > 0.0 { sv.max() / sv.min() } else { f64::INFINITY };
    let x = svd.solve(&rhs, 1e-300).map_err(|_| Error::Numerical(UNOBSERVABLE.into()))?;
    // Noise and distortion can push a poorly determined 1/α² below zero: take its size, as
    // OpenCV does, and leave the rest to the refinement (which reports the uncertainty).
    let (ia2, ib2) = (x[0].abs(), x[1].abs());
    if !(ia2 > 0.0 && ib2 > 0.0 && ia2.is_finite() && ib2.is_finite()) {
        return Err(Error::Numerical(UNOBSERVABLE.into()));
    }
    Ok((Matrix3::new(1.0 / ia2.sqrt(), 0.0, 0.0, 0.0, 1.0 / ib2.sqrt(), 0.0, 0.0, 0.0, 1.0), cond))
}

/// Board-to-camera pose from a homography and K: (R, t) with the board in front.
pub fn extrinsics(h: &Homography, k: &DMat3) -> Option<(DMat3, DVec3)> {
    let kinv = k.inverse();
    let col = |c: usize| kinv * DVec3::new(h[(0, c)], h[(1, c)], h[(2, c)]);
    let (h1, h2, h3) = (col(0), col(1), col(2));
    let mut lambda = 1.0 / h1.length();
    if (lambda * h3).z < 0.0 {
        lambda = -lambda;
    }
    let r1 = h1 * lambda;
    let r2 = h2 * lambda;
    let r3 = r1.cross(r2);
    let t = h3 * lambda;
    // The nearest rotation to [r1 r2 r3] (polar decomposition by SVD).
    let m = nalgebra::Matrix3::from_columns(&[
        nalgebra::Vector3::new(r1.x, r1.y, r1.z),
        nalgebra::Vector3::new(r2.x, r2.y, r2.z),
        nalgebra::Vector3::new(r3.x, r3.y, r3.z),
    ]);
    let svd = SVD::new(m, true, true);
    let mut r = svd.u? * svd.v_t?;
    if r.determinant() < 0.0 {
        r = -r;
    }
    let rot = DMat3::from_cols_array(&[
        r[(0, 0)],
        r[(1, 0)],
        r[(2, 0)],
        r[(0, 1)],
        r[(1, 1)],
        r[(2, 1)],
        r[(0, 2)],
        r[(1, 2)],
        r[(2, 2)],
    ]);
    (t.is_finite() && rot.is_finite()).then_some((rot, t))
}
