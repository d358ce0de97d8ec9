//! Unscented Kalman filter with the scaled unscented transform: a building block for the detectors
//! (method 002, `docs/findings-seed002.md`, the dual-model air-data detector, and any other detector whose model
//! implements [`DiscreteModel`]).
//!
//! Model, discrete time: `x(k+1) = f(x(k), u(k)) + w(k)`, `y(k) = h(x(k)) + v(k)`, `cov w = Q`,
//! `cov v = R`, both additive. `Q` may change from step to step ([`Ukf::set_process_noise`]): a detector
//! whose process noise comes from noisy inputs maps the input noise into `Q` at the current state.
//!
//! # Sigma points (scaled unscented transform)
//! ```text
//! lambda = alpha^2 (N + kappa) - N,        c = sqrt(N + lambda) = alpha sqrt(N + kappa)
//! X_0 = x,   X_i = x + c L_i,   X_(N+i) = x - c L_i      (L L' = P by Cholesky, L_i its column i)
//! Wm_0 = lambda / (N + lambda),   Wc_0 = Wm_0 + 1 - alpha^2 + beta,   Wm_i = Wc_i = 1 / (2 (N + lambda))
//! ```
//! (Julier, "The scaled unscented transformation", ACC 2002; weights as in Wan & van der Merwe, "The
//! unscented Kalman filter for nonlinear estimation", AS-SPCC 2000.) The mean weights sum to 1 and the
//! points reproduce the mean and covariance exactly, so on a linear model the filter *is* the Kalman
//! filter (tested).
//!
//! Defaults ([`UnscentedParams::seed`]): `alpha = 1`, `beta = 2`, `kappa = 0`. Why:
//! - `alpha = 1, kappa = 0` gives `lambda = 0`: the points sit at `sqrt(N)` standard deviations (2.4 for
//!   N = 6), `Wm_0 = 0` and every covariance weight is non-negative (`Wc_0 = 2`), so a predicted
//!   covariance is a sum of positive semi-definite terms plus `Q`. The often-quoted `alpha = 1e-3` makes
//!   `Wm_0 ~ -1e6` for N = 6: the covariance is then a difference of numbers a million times larger than
//!   itself and loses positive definiteness to rounding.
//! - `beta = 2` is the optimal value for a Gaussian prior (it adds the fourth-moment term to `Wc_0`).
//! - `kappa = 3 - N` (the other classic choice) is negative for N > 3 and makes `Wm_0` negative.
//!
//! # One cycle
//! The patent's order (seed 002, steps 4.1-4.6): time update, then *new* sigma points for the
//! measurement update. [`Ukf::step`] takes `y(k)` and `u(k)` as [`crate::estimation::Stekf::step`] does:
//! ```text
//! update (sigma points of x(k|k-1), P(k|k-1)):  Y_i = h(X_i),  y^ = sum Wm_i Y_i,  gamma = y - y^
//!     S = sum Wc_i (Y_i - y^)(Y_i - y^)' + R,   Pxy = sum Wc_i (X_i - x)(Y_i - y^)'
//!     K = Pxy S^-1,   x(k|k) = x + K gamma,   P(k|k) = P - K S K'
//! predict (sigma points of x(k|k), P(k|k)):  X_i' = f(X_i, u),  x(k+1|k) = sum Wm_i X_i'
//!     P(k+1|k) = sum Wc_i (X_i' - x(k+1|k))(X_i' - x(k+1|k))' + Q
//! ```
//! [`Ukf::update`] and [`Ukf::predict`] are also public, so a detector can act between them (the
//! dual-model detector re-initialises its filters there). The filter holds one estimate `(x, P)`: after
//! an update it is `x(k|k)`, after a prediction `x(k+1|k)`.
//!
//! # Numerical health (counted in [`UkfHealth`], never a panic)
//! - `P` is symmetrised, `(P + P') / 2`, after every update and prediction (rounding only).
//! - Before sigma points are drawn `P` must have a Cholesky factor. If it has none, `P` is repaired by
//!   adding `2 delta I`, with `delta` the first jitter that gives a factor: starting at `1e-12` times the
//!   largest diagonal entry and growing tenfold, capped by the Gershgorin bound (which makes the matrix
//!   strictly diagonally dominant, hence positive definite). Doubling keeps the smallest eigenvalue at
//!   least `delta` instead of a rounding error above zero, and the change is at most 20 times the most
//!   negative eigenvalue. The repaired `P` replaces the filter's (so the estimate and the covariance its
//!   sigma points came from agree) and `covariance_repairs` counts it.
//! - `S` is factored by Cholesky (it is `Pyy + R`, symmetric); if that fails the update is skipped,
//!   `singular_innovation` counts it and the returned [`Innovation`] has no inverse (likelihood zero in
//!   [`crate::estimation::bank`]).
//! - A non-finite measurement, transformed point, estimate or covariance skips the step (the previous
//!   estimate is kept) and `non_finite` counts it.
#![allow(non_snake_case)]

