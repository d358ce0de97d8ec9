//! Detection-filter gain design by eigenstructure assignment (method 000, `docs/findings-seed000.md`).
//!
//! Given `(A, C)`, fault directions `F = [f_1 .. f_r]` (n x r) and distinct eigenvalues `lambda_i`,
//! find `K` with `(A - K C) f_i = lambda_i f_i`. Then `K C F = A F - F Lambda`, and when `C F` has full
//! column rank the minimum-norm solution is
//!
//! ```text
//! K = (A F - F Lambda) (C F)^+
//! ```
//!
//! Any `K + Z` with `Z C F = 0` also assigns the same pairs; the minimum-norm one is what the seed's
//! printed gain matches (rows 1, 3, 4, 5, after its columns 4 and 5 are swapped back).
//! Assumptions: real, distinct eigenvalues; `(A, C)` observable; `rank(C F) = r`. With `r < n` the other
//! `n - r` closed-loop eigenvalues are whatever the minimum-norm gain leaves, so they are reported and
//! checked for stability, not chosen.
//!
//! The same kernel designs the continuous-time gain (eigenvalues `lambda`, stable when `Re < 0`) and the
//! discrete-time gain the simulated filter uses (on the ZOH `Ad`, eigenvalues `exp(lambda dt)`, stable
//! when `|z| < 1`): both give error dynamics with the same eigenvectors and the same time constants.
#![allow(non_snake_case)]

use faer::Mat;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use crate::linalg::{self, to_faer};

pub mod kalman;

/// Why a gain cannot be designed. Kept as data: a Monte Carlo trial with a failed design is a row.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    #[error(
        "the pair (A, C) is not observable: no output sees the mode(s) at {}; the observable subspace has \
         dimension {rank} of {states}",
        modes_text(.modes)
    )]
    Unobservable { rank: usize, states: usize, modes: Vec<Eigenvalue> },
    #[error("rank(C F) = {rank} but there are {directions} fault directions: their outputs cannot be told apart")]
    FaultDirectionsNotSeparable { rank: usize, directions: usize },
    #[error("eigenvalues {first} and {second} are not distinct: each fault direction needs its own eigenvalue")]
    RepeatedEigenvalues { first: f64, second: f64 },
    #[error("{what} did not converge (non-finite matrix entries?)")]
    Decomposition { what: &'static str },
    #[error("the assignment residual |(A - K C) F - F Lambda| / |A F| = {relative_residual:.3e} exceeds 1e-8")]
    AssignmentFailed { relative_residual: f64 },
    #[error("closed-loop eigenvalue {re:.6} {im:+.6}i is not stable ({domain})")]
    Unstable { re: f64, im: f64, domain: &'static str },
}

/// Whether the eigenvalues are of a continuous-time (`Re < 0` stable) or discrete-time (`|z| < 1`) system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Domain {
    Continuous,
    Discrete,
}

/// A closed-loop eigenvalue as a real pair (for JSON and tables).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Eigenvalue {
    pub re: f64,
    pub im: f64,
}

/// `-0.7` or `-1.2+0.5i`, both parts at the formatter's precision (`{:.6}`).
impl std::fmt::Display for Eigenvalue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = f.precision().unwrap_or(6);
        if self.im == 0.0 { write!(f, "{:.p$}", self.re) } else { write!(f, "{:.p$}{:+.p$}i", self.re, self.im) }
    }
}

/// A designed gain with the evidence that it does what was asked.
#[derive(Debug, Clone)]
pub struct Assignment {
    /// Observer gain (n x m).
    pub K: DMatrix<f64>,
    /// Eigenvalues of `A - K C`, from faer's non-symmetric eigensolver, sorted by real part, descending.
    pub closed_loop_eigenvalues: Vec<Eigenvalue>,
    /// 2-norm condition number of the eigenvector matrix of `A - K C` (large = eigenvalues sensitive to
    /// model error, the robustness question the Monte Carlo study answers empirically).
    pub eigenvector_condition: f64,
    /// `|(A - K C) F - F Lambda|_F / |A F|_F`: how exactly the pairs were assigned (NaN for a gain that
    /// assigns none, such as a Kalman filter's).
    pub relative_residual: f64,
}

