//! `kind = "kalman_chi2"`: the textbook Kalman-filter innovation test, a baseline for method 000 on the
//! same trials. A steady-state Kalman filter of the design model, designed from the deck's sensor noise
//! and the detector's `design_process_sigma_per_step` (`design::kalman`, the discrete Riccati
//! recursion); the normalised innovation squared `r' S^-1 r` summed over the last `window` samples
//! against the chi-square(window x outputs) quantile at `false_alarm_probability` per window; isolation
//! by the largest normalised innovation `|mean r_j| / sqrt(S_jj)`.
//!
//! The filter runs as any detection filter does (`xhat(k + 1) = Ad xhat + Bd u + K gamma`); only its
//! gain, its test and its isolation rule are this file's.
#![allow(non_snake_case)]

use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::{DMatrix, DVector};

use super::decision::{Decision, LaneStatistic, ResidualTest, TestState};
use super::filter::{DetectionFilter, DetectionFilterParams, DetectorDeck, Gain, GainDesign, Isolation};
use crate::design::kalman::steady_state_kalman;
use crate::design::{Assignment, DesignError, eigen_report};
use crate::engine::scenario::deck::DeckError;
use crate::lti::LtiPlant;

/// The noise the filter is designed for (covariances per step) and the test's window (samples).
#[derive(Debug, Clone)]
pub struct KalmanChi2 {
    pub process_covariance: DMatrix<f64>,
    pub sensor_covariance: DMatrix<f64>,
    pub window: usize,
    /// The test's false-alarm probability per window (its threshold, the chi-square quantile, is the
    /// detector's `thresholds`).
    pub false_alarm_probability: f64,
}

impl GainDesign for KalmanChi2 {
    /// The steady-state Kalman filter on the ZOH design model; the test holds its innovation covariance.
    fn design(
        &self,
        params: &DetectionFilterParams,
        design: &LtiPlant,
        dt_s: f64,
    ) -> Result<DetectionFilter, DesignError> {
        let sampled = design.discretise(dt_s);
        let steady = steady_state_kalman(&sampled.Ad, &sampled.C, &self.process_covariance, &self.sensor_covariance)?;
        let phi = &sampled.Ad - &steady.K * &sampled.C;
        let (closed_loop_eigenvalues, eigenvector_condition) = eigen_report(&phi)?;
        // No eigenstructure is assigned, so there is no assignment residual (NaN: `design` leaves it out).
        let discrete = Assignment {
            K: steady.K.clone(),
            closed_loop_eigenvalues,
            eigenvector_condition,
            relative_residual: f64::NAN,
        };
        let s_inv = steady.S.clone().try_inverse().ok_or(DesignError::Decomposition { what: "inverse of S" })?;
        let test = WindowedNis { window: self.window, s_inv, false_alarm_probability: self.false_alarm_probability };
        let isolation_scale = steady.S.diagonal().map(f64::sqrt);
        DetectionFilter::new(sampled, None, discrete, params, Decision::new(test), isolation_scale)
    }

    fn describe(&self) -> String {
        "the steady-state Kalman filter of the design model and the deck's sensor noise (predictor gain)".into()
    }

    fn kind(&self) -> &'static str {
        "kalman_chi2"
    }

    fn runs_on_lanes(&self) -> bool {
        true
    }
}

/// The window test on a designed filter's innovations: one joint statistic, recorded under every
/// output (any output's alarm is the joint alarm).
struct WindowedNis {
    window: usize,
    s_inv: DMatrix<f64>,
    false_alarm_probability: f64,
}

impl ResidualTest for WindowedNis {
    fn describe(&self) -> String {
        format!(
            "the normalised innovation squared summed over {} samples (threshold: its chi-square quantile at {} per window)",
            self.window, self.false_alarm_probability
        )
    }

    fn on_lanes(&self) -> Option<LaneStatistic> {
        Some(LaneStatistic::WindowedNis { window: self.window, s_inv: self.s_inv.clone() })
    }

    fn start(&self, _outputs: usize, _dt_s: f64) -> Box<dyn TestState> {
        Box::new(NisState {
            s_inv: self.s_inv.clone(),
            recent: VecDeque::with_capacity(self.window + 1),
            window: self.window,
        })
    }
}

#[derive(Clone)]
struct NisState {
    s_inv: DMatrix<f64>,
    recent: VecDeque<f64>,
    window: usize,
}

