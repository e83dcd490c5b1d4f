//! The essential matrices of five calibrated correspondences: Nistér's five-point problem
//! ("An efficient solution to the five-point relative pose problem", PAMI 26(6), 2004), solved
//! by Stewénius' Gröbner-basis route ("Recent developments on direct relative orientation",
//! ISPRS J. 60, 2006).
//!
//! Each correspondence (rays q in view 1, q' in view 2) gives q'ᵀ E q = 0, linear in E's nine
//! entries: five such rows leave a four-dimensional null space, E = x·X + y·Y + z·Z + W. An
//! essential matrix also satisfies det E = 0 and 2·E Eᵀ E − tr(E Eᵀ)·E = 0: ten cubic
//! equations in (x, y, z) over the 20 monomials of degree ≤ 3. Gauss-Jordan elimination of
//! their 10 cubic monomials writes each as a combination of the 10 others, [x², xy, xz, y², yz,
//! z², x, y, z, 1], which are a basis of the quotient ring (10 solutions, complex ones
//! included). Multiplication by x maps that basis into the cubic monomials x³, x²y, x²z, xy²,
//! xyz, xz² and into the basis itself: the 10 × 10 action matrix, whose real eigenvalues are the
//! solutions' x and whose eigenvectors hold their (x, y, z) in the entries of x, y and z.
//!
//! Unlike the 8-point algorithm, five points on one plane are not degenerate for it, so a scene
//! dominated by one plane (a façade) among many wrong matches still yields the right E from a
//! sample with a few points off the plane.

use nalgebra::{DMatrix, Matrix3, SMatrix, SVector, Schur};

/// Iterations allowed to each SVD and Schur decomposition (they converge in tens).
const MAX_ITERATIONS: usize = 1000;

/// A polynomial in (x, y, z) of degree ≤ 3: coefficients over `MONOMIALS`.
type Poly = [f64; 20];

/// Exponents (x, y, z) of the monomials: first the ten cubic ones (eliminated), then the basis
/// [x², xy, xz, y², yz, z², x, y, z, 1].
const MONOMIALS: [[u8; 3]; 20] = [
    [3, 0, 0],
    [2, 1, 0],
    [2, 0, 1],
    [1, 2, 0],
    [1, 1, 1],
    [1, 0, 2],
    [0, 3, 0],
    [0, 2, 1],
    [0, 1, 2],
    [0, 0, 3],
    [2, 0, 0],
    [1, 1, 0],
    [1, 0, 1],
    [0, 2, 0],
    [0, 1, 1],
    [0, 0, 2],
    [1, 0, 0],
    [0, 1, 0],
    [0, 0, 1],
    [0, 0, 0],
];

fn index(e: [u8; 3]) -> usize {
    // Every product formed here has degree ≤ 3, so the search always succeeds.
    MONOMIALS.iter().position(|m| *m == e).unwrap_or(19)
}

fn mul(a: &Poly, b: &Poly) -> Poly {
    let mut out = [0.0; 20];
    for (i, &ai) in a.iter().enumerate() {
        if ai == 0.0 {
            continue;
        }
        for (j, &bj) in b.iter().enumerate() {
            if bj == 0.0 {
                continue;
            }
            let (m, n) = (MONOMIALS[i], MONOMIALS[j]);
            out[index([m[0] + n[0], m[1] + n[1], m[2] + n[2]])] += ai * bj;
        }
    }
    out
}

fn add(a: &Poly, b: &Poly, s: f64) -> Poly {
    std::array::from_fn(|i| a[i] + s * b[i])
}

