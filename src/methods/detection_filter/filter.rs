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

use std::fmt;
use std::sync::Arc;

use nalgebra::{DMatrix, DVector};

use super::decision::Decision;
use super::deck::DetectorSection;
use crate::design::{Assignment, DesignError, Domain, assign_eigenstructure};
use crate::engine::scenario::deck::{DeckError, Validator};
use crate::lti::{DiscreteLti, LtiPlant};

/// A detector of an LTI deck: how its gain is designed, the test its residual meets and how it
/// isolates. `kind = "detection_filter"` is the seed's (this file); `cusum.rs` and `kalman_chi2.rs`
/// are the baselines.
#[derive(Debug, Clone)]
pub struct DetectionFilterParams {
    pub gain: Gain,
    /// Alarm when output j's statistic exceeds `thresholds[j]`.
    pub thresholds: DVector<f64>,
    /// The test the residual meets (`|residual|` for the seed's kind); `None`: the gain design builds
    /// it from the designed filter (`kalman_chi2`: from the innovation covariance).
    pub decision: Option<Decision>,
    pub isolation: Isolation,
    /// Isolation looks at the mean residual over `[alarm + delay, alarm + delay + window]`, after the
    /// filter's transient (the slowest eigenvalue's time constant sets a sensible delay).
    pub isolation_delay_s: f64,
    pub isolation_window_s: f64,
}

/// How a detector's gain is designed.
#[derive(Debug, Clone)]
pub enum Gain {
    /// The seed's: continuous-time eigenvalues (1/s, distinct and negative) assigned to the fault
    /// directions `F` (n x r, one column per eigenvalue), continuous and discrete.
    Eigenstructure { eigenvalues_per_s: Vec<f64>, fault_directions: DMatrix<f64> },
    /// A baseline's own design.
    Own(Arc<dyn GainDesign>),
}

/// A gain design of a baseline detector (`kalman_chi2.rs`).
pub trait GainDesign: Send + Sync + fmt::Debug {
    /// The designed filter on the `design` plant sampled at `dt_s`, for `params`.
    fn design(
        &self,
        params: &DetectionFilterParams,
        design: &LtiPlant,
        dt_s: f64,
    ) -> Result<DetectionFilter, DesignError>;
    /// What `fdimc validate` says of it.
    fn describe(&self) -> String;
    /// The deck's `kind` of a detector with this gain.
    fn kind(&self) -> &'static str;
    /// Whether the lane path runs its filters: their test (the designed filter's `decision`) has a
    /// [`LaneStatistic`](super::decision::LaneStatistic).
    fn runs_on_lanes(&self) -> bool {
        false
    }
}

/// Which output a detector names after its alarm, from the mean residual in the isolation window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isolation {
    /// The output whose bias signature the residual is most parallel to (the seed's).
    Signature,
    /// The output with the largest normalised innovation (`kalman_chi2`).
    LargestNormalised,
    /// The output the test itself names at the end of the window (a detector FMU's channel).
    Named,
}

/// A designed detection filter (`sim::FilterStep` runs it). If it exists, its gains exist and are stable.
#[derive(Debug, Clone)]
pub struct DetectionFilter {
    /// The sampled design model the filter runs: `Ad`, `Bd`, `C`, `D`.
    pub model: DiscreteLti,
    /// Continuous-time design (the seed's `K`), for reports; `None` for a design with none (Kalman).
    pub continuous: Option<Assignment>,
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
        let (eigenvalues_per_s, F) = match &self.gain {
            Gain::Own(g) => return g.design(self, design, dt_s),
            Gain::Eigenstructure { eigenvalues_per_s, fault_directions } => (eigenvalues_per_s, fault_directions),
        };
        let continuous = assign_eigenstructure(&design.A, &design.C, F, eigenvalues_per_s, Domain::Continuous)?;
        let sampled = design.discretise(dt_s);
        let z: Vec<f64> = eigenvalues_per_s.iter().map(|l| (l * dt_s).exp()).collect();
        let discrete = assign_eigenstructure(&sampled.Ad, &sampled.C, F, &z, Domain::Discrete)?;