impl TestState for NisState {
    fn step(&mut self, residual: &[f64], statistic: &mut [f64]) {
        // r' S^-1 r without allocating: this runs every sample of every trial. Sums run in index order
        // from -0.0, as the lane path's do (lanes.rs), so both give the same bits.
        let m = residual.len();
        let nis = (0..m).fold(-0.0, |acc, i| {
            acc + residual[i] * (0..m).fold(-0.0, |inner, j| inner + self.s_inv[(i, j)] * residual[j])
        });
        self.recent.push_back(nis);
        if self.recent.len() > self.window {
            self.recent.pop_front();
        }
        // Summed anew each sample, oldest first (a short window), so no rounding accumulates over a
        // long trial.
        statistic.fill(self.recent.iter().fold(-0.0, |acc, v| acc + v));
    }

    fn fork(&self) -> Option<Box<dyn TestState>> {
        Some(Box::new(self.clone()))
    }
}

/// Reads detector `i` of `kind = "kalman_chi2"`: `window`, `false_alarm_probability`,
/// `design_process_sigma_per_step` (one per state), optional isolation timing; no eigenvalues,
/// directions, thresholds or drift.
pub(crate) fn read(r: &DetectorDeck) -> Result<DetectionFilterParams, DeckError> {
    let DetectorDeck { chk, i, d, plant, sensor_sigma, .. } = *r;
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    let f = |name: &str| format!("detector[{i}].{name}");
    let (n, ny) = (plant.n_states(), plant.n_outputs());
    r.refuse(
        &[
            ("eigenvalues_per_s", d.eigenvalues_per_s.is_some()),
            ("fault_directions", d.fault_directions.is_some()),
            ("thresholds", d.thresholds.is_some()),
            ("drift", d.drift.is_some()),
        ],
        "does not apply to kind = \"kalman_chi2\" (its gain is the Kalman filter's, its threshold the chi-square quantile)",
    )?;
    let window = match d.window {
        Some(w) if (1..=10_000).contains(&w) => w,
        Some(w) => return Err(chk.err(f("window"), format!("allowed 1 to 10000 samples, got {w}"))),
        None => return Err(chk.err(f("window"), "required for kind = \"kalman_chi2\": the samples summed")),
    };
    let pfa = match d.false_alarm_probability {
        Some(p) if p > 0.0 && p < 1.0 => p,
        Some(p) => {
            return Err(chk.err(f("false_alarm_probability"), format!("allowed 0 < p < 1 (per window), got {p}")));
        }
        None => {
            return Err(chk.err(
                f("false_alarm_probability"),
                "required for kind = \"kalman_chi2\": the chi-square test's false-alarm probability per window",
            ));
        }
    };
    let q = d.design_process_sigma_per_step.as_ref().ok_or_else(|| {
        chk.err(
            f("design_process_sigma_per_step"),
            format!(
                "required for kind = \"kalman_chi2\": {n} numbers >= 0, the process noise per step the filter assumes"
            ),
        )
    })?;
    let q = chk.vector(&f("design_process_sigma_per_step"), q, n, "one per state, state units per step")?;
    if let Some(k) = q.iter().position(|v| *v < 0.0) {
        return Err(chk.err(f(&format!("design_process_sigma_per_step[{k}]")), format!("must be >= 0, got {}", q[k])));
    }
    let dof = (window * ny) as f64;
    let quantile = ChiSquared::new(dof).map(|c| c.inverse_cdf(1.0 - pfa)).unwrap_or(f64::NAN);
    if !(quantile.is_finite() && quantile > 0.0) {
        return Err(chk.err(f("false_alarm_probability"), format!("{pfa}: no chi-square({dof}) quantile")));
    }
    // Our choice, not a paper's: the innovations carry the fault at once (no filter transient to wait
    // out), averaged over 1 s.
    let (isolation_delay_s, isolation_window_s) = r.isolation_timing(0.0, 1.0)?;
    let design = KalmanChi2 {
        process_covariance: DMatrix::from_diagonal(&q.map(|s| s * s)),
        sensor_covariance: DMatrix::from_diagonal(&sensor_sigma.map(|s| s * s)),
        window,
        false_alarm_probability: pfa,
    };
    Ok(DetectionFilterParams {
        gain: Gain::Own(Arc::new(design)),
        thresholds: DVector::from_element(ny, quantile),
        decision: None,
        isolation: Isolation::LargestNormalised,
        isolation_delay_s,
        isolation_window_s,
    })
}
