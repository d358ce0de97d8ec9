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

/// The principal matrix logarithm by inverse scaling and squaring: square roots until `|m - I|_F <=
/// 0.1`, then the series `log(I + E) = E - E^2/2 + E^3/3 - ...`, times `2^roots`. `None` when a square
/// root does not converge (an eigenvalue on the closed negative real axis has no real logarithm).
pub fn logm(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let identity = DMatrix::<f64>::identity(m.nrows(), m.ncols());
    let (mut x, mut roots) = (m.clone(), 0);
    while (&x - &identity).norm() > 0.1 {
        if roots == 60 {
            return None;
        }
        x = sqrtm(&x)?;
        roots += 1;
    }
    let e = &x - &identity;
    let (mut power, mut log) = (e.clone(), e.clone());
    for k in 2..=60 {
        power = &power * &e;
        let term = &power * (if k % 2 == 0 { -1.0 } else { 1.0 } / k as f64);
        log += &term;
        if term.norm() <= f64::EPSILON * log.norm() {
            break;
        }
    }
    Some(log * 2f64.powi(roots))
}

/// The principal square root by the Denman-Beavers iteration (`Y -> sqrt(A)`, `Z -> sqrt(A)^-1`).
fn sqrtm(a: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let (mut y, mut z) = (a.clone(), DMatrix::<f64>::identity(a.nrows(), a.ncols()));
    for _ in 0..100 {
        let (y_inv, z_inv) = (y.clone().try_inverse()?, z.clone().try_inverse()?);
        let y_next = (&y + &z_inv) * 0.5;
        z = (&z + &y_inv) * 0.5;
        let change = (&y_next - &y).norm();
        y = y_next;
        if !change.is_finite() {
            return None;
        }
        if change <= 1e-14 * y.norm() {
            return Some(y);
        }
    }
    None
}

/// Moore-Penrose pseudo-inverse through faer's thin SVD.
pub fn pseudo_inverse(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let svd = to_faer(m).thin_svd().ok()?;
    Some(from_faer(svd.pseudoinverse().as_ref()))
}

/// What an orthogonal staircase reduction finds of a pair `(A, B)`: the dimension of the controllable
/// subspace and the block of `A` acting on the rest, whose eigenvalues are the modes `B` cannot reach.
#[derive(Debug, Clone)]
pub struct Staircase {
    pub controllable: usize,
    /// `A` on the uncontrollable subspace (0 x 0 when the pair is controllable), in an orthonormal basis.
    pub uncontrollable_block: DMatrix<f64>,
}

/// Relative size below which a coupling counts as none in [`staircase`] (a choice): about 10^5 times the
/// rounding of the orthogonal transforms at 100 states (n eps ~ 2e-14), so rounding never counts as a
/// coupling, and small enough that no mode of the tested plants (eigenvalues -0.05 to -50 1/s) is lost.
pub const STAIRCASE_TOLERANCE: f64 = 1e-9;

/// The controllable subspace of `(A, B)` by the orthogonal staircase (Hessenberg) reduction: the SVD of
/// the input block splits off the directions it reaches, the rest of `A` restricted to the others
/// couples them on, and so on until nothing couples. Orthogonal steps keep rounding at `n eps |A|`,
/// where the Kalman matrix `[B, AB, ..]` grows like `|A|^(n-1)` and drowns small singular values from
/// about 14 states on. A coupling counts when a singular value exceeds [`STAIRCASE_TOLERANCE`] times
/// `|[A, B]|_F`. `None` when an SVD fails (non-finite input).
pub fn staircase(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Option<Staircase> {
    let tol = STAIRCASE_TOLERANCE * (a.norm_squared() + b.norm_squared()).sqrt();
    let (mut rest, mut input) = (a.clone(), b.clone());
    let mut controllable = 0;
    while rest.nrows() > 0 && input.ncols() > 0 {
        let svd = to_faer(&input).svd().ok()?;
        let reached = svd.S().column_vector().iter().filter(|&&s| s > tol).count();
        if reached == 0 {
            break;
        }
        controllable += reached;
        let u = from_faer(svd.U());
        let turned = u.transpose() * &rest * &u;
        let left = rest.nrows() - reached;
        input = turned.view((reached, 0), (left, reached)).into_owned();
        rest = turned.view((reached, reached), (left, left)).into_owned();
    }
    Some(Staircase { controllable, uncontrollable_block: rest })
}

/// The observable subspace of `(A, C)`: the staircase of the dual pair `(A', C')`, whose remaining block's
/// eigenvalues are those of `A`'s unobservable part.
pub fn observable(a: &DMatrix<f64>, c: &DMatrix<f64>) -> Option<Staircase> {
    staircase(&a.transpose(), &c.transpose())
}

/// The eigenvalues of `m` as (re, im), sorted by real part, descending; `None` if the solver fails.
pub fn eigenvalues(m: &DMatrix<f64>) -> Option<Vec<(f64, f64)>> {
    if m.is_empty() {
        return Some(Vec::new());
    }
    let mut ev: Vec<(f64, f64)> = to_faer(m).eigenvalues().ok()?.iter().map(|z| (z.re, z.im)).collect();
    ev.sort_by(|x, y| y.0.total_cmp(&x.0).then(y.1.total_cmp(&x.1)));
    Some(ev)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_logarithm_of_an_exponential_is_the_matrix_back() {
        // An oscillatory pair (-0.35 +/- 1.4i per unit), a slow real mode and an integrator, scaled so
        // that exp(M) is far from I (square roots needed) but inside the principal branch.
        let m = DMatrix::from_row_slice(
            4,
            4,
            &[-0.35, 1.4, 0.0, 0.0, -1.4, -0.35, 0.0, 0.0, 0.3, 0.0, -0.05, 0.0, 0.0, 1.0, 2.0, 0.0],
        ) * 1.5;
        let log = logm(&m.clone().exp()).expect("a real logarithm");
        assert!((&log - &m).amax() < 1e-12, "{log} against {m}");
        // -1 has no real logarithm.
        assert!(logm(&DMatrix::from_row_slice(1, 1, &[-1.0])).is_none());
    }
}
