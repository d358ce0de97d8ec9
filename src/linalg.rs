//! Bridges between nalgebra (the per-step hot loop) and faer (decompositions in design).
//!
//! faer is built without its `rayon` feature, so every decomposition here runs on the calling
//! thread: trials already run in parallel and nested parallelism would only contend.

use faer::Mat;
use nalgebra::DMatrix;

/// Copies a nalgebra matrix into a faer matrix.
pub fn to_faer(m: &DMatrix<f64>) -> Mat<f64> {
    Mat::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// Copies a faer matrix into a nalgebra matrix.
pub fn from_faer(m: faer::MatRef<'_, f64>) -> DMatrix<f64> {
    DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// Numerical rank: singular values above `max(rows, cols) * eps * sigma_max` (the LAPACK/MATLAB rule,
/// so the ranks agree with the `rank()` the seed papers used).
/// `None` when the SVD does not converge, which only non-finite input causes.
pub fn rank(m: &DMatrix<f64>) -> Option<usize> {
    if m.is_empty() {
        return Some(0);
    }
    let sigma = to_faer(m).singular_values().ok()?;
    let sigma_max = sigma.first().copied().unwrap_or(0.0);
    let tol = m.nrows().max(m.ncols()) as f64 * f64::EPSILON * sigma_max;
    Some(sigma.iter().filter(|&&s| s > tol).count())
}

/// Moore-Penrose pseudo-inverse through faer's thin SVD.
pub fn pseudo_inverse(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let svd = to_faer(m).thin_svd().ok()?;
    Some(from_faer(svd.pseudoinverse().as_ref()))
}

/// Controllability matrix `[B, AB, ..., A^(n-1) B]`.
pub fn controllability_matrix(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let mut blocks = Vec::with_capacity(n);
    let mut block = b.clone();
    for _ in 0..n {
        let next = a * &block;
        blocks.push(block);
        block = next;
    }
    DMatrix::from_columns(&blocks.iter().flat_map(|m| m.column_iter().map(|c| c.into_owned())).collect::<Vec<_>>())
}

/// Observability matrix `[C; CA; ...; C A^(n-1)]`.
pub fn observability_matrix(a: &DMatrix<f64>, c: &DMatrix<f64>) -> DMatrix<f64> {
    controllability_matrix(&a.transpose(), &c.transpose()).transpose()
}
