//! Perspective-three-point: the poses of a calibrated camera from three 3D points and their
//! rays, Grunert's solution (1841) in the form reviewed by Haralick et al., "Review and
//! analysis of solutions of the three point perspective pose estimation problem" (IJCV 13(3),
//! 1994).
//!
//! With unit rays j₁, j₂, j₃ (x̂ = K⁻¹x, normalised), their cosines cα = j₂·j₃, cβ = j₁·j₃,
//! cγ = j₁·j₂ and the sides a = |X₂ − X₃|, b = |X₁ − X₃|, c = |X₁ − X₂|, the distances sᵢ along
//! the rays obey the law of cosines
//!
//!   s₁² + s₂² − 2s₁s₂·cγ = c²,   s₁² + s₃² − 2s₁s₃·cβ = b²,   s₂² + s₃² − 2s₂s₃·cα = a².
//!
//! With s₂ = u·s₁ and s₃ = v·s₁, eliminating s₁² leaves u linear in v, u = N/D, with
//!
//!   K = (c²/b²)·(1 + v² − 2v·cβ) − 1,   N = (a²/b²)·(1 + v² − 2v·cβ) − K − v²,
//!   D = 2(cγ − v·cα),
//!
//! and N² − 2cγ·N·D − K·D² = 0, a quartic in v. Its real roots come from the eigenvalues of
//! the companion matrix (each polished by two Newton steps); each with u, v > 0 gives
//! s₁ = c/√(1 + u² − 2u·cγ), the points sᵢ·jᵢ in the camera frame, and the pose that maps the
//! three world points onto them (Kabsch: R = U·diag(1, 1, det UVᵀ)·Vᵀ from the SVD of their
//! centred cross-covariance, t = X̄_cam − R·X̄_world). Up to four poses; the caller's RANSAC
//! keeps the one most correspondences agree with.

use super::bundle::Pose;
use nalgebra::{Matrix3, Matrix4, Schur, Vector3};

/// Iterations allowed to the Schur and SVD decompositions (they converge in tens).
const MAX_ITERATIONS: usize = 1000;

/// Coefficients of a polynomial in v, lowest degree first.
type Poly = [f64; 5];

fn mul(a: &Poly, b: &Poly) -> Poly {
    let mut out = [0.0; 5];
    for (i, &x) in a.iter().enumerate() {
        for (j, &y) in b.iter().enumerate() {
            if i + j < 5 {
                out[i + j] += x * y;
            } else {
                debug_assert!(x * y == 0.0, "degree above 4");
            }
        }
    }
    out
}

fn eval(p: &Poly, v: f64) -> f64 {
    p.iter().rev().fold(0.0, |acc, &c| acc * v + c)
}

/// The real roots of the quartic `p` (degree 4 exactly, relative to its other coefficients).
fn real_roots(p: &Poly) -> Vec<f64> {
    let scale = p.iter().fold(0.0f64, |m, c| m.max(c.abs()));
    if !(scale > 0.0) || !scale.is_finite() || p[4].abs() < 1e-12 * scale {
        return Vec::new();
    }
    // Companion matrix of the monic polynomial.
    let mut m = Matrix4::<f64>::zeros();
    for i in 0..3 {
        m[(i + 1, i)] = 1.0;
    }
    for i in 0..4 {
        m[(i, 3)] = -p[i] / p[4];
    }
    let Some(schur) = Schur::try_new(m, f64::EPSILON, MAX_ITERATIONS) else { return Vec::new() };
    let dp: [f64; 4] = [p[1], 2.0 * p[2], 3.0 * p[3], 4.0 * p[4]];
    schur
        .complex_eigenvalues()
        .iter()
        .filter(|z| z.im.abs() <= 1e-8 * (1.0 + z.re.abs()))
        .map(|z| {
            let mut v = z.re;
            for _ in 0..2 {
                let d = dp.iter().rev().fold(0.0, |acc, &c| acc * v + c);
                if d != 0.0 {
                    v -= eval(p, v) / d;
                }
            }
            v
        })
        .filter(|v| v.is_finite())
        .collect()
}

/// The pose mapping `world` onto `cam` (three points each) by Kabsch's method.
fn absolute_orientation(world: &[Vector3<f64>; 3], cam: &[Vector3<f64>; 3]) -> Option<Pose> {
    let wc = (world[0] + world[1] + world[2]) / 3.0;
    let cc = (cam[0] + cam[1] + cam[2]) / 3.0;
    let mut h = Matrix3::<f64>::zeros();
    for i in 0..3 {
        h += (cam[i] - cc) * (world[i] - wc).transpose();
    }
    let svd = nalgebra::SVD::try_new(h, true, true, f64::EPSILON, MAX_ITERATIONS)?;
    let (u, vt) = (svd.u?, svd.v_t?);
    let d = (u * vt).determinant().signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
    let t = cc - r * wc;
    (r.iter().all(|x| x.is_finite()) && t.iter().all(|x| x.is_finite())).then_some(Pose { r, t })
}

