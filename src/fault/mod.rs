//! Fault models on one channel (the fault kinds of `docs/deck.md`): a sensor's output, or an
//! actuator's input (detection-filter decks: the command the controller sends is what the detectors
//! see, the faulty value is what the plant gets). Method 004's control-surface faults, with their
//! actuator lag, are in [`crate::methods::surface_bank::actuator`].
//!
//! With `y_in` the healthy value (a noisy sensor output, or the commanded input) and `t0` the onset,
//! for `t >= t0`:
//!
//! | mode          | faulty value                                | `size` means                    |
//! |---------------|---------------------------------------------|---------------------------------|
//! | stuck         | `c`: a given value, or `y_in` held at onset | the value (channel units), or none |
//! | gain          | `a * y_in`                                  | `a` (dimensionless, != 1)       |
//! | bias          | `y_in + b`                                  | `b` (channel units, != 0)       |
//! | total failure | `0` (sensors)                               | none                            |
//! | float         | `0` (actuators: the deviation from trim)    | none                            |
//! | drift         | `y_in + s (t - t0)`                         | `s` (channel units per second)  |
//! | oscillation   | `y_in + A sin(2 pi f (t - t0))`             | `A` (channel units), plus `f`   |
//!
//! A held stuck value is the channel's value at the first sample at or after onset (noise included):
//! a frozen sensor repeats what it last produced, a jammed actuator stays where it was commanded last.
//! A floating surface carries no hinge moment and trails with the airflow; a model's inputs cannot
//! say where that is, so fdimc puts it at the trim (deviation 0), its own choice. Several faults on one
//! channel apply in deck order.

pub mod deck;

use serde::Serialize;

/// What a faulty sensor does. Sizes are in the channel's own units (see the module table).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FaultMode {
    Stuck { value: Option<f64> },
    Gain { factor: f64 },
    Bias { bias: f64 },
    TotalFailure,
    Float,
    Drift { rate_per_s: f64 },
    Oscillation { amplitude: f64, frequency_hz: f64 },
}

impl FaultMode {
    /// The deck name of the mode.
    pub fn name(&self) -> &'static str {
        match self {
            FaultMode::Stuck { .. } => "stuck",
            FaultMode::Gain { .. } => "gain",
            FaultMode::Bias { .. } => "bias",
            FaultMode::TotalFailure => "total_failure",
            FaultMode::Float => "float",
            FaultMode::Drift { .. } => "drift",
            FaultMode::Oscillation { .. } => "oscillation",
        }
    }

    /// The records' `kind` of the mode on an actuator: `actuator_<name>`.
    pub fn actuator_name(&self) -> &'static str {
        match self {
            FaultMode::Stuck { .. } => "actuator_stuck",
            FaultMode::Gain { .. } => "actuator_gain",
            FaultMode::Bias { .. } => "actuator_bias",
            FaultMode::TotalFailure => "actuator_total_failure",
            FaultMode::Float => "actuator_float",
            FaultMode::Drift { .. } => "actuator_drift",
            FaultMode::Oscillation { .. } => "actuator_oscillation",
        }
    }

    /// The deck's `size` (NaN where the mode has none, e.g. a held stuck value).
    pub fn size(&self) -> f64 {
        match *self {
            FaultMode::Stuck { value } => value.unwrap_or(f64::NAN),
            FaultMode::Gain { factor } => factor,
            FaultMode::Bias { bias } => bias,
            FaultMode::TotalFailure | FaultMode::Float => f64::NAN,
            FaultMode::Drift { rate_per_s } => rate_per_s,
            FaultMode::Oscillation { amplitude, .. } => amplitude,
        }
    }
}

/// One fault on one channel: a sensor output, or an actuator input (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ChannelFault {
    /// Index of the faulty channel among the outputs (sensor faults) or the inputs (actuator faults).
    pub channel: usize,
    pub onset_s: f64,
    #[serde(flatten)]
    pub mode: FaultMode,
}

/// The faults of one trial with their run-time state (the values held by stuck sensors).
#[derive(Debug, Clone)]
pub struct ActiveFaults {
    faults: Vec<ChannelFault>,
    held: Vec<Option<f64>>,
}

impl ActiveFaults {
    pub fn new(faults: Vec<ChannelFault>) -> Self {
        let held = vec![None; faults.len()];
        ActiveFaults { faults, held }
    }

    /// Earliest onset of any fault (`None` for a fault-free trial).
    pub fn first_onset_s(&self) -> Option<f64> {
        self.faults.iter().map(|f| f.onset_s).min_by(f64::total_cmp)
    }