        let decision = self.decision.clone().unwrap_or_else(Decision::absolute);
        DetectionFilter::new(sampled, Some(continuous), discrete, self, decision, self.thresholds.clone())
    }

    /// The deck's `kind` of the detector.
    pub fn kind(&self) -> &'static str {
        match (&self.gain, &self.decision) {
            (Gain::Own(g), _) => g.kind(),
            (Gain::Eigenstructure { .. }, Some(d)) => d.kind(),
            (Gain::Eigenstructure { .. }, None) => Decision::absolute().kind(),
        }
    }

    /// Whether the lane path can run it: a test the lanes compute, on the seed's gain or a gain whose
    /// design says so.
    pub fn runs_on_lanes(&self) -> bool {
        match &self.gain {
            Gain::Eigenstructure { .. } => self.decision.as_ref().is_some_and(Decision::runs_on_lanes),
            Gain::Own(g) => g.runs_on_lanes(),
        }
    }
}

/// One `[[detector]]` table being read, with what it is read against.
#[derive(Clone, Copy)]
pub(crate) struct DetectorDeck<'a> {
    pub chk: &'a Validator<'a>,
    /// Its index in the deck's `[[detector]]` list.
    pub i: usize,
    pub d: &'a DetectorSection,
    /// The true plant (dimensions).
    pub plant: &'a LtiPlant,
    pub sensor_sigma: &'a DVector<f64>,
    /// The FMU truth, whose trims an FMU detector's signals get back.
    pub truth: Option<&'a crate::fmu::plant::FmuPlant>,
    pub header: &'a crate::engine::scenario::deck::StudyHeader,
}

impl DetectorDeck<'_> {
    /// Refuses, with `why`, the first of the detector's `fields` that is given.
    pub(crate) fn refuse(&self, fields: &[(&str, bool)], why: &str) -> Result<(), DeckError> {
        match fields.iter().find(|(_, given)| *given) {
            Some((field, _)) => Err(self.chk.err(format!("detector[{}].{field}", self.i), why)),
            None => Ok(()),
        }
    }

    /// `isolation_delay_s` (>= 0) and `isolation_window_s` (> 0), each its kind's default when not given.
    pub(crate) fn isolation_timing(&self, delay_s: f64, window_s: f64) -> Result<(f64, f64), DeckError> {
        let field = |name: &str| format!("detector[{}].{name}", self.i);
        let delay_s = match self.d.isolation_delay_s {
            Some(v) => self.chk.non_negative(&field("isolation_delay_s"), v)?,
            None => delay_s,
        };
        let window_s = match self.d.isolation_window_s {
            Some(v) => self.chk.positive(&field("isolation_window_s"), v)?,
            None => window_s,
        };
        Ok((delay_s, window_s))
    }
}

/// Reads a detector of `kind = "detection_filter"`, the seed's test `|residual_j| > thresholds[j]`.
pub(crate) fn read(r: &DetectorDeck) -> Result<DetectionFilterParams, DeckError> {
    r.refuse(&[("drift", r.d.drift.is_some())], "applies to kind = \"cusum\" only (a CUSUM's allowance per sample)")?;
    read_eigenstructure_filter(r, Decision::absolute())
}

