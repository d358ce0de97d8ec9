//! `kind = "cusum"`: the seed's detection filter with Page's one-sided CUSUM on `|residual_j|` in place
//! of the seed's `|residual_j| > threshold_j`, the sequential test engineers reach for when a bias is
//! small:
//!
//! ```text
//! g_j(k) = max(0, g_j(k - 1) + |r_j(k)| - drift_j),   g_j(0) = 0,   alarm when g_j > thresholds[j]
//! ```
//! A step of size `mu > drift` on output j alarms `ceil(threshold / (mu - drift))` samples after it
//! starts (noise-free). The gain, thresholds and isolation are the seed filter's (`filter.rs`); the lane
//! path runs the sum vectorised ([`LaneStatistic::Accumulated`]).

use super::decision::{Decision, LaneStatistic, ResidualTest, TestState};
use super::filter::{DetectionFilterParams, DetectorDeck, read_eigenstructure_filter};
use crate::engine::scenario::deck::DeckError;

/// The CUSUM test with its allowance per sample and output (output units).
#[derive(Debug, Clone, PartialEq)]
pub struct Cusum {
    pub drift: Vec<f64>,
}

impl ResidualTest for Cusum {
    fn describe(&self) -> String {
        let d: Vec<String> = self.drift.iter().map(|v| format!("{v}")).collect();
        format!("cusum on |residual|, drift [{}]", d.join(", "))
    }

    fn start(&self, outputs: usize, _dt_s: f64) -> Box<dyn TestState> {
        Box::new(CusumState { drift: self.drift.clone(), g: vec![0.0; outputs] })
    }

    fn kind(&self) -> &'static str {
        "cusum"
    }

    fn on_lanes(&self) -> Option<LaneStatistic> {
        Some(LaneStatistic::Accumulated { drift: self.drift.clone() })
    }
}

#[derive(Clone)]
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

    fn fork(&self) -> Option<Box<dyn TestState>> {
        Some(Box::new(self.clone()))
    }
}

/// Reads detector `i` of `kind = "cusum"`: the seed filter's fields plus `drift`, one per output, >= 0.
pub(crate) fn read(r: &DetectorDeck) -> Result<DetectionFilterParams, DeckError> {
    let DetectorDeck { chk, i, d, plant, .. } = *r;
    let field = format!("detector[{i}].drift");
    let ny = plant.n_outputs();
    let drift = d.drift.as_ref().ok_or_else(|| {
        chk.err(
            &field,
            format!("required for kind = \"cusum\": {ny} numbers, the residual each output may carry per sample without counting as evidence"),
        )
    })?;
    let drift = chk.vector(&field, drift, ny, "one per output, output units per sample")?;
    if let Some(k) = drift.iter().position(|v| *v < 0.0) {
        return Err(chk.err(format!("{field}[{k}]"), format!("must be >= 0, got {}", drift[k])));
    }
    read_eigenstructure_filter(r, Decision::new(Cusum { drift: drift.iter().copied().collect() }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step of size mu > drift on a noise-free residual: g rises by (mu - drift) per sample, so a
    /// threshold h alarms at the ceil(h / (mu - drift))-th sample of the step.
    #[test]
    fn cusum_detects_a_step_after_the_delay_its_parameters_imply() {
        let (mu, drift, h) = (0.3, 0.1, 0.9);
        let mut state = Cusum { drift: vec![drift, drift] }.start(2, 0.01);
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
}
