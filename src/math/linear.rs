//! Small dense linear algebra the solvers share.

use nalgebra::{DMatrix, DVector};

/// The unit eigenvector of the smallest eigenvalue of a symmetric AᵀA: the least-squares
/// solution of A x = 0 with ‖x‖ = 1, for the DLT systems of homographies, essential
/// matrices, camera poses and points (AᵀA is at most 12 × 12 there, however many rows A has).
/// None if the eigen-decomposition does not converge.
pub fn least_eigenvector(ata: DMatrix<f64>) -> Option<DVector<f64>> {
    let eig = nalgebra::SymmetricEigen::try_new(ata, 1e-14, 1000)?;
    let k = eig.eigenvalues.iter().enumerate().min_by(|p, q| p.1.total_cmp(q.1))?.0;
    Some(eig.eigenvectors.column(k).into_owned())
}