/// The essential matrices (unit Frobenius norm) of the five correspondences `x1[i]` ↔
/// `x2[i]` (normalised image coordinates, rays (x, y, 1)), for i in `idx`; up to ten, usually
/// two to four. Empty when the five are degenerate (for example two of them equal).
pub fn essentials(x1: &[[f64; 2]], x2: &[[f64; 2]], idx: &[usize]) -> Vec<Matrix3<f64>> {
    if idx.len() != 5 {
        return Vec::new();
    }
    // The null space of the 5 × 9 constraint rows: the right singular vectors of the four
    // smallest singular values of the rows padded to 9 × 9.
    let mut q = SMatrix::<f64, 9, 9>::zeros();
    for (r, &i) in idx.iter().enumerate() {
        let (p, pp) = ([x1[i][0], x1[i][1], 1.0], [x2[i][0], x2[i][1], 1.0]);
        for a in 0..3 {
            for b in 0..3 {
                q[(r, 3 * a + b)] = pp[a] * p[b];
            }
        }
    }
    // Capped iterations: nalgebra's uncapped decompositions loop for ever on a NaN.
    if !q.iter().all(|v| v.is_finite()) {
        return Vec::new();
    }
    let Some(svd) = q.try_svd(false, true, f64::EPSILON, MAX_ITERATIONS) else { return Vec::new() };
    let Some(vt) = svd.v_t else { return Vec::new() };
    let mut order: Vec<usize> = (0..9).collect();
    order.sort_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]));
    let basis: Vec<SVector<f64, 9>> = order[..4].iter().map(|&k| vt.row(k).transpose()).collect();
    // E's entries as polynomials of degree 1: x·X + y·Y + z·Z + W.
    let e: [[Poly; 3]; 3] = std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            let mut p = [0.0; 20];
            p[16] = basis[0][3 * r + c];
            p[17] = basis[1][3 * r + c];
            p[18] = basis[2][3 * r + c];
            p[19] = basis[3][3 * r + c];
            p
        })
    });
    let mut m = DMatrix::<f64>::zeros(10, 20);
    // det E.
    let minor = |a: usize, b: usize, c: usize, d: usize| {
        add(&mul(&e[1][a], &e[2][b]), &mul(&e[1][c], &e[2][d]), -1.0)
    };
    let det = [(0, minor(1, 2, 2, 1), 1.0), (1, minor(0, 2, 2, 0), -1.0), (2, minor(0, 1, 1, 0), 1.0)]
        .iter()
        .fold([0.0; 20], |acc, (c, mnr, s)| add(&acc, &mul(&e[0][*c], mnr), *s));
    for (k, v) in det.iter().enumerate() {
        m[(0, k)] = *v;
    }
    // 2·E Eᵀ E − tr(E Eᵀ)·E.
    let eet: [[Poly; 3]; 3] = std::array::from_fn(|r| {
        std::array::from_fn(|c| (0..3).fold([0.0; 20], |acc, k| add(&acc, &mul(&e[r][k], &e[c][k]), 1.0)))
    });
    let trace = add(&add(&eet[0][0], &eet[1][1], 1.0), &eet[2][2], 1.0);
    for r in 0..3 {
        for c in 0..3 {
            let product = (0..3).fold([0.0; 20], |acc, k| add(&acc, &mul(&eet[r][k], &e[k][c]), 1.0));
            let row = add(&product.map(|v| 2.0 * v), &mul(&trace, &e[r][c]), -1.0);
            for (k, v) in row.iter().enumerate() {
                m[(1 + 3 * r + c, k)] = *v;
            }
        }
    }
    // Gauss-Jordan on the cubic monomials: cubic_i = −B_i · basis.
    let lead = m.columns(0, 10).into_owned();
    let rest = m.columns(10, 10).into_owned();
    let Some(b) = lead.lu().solve(&rest) else { return Vec::new() };
    let mut action = SMatrix::<f64, 10, 10>::zeros();
    for i in 0..6 {
        for j in 0..10 {
            action[(i, j)] = -b[(i, j)];
        }
    }
    // x·x = x², x·y = xy, x·z = xz, x·1 = x.
    for (row, col) in [(6, 0), (7, 1), (8, 2), (9, 6)] {
        action[(row, col)] = 1.0;
    }
    if !action.iter().all(|v| v.is_finite()) {
        return Vec::new();
    }
    let Some(schur) = Schur::try_new(action, f64::EPSILON, MAX_ITERATIONS) else { return Vec::new() };
    let mut out = Vec::new();
    for lambda in schur.complex_eigenvalues().iter() {
        if lambda.im.abs() > 1e-8 * (1.0 + lambda.re.abs()) {
            continue;
        }
        let shifted = action - SMatrix::<f64, 10, 10>::identity() * lambda.re;
        let Some(svd) = shifted.try_svd(false, true, f64::EPSILON, MAX_ITERATIONS) else { continue };
        let Some(vt) = svd.v_t else { continue };
        let v = vt.row(svd.singular_values.imin());
        if v[9].abs() < 1e-12 {
            continue;
        }
        let (x, y, z) = (v[6] / v[9], v[7] / v[9], v[8] / v[9]);
        let vec = basis[0] * x + basis[1] * y + basis[2] * z + basis[3];
        let e = Matrix3::new(vec[0], vec[1], vec[2], vec[3], vec[4], vec[5], vec[6], vec[7], vec[8]);
        let norm = e.norm();
        if norm > 0.0 && e.iter().all(|v| v.is_finite()) {
            out.push(e / norm);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    /// Degenerate and non-finite input gives no solution, never a hang or a NaN.
    #[test]
    fn degenerate_input_gives_nothing() {
        let same = [[0.1, 0.2]; 5];
        assert!(essentials(&same, &same, &[0, 1, 2, 3, 4]).iter().all(|e| e.iter().all(|v| v.is_finite())));
        let mut bad = [[0.1, 0.2], [0.3, -0.1], [-0.2, 0.4], [0.0, 0.0], [0.5, 0.5]];
        bad[2][0] = f64::NAN;
        assert!(essentials(&bad, &bad, &[0, 1, 2, 3, 4]).is_empty());
        assert!(essentials(&bad, &bad, &[0, 1, 2]).is_empty());
    }

    /// Five points seen from two poses, exactly: one of the solutions is [t]×R (up to sign),
    /// and every solution satisfies the five constraints and the essential-matrix identities.
    #[test]
    fn recovers_the_true_essential_matrix() {
        for (seed, planar) in [(1u64, false), (2, false), (3, true)] {
            let mut s = seed;
            let mut next = || {
                s = crate::render::sampler::mix64(s);
                (s >> 11) as f64 / (1u64 << 53) as f64
            };
            let r =
                Rotation3::from_euler_angles(0.1 * next(), 0.3 * next() - 0.15, 0.2 * next()).into_inner();
            let t = Vector3::new(1.0, 0.2 * next(), 0.1 * next()).normalize();
            let mut x1 = Vec::new();
            let mut x2 = Vec::new();
            for _ in 0..5 {
                let depth = if planar { 5.0 } else { 4.0 + 3.0 * next() };
                let p = Vector3::new(2.0 * next() - 1.0, 2.0 * next() - 1.0, 1.0) * depth;
                let q = r * p + t;
                x1.push([p[0] / p[2], p[1] / p[2]]);
                x2.push([q[0] / q[2], q[1] / q[2]]);
            }
            let sols = essentials(&x1, &x2, &[0, 1, 2, 3, 4]);
            assert!(!sols.is_empty(), "seed {seed}: no solution");
            let truth = t.cross_matrix() * r;
            let truth = truth / truth.norm();
            let best =
                sols.iter().map(|e| (e - truth).norm().min((e + truth).norm())).fold(f64::INFINITY, f64::min);
            assert!(best < 1e-8, "seed {seed} (planar {planar}): closest solution {best} from the truth");
            for e in &sols {
                for i in 0..5 {
                    let c = Vector3::new(x2[i][0], x2[i][1], 1.0)
                        .dot(&(e * Vector3::new(x1[i][0], x1[i][1], 1.0)));
                    assert!(c.abs() < 1e-9, "constraint {c}");
                }
                assert!(e.determinant().abs() < 1e-9);
                let id = 2.0 * e * e.transpose() * e - (e * e.transpose()).trace() * e;
                assert!(id.norm() < 1e-8, "{id}");
            }
        }
    }
}