/// Eigenvector condition number above which a design is warned about: a relative model error of 1e-6
/// can then move the closed-loop eigenvalues by their own size, so the assigned directions (what
/// isolation relies on) no longer hold on the true plant. A choice, not the seed's.
pub const EIGENVECTOR_CONDITION_WARNING: f64 = 1e6;

impl Assignment {
    /// Why this design's isolation directions may be meaningless, if they may.
    pub fn conditioning_warning(&self) -> Option<String> {
        (self.eigenvector_condition > EIGENVECTOR_CONDITION_WARNING).then(|| {
            format!(
                "eigenvector condition number {:.3e} exceeds {EIGENVECTOR_CONDITION_WARNING:.0e}: a relative model \
                 error of 1e-6 can move the closed-loop eigenvalues by their own size, so the assigned fault \
                 directions (and isolation by them) do not hold on the true plant; choose eigenvalues or \
                 directions that keep the eigenvectors apart",
                self.eigenvector_condition
            )
        })
    }
}

/// Assigns eigenvalue `lambda[i]` to direction `F[:, i]` (see the module docs).
///
/// Panics only on inconsistent dimensions (a programmer error: decks are validated before this).
#[track_caller]
pub fn assign_eigenstructure(
    A: &DMatrix<f64>,
    C: &DMatrix<f64>,
    F: &DMatrix<f64>,
    lambda: &[f64],
    domain: Domain,
) -> Result<Assignment, DesignError> {
    let n = A.nrows();
    let r = F.ncols();
    assert!(A.is_square() && C.ncols() == n && F.nrows() == n && lambda.len() == r, "dimension mismatch");

    unobservable_modes(A, C)?;
    let CF = C * F;
    let cf_rank = linalg::rank(&CF).ok_or(DesignError::Decomposition { what: "SVD of C F" })?;
    if cf_rank < r {
        return Err(DesignError::FaultDirectionsNotSeparable { rank: cf_rank, directions: r });
    }
    for i in 0..r {
        for j in i + 1..r {
            let scale = lambda[i].abs().max(lambda[j].abs()).max(1.0);
            if (lambda[i] - lambda[j]).abs() <= 1e-9 * scale {
                return Err(DesignError::RepeatedEigenvalues { first: lambda[i], second: lambda[j] });
            }
        }
    }

    let Lambda = DMatrix::from_diagonal(&DVector::from_column_slice(lambda));
    let AF = A * F;
    let target = &AF - F * &Lambda;
    let CF_pinv = linalg::pseudo_inverse(&CF).ok_or(DesignError::Decomposition { what: "SVD of C F" })?;
    let K = &target * CF_pinv;

    let closed = A - &K * C;
    let relative_residual = (&closed * F - F * &Lambda).norm() / AF.norm().max(f64::MIN_POSITIVE);
    if !(relative_residual <= 1e-8) {
        return Err(DesignError::AssignmentFailed { relative_residual });
    }

    let (closed_loop_eigenvalues, eigenvector_condition) = eigen_report(&closed)?;
    for ev in &closed_loop_eigenvalues {
        let stable = match domain {
            Domain::Continuous => ev.re < 0.0,
            Domain::Discrete => ev.re.hypot(ev.im) < 1.0,
        };
        if !stable {
            let domain = match domain {
                Domain::Continuous => "continuous time needs Re < 0",
                Domain::Discrete => "discrete time needs |z| < 1",
            };
            return Err(DesignError::Unstable { re: ev.re, im: ev.im, domain });
        }
    }
    Ok(Assignment { K, closed_loop_eigenvalues, eigenvector_condition, relative_residual })
}

/// Refuses a pair `(A, C)` with modes no output sees, naming them: the orthogonal staircase
/// (`linalg::observable`), sound at any size where the Kalman observability matrix is not.
pub fn unobservable_modes(A: &DMatrix<f64>, C: &DMatrix<f64>) -> Result<(), DesignError> {
    let failed = DesignError::Decomposition { what: "staircase reduction of (A, C)" };
    let stairs = linalg::observable(A, C).ok_or(failed.clone())?;
    if stairs.controllable == A.nrows() {
        return Ok(());
    }
    let modes = linalg::eigenvalues(&stairs.uncontrollable_block).ok_or(failed)?;
    Err(DesignError::Unobservable {
        rank: stairs.controllable,
        states: A.nrows(),
        modes: modes.into_iter().map(|(re, im)| Eigenvalue { re, im }).collect(),
    })
}

