//! Gauge-free comparison of a reconstruction with ground-truth cameras: pairwise relative
//! rotation errors (the angle of R_ij,est·R_ij,trueᵀ for every pair of registered images, as
//! COLMAP's and GLOMAP's evaluations) and camera-centre errors after the similarity that best
//! maps the estimated centres onto the true ones (Umeyama, "Least-squares estimation of
//! transformation parameters between two point patterns", PAMI 13(4), 1991; as OpenMVG's
//! quality evaluation aligns).

use super::bundle::Pose;
use crate::math::WorldToCamera;
use nalgebra::{Matrix3, Vector3};

/// s, R, t minimising Σ‖dst − (s R src + t)‖², or None for fewer than 3 points or a
/// degenerate (collinear) set.
pub fn similarity(src: &[Vector3<f64>], dst: &[Vector3<f64>]) -> Option<(f64, Matrix3<f64>, Vector3<f64>)> {
    let n = src.len().min(dst.len());
    if n < 3 {
        return None;
    }
    let mu_s = src.iter().take(n).sum::<Vector3<f64>>() / n as f64;
    let mu_d = dst.iter().take(n).sum::<Vector3<f64>>() / n as f64;
    let var_s = src.iter().take(n).map(|p| (p - mu_s).norm_squared()).sum::<f64>() / n as f64;
    let mut cov = Matrix3::<f64>::zeros();
    for (a, b) in src.iter().zip(dst).take(n) {
        cov += (b - mu_d) * (a - mu_s).transpose();
    }
    cov /= n as f64;
    let svd = nalgebra::SVD::try_new(cov, true, true, 1e-14, 200)?;
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::<f64>::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * vt;
    if var_s <= 0.0 || svd.singular_values[1] <= 1e-12 * svd.singular_values[0] {
        return None;
    }
    let s = (svd.singular_values.component_mul(&d.diagonal())).sum() / var_s;
    Some((s, r, mu_d - s * r * mu_s))
}

/// Relative rotation errors (degrees) over every pair of images registered in `est` and
/// known in `truth`.
pub fn pairwise_rotation_errors(est: &[Option<Pose>], truth: &[WorldToCamera]) -> Vec<f64> {
    let truth: Vec<Pose> = truth.iter().map(Pose::from).collect();
    let mut out = Vec::new();
    for i in 0..est.len() {
        for j in i + 1..est.len() {
            if let (Some(a), Some(b)) = (&est[i], &est[j]) {
                // R_ij maps camera i to camera j: R_j R_iᵀ.
                let e = b.r * a.r.transpose();
                let t = truth[j].r * truth[i].r.transpose();
                out.push(super::two_view::rotation_angle_deg(&(e * t.transpose())));
            }
        }
    }
    out
}

/// Relative rotation errors over the same pairs as `pairwise_rotation_errors`, as rotation
/// vectors (axis × angle in degrees, camera j's frame), keyed by the pair (i, j): the
/// components a first-order propagation can add, where the angles are their norms.
pub fn pairwise_rotation_error_vectors(
    est: &[Option<Pose>],
    truth: &[WorldToCamera],
) -> Vec<((usize, usize), [f64; 3])> {
    let truth: Vec<Pose> = truth.iter().map(Pose::from).collect();
    let mut out = Vec::new();
    for i in 0..est.len() {
        for j in i + 1..est.len() {
            if let (Some(a), Some(b)) = (&est[i], &est[j]) {
                let e = b.r * a.r.transpose() * (truth[j].r * truth[i].r.transpose()).transpose();
                let v = nalgebra::Rotation3::from_matrix_unchecked(e).scaled_axis().map(f64::to_degrees);
                out.push(((i, j), [v.x, v.y, v.z]));
            }
        }
    }
    out
}

/// Camera-centre errors after aligning the registered centres to the truth's by a
/// similarity, in the truth's units; None when fewer than 3 are registered.
pub fn centre_errors(est: &[Option<Pose>], truth: &[WorldToCamera]) -> Option<Vec<f64>> {
    let truth: Vec<Pose> = truth.iter().map(Pose::from).collect();
    let pairs: Vec<(Vector3<f64>, Vector3<f64>)> =
        est.iter().zip(truth).filter_map(|(e, t)| e.map(|e| (e.centre(), t.centre()))).collect();
    let src: Vec<Vector3<f64>> = pairs.iter().map(|p| p.0).collect();
    let dst: Vec<Vector3<f64>> = pairs.iter().map(|p| p.1).collect();
    let (s, r, t) = similarity(&src, &dst)?;
    Some(src.iter().zip(&dst).map(|(a, b)| (s * r * a + t - b).norm()).collect())
}

/// The largest distance between two true camera centres: the scale centre errors are
/// given relative to.
pub fn centre_spread(truth: &[WorldToCamera]) -> f64 {
    let truth: Vec<Pose> = truth.iter().map(Pose::from).collect();
    truth.iter().flat_map(|a| truth.iter().map(move |b| (a.centre() - b.centre()).norm())).fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A known similarity comes back from four points to machine precision.
    #[test]
    fn similarity_round_trip() {
        let src = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 2.0, 0.0),
            Vector3::new(0.3, 0.1, 1.5),
        ];
        let r = nalgebra::Rotation3::new(Vector3::new(0.3, -0.2, 0.9)).into_inner();
        let (s, t) = (2.5, Vector3::new(1.0, -3.0, 0.5));
        let dst: Vec<Vector3<f64>> = src.iter().map(|p| s * r * p + t).collect();
        let (s2, r2, t2) = similarity(&src, &dst).unwrap();
        assert!((s2 - s).abs() < 1e-12 && (r2 - r).norm() < 1e-12 && (t2 - t).norm() < 1e-12);
    }
}
