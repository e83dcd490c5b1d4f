//! The reduced camera system of bundle adjustment, S δc = b (`bundle` module docs), kept
//! sparse: S has a 6 × 6 block for each camera with itself and for each pair of free cameras
//! that see a point in common, and nothing elsewhere; intrinsics every camera shares (focal
//! length, principal point, radial distortion: up to `MAX_SHARED`) add last rows and columns
//! that touch every camera. Along a path of thousands of images each camera sees
//! points with a few dozen others, so S is mostly empty, and a dense S (36·n² numbers: 7 GB
//! for 5000 images) would not fit.
//!
//! S is solved by faer's sparse Cholesky factorisation (faer picks a simplicial or
//! supernodal factorisation and orders the unknowns by approximate minimum degree to limit
//! fill-in). The pattern does not change while one adjustment iterates, so its symbolic
//! analysis is done once (`Pattern::new`) and each damped solve only refactors the numbers.
//! S is symmetric: only its lower triangle is stored.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use nalgebra::{DVector, Matrix6, SMatrix};

/// Most shared unknowns (f, cx, cy, k1, k2).
pub const MAX_SHARED: usize = 5;

/// Which blocks of S exist, and the symbolic factorisation of that pattern.
pub struct Pattern {
    cameras: usize,
    shared: usize,
    /// Per block column c: the block rows below the diagonal that exist, ascending.
    below: Vec<Vec<usize>>,
    /// Per block column: the index of its first off-diagonal block in `System::off`.
    first: Vec<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    symbolic: SymbolicLlt<usize>,
}

/// The numbers of S and b for one pattern.
pub struct System {
    /// S's diagonal blocks, one per camera.
    pub diag: Vec<Matrix6<f64>>,
    /// S's blocks below the diagonal, in the order `Pattern::block` gives.
    pub off: Vec<Matrix6<f64>>,
    /// With shared unknowns θ (the first `shared` columns used): per camera S[camera, θ], and
    /// S[θ, θ].
    pub shared_col: Vec<SMatrix<f64, 6, MAX_SHARED>>,
    pub shared_shared: SMatrix<f64, MAX_SHARED, MAX_SHARED>,
    pub b: DVector<f64>,
}