use nalgebra::{SMatrix, SVector};
use thiserror::Error;

use crate::estimation::stekf::{DiscreteModel, FilterHealth, Innovation};

/// Parameters of the scaled unscented transform; see the module docs for the defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnscentedParams {
    /// Spread of the points around the mean (`0 < alpha <= 1` usually).
    pub alpha: f64,
    /// Prior-distribution term of the centre covariance weight (2 for a Gaussian).
    pub beta: f64,
    /// Secondary scaling; `N + kappa` must be positive.
    pub kappa: f64,
}

impl UnscentedParams {
    /// `alpha = 1`, `beta = 2`, `kappa = 0` (module docs: non-negative covariance weights).
    pub fn seed() -> Self {
        UnscentedParams { alpha: 1.0, beta: 2.0, kappa: 0.0 }
    }

    /// The weights for an `n`-dimensional state; `Err` when `alpha^2 (n + kappa)` is not positive and
    /// finite (the points would collapse or be imaginary).
    pub fn weights(&self, n: usize) -> Result<SigmaWeights, UkfError> {
        let scale = self.alpha * self.alpha * (n as f64 + self.kappa);
        if !(scale > 0.0 && scale.is_finite() && self.beta.is_finite()) {
            return Err(UkfError::InvalidSpread { alpha: self.alpha, beta: self.beta, kappa: self.kappa, n });
        }
        let lambda = scale - n as f64;
        let mean_center = lambda / scale;
        Ok(SigmaWeights {
            spread: scale.sqrt(),
            mean_center,
            covariance_center: mean_center + 1.0 - self.alpha * self.alpha + self.beta,
            other: 1.0 / (2.0 * scale),
        })
    }
}

impl Default for UnscentedParams {
    fn default() -> Self {
        Self::seed()
    }
}

/// Weights and spread of the `2N + 1` sigma points (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SigmaWeights {
    /// `c = sqrt(N + lambda)`: the points are `x +- c L_i`.
    pub spread: f64,
    /// `Wm_0`.
    pub mean_center: f64,
    /// `Wc_0`.
    pub covariance_center: f64,
    /// `Wm_i = Wc_i`, `i = 1..2N`.
    pub other: f64,
}

/// Why a filter cannot be built.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum UkfError {
    #[error(
        "unscented parameters alpha = {alpha}, beta = {beta}, kappa = {kappa} give no valid spread for {n} \
             states: alpha^2 (n + kappa) must be positive and finite"
    )]
    InvalidSpread { alpha: f64, beta: f64, kappa: f64, n: usize },
}

/// `2N + 1` points of dimension `D` drawn for (or mapped from) an `N`-dimensional state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SigmaPoints<const N: usize, const D: usize> {
    pub center: SVector<f64, D>,
    /// `x + c L_i` (mapped), `i = 0..N`.
    pub plus: [SVector<f64, D>; N],
    /// `x - c L_i` (mapped).
    pub minus: [SVector<f64, D>; N],
}

