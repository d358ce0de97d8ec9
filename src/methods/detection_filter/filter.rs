//! Method 000: the eigenstructure-assigned detection filter (a Luenberger observer), discrete time.
//!
//! ```text
//! gamma(k)    = y(k) - C xhat(k) - D u(k)                 residual
//! xhat(k + 1) = Ad xhat(k) + Bd u(k) + Kd gamma(k)        (+ Kd: the seed's printed "- K" is an erratum)
//! ```
//! so the state error obeys `e(k + 1) = (Ad - Kd C) e(k) - Kd Q f(k)`, `gamma = C e + Q f`.
//! `Kd` is designed on the ZOH model of the *design* plant with eigenvalues `exp(lambda_i dt)` on the
//! fault directions, the discrete counterpart of the seed's continuous design (same eigenvectors, same
//! time constants). The continuous gain is designed too, to compare with the seed and to report.
//!
//! Isolation signatures: a constant bias `b` on output `j` drives the residual to
//! `s_j b` with `s_j = (I - C (I - Phi)^-1 Kd) e_j`, `Phi = Ad - Kd C`, so `S = I - C (I - Phi)^-1 Kd`.
//! A residual is attributed to the output whose signature it is most parallel to (in threshold-scaled
//! coordinates), and, separately, to its largest threshold-scaled channel.
#![allow(non_snake_case)]

use nalgebra::{DMatrix, DVector};

use crate::design::kalman::steady_state_kalman;
use crate::design::{Assignment, DesignError, Domain, assign_eigenstructure, eigen_report};
use crate::lti::LtiPlant;
use crate::methods::detection_filter::decision::Decision;
use crate::methods::detection_filter::study::{DetectionFilterParams, KalmanParams};

/// A designed detection filter (`sim::FilterStep` runs it). If it exists, its gains exist and are stable.
#[derive(Debug, Clone)]
pub struct DetectionFilter {
    pub Ad: DMatrix<f64>,
    pub Bd: DMatrix<f64>,
    pub C: DMatrix<f64>,
    pub D: DMatrix<f64>,
    /// Continuous-time design (the seed's `K`), for reports.
    pub continuous: Assignment,
    /// Discrete-time design; `discrete.K` is the gain the filter runs.
    pub discrete: Assignment,
    /// Steady-state residual per unit bias on each output (column j), see the module docs.
    pub signatures: DMatrix<f64>,
    pub thresholds: DVector<f64>,
    /// The test the residual meets before its thresholds.
    pub decision: Decision,
    /// Per output, what isolation divides the mean residual by: the thresholds, or for a Kalman
    /// filter the innovation standard deviations (isolation by the largest normalised innovation).
    pub isolation_scale: DVector<f64>,
    /// Isolation window after the first alarm: start delay and length (s).
    pub isolation_delay_s: f64,
    pub isolation_window_s: f64,
}

impl DetectionFilterParams {
    /// Designs the filter for the `design` plant sampled at `dt_s`.
    pub fn design(&self, design: &LtiPlant, dt_s: f64) -> Result<DetectionFilter, DesignError> {
        if let Some(k) = &self.kalman {
            return self.design_kalman(k, design, dt_s);
        }
        let F = &self.fault_directions;
        let continuous = assign_eigenstructure(&design.A, &design.C, F, &self.eigenvalues_per_s, Domain::Continuous)?;
        let sampled = design.discretise(dt_s);
        let z: Vec<f64> = self.eigenvalues_per_s.iter().map(|l| (l * dt_s).exp()).collect();
        let discrete = assign_eigenstructure(&sampled.Ad, &sampled.C, F, &z, Domain::Discrete)?;

        let n = design.n_states();
        let m = design.n_outputs();
        let phi = &sampled.Ad - &discrete.K * &sampled.C;
        let i_minus_phi = DMatrix::identity(n, n) - phi;
        let solved =
            i_minus_phi.lu().solve(&discrete.K).ok_or(DesignError::Decomposition { what: "LU of I - (Ad - Kd C)" })?;
        let signatures = DMatrix::identity(m, m) - &sampled.C * solved;

        Ok(DetectionFilter {
            Ad: sampled.Ad,
            Bd: sampled.Bd,
            C: sampled.C,
            D: sampled.D,
            continuous,
            discrete,
            signatures,
            thresholds: self.thresholds.clone(),
            decision: self.decision.clone(),
            isolation_scale: self.thresholds.clone(),
            isolation_delay_s: self.isolation_delay_s,
            isolation_window_s: self.isolation_window_s,
        })
    }

    /// The steady-state Kalman filter on the ZOH design model (`design::kalman`), its chi-square test
    /// holding the innovation covariance; `continuous` repeats the discrete design (there is none other).
    fn design_kalman(&self, k: &KalmanParams, design: &LtiPlant, dt_s: f64) -> Result<DetectionFilter, DesignError> {
        let sampled = design.discretise(dt_s);
        let steady = steady_state_kalman(&sampled.Ad, &sampled.C, &k.process_covariance, &k.sensor_covariance)?;
        let phi = &sampled.Ad - &steady.K * &sampled.C;
        let (closed_loop_eigenvalues, eigenvector_condition) = eigen_report(&phi)?;
        let discrete =
            Assignment { K: steady.K.clone(), closed_loop_eigenvalues, eigenvector_condition, relative_residual: 0.0 };
        let (n, m) = (design.n_states(), design.n_outputs());
        let solved = (DMatrix::identity(n, n) - phi)
            .lu()
            .solve(&steady.K)
            .ok_or(DesignError::Decomposition { what: "LU of I - (Ad - K C)" })?;
        let signatures = DMatrix::identity(m, m) - &sampled.C * solved;
        let s_inv = steady.S.clone().try_inverse().ok_or(DesignError::Decomposition { what: "inverse of S" })?;
        let window = match self.decision {
            Decision::Nis { window, .. } => window,
            _ => 1,
        };
        Ok(DetectionFilter {
            Ad: sampled.Ad,
            Bd: sampled.Bd,
            C: sampled.C,
            D: sampled.D,
            continuous: discrete.clone(),
            discrete,
            signatures,
            thresholds: self.thresholds.clone(),
            decision: Decision::Nis { window, s_inv },
            isolation_scale: steady.S.diagonal().map(f64::sqrt),
            isolation_delay_s: self.isolation_delay_s,
            isolation_window_s: self.isolation_window_s,
        })
    }
}

impl DetectionFilter {
    /// Output whose scaled residual is largest (threshold-scaled; innovation-normalised for a Kalman
    /// filter).
    pub fn isolate_by_max(&self, mean_residual: &DVector<f64>) -> usize {
        mean_residual.component_div(&self.isolation_scale).iamax()
    }

    /// Output whose bias signature is most parallel to the residual (threshold-scaled, either sign).
    pub fn isolate_by_direction(&self, mean_residual: &DVector<f64>) -> usize {
        let w = mean_residual.component_div(&self.isolation_scale);
        let w_norm = w.norm().max(f64::MIN_POSITIVE);
        let mut best = (0, f64::NEG_INFINITY);
        for (j, s) in self.signatures.column_iter().enumerate() {
            let s = s.component_div(&self.isolation_scale);
            let cos = w.dot(&s).abs() / (w_norm * s.norm().max(f64::MIN_POSITIVE));
            if cos > best.1 {
                best = (j, cos);
            }
        }
        best.0
    }
}