/// Up to four world-to-camera poses that put the three `points` on the three `rays` (camera
/// frame directions, any length; module docs). Empty for degenerate input (collinear points,
/// parallel rays, non-finite values).
pub fn solve(points: &[Vector3<f64>; 3], rays: &[Vector3<f64>; 3]) -> Vec<Pose> {
    let j: Vec<Vector3<f64>> = rays.iter().map(|r| r.normalize()).collect();
    if !j.iter().chain(points.iter()).all(|v| v.iter().all(|x| x.is_finite())) {
        return Vec::new();
    }
    let (ca, cb, cg) = (j[1].dot(&j[2]), j[0].dot(&j[2]), j[0].dot(&j[1]));
    let a2 = (points[1] - points[2]).norm_squared();
    let b2 = (points[0] - points[2]).norm_squared();
    let c2 = (points[0] - points[1]).norm_squared();
    // Collinear points (zero area) or coincident ones leave the pose undetermined.
    if !(b2 > 0.0)
        || (points[1] - points[0]).cross(&(points[2] - points[0])).norm_squared() <= 1e-20 * b2 * b2
    {
        return Vec::new();
    }
    // 1 + v² − 2v·cβ, K, N and D as polynomials in v.
    let q: Poly = [1.0, -2.0 * cb, 1.0, 0.0, 0.0];
    let k: Poly = std::array::from_fn(|i| c2 / b2 * q[i] - if i == 0 { 1.0 } else { 0.0 });
    let n: Poly = std::array::from_fn(|i| a2 / b2 * q[i] - k[i] - if i == 2 { 1.0 } else { 0.0 });
    let d: Poly = [2.0 * cg, -2.0 * ca, 0.0, 0.0, 0.0];
    let nn = mul(&n, &n);
    let nd = mul(&n, &d);
    let kdd = mul(&k, &mul(&d, &d));
    let quartic: Poly = std::array::from_fn(|i| nn[i] - 2.0 * cg * nd[i] - kdd[i]);
    let mut poses = Vec::new();
    for v in real_roots(&quartic) {
        let dv = eval(&d, v);
        if dv.abs() < 1e-12 {
            continue;
        }
        let u = eval(&n, v) / dv;
        let den = 1.0 + u * u - 2.0 * u * cg;
        if !(u > 0.0 && v > 0.0 && den > 0.0) {
            continue;
        }
        let s1 = (c2 / den).sqrt();
        let cam = [j[0] * s1, j[1] * (u * s1), j[2] * (v * s1)];
        if let Some(p) = absolute_orientation(points, &cam) {
            poses.push(p);
        }
    }
    poses
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn stream(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = crate::render::sampler::mix64(s);
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Random poses and triples of points in front of the camera: one of the solutions is the
    /// true pose (to 1e-9 in 95 % of the triples, 1e-4 in all), and every solution puts the
    /// three points on their rays.
    #[test]
    fn the_true_pose_is_among_the_solutions() {
        let mut next = stream(11);
        let mut worst = Vec::new();
        for trial in 0..200 {
            let axis = Vector3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            let r = Rotation3::new(axis * 2.0).into_inner();
            let t = Vector3::new(next() - 0.5, next() - 0.5, 4.0 + 4.0 * next());
            let points: [Vector3<f64>; 3] = std::array::from_fn(|_| {
                // A point in front of the camera, expressed in the world frame.
                let xc = Vector3::new(next() * 4.0 - 2.0, next() * 3.0 - 1.5, 2.0 + 6.0 * next());
                r.transpose() * (xc - t)
            });
            let rays: [Vector3<f64>; 3] = std::array::from_fn(|i| (r * points[i] + t) * (0.5 + next()));
            let poses = solve(&points, &rays);
            assert!(!poses.is_empty() && poses.len() <= 4, "trial {trial}: {} poses", poses.len());
            let best =
                poses.iter().map(|p| (p.r - r).norm() + (p.t - t).norm()).fold(f64::INFINITY, f64::min);
            worst.push(best);
            for p in &poses {
                for i in 0..3 {
                    let xc = p.r * points[i] + p.t;
                    assert!(xc.normalize().dot(&rays[i].normalize()) > 1.0 - 1e-9, "trial {trial}");
                    assert!((p.r.determinant() - 1.0).abs() < 1e-9);
                }
            }
        }
        // Near a double root of the quartic (two solutions merging) a root is good only to
        // about √ε times its conditioning: a few triples in two hundred.
        worst.sort_by(f64::total_cmp);
        assert!(worst[worst.len() - 1] < 1e-4 && worst[worst.len() * 95 / 100] < 1e-9, "{worst:?}");
    }

    /// Collinear or coincident points and non-finite rays give nothing.
    #[test]
    fn degenerate_input_gives_nothing() {
        let ray = Vector3::new(0.0, 0.0, 1.0);
        let line = [Vector3::new(0.0, 0.0, 5.0), Vector3::new(1.0, 0.0, 5.0), Vector3::new(2.0, 0.0, 5.0)];
        let rays = [ray, Vector3::new(0.2, 0.0, 1.0), Vector3::new(0.4, 0.0, 1.0)];
        assert!(solve(&line, &rays).is_empty());
        let same = [line[0]; 3];
        assert!(solve(&same, &rays).is_empty());
        let tri = [line[0], line[1], Vector3::new(0.0, 1.0, 5.0)];
        assert!(solve(&tri, &[ray, Vector3::new(f64::NAN, 0.0, 1.0), ray]).is_empty());
    }
}