impl<const N: usize> SigmaPoints<N, N> {
    /// The points of `x` and the lower Cholesky factor `L` of its covariance.
    pub fn new(x: &SVector<f64, N>, L: &SMatrix<f64, N, N>, weights: &SigmaWeights) -> Self {
        let offset = |i: usize| L.column(i) * weights.spread;
        SigmaPoints {
            center: *x,
            plus: std::array::from_fn(|i| x + offset(i)),
            minus: std::array::from_fn(|i| x - offset(i)),
        }
    }
}

impl<const N: usize, const D: usize> SigmaPoints<N, D> {
    /// Every point through `g`.
    #[inline]
    pub fn map<const E: usize>(&self, g: impl Fn(&SVector<f64, D>) -> SVector<f64, E>) -> SigmaPoints<N, E> {
        SigmaPoints {
            center: g(&self.center),
            plus: std::array::from_fn(|i| g(&self.plus[i])),
            minus: std::array::from_fn(|i| g(&self.minus[i])),
        }
    }

    /// `sum Wm_i X_i`.
    pub fn mean(&self, w: &SigmaWeights) -> SVector<f64, D> {
        let others: SVector<f64, D> = self.plus.iter().chain(&self.minus).sum();
        self.center * w.mean_center + others * w.other
    }

    #[inline]
    fn all_finite(&self) -> bool {
        self.center.iter().chain(self.plus.iter().flatten()).chain(self.minus.iter().flatten()).all(|v| v.is_finite())
    }
}

/// Numerical-health counters of one filter over a run (see the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UkfHealth {
    /// Times `P` had no Cholesky factor and was repaired before drawing sigma points.
    pub covariance_repairs: u32,
    /// Updates skipped because `S` had no Cholesky factor.
    pub singular_innovation: u32,
    /// Updates or predictions skipped because something was not finite.
    pub non_finite: u32,
}

impl UkfHealth {
    /// Sum of two filters' counters.
    pub fn plus(self, other: UkfHealth) -> UkfHealth {
        UkfHealth {
            covariance_repairs: self.covariance_repairs + other.covariance_repairs,
            singular_innovation: self.singular_innovation + other.singular_innovation,
            non_finite: self.non_finite + other.non_finite,
        }
    }
}

/// The EKF's counter set, for tables that already have its columns: a repair is a covariance that was
/// not positive definite; the UKF's covariance is never asymmetric (it is symmetrised every step).
impl From<UkfHealth> for FilterHealth {
    fn from(h: UkfHealth) -> FilterHealth {
        FilterHealth {
            singular_innovation: h.singular_innovation,
            asymmetric: 0,
            not_positive_definite: h.covariance_repairs,
            non_finite: h.non_finite,
        }
    }
}

/// Lower Cholesky factor of the symmetric part of `P`, repairing it when it has none (module docs).
/// Returns `(L, L L', repaired)`, or `None` when `P` is not finite.
pub fn cholesky_repaired<const N: usize>(
    P: &SMatrix<f64, N, N>,
) -> Option<(SMatrix<f64, N, N>, SMatrix<f64, N, N>, bool)> {
    if !P.iter().all(|v| v.is_finite()) {
        return None;
    }
    let sym = (P + P.transpose()) * 0.5;
    if let Some(chol) = sym.cholesky() {
        return Some((chol.l(), sym, false));
    }
    // The smallest jitter that works, within a factor 10; the Gershgorin bound is certain to work.
    let scale = sym.diagonal().amax().max(f64::MIN_POSITIVE);
    let gershgorin = (0..N)
        .map(|i| (0..N).filter(|&j| j != i).map(|j| sym[(i, j)].abs()).sum::<f64>() - sym[(i, i)])
        .fold(0.0f64, f64::max)
        + REPAIR_START_RELATIVE * scale;
    let mut delta = REPAIR_START_RELATIVE * scale;
    while delta.is_finite() {
        if (sym + SMatrix::<f64, N, N>::identity() * delta).cholesky().is_some() {
            // Twice the first jitter that works: the smallest eigenvalue is then at least `delta`, not a
            // rounding error away from zero.
            let repaired = sym + SMatrix::<f64, N, N>::identity() * (REPAIR_MARGIN * delta);
            if let Some(chol) = repaired.cholesky() {
                return Some((chol.l(), repaired, true));
            }
        }
        // Up to the Gershgorin bound exactly; past it only if rounding defeats it.
        delta = if delta < gershgorin { (delta * REPAIR_GROWTH).min(gershgorin) } else { delta * REPAIR_GROWTH };
    }
    None
}