impl Pattern {
    /// The pattern of `cameras` free cameras and `shared` shared unknowns (at most
    /// `MAX_SHARED`), the pairs of cameras in `pairs` (either order, repeats allowed) coupled.
    /// `None` when faer cannot allocate the analysis.
    pub fn new(
        cameras: usize,
        shared: usize,
        pairs: impl IntoIterator<Item = (usize, usize)>,
    ) -> Option<Pattern> {
        let mut below: Vec<Vec<usize>> = vec![Vec::new(); cameras];
        for (a, b) in pairs {
            if a != b {
                below[a.min(b)].push(a.max(b));
            }
        }
        for rows in &mut below {
            rows.sort_unstable();
            rows.dedup();
        }
        let mut first = Vec::with_capacity(cameras);
        let mut blocks = 0;
        for rows in &below {
            first.push(blocks);
            blocks += rows.len();
        }
        // Scalar columns: camera c's column q holds rows 6c + q..6c + 6 of its diagonal block,
        // then 6 rows per block below, then the shared unknowns' rows.
        let shared = shared.min(MAX_SHARED);
        let n = 6 * cameras + shared;
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0);
        for (c, rows) in below.iter().enumerate() {
            for q in 0..6 {
                row_idx.extend(6 * c + q..6 * c + 6);
                for &r in rows {
                    row_idx.extend(6 * r..6 * r + 6);
                }
                row_idx.extend(6 * cameras..n);
                col_ptr.push(row_idx.len());
            }
        }
        for q in 6 * cameras..n {
            row_idx.extend(q..n);
            col_ptr.push(row_idx.len());
        }
        let structure = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let symbolic = SymbolicLlt::try_new(structure, faer::Side::Lower).ok()?;
        Some(Pattern { cameras, shared, below, first, col_ptr, row_idx, symbolic })
    }

    /// The index in `System::off` of block (a, b), a > b, if the pattern has it.
    pub fn block(&self, a: usize, b: usize) -> Option<usize> {
        self.below[b].binary_search(&a).ok().map(|k| self.first[b] + k)
    }

    /// A system of zeros for this pattern.
    pub fn zeros(&self) -> System {
        let n = 6 * self.cameras + self.shared;
        System {
            diag: vec![Matrix6::zeros(); self.cameras],
            off: vec![
                Matrix6::zeros();
                self.first.last().map_or(0, |f| f + self.below[self.cameras - 1].len())
            ],
            shared_col: vec![SMatrix::zeros(); if self.shared > 0 { self.cameras } else { 0 }],
            shared_shared: SMatrix::zeros(),
            b: DVector::zeros(n),
        }
    }

    /// δc = S⁻¹ b, or `None` when S is not positive definite (numerically).
    pub fn solve(&self, s: &System) -> Option<DVector<f64>> {
        let n = 6 * self.cameras + self.shared;
        if n == 0 {
            return Some(DVector::zeros(0));
        }
        let mut values = Vec::with_capacity(self.row_idx.len());
        for (c, rows) in self.below.iter().enumerate() {
            for q in 0..6 {
                values.extend((q..6).map(|r| s.diag[c][(r, q)]));
                for k in 0..rows.len() {
                    let block = &s.off[self.first[c] + k];
                    values.extend((0..6).map(|r| block[(r, q)]));
                }
                values.extend((0..self.shared).map(|j| s.shared_col[c][(q, j)]));
            }
        }
        for q in 0..self.shared {
            values.extend((q..self.shared).map(|r| s.shared_shared[(r, q)]));
        }
        let structure = SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
        let matrix = SparseColMatRef::new(structure, &values);
        let llt = Llt::try_new_with_symbolic(self.symbolic.clone(), matrix, faer::Side::Lower).ok()?;
        let mut x = faer::Col::<f64>::from_fn(n, |i| s.b[i]);
        llt.solve_in_place(&mut x);
        let x = DVector::from_fn(n, |i, _| x[i]);
        x.iter().all(|v| v.is_finite()).then_some(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// A sparse system with two shared rows, solved against the same system written out
    /// densely.
    #[test]
    fn matches_the_dense_solve() {
        let cameras = 5;
        let shared = 2;
        let pairs = [(0, 1), (1, 2), (3, 1), (2, 4), (1, 0)];
        let pattern = Pattern::new(cameras, shared, pairs).unwrap();
        let mut s = pattern.zeros();
        let n = 6 * cameras + shared;
        // A random symmetric positive-definite matrix with this pattern: Aᵀ A restricted to
        // the pattern is not PD in general, so build diagonally dominant blocks instead.
        let mut rng = 0x9e3779b97f4a7c15u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut dense = DMatrix::<f64>::zeros(n, n);
        for &(a, b) in &pairs {
            let (hi, lo) = (a.max(b), a.min(b));
            let k = pattern.block(hi, lo).unwrap();
            let m = Matrix6::from_fn(|_, _| next());
            s.off[k] += m;
            let mut v = dense.view_mut((6 * hi, 6 * lo), (6, 6));
            v += m;
            let mut t = dense.view_mut((6 * lo, 6 * hi), (6, 6));
            t += m.transpose();
        }
        for c in 0..cameras {
            let m = Matrix6::from_fn(|_, _| next());
            let d = m + m.transpose() + Matrix6::identity() * 40.0;
            s.diag[c] = d;
            dense.view_mut((6 * c, 6 * c), (6, 6)).copy_from(&d);
            for j in 0..shared {
                let f = nalgebra::Vector6::from_fn(|_, _| next());
                s.shared_col[c].set_column(j, &f);
                dense.view_mut((6 * c, 6 * cameras + j), (6, 1)).copy_from(&f);
                dense.view_mut((6 * cameras + j, 6 * c), (1, 6)).copy_from(&f.transpose());
            }
        }
        let off = next();
        s.shared_shared[(0, 0)] = 50.0;
        s.shared_shared[(1, 1)] = 60.0;
        s.shared_shared[(1, 0)] = off;
        dense[(n - 2, n - 2)] = 50.0;
        dense[(n - 1, n - 1)] = 60.0;
        (dense[(n - 1, n - 2)], dense[(n - 2, n - 1)]) = (off, off);
        s.b = DVector::from_fn(n, |_, _| next());
        let x = pattern.solve(&s).unwrap();
        let reference = dense.clone().cholesky().unwrap().solve(&s.b);
        assert!((x - reference).amax() < 1e-12);
        assert!(pattern.block(4, 0).is_none());
        // Not positive definite: no solution.
        s.diag[2] = -s.diag[2];
        assert!(pattern.solve(&s).is_none());
    }
}
