//! The test a detection filter's residual meets: each sample, one statistic per output, and an alarm
//! when output j's statistic exceeds its threshold. Built in: the seed's `|residual_j|` and a CUSUM;
//! a user brings their own by implementing [`ResidualTest`] (see `examples/custom_detector.rs`).
//!
//! The statistic is what `trials.parquet` records per output (`pre_max_<out>`, the first-passage
//! profile `fp_*_<out>`), so thresholds calibrate and the report draws its ROC for any test alike.
//! Isolation stays the filter's: it reads the raw residual after the alarm.

use std::collections::VecDeque;
use std::fmt;
use std::sync::Arc;

use nalgebra::DMatrix;

/// A decision rule on the residual, designed once per detector.
pub trait ResidualTest: Send + Sync {
    /// What `fdimc validate` prints for it, e.g. `cusum (drift [0.01, 0.02])`.
    fn describe(&self) -> String;
    /// A fresh state for one trial of a filter with `outputs` outputs sampled every `dt_s`.
    fn start(&self, outputs: usize, dt_s: f64) -> Box<dyn TestState>;
}

/// One trial's memory of a [`ResidualTest`].
pub trait TestState {
    /// Writes each output's statistic after residual sample `residual` (both of the filter's output
    /// count); a statistic must be >= 0 and grow with the evidence of a fault.
    fn step(&mut self, residual: &[f64], statistic: &mut [f64]);
}

/// The test a detector of an LTI deck applies: `kind = "detection_filter"` ([`Decision::Absolute`]),
/// `kind = "cusum"` ([`Decision::Cusum`]) or one given through the library ([`Decision::Own`]).
#[derive(Clone)]
pub enum Decision {
    /// `|residual_j|`, the seed's test (and the only one the lane path runs).
    Absolute,
    /// Page's one-sided CUSUM on `|residual_j|`: `g_j = max(0, g_j + |r_j| - drift_j)`, starting at 0.
    Cusum { drift: Vec<f64> },
    /// `kind = "kalman_chi2"`: the normalised innovation squared `r' S^-1 r` summed over the last
    /// `window` samples, one joint statistic recorded under every output (any output's alarm is the
    /// joint alarm). `s_inv` is the designed filter's (empty in the deck's parameters).
    Nis { window: usize, s_inv: DMatrix<f64> },
    /// A test of the user's own.
    Own(Arc<dyn ResidualTest>),
}

impl fmt::Debug for Decision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.describe())
    }
}

impl Decision {
    pub fn describe(&self) -> String {
        match self {
            Decision::Absolute => "|residual|".into(),
            Decision::Cusum { drift } => {
                let d: Vec<String> = drift.iter().map(|v| format!("{v}")).collect();
                format!("cusum on |residual|, drift [{}]", d.join(", "))
            }
            Decision::Nis { window, .. } => format!("the normalised innovation squared summed over {window} samples"),
            Decision::Own(t) => t.describe(),
        }
    }

    pub fn start(&self, outputs: usize, dt_s: f64) -> Box<dyn TestState> {
        match self {
            Decision::Absolute => Box::new(AbsoluteState),
            Decision::Cusum { drift } => Box::new(CusumState { drift: drift.clone(), g: vec![0.0; outputs] }),
            Decision::Nis { window, s_inv } => Box::new(NisState {
                s_inv: s_inv.clone(),
                recent: VecDeque::with_capacity(*window + 1),
                window: *window,
            }),
            Decision::Own(t) => t.start(outputs, dt_s),
        }
    }

    /// Whether the lane path can run it (the built-in tests; a user's own runs one trial at a time).
    pub fn runs_on_lanes(&self) -> bool {
        matches!(self, Decision::Absolute | Decision::Cusum { .. })
    }

    /// The deck's `kind` of a detector with this test.
    pub fn kind(&self) -> &'static str {
        match self {
            Decision::Absolute => "detection_filter",
            Decision::Cusum { .. } => "cusum",
            Decision::Nis { .. } => "kalman_chi2",
            Decision::Own(_) => "own test",
        }
    }
}

struct AbsoluteState;

impl TestState for AbsoluteState {
    fn step(&mut self, residual: &[f64], statistic: &mut [f64]) {
        for (s, r) in statistic.iter_mut().zip(residual) {
            *s = r.abs();
        }
    }
}

struct CusumState {
    drift: Vec<f64>,
    g: Vec<f64>,
}

impl TestState for CusumState {
    fn step(&mut self, residual: &[f64], statistic: &mut [f64]) {
        for j in 0..self.g.len() {
            // A non-finite residual passes through, so the tracker sees the divergence.
            let g = self.g[j] + residual[j].abs() - self.drift[j];
            self.g[j] = if g.is_finite() { g.max(0.0) } else { g };
            statistic[j] = self.g[j];
        }
    }
}

struct NisState {
    s_inv: DMatrix<f64>,
    recent: VecDeque<f64>,
    window: usize,
}

impl TestState for NisState {
    fn step(&mut self, residual: &[f64], statistic: &mut [f64]) {
        // r' S^-1 r without allocating: this runs every sample of every trial.
        let m = residual.len();
        let nis: f64 =
            (0..m).map(|i| residual[i] * (0..m).map(|j| self.s_inv[(i, j)] * residual[j]).sum::<f64>()).sum();
        self.recent.push_back(nis);
        if self.recent.len() > self.window {
            self.recent.pop_front();
        }
        // Summed anew each sample (a short window), so no rounding accumulates over a long trial.
        statistic.fill(self.recent.iter().sum());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step of size mu > drift on a noise-free residual: g rises by (mu - drift) per sample, so a
    /// threshold h alarms at the ceil(h / (mu - drift))-th sample of the step.
    #[test]
    fn cusum_detects_a_step_after_the_delay_its_parameters_imply() {
        let (mu, drift, h) = (0.3, 0.1, 0.9);
        let mut state = Decision::Cusum { drift: vec![drift, drift] }.start(2, 0.01);
        let mut stat = [0.0; 2];
        // Before the step: residual below the drift, the sum stays at 0.
        for _ in 0..50 {
            state.step(&[0.05, -0.08], &mut stat);
            assert_eq!(stat, [0.0, 0.0]);
        }
        let alarm = (1..=100).find(|_| {
            state.step(&[-mu, 0.05], &mut stat);
            stat[0] > h
        });
        assert_eq!(alarm, Some((h / (mu - drift)).ceil() as usize));
        assert_eq!(alarm, Some(5), "0.2 per sample passes 0.9 at the fifth");
        assert_eq!(stat[1], 0.0, "the healthy output's sum stays at 0");
    }

    #[test]
    fn the_absolute_test_is_the_residual_magnitude() {
        let mut state = Decision::Absolute.start(3, 0.01);
        let mut stat = [0.0; 3];
        state.step(&[-0.5, 0.25, 0.0], &mut stat);
        assert_eq!(stat, [0.5, 0.25, 0.0]);
    }
}