/// First jitter of a repair, relative to the largest diagonal entry.
const REPAIR_START_RELATIVE: f64 = 1e-12;
/// Growth of the jitter between attempts.
const REPAIR_GROWTH: f64 = 10.0;
/// The jitter applied is this times the first that gives a Cholesky factor.
const REPAIR_MARGIN: f64 = 2.0;

/// An unscented Kalman filter; see the module docs.
#[derive(Debug, Clone)]
pub struct Ukf<const N: usize, const M: usize> {
    x: SVector<f64, N>,
    P: SMatrix<f64, N, N>,
    Q: SMatrix<f64, N, N>,
    R: SMatrix<f64, M, M>,
    weights: SigmaWeights,
    health: UkfHealth,
}

impl<const N: usize, const M: usize> Ukf<N, M> {
    /// A filter at the prior `x(0|-1) = x0`, `P(0|-1) = P0`.
    pub fn new(
        x0: SVector<f64, N>,
        P0: SMatrix<f64, N, N>,
        Q: SMatrix<f64, N, N>,
        R: SMatrix<f64, M, M>,
        params: &UnscentedParams,
    ) -> Result<Self, UkfError> {
        let weights = params.weights(N)?;
        Ok(Ukf { x: x0, P: (P0 + P0.transpose()) * 0.5, Q, R, weights, health: UkfHealth::default() })
    }