/// Eigenvalues as a message lists them: `-0.700000, -1.200000+0.500000i`.
fn modes_text(modes: &[Eigenvalue]) -> String {
    modes.iter().map(|e| format!("{e:.6}")).collect::<Vec<_>>().join(", ")
}

/// Eigenvalues (sorted by real part, descending) and the eigenvector matrix's condition number.
pub fn eigen_report(M: &DMatrix<f64>) -> Result<(Vec<Eigenvalue>, f64), DesignError> {
    let evd = to_faer(M).eigen().map_err(|_| DesignError::Decomposition { what: "eigendecomposition" })?;
    let mut eigenvalues: Vec<Eigenvalue> =
        evd.S().column_vector().iter().map(|z| Eigenvalue { re: z.re, im: z.im }).collect();
    eigenvalues.sort_by(|a, b| b.re.total_cmp(&a.re).then(b.im.total_cmp(&a.im)));
    // faer's eigenvectors are not normalised (one may be 1e7 long): unit columns, the usual definition,
    // so the number measures how close the directions are, not their lengths.
    let U = evd.U();
    let norms: Vec<f64> =
        (0..U.ncols()).map(|j| (0..U.nrows()).map(|i| U[(i, j)].norm_sqr()).sum::<f64>().sqrt()).collect();
    let V: Mat<faer::c64> = Mat::from_fn(U.nrows(), U.ncols(), |i, j| U[(i, j)] / norms[j]);
    let sigma = V.singular_values().map_err(|_| DesignError::Decomposition { what: "SVD of the eigenvectors" })?;
    let condition = match (sigma.first(), sigma.last()) {
        (Some(&hi), Some(&lo)) if lo > 0.0 => hi / lo,
        _ => f64::INFINITY,
    };
    Ok((eigenvalues, condition))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seed 000: longitudinal model at Mach 0.8, H = 50 m.
    fn seed000() -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
        #[rustfmt::skip]
        let A = DMatrix::from_row_slice(5, 5, &[
            0.0, 0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, -1.5122, 1.0, 0.0,
            0.0, -7.9101, -3.0241, 0.0, 0.0,
            0.0, 0.0, 1.0, 0.0, 0.0,
            0.0, -272.24, 0.0, 272.24, 0.0,
        ]);
        let B = DMatrix::from_row_slice(5, 2, &[0.0, 0.0, 0.0, -0.2779, 0.0, -26.3821, 0.0, 0.0, 0.0, 0.0]);
        #[rustfmt::skip]
        let C = DMatrix::from_row_slice(6, 5, &[
            1.0, 0.0, 0.0, 0.0, 0.0,
            0.0, 1.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 1.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0, 0.0,
            0.0, -1.0, 0.0, 1.0, 0.0,
            0.0, 0.0, 0.0, 0.0, 1.0,
        ]);
        (A, B, C)
    }

    /// The gain printed in seed 000, as printed (rounded to 4 decimals).
    #[rustfmt::skip]
    fn seed000_printed_k() -> DMatrix<f64> {
        DMatrix::from_row_slice(5, 6, &[
            1.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            0.0, 0.3252, 1.0, -0.1626, 0.1626, 0.0,
            0.0, -5.2734, -0.0241, 2.6367, -2.6367, 0.0,
            0.0, 1.3333, 1.0, 1.3333, 2.6667, 0.0,
            0.0, -90.7467, 0.0, 181.4933, 90.7467, 5.0,
        ])
    }

    #[test]
    fn seed000_ranks_are_4_and_5() {
        let (A, B, C) = seed000();
        assert_eq!(linalg::staircase(&A, &B).unwrap().controllable, 4);
        assert_eq!(linalg::observable(&A, &C).unwrap().controllable, 5);
        // The mode no input reaches: the first state's integrator (its row and column of A are zero).
        let stairs = linalg::staircase(&A, &B).unwrap();
        let modes = linalg::eigenvalues(&stairs.uncontrollable_block).unwrap();
        assert!(modes.len() == 1 && modes[0].0.abs() < 1e-12 && modes[0].1 == 0.0, "{modes:?}");
    }

    /// A random stable plant of `n` states: `A = Q (D + N) Q^T` with `Q` a random orthogonal matrix, `D`
    /// real eigenvalues log-uniform in [-50, -0.05] (slow phugoid-like modes to fast actuators) and `N`
    /// strictly upper triangular (non-normal, as aircraft models are), so its eigenvalues are those of `D`.
    fn random_stable(n: usize, seed: u64) -> (DMatrix<f64>, DMatrix<f64>, Vec<f64>) {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        let g = DMatrix::from_fn(n, n, |_, _| rng.random::<f64>() - 0.5);
        let q = g.qr().q();
        let eig: Vec<f64> = (0..n).map(|_| -0.05 * 1000f64.powf(rng.random::<f64>())).collect();
        let t = DMatrix::from_fn(n, n, |i, j| {
            if i == j {
                eig[i]
            } else if j > i {
                rng.random::<f64>() - 0.5
            } else {
                0.0
            }
        });
        (&q * t * q.transpose(), q, eig)
    }

    /// Issue 19: the Kalman observability matrix refused most random 20-state plants measured by C = I.
    #[test]
    fn random_stable_plants_with_all_states_measured_are_observable_up_to_100_states() {
        for n in [5, 12, 16, 20, 24, 50, 100] {
            for seed in 0..if n <= 24 { 20 } else { 3 } {
                let (A, _, _) = random_stable(n, seed);
                unobservable_modes(&A, &DMatrix::identity(n, n))
                    .unwrap_or_else(|e| panic!("{n} states, seed {seed}: {e}"));
            }
        }
        // One output (a random combination of the states) sees every mode of a generic plant as well.
        for seed in 0..5 {
            let (A, _, _) = random_stable(24, seed);
            let c = DMatrix::from_fn(1, 24, |_, j| 1.0 + 0.1 * j as f64);
            unobservable_modes(&A, &c).unwrap_or_else(|e| panic!("24 states, one output, seed {seed}: {e}"));
        }
    }

    /// Issue 19.2: with r < n (16 measured states of 50, `F = [I; 0]`) the minimum-norm gain assigns the
    /// 16 pairs and leaves the unmeasured block's eigenvalues: closed loop `[Lambda, A12; 0, A22]`, so its
    /// spectrum is `Lambda` and that of `A22`, computed here on `A22` alone. Well conditioned: no warning.
    #[test]
    fn fifty_states_with_sixteen_outputs_assign_lambda_and_keep_the_unmeasured_block() {
        use rand::{RngExt, SeedableRng};
        let (n, m) = (50, 16);
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(3);
        // Diagonally dominant (Gershgorin): every principal block is stable.
        let d: Vec<f64> = (0..n).map(|_| 0.5 * 100f64.powf(rng.random::<f64>())).collect();
        let A = DMatrix::from_fn(n, n, |i, j| {
            if i == j { -d[i] } else { 0.9 * d[i] / (n - 1) as f64 * (2.0 * rng.random::<f64>() - 1.0) }
        });
        let C = DMatrix::from_fn(m, n, |i, j| if i == j { 1.0 } else { 0.0 });
        let F = C.transpose();
        let lambda: Vec<f64> = (1..=m).map(|i| -(i as f64)).collect();
        let a = assign_eigenstructure(&A, &C, &F, &lambda, Domain::Continuous).unwrap();
        assert!(a.relative_residual < 1e-12, "{}", a.relative_residual);
        let mut want: Vec<(f64, f64)> = lambda.iter().map(|&l| (l, 0.0)).collect();
        want.extend(linalg::eigenvalues(&A.view((m, m), (n - m, n - m)).into_owned()).unwrap());
        want.sort_by(|x, y| y.0.total_cmp(&x.0).then(y.1.total_cmp(&x.1)));
        assert_eq!(a.closed_loop_eigenvalues.len(), n);
        for (got, w) in a.closed_loop_eigenvalues.iter().zip(&want) {
            assert!(
                (got.re - w.0).abs() < 1e-8 * w.0.abs().max(1.0) && (got.im - w.1).abs() < 1e-8,
                "{got:?} vs {w:?}"
            );
        }
        assert!(
            a.eigenvector_condition.is_finite() && a.conditioning_warning().is_none(),
            "{}",
            a.eigenvector_condition
        );
    }

    /// With `C = I` the closed loop is `F Lambda F^-1`: its eigenvector matrix is `F`, whose condition
    /// number (about 2e7 for directions 1e-7 apart) the design reports and warns about.
    #[test]
    fn nearly_parallel_directions_are_warned_about() {
        let A = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let F = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1e-7]);
        let a = assign_eigenstructure(&A, &DMatrix::identity(2, 2), &F, &[-1.0, -2.0], Domain::Continuous).unwrap();
        let cond_f = {
            let s = F.clone().svd(false, false).singular_values;
            s.max() / s.min()
        };
        assert!((a.eigenvector_condition / cond_f - 1.0).abs() < 1e-3, "{} vs {cond_f}", a.eigenvector_condition);
        assert!(a.conditioning_warning().unwrap().contains("exceeds 1e6"));
    }

    /// A plant with one mode hidden from the outputs (`C` orthogonal to its eigenvector's direction in the
    /// Schur basis) is refused with that mode named, at 5 and at 50 states.
    #[test]
    fn an_unobservable_mode_is_named_at_5_and_50_states() {
        for n in [5, 50] {
            let (_, q, eig) = random_stable(n, 7);
            // Block-triangular in the basis q: the last Schur vector's mode -0.7 feeds nothing the
            // outputs see (row n-1 of the Schur form holds only its eigenvalue; C reads the others).
            let mut t = DMatrix::from_fn(n, n, |i, j| {
                if i == j {
                    eig[i]
                } else if j > i {
                    0.3
                } else {
                    0.0
                }
            });
            t[(n - 1, n - 1)] = -0.7;
            for i in 0..n - 1 {
                t[(i, n - 1)] = 0.0;
            }
            let A = &q * t * q.transpose();
            let C = DMatrix::from_fn(n - 1, n, |i, j| q[(j, i)]);
            let e = unobservable_modes(&A, &C).unwrap_err();
            let DesignError::Unobservable { rank, states, modes } = &e else { panic!("{e:?}") };
            assert_eq!((*rank, *states), (n - 1, n));
            assert_eq!(modes.len(), 1, "{modes:?}");
            assert!((modes[0].re + 0.7).abs() < 1e-9 && modes[0].im == 0.0, "{modes:?}");
            assert!(e.to_string().contains("no output sees the mode(s) at -0.700000"), "{e}");
        }
    }

    #[test]
    fn seed000_design_places_minus_one_to_minus_five_on_a_diagonal() {
        let (A, _, C) = seed000();
        let lambda = [-1.0, -2.0, -3.0, -4.0, -5.0];
        let d = assign_eigenstructure(&A, &C, &DMatrix::identity(5, 5), &lambda, Domain::Continuous).unwrap();
        let want = [-1.0, -2.0, -3.0, -4.0, -5.0];
        for (ev, w) in d.closed_loop_eigenvalues.iter().zip(want) {
            assert!((ev.re - w).abs() < 1e-9 && ev.im.abs() < 1e-9, "{ev:?} vs {w}");
        }
        let closed = &A - &d.K * &C;
        let diag = DMatrix::from_diagonal(&DVector::from_column_slice(&lambda));
        assert!((&closed - &diag).amax() < 1e-12, "A - K C is not diag(-1..-5):\n{closed}");
        // Eigenvectors are the unit vectors: perfectly conditioned.
        assert!((d.eigenvector_condition - 1.0).abs() < 1e-9);
        // Minimum-norm values the seed's rows 3 and 5 print.
        assert!((d.K[(2, 1)] - -5.2734).abs() < 5e-5 && (d.K[(4, 4)] - 181.4933).abs() < 5e-5);
    }

    #[test]
    fn seed000_printed_gain_is_inconsistent_and_columns_4_5_are_swapped() {
        let (A, _, C) = seed000();
        let lambda = [-1.0, -2.0, -3.0, -4.0, -5.0];
        let printed = seed000_printed_k();

        // As printed, the closed loop is not diag(-1..-5): it even has an unstable eigenvalue. Reference:
        // numpy.linalg.eigvals(A - K C) of these matrices (LAPACK dgeev): 2.466879353141456, -1,
        // -3.882007220087202, -5, -5.747472133054259.
        let (ev, _) = eigen_report(&(&A - &printed * &C)).unwrap();
        let mut re: Vec<f64> = ev.iter().map(|e| e.re).collect();
        re.sort_by(|a, b| b.total_cmp(a));
        for (got, want) in re.iter().zip([2.466879353141456, -1.0, -3.882007220087202, -5.0, -5.747472133054259]) {
            assert!((got - want).abs() < 1e-9, "{re:?}");
        }
        assert!(ev.iter().all(|e| e.im.abs() < 1e-9), "{ev:?}");

        let ours = assign_eigenstructure(&A, &C, &DMatrix::identity(5, 5), &lambda, Domain::Continuous).unwrap().K;
        let mut swapped = printed.clone();
        swapped.swap_columns(3, 4);
        for row in [0, 2, 3, 4] {
            let diff = (swapped.row(row) - ours.row(row)).amax();
            assert!(diff < 1e-4, "row {} differs by {diff}", row + 1);
        }
        // Row 2 fails the design equation even after the swap: (A - K C) e_2 != -2 e_2.
        let closed_row2 = A.row(1) - swapped.row(1) * &C;
        assert!((closed_row2[(0, 1)] - -2.0).abs() > 1.0, "row 2 unexpectedly consistent: {closed_row2}");
        assert!((swapped.row(1) - ours.row(1)).amax() > 1.0);
    }

    #[test]
    fn discrete_design_places_exp_lambda_dt() {
        let (A, B, C) = seed000();
        let plant = crate::lti::LtiPlant {
            state_names: vec![String::new(); 5],
            input_names: vec![String::new(); 2],
            output_names: vec![String::new(); 6],
            D: DMatrix::zeros(6, 2),
            A,
            B,
            C,
        };
        let dt = 0.01;
        let d = plant.discretise(dt);
        let lambda: Vec<f64> = [-1.0f64, -2.0, -3.0, -4.0, -5.0].iter().map(|l| (l * dt).exp()).collect();
        let a = assign_eigenstructure(&d.Ad, &d.C, &DMatrix::identity(5, 5), &lambda, Domain::Discrete).unwrap();
        for (ev, l) in a.closed_loop_eigenvalues.iter().zip(&lambda) {
            assert!((ev.re - l).abs() < 1e-12, "{ev:?} vs {l}");
        }
    }

    #[test]
    fn infeasible_designs_are_errors_with_reasons() {
        let (A, _, C) = seed000();
        let lambda = [-1.0, -2.0, -3.0, -4.0, -5.0];
        let I = DMatrix::identity(5, 5);
        // Repeated eigenvalues.
        let e = assign_eigenstructure(&A, &C, &I, &[-1.0, -2.0, -2.0, -4.0, -5.0], Domain::Continuous);
        assert!(matches!(e, Err(DesignError::RepeatedEigenvalues { first: -2.0, second: -2.0 })));
        // Altitude not measured and nothing feeds it back: unobservable.
        let C_no_h = C.columns(0, 4).into_owned().insert_column(4, 0.0);
        let e = assign_eigenstructure(&A, &C_no_h, &I, &lambda, Domain::Continuous);
        let Err(DesignError::Unobservable { rank: 4, states: 5, modes }) = &e else { panic!("{e:?}") };
        assert_eq!(modes.len(), 1, "{modes:?}");
        assert!(modes[0].re.abs() < 1e-12 && modes[0].im == 0.0, "altitude's integrator: {modes:?}");
        assert!(e.unwrap_err().to_string().contains("no output sees the mode(s) at 0.000000"));
        // Two fault directions that look the same at the outputs.
        let F = DMatrix::from_row_slice(5, 2, &[1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let e = assign_eigenstructure(&A, &C, &F, &[-1.0, -2.0], Domain::Continuous);
        assert!(matches!(e, Err(DesignError::FaultDirectionsNotSeparable { rank: 1, directions: 2 })));
        // Eigenvalues assigned in the right half plane are assigned exactly, and refused as unstable.
        let e = assign_eigenstructure(&A, &C, &I, &[1.0, -2.0, -3.0, -4.0, -5.0], Domain::Continuous);
        assert!(matches!(e, Err(DesignError::Unstable { .. })), "{e:?}");
    }
}
