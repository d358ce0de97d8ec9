//! The test a detection filter's residual meets: each sample, one statistic per output, and an alarm
//! when output j's statistic exceeds its threshold. Built in: the seed's `|residual_j|` (here), a CUSUM
//! (`cusum.rs`) and the Kalman baseline's windowed chi-square test (`kalman_chi2.rs`); a user brings
//! their own by implementing [`ResidualTest`] (see `examples/custom_detector.rs`).
//!
//! The statistic is what `trials.parquet` records per output (`pre_max_<out>`, the first-passage
//! profile `fp_*_<out>`), so thresholds calibrate and the report draws its ROC for any test alike.
//! Isolation stays the filter's: it reads the raw residual after the alarm.

use std::fmt;
use std::sync::Arc;

/// A decision rule on the residual, designed once per detector.
pub trait ResidualTest: Send + Sync {
    /// What `fdimc validate` prints for it, e.g. `cusum (drift [0.01, 0.02])`.
    fn describe(&self) -> String;
    /// A fresh state for one trial of a filter with `outputs` outputs sampled every `dt_s`.
    fn start(&self, outputs: usize, dt_s: f64) -> Box<dyn TestState>;
    /// The deck's `kind` of a detector with this test.
    fn kind(&self) -> &'static str {
        "own test"
    }
    /// What the lane path (`lanes.rs`, many trials at once) computes for it, if it can; a test that
    /// returns `None` runs one trial at a time.
    fn on_lanes(&self) -> Option<LaneStatistic> {
        None
    }
    /// Whether the test names the faulty output itself ([`TestState::isolated`], a detector FMU's
    /// isolated channel) instead of the filter's isolation from the mean residual.
    fn isolates(&self) -> bool {
        false
    }
    /// The FMU the test runs, if it runs one (for the manifest and the thread count).
    fn fmu(&self) -> Option<&crate::fmu::plant::FmuPlant> {
        None
    }
}

/// One trial's memory of a [`ResidualTest`].
pub trait TestState {
    /// Writes each output's statistic after residual sample `residual` (both of the filter's output
    /// count); a statistic must be >= 0 and grow with the evidence of a fault.
    fn step(&mut self, residual: &[f64], statistic: &mut [f64]);
    /// A copy of this memory, for `fdimc rare-event`'s splitting (which copies trials mid-way); a test
    /// that does not give one is refused there with a message, and runs everywhere else.
    fn fork(&self) -> Option<Box<dyn TestState>> {
        None
    }
    /// This sample's inputs to the plant (deviations from any trim), given before [`step`](Self::step)
    /// for a test that reads them.
    fn inputs(&mut self, _u: &[f64]) {}
    /// The output the test names now, for a test that [isolates](ResidualTest::isolates).
    fn isolated(&self) -> Option<usize> {
        None
    }
    /// Why the test cannot go on (a detector FMU that returned an error), taken once: the trial fails.
    fn failure(&mut self) -> Option<String> {
        None
    }
}

/// The statistics the lane path computes per output.
#[derive(Debug, Clone, PartialEq)]
pub enum LaneStatistic {
    /// `|r_j|`.
    Absolute,
    /// `g_j = max(0, g_j + |r_j| - drift_j)` from 0 (a CUSUM).
    Accumulated { drift: Vec<f64> },
    /// The normalised innovation squared `r' S^-1 r` summed over the last `window` samples, one joint
    /// statistic under every output (the Kalman chi-square test; `s_inv` is each design's own).
    WindowedNis { window: usize, s_inv: nalgebra::DMatrix<f64> },
}

/// The test a detector applies, shared by every trial.
#[derive(Clone)]
pub struct Decision(Arc<dyn ResidualTest>);

impl fmt::Debug for Decision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.describe())
    }
}

impl Decision {
    pub fn new(test: impl ResidualTest + 'static) -> Self {
        Decision(Arc::new(test))
    }

    /// `kind = "detection_filter"`: `|residual_j|`, the seed's test.
    pub fn absolute() -> Self {
        Decision::new(Absolute)
    }

    pub fn describe(&self) -> String {
        self.0.describe()
    }

    pub fn start(&self, outputs: usize, dt_s: f64) -> Box<dyn TestState> {
        self.0.start(outputs, dt_s)
    }

    pub fn kind(&self) -> &'static str {
        self.0.kind()
    }

    pub fn on_lanes(&self) -> Option<LaneStatistic> {
        self.0.on_lanes()
    }

    pub fn isolates(&self) -> bool {
        self.0.isolates()
    }

    pub fn fmu(&self) -> Option<&crate::fmu::plant::FmuPlant> {
        self.0.fmu()
    }

    /// Whether the lane path can run it.
    pub fn runs_on_lanes(&self) -> bool {
        self.0.on_lanes().is_some()
    }
}

/// The seed's test: `|residual_j|`.
struct Absolute;

impl ResidualTest for Absolute {
    fn describe(&self) -> String {
        "|residual|".into()
    }

    fn start(&self, _outputs: usize, _dt_s: f64) -> Box<dyn TestState> {
        Box::new(Absolute)
    }

    fn kind(&self) -> &'static str {
        "detection_filter"
    }

    fn on_lanes(&self) -> Option<LaneStatistic> {
        Some(LaneStatistic::Absolute)
    }
}

impl TestState for Absolute {
    fn step(&mut self, residual: &[f64], statistic: &mut [f64]) {
        for (s, r) in statistic.iter_mut().zip(residual) {
            *s = r.abs();
        }
    }

    fn fork(&self) -> Option<Box<dyn TestState>> {
        Some(Box::new(Absolute))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_absolute_test_is_the_residual_magnitude() {
        let mut state = Decision::absolute().start(3, 0.01);
        let mut stat = [0.0; 3];
        state.step(&[-0.5, 0.25, 0.0], &mut stat);
        assert_eq!(stat, [0.5, 0.25, 0.0]);
        assert_eq!(Decision::absolute().on_lanes(), Some(LaneStatistic::Absolute));
    }
}