    /// The current estimate: `x(k|k)` after an update, `x(k+1|k)` after a prediction.
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// The covariance of [`state`](Self::state).
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.P
    }

    pub fn weights(&self) -> &SigmaWeights {
        &self.weights
    }

    pub fn health(&self) -> UkfHealth {
        self.health
    }

    pub fn process_noise(&self) -> &SMatrix<f64, N, N> {
        &self.Q
    }

    pub fn measurement_noise(&self) -> &SMatrix<f64, M, M> {
        &self.R
    }

    /// `Q` for the following predictions.
    pub fn set_process_noise(&mut self, Q: SMatrix<f64, N, N>) {
        self.Q = Q;
    }

    /// `R` for the following updates.
    pub fn set_measurement_noise(&mut self, R: SMatrix<f64, M, M>) {
        self.R = R;
    }

    /// Replaces the estimate and its covariance (symmetrised); the health counters are kept.
    pub fn reinitialise(&mut self, x: SVector<f64, N>, P: SMatrix<f64, N, N>) {
        self.x = x;
        self.P = (P + P.transpose()) * 0.5;
    }

    /// Sigma points of the current estimate, repairing `P` if needed; `None` when not finite.
    // The `#[inline]`s on the steps and their sigma-point helpers: whether the compiler inlined them
    // into the caller came and went with unrelated changes, and when it did not, the sigma points were
    // copied as return values (`memmove` 7.5 % of method 002's profile, its trials 11 % slower).
    #[inline]
    fn sigma_points(&mut self) -> Option<SigmaPoints<N, N>> {
        if !self.x.iter().all(|v| v.is_finite()) {
            return None;
        }
        let (L, P, repaired) = cholesky_repaired(&self.P)?;
        if repaired {
            self.health.covariance_repairs += 1;
            self.P = P;
        }
        Some(SigmaPoints::new(&self.x, &L, &self.weights))
    }

    /// Measurement update with `y`; returns the innovation `gamma = y - y^` and `S`.
    #[inline]
    pub fn update<D: SigmaModel<N, M>>(&mut self, model: &D, y: &SVector<f64, M>) -> Innovation<M> {
        let skipped = |gamma: SVector<f64, M>, S: SMatrix<f64, M, M>| Innovation {
            gamma,
            S,
            S_inverse: None,
            S_determinant: None,
        };
        let Some(X) = self.sigma_points() else {
            self.health.non_finite += 1;
            return skipped(SVector::repeat(f64::NAN), SMatrix::repeat(f64::NAN));
        };
        let Y = model.measurement_points(&X);
        let y_hat = Y.mean(&self.weights);
        let gamma = y - y_hat;
        let S = weighted_covariance(&Y, &y_hat, &Y, &y_hat, &self.weights) + self.R;
        if !(Y.all_finite() && gamma.iter().all(|v| v.is_finite()) && S.iter().all(|v| v.is_finite())) {
            self.health.non_finite += 1;
            return skipped(gamma, S);
        }
        let S_sym = (S + S.transpose()) * 0.5;
        let Some(chol) = S_sym.cholesky() else {
            self.health.singular_innovation += 1;
            return skipped(gamma, S);
        };
        let S_inverse = chol.inverse();
        let Pxy = weighted_covariance(&X, &self.x, &Y, &y_hat, &self.weights);
        let K = Pxy * S_inverse;
        let x = self.x + K * gamma;
        let P = self.P - K * S_sym * K.transpose();
        if x.iter().chain(P.iter()).all(|v| v.is_finite()) {
            self.x = x;
            self.P = (P + P.transpose()) * 0.5;
        } else {
            self.health.non_finite += 1;
        }
        Innovation { gamma, S: S_sym, S_inverse: Some(S_inverse), S_determinant: None }
    }

    /// Time update with the input `u` and the current `Q`.
    #[inline]
    pub fn predict<D: SigmaModel<N, M>>(&mut self, model: &D, u: &D::Input) {
        let Some(X) = self.sigma_points() else {
            self.health.non_finite += 1;
            return;
        };
        let F = model.transition_points(&X, u);
        let x = F.mean(&self.weights);
        let P = weighted_covariance(&F, &x, &F, &x, &self.weights) + self.Q;
        if F.all_finite() && x.iter().chain(P.iter()).all(|v| v.is_finite()) {
            self.x = x;
            self.P = (P + P.transpose()) * 0.5;
        } else {
            self.health.non_finite += 1;
        }
    }

    /// One sample: update with `y(k)`, then predict with `u(k)`. Returns the innovation of `y(k)`.
    pub fn step<D: SigmaModel<N, M>>(&mut self, model: &D, y: &SVector<f64, M>, u: &D::Input) -> Innovation<M> {
        let innovation = self.update(model, y);
        self.predict(model, u);
        innovation
    }
}

/// How a UKF maps its sigma points through a model: point by point, unless the model shares work among
/// points (method 002's fault model: six of its 13 points have the centre's velocity, so their air data
/// and velocity propagation are the centre's).
pub trait SigmaModel<const N: usize, const M: usize>: DiscreteModel<N, M> {
    /// `h` at every point.
    fn measurement_points(&self, X: &SigmaPoints<N, N>) -> SigmaPoints<N, M> {
        X.map(|x| self.measurement(x))
    }
    /// `f(., u)` at every point.
    fn transition_points(&self, X: &SigmaPoints<N, N>, u: &Self::Input) -> SigmaPoints<N, N> {
        X.map(|x| self.transition(x, u))
    }
}