/// Reads the seed filter's fields of detector `i` (eigenvalues, fault directions, thresholds,
/// isolation timing) for a kind that runs the seed's filter with `decision` as its test.
pub(crate) fn read_eigenstructure_filter(
    deck: &DetectorDeck,
    decision: Decision,
) -> Result<DetectionFilterParams, DeckError> {
    let DetectorDeck { chk, i, d, plant, .. } = *deck;
    let f = |name: &str| format!("detector[{i}].{name}");
    let (n, ny) = (plant.n_states(), plant.n_outputs());
    deck.refuse(
        &[
            ("window", d.window.is_some()),
            ("false_alarm_probability", d.false_alarm_probability.is_some()),
            ("design_process_sigma_per_step", d.design_process_sigma_per_step.is_some()),
        ],
        "applies to kind = \"kalman_chi2\" only",
    )?;
    let eigenvalues = d.eigenvalues_per_s.as_ref().ok_or_else(|| {
        chk.err(f("eigenvalues_per_s"), format!("required for kind = {:?}: the filter's eigenvalues (1/s)", d.kind))
    })?;
    let given_thresholds = d.thresholds.as_ref().ok_or_else(|| {
        chk.err(f("thresholds"), format!("required for kind = {:?}: {ny} numbers, one per output", d.kind))
    })?;
    let r = eigenvalues.len();
    if r == 0 || r > n {
        return Err(chk
            .err(f("eigenvalues_per_s"), format!("expected 1 to {n} eigenvalues (one per fault direction), got {r}")));
    }
    for (k, &l) in eigenvalues.iter().enumerate() {
        let field = f(&format!("eigenvalues_per_s[{k}]"));
        if !(l.is_finite() && l < 0.0) {
            return Err(chk.err(
                field,
                format!("must be a finite negative number (a stable continuous-time eigenvalue, 1/s), got {l}"),
            ));
        }
    }
    let fault_directions = match &d.fault_directions {
        // Listed as r vectors f_i of length n: the columns of F.
        Some(dirs) => chk
            .matrix(&f("fault_directions"), dirs, r, n, &format!("one direction of {n} numbers per eigenvalue"))?
            .transpose(),
        None if r == n => DMatrix::identity(n, n),
        None => {
            return Err(chk.err(
                f("fault_directions"),
                format!("required when there are fewer eigenvalues ({r}) than states ({n})"),
            ));
        }
    };
    let thresholds = chk.vector(&f("thresholds"), given_thresholds, ny, "one per output, output units")?;
    for (k, &t) in thresholds.iter().enumerate() {
        if t <= 0.0 {
            return Err(chk.err(f(&format!("thresholds[{k}]")), format!("must be > 0, got {t}")));
        }
    }
    let slowest_time_constant_s = 1.0 / eigenvalues.iter().fold(f64::INFINITY, |m, l| m.min(-l));
    let (isolation_delay_s, isolation_window_s) =
        deck.isolation_timing(3.0 * slowest_time_constant_s, slowest_time_constant_s)?;
    Ok(DetectionFilterParams {
        gain: Gain::Eigenstructure { eigenvalues_per_s: eigenvalues.clone(), fault_directions },
        thresholds,
        decision: Some(decision),
        isolation: Isolation::Signature,
        isolation_delay_s,
        isolation_window_s,
    })
}

/// Steady-state residual per unit bias on each output (column j) of a filter running the gain `K` on
/// `model`: `S = I - C (I - (Ad - K C))^-1 K` (module docs). Every gain design's filter has them.
pub fn bias_signatures(model: &DiscreteLti, K: &DMatrix<f64>) -> Result<DMatrix<f64>, DesignError> {
    let (n, m) = (model.Ad.nrows(), model.C.nrows());
    let phi = &model.Ad - K * &model.C;
    let solved = (DMatrix::identity(n, n) - phi)
        .lu()
        .solve(K)
        .ok_or(DesignError::Decomposition { what: "LU of I - (Ad - K C)" })?;
    Ok(DMatrix::identity(m, m) - &model.C * solved)
}

impl DetectionFilter {
    /// The filter running `discrete.K` on the sampled design model `model`, with its bias signatures; its
    /// thresholds and isolation window from `params`, its test `decision`, isolation dividing by
    /// `isolation_scale`. What every gain design ends with.
    pub fn new(
        model: DiscreteLti,
        continuous: Option<Assignment>,
        discrete: Assignment,
        params: &DetectionFilterParams,
        decision: Decision,
        isolation_scale: DVector<f64>,
    ) -> Result<DetectionFilter, DesignError> {
        let signatures = bias_signatures(&model, &discrete.K)?;
        Ok(DetectionFilter {
            model,
            continuous,
            discrete,
            signatures,
            thresholds: params.thresholds.clone(),
            decision,
            isolation_scale,
            isolation_delay_s: params.isolation_delay_s,
            isolation_window_s: params.isolation_window_s,
        })
    }

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
