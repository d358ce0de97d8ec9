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

/// `y = alpha A x + beta y` for a column-major `A`, with exactly nalgebra's `gemv` operations in its
/// order (`(alpha a_ij) x_j + 1 y_i`, column by column; `y` not read when `beta == 0`), so results are
/// bit-identical to it, without its per-call overhead on the small matrices of the per-step loop.
#[inline]
pub fn gemv(y: &mut [f64], alpha: f64, a: &DMatrix<f64>, x: &[f64], beta: f64) {
    let rows = y.len();
    debug_assert!(a.nrows() == rows && a.ncols() == x.len(), "gemv: dimension mismatch");
    let a = a.as_slice();
    if x.is_empty() {
        for yi in y.iter_mut() {
            *yi = if beta == 0.0 { 0.0 } else { *yi * beta };
        }
        return;
    }
    let (first, rest) = a.split_at(rows);
    let x0 = x[0];
    if beta == 0.0 {
        for (yi, aij) in y.iter_mut().zip(first) {
            *yi = alpha * aij * x0;
        }
    } else {
        for (yi, aij) in y.iter_mut().zip(first) {
            *yi = alpha * aij * x0 + beta * *yi;
        }
    }
    for (col, &xj) in rest.chunks_exact(rows).zip(&x[1..]) {
        for (yi, aij) in y.iter_mut().zip(col) {
            *yi = alpha * aij * xj + 1.0 * *yi;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    #[test]
    fn gemv_is_bit_identical_to_nalgebra() {
        let a = DMatrix::from_fn(6, 5, |i, j| ((i * 7 + j * 3) as f64).sin() * 10f64.powi(j as i32 - 2));
        let x = DVector::from_fn(5, |i, _| ((i + 1) as f64).cos() * 1e-3 + 0.1);
        for (alpha, beta) in [(1.0, 0.0), (-1.0, 1.0), (1.0, 1.0), (0.3, -2.5)] {
            let mut want = DVector::from_fn(6, |i, _| (i as f64 - 2.5) * 0.37);
            let mut got = want.clone();
            want.gemv(alpha, &a, &x, beta);
            gemv(got.as_mut_slice(), alpha, &a, x.as_slice(), beta);
            assert_eq!(
                got.as_slice().iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                want.as_slice().iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
        }
    }
}