/// `sum Wc_i (A_i - a)(B_i - b)'` over two point sets drawn from the same `N`-dimensional points.
pub fn weighted_covariance<const N: usize, const D: usize, const E: usize>(
    A: &SigmaPoints<N, D>,
    a: &SVector<f64, D>,
    B: &SigmaPoints<N, E>,
    b: &SVector<f64, E>,
    w: &SigmaWeights,
) -> SMatrix<f64, D, E> {
    let mut others = SMatrix::<f64, D, E>::zeros();
    for i in 0..N {
        others += (A.plus[i] - a) * (B.plus[i] - b).transpose();
        others += (A.minus[i] - a) * (B.minus[i] - b).transpose();
    }
    (A.center - a) * (B.center - b).transpose() * w.covariance_center + others * w.other
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Matrix4, Matrix4x2, SMatrix, Vector1, Vector2, Vector4};
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// `x(k+1) = A x + B u`, `y = H x`: the case where the UKF must equal the Kalman filter.
    struct Linear {
        A: Matrix4<f64>,
        B: Matrix4x2<f64>,
        H: SMatrix<f64, 2, 4>,
    }

    impl DiscreteModel<4, 2> for Linear {
        type Input = Vector2<f64>;
        fn transition(&self, x: &Vector4<f64>, u: &Vector2<f64>) -> Vector4<f64> {
            self.A * x + self.B * u
        }
        fn measurement(&self, x: &Vector4<f64>) -> Vector2<f64> {
            self.H * x
        }
    }

    impl SigmaModel<4, 2> for Linear {}

    fn linear_model() -> Linear {
        // A damped oscillator pair with coupling (dt = 0.05 s), both positions measured with a cross term.
        let A = Matrix4::new(
            1.0, 0.05, 0.0, 0.0, //
            -0.1, 0.98, 0.02, 0.0, //
            0.0, 0.0, 1.0, 0.05, //
            0.03, 0.0, -0.2, 0.97,
        );
        let B = Matrix4x2::new(0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.05);
        let H = SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0, 0.0);
        Linear { A, B, H }
    }

    fn normal(rng: &mut ChaCha8Rng) -> f64 {
        StandardNormal.sample(rng)
    }

    /// The weights of every tested parameter set sum to 1 (mean) and `1 + 1 - alpha^2 + beta`
    /// (covariance), and the points give back the mean and covariance to 1e-12 for N = 3 and 6.
    #[test]
    fn sigma_points_reproduce_mean_and_covariance() {
        let sets = [
            UnscentedParams::seed(),
            UnscentedParams { alpha: 0.5, beta: 2.0, kappa: 1.0 },
            UnscentedParams { alpha: 1e-3, beta: 2.0, kappa: 0.0 },
        ];
        for params in sets {
            check_points::<3>(&params);
            check_points::<6>(&params);
        }
        let w = UnscentedParams::seed().weights(6).unwrap();
        assert_eq!((w.mean_center, w.covariance_center, w.other), (0.0, 2.0, 1.0 / 12.0));
        assert!((w.spread - 6f64.sqrt()).abs() < 1e-15);
        assert!(UnscentedParams { alpha: 1.0, beta: 2.0, kappa: -6.0 }.weights(6).is_err());
        assert!(UnscentedParams { alpha: f64::NAN, beta: 2.0, kappa: 0.0 }.weights(3).is_err());
    }

    fn check_points<const N: usize>(params: &UnscentedParams) {
        let w = params.weights(N).unwrap();
        let sum_mean = w.mean_center + 2.0 * N as f64 * w.other;
        let sum_cov = w.covariance_center + 2.0 * N as f64 * w.other;
        assert!((sum_mean - 1.0).abs() < 1e-9, "{params:?}: {sum_mean}");
        assert!((sum_cov - (2.0 - params.alpha.powi(2) + params.beta)).abs() < 1e-9 * w.mean_center.abs().max(1.0));
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let x = SVector::<f64, N>::from_fn(|_, _| normal(&mut rng));
        let G = SMatrix::<f64, N, N>::from_fn(|_, _| normal(&mut rng));
        let P = G * G.transpose() + SMatrix::<f64, N, N>::identity();
        let (L, _, repaired) = cholesky_repaired(&P).unwrap();
        assert!(!repaired);
        let X = SigmaPoints::new(&x, &L, &w);
        let mean = X.mean(&w);
        // alpha = 1e-3 cancels terms a million times larger than the result: tolerance scaled by |Wm_0|.
        let tol = 1e-12 * w.mean_center.abs().max(1.0) * P.amax();
        assert!((mean - x).amax() < tol, "{params:?}: mean off by {:e}", (mean - x).amax());
        let cov = weighted_covariance(&X, &mean, &X, &mean, &w);
        // The centre point contributes nothing to the covariance when it is the mean.
        assert!((cov - P).amax() < tol, "{params:?}: covariance off by {:e}", (cov - P).amax());
    }

    /// The transform is exact for a quadratic: `E[x^2] = m^2 + s^2` for `x ~ N(m, s^2)` (measured error
    /// 0 to rounding), where a linearisation gives `m^2`.
    #[test]
    fn the_unscented_mean_of_a_quadratic_is_exact() {
        let w = UnscentedParams::seed().weights(1).unwrap();
        let (m, s) = (1.5, 0.7);
        let X = SigmaPoints::new(&Vector1::new(m), &SMatrix::<f64, 1, 1>::new(s), &w);
        let Y = X.map(|x| Vector1::new(x[0] * x[0]));
        assert!((Y.mean(&w)[0] - (m * m + s * s)).abs() < 1e-14);
    }

    /// 500 steps of the UKF and a hand-written Kalman filter on the same linear model and noisy data:
    /// state and covariance agree to 1e-9 after every update and prediction (measured: 1.3e-14 and 6.7e-15
    /// at most), and no repair is needed.
    #[test]
    fn on_a_linear_model_the_ukf_is_the_kalman_filter() {
        let model = linear_model();
        let Q = Matrix4::from_diagonal(&Vector4::new(1e-4, 4e-4, 1e-4, 4e-4));
        let R = Matrix2::new(0.04, 0.01, 0.01, 0.09);
        let (x0, P0) = (Vector4::new(0.5, 0.0, -0.3, 0.1), Matrix4::identity() * 2.0);
        let mut ukf = Ukf::new(x0, P0, Q, R, &UnscentedParams::seed()).unwrap();
        let (mut x, mut P) = (x0, P0);
        let mut truth = Vector4::new(1.0, -0.5, 0.2, 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut worst_x, mut worst_P) = (0.0f64, 0.0f64);
        for k in 0..500 {
            let u = Vector2::new((0.05 * k as f64).sin(), 0.5);
            let y = model.H * truth + Vector2::new(0.2 * normal(&mut rng), 0.3 * normal(&mut rng));
            truth = model.A * truth + model.B * u + Vector4::from_fn(|_, _| 0.01 * normal(&mut rng));

            let innovation = ukf.update(&model, &y);
            let S = model.H * P * model.H.transpose() + R;
            let K = P * model.H.transpose() * S.try_inverse().unwrap();
            let gamma = y - model.H * x;
            x += K * gamma;
            P = (Matrix4::identity() - K * model.H) * P;
            assert!((innovation.gamma - gamma).amax() < 1e-9 && (innovation.S - S).amax() < 1e-9);
            worst_x = worst_x.max((ukf.state() - x).amax());
            worst_P = worst_P.max((ukf.covariance() - P).amax());

            ukf.predict(&model, &u);
            x = model.A * x + model.B * u;
            P = model.A * P * model.A.transpose() + Q;
            worst_x = worst_x.max((ukf.state() - x).amax());
            worst_P = worst_P.max((ukf.covariance() - P).amax());
        }
        assert!(worst_x < 1e-9 && worst_P < 1e-9, "state {worst_x:e}, covariance {worst_P:e}");
        assert_eq!(ukf.health(), UkfHealth::default());
    }

    /// `[[1, 2], [2, 1]]` (eigenvalues 3 and -1) has no Cholesky factor: the repair adds twice the first
    /// jitter that works (eigenvalues 5 and 1 after it), counts one repair and the filter goes on with a
    /// positive definite covariance; a valid covariance is never repaired.
    #[test]
    fn a_non_positive_definite_covariance_is_repaired_and_counted() {
        let bad = Matrix2::new(1.0, 2.0, 2.0, 1.0);
        let (L, repaired, was_repaired) = cholesky_repaired(&bad).unwrap();
        assert!(was_repaired);
        assert!((L * L.transpose() - repaired).amax() < 1e-12);
        // First working jitter: the Gershgorin bound 1 + 1e-12 (0.1 and 1 fail), doubled.
        let jitter = repaired[(0, 0)] - 1.0;
        assert!((jitter - 2.0).abs() < 1e-9, "jitter {jitter}");
        assert_eq!(repaired[(0, 1)], 2.0);
        let eigenvalues = repaired.symmetric_eigenvalues();
        assert!(eigenvalues.min() > 0.99, "smallest eigenvalue {} is at least the jitter found", eigenvalues.min());
        assert!(cholesky_repaired(&Matrix2::new(f64::NAN, 0.0, 0.0, 1.0)).is_none());

        struct Walk;
        impl DiscreteModel<2, 1> for Walk {
            type Input = ();
            fn transition(&self, x: &Vector2<f64>, _: &()) -> Vector2<f64> {
                *x
            }
            fn measurement(&self, x: &Vector2<f64>) -> Vector1<f64> {
                Vector1::new(x[0] + x[1])
            }
        }
        impl SigmaModel<2, 1> for Walk {}
        let Q = Matrix2::identity() * 1e-3;
        let R = SMatrix::<f64, 1, 1>::new(0.01);
        let mut f = Ukf::new(Vector2::zeros(), Matrix2::identity(), Q, R, &UnscentedParams::seed()).unwrap();
        f.step(&Walk, &Vector1::new(0.3), &());
        assert_eq!(f.health().covariance_repairs, 0);
        f.reinitialise(Vector2::zeros(), bad);
        f.predict(&Walk, &());
        assert_eq!(f.health().covariance_repairs, 1);
        assert!(f.covariance().cholesky().is_some());
        let innovation = f.update(&Walk, &Vector1::new(0.3));
        assert!(innovation.S_inverse.is_some());
        assert_eq!(f.health().covariance_repairs, 1, "the repaired covariance needs no second repair");
        assert_eq!(FilterHealth::from(f.health()).not_positive_definite, 1);
    }

    /// A NaN measurement and a singular `S` each skip the update, keep the estimate and are counted;
    /// the innovation then has no inverse (likelihood zero for the bank).
    #[test]
    fn non_finite_and_singular_updates_are_skipped_and_counted() {
        let model = linear_model();
        let mut f = Ukf::new(
            Vector4::repeat(1.0),
            Matrix4::identity(),
            Matrix4::identity() * 1e-3,
            Matrix2::identity() * 0.1,
            &UnscentedParams::seed(),
        )
        .unwrap();
        let before = (*f.state(), *f.covariance());
        let innovation = f.update(&model, &Vector2::new(f64::NAN, 0.0));
        assert!(innovation.S_inverse.is_none());
        assert_eq!((*f.state(), *f.covariance()), before);
        assert_eq!(f.health().non_finite, 1);

        struct Blind;
        impl DiscreteModel<4, 2> for Blind {
            type Input = ();
            fn transition(&self, x: &Vector4<f64>, _: &()) -> Vector4<f64> {
                *x
            }
            fn measurement(&self, _: &Vector4<f64>) -> Vector2<f64> {
                Vector2::zeros()
            }
        }
        impl SigmaModel<4, 2> for Blind {}
        f.set_measurement_noise(Matrix2::zeros());
        let innovation = f.update(&Blind, &Vector2::new(1.0, 2.0));
        assert!(innovation.S_inverse.is_none());
        assert_eq!(f.health().singular_innovation, 1);
        assert_eq!((*f.state(), *f.covariance()), before);
    }
}