    /// Replaces healthy outputs `y` (in place) by what the faulty sensors report at time `t_s`.
    pub fn apply(&mut self, t_s: f64, y: &mut [f64]) {
        for (fault, held) in self.faults.iter().zip(self.held.iter_mut()) {
            if t_s >= fault.onset_s {
                y[fault.channel] = fault.reading(t_s, y[fault.channel], held);
            }
        }
    }

    /// [`apply`](Self::apply) on lane `lane` of outputs stored lane-wise (`y[channel][lane]`).
    #[inline]
    pub fn apply_to_lane<const LANES: usize>(&mut self, t_s: f64, y: &mut [[f64; LANES]], lane: usize) {
        for (fault, held) in self.faults.iter().zip(self.held.iter_mut()) {
            if t_s >= fault.onset_s {
                let v = &mut y[fault.channel][lane];
                *v = fault.reading(t_s, *v, held);
            }
        }
    }
}

impl ChannelFault {
    /// What the sensor reports at `t_s >= onset_s` when the healthy reading is `y_in`; `held` keeps a
    /// held stuck value.
    #[inline]
    fn reading(&self, t_s: f64, y_in: f64, held: &mut Option<f64>) -> f64 {
        let dt = t_s - self.onset_s;
        match self.mode {
            FaultMode::Stuck { value: Some(c) } => c,
            FaultMode::Stuck { value: None } => *held.get_or_insert(y_in),
            FaultMode::Gain { factor } => factor * y_in,
            FaultMode::Bias { bias } => y_in + bias,
            FaultMode::TotalFailure | FaultMode::Float => 0.0,
            FaultMode::Drift { rate_per_s } => y_in + rate_per_s * dt,
            FaultMode::Oscillation { amplitude, frequency_hz } => {
                y_in + amplitude * (std::f64::consts::TAU * frequency_hz * dt).sin()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Applies `mode` on channel 1 with onset 2 s to a healthy signal y = [10, 3 + t], returns channel 1.
    fn run(mode: FaultMode, times: &[f64]) -> Vec<f64> {
        let mut f = ActiveFaults::new(vec![ChannelFault { channel: 1, onset_s: 2.0, mode }]);
        times
            .iter()
            .map(|&t| {
                let mut y = [10.0, 3.0 + t];
                f.apply(t, &mut y);
                assert_eq!(y[0], 10.0, "other channels untouched");
                y[1]
            })
            .collect()
    }

    const T: [f64; 4] = [0.0, 1.99, 2.0, 5.0];

    #[test]
    fn every_mode_follows_its_formula() {
        let healthy = [3.0, 4.99];
        let cases: [(FaultMode, [f64; 2]); 8] = [
            (FaultMode::Stuck { value: Some(-1.5) }, [-1.5, -1.5]),
            (FaultMode::Stuck { value: None }, [5.0, 5.0]),
            (FaultMode::Gain { factor: 1.5 }, [7.5, 12.0]),
            (FaultMode::Bias { bias: 0.1 }, [5.1, 8.1]),
            (FaultMode::TotalFailure, [0.0, 0.0]),
            (FaultMode::Float, [0.0, 0.0]),
            (FaultMode::Drift { rate_per_s: 0.5 }, [5.0, 8.0 + 1.5]),
            (
                FaultMode::Oscillation { amplitude: 2.0, frequency_hz: 0.25 },
                [5.0, 8.0 + 2.0 * (std::f64::consts::TAU * 0.75).sin()],
            ),
        ];
        for (mode, after) in cases {
            let got = run(mode, &T);
            let want = [healthy[0], healthy[1], after[0], after[1]];
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-12, "{mode:?}: got {got:?}, want {want:?}");
            }
        }
    }

    #[test]
    fn faults_on_one_channel_compose_in_order() {
        let mut f = ActiveFaults::new(vec![
            ChannelFault { channel: 0, onset_s: 1.0, mode: FaultMode::Gain { factor: 2.0 } },
            ChannelFault { channel: 0, onset_s: 3.0, mode: FaultMode::Bias { bias: 1.0 } },
        ]);
        let mut at = |t: f64| {
            let mut y = [4.0];
            f.apply(t, &mut y);
            y[0]
        };
        assert_eq!([at(0.0), at(1.0), at(3.0)], [4.0, 8.0, 9.0]);
        assert_eq!(ActiveFaults::new(vec![]).first_onset_s(), None);
    }
}
