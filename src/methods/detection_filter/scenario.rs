//! Detection-filter trial scenarios (method 000): which sensor fault (kind, output, size, onset), noise
//! level and parameter errors trial i has, by the shared scheme of [`crate::engine::scenario::draws`].

use super::study::LtiStudy;
use crate::engine::results::schema::ExactDelays;
use crate::engine::scenario::deck::{ModelTarget, time_to_hazard};
use crate::engine::scenario::design::{Factors, Part, Slot};
use crate::engine::scenario::draws::{DIM_NOISE, DIM_ONSET, DIM_SIZE, FIRST_OWN_DIM, UnitSampler};
use crate::fault::deck::{FaultTarget, TrialFaults};

/// Continuous-factor dimensions, fixed so a trial's draws do not depend on which factors are present.
pub(super) const DIM_PARAMETERS: usize = FIRST_OWN_DIM;

/// One trial's scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialSpec {
    pub trial: u64,
    /// The trial whose noise streams this one uses: itself, except in a sensitivity design.
    pub noise_trial: u64,
    /// The trial's faults and their labels.
    pub fault: TrialFaults,
    pub noise_scale: f64,
    pub noise_bin: f64,
    /// Relative error of each `monte_carlo.parameter_error`, in deck order.
    pub parameter_errors: Vec<f64>,
    /// Largest |group label| of the parameter errors (0 without any).
    pub parameter_error_bin: f64,
}

impl TrialSpec {
    /// The name of the faulty channel the records give (an output, or an input for an actuator
    /// fault); `None` when fault-free.
    pub fn target_name<'s>(&self, study: &'s LtiStudy) -> Option<&'s str> {
        self.fault.target().map(|t| match t {
            FaultTarget::Output(j) => study.plant.output_names[j].as_str(),
            FaultTarget::Input(j) => study.failing_inputs[j].as_str(),
        })
    }

    /// Where this trial's profiles keep the running maximum exactly: at the end of the detection window
    /// and at the fault's time to hazard, after its onset (the detection and the miss before the hazard
    /// then replay exactly at any threshold).
    pub fn exact_delays(&self, study: &LtiStudy) -> ExactDelays {
        let common = &study.monte_carlo.common;
        let hazard_s = self
            .target_name(study)
            .and_then(|target| time_to_hazard(&common.time_to_hazard_s, self.fault.kind, target));
        ExactDelays::new(self.fault.onset_s, [common.detection_window_s, hazard_s.unwrap_or(f64::INFINITY)])
    }
}

/// Draws trial scenarios for one study.
pub struct ScenarioSampler<'a> {
    study: &'a LtiStudy,
    units: UnitSampler,
}

impl<'a> ScenarioSampler<'a> {
    pub fn new(study: &'a LtiStudy) -> Self {
        let mc = &study.monte_carlo;
        let dims = DIM_PARAMETERS + mc.parameter_errors.len();
        ScenarioSampler { study, units: UnitSampler::for_study(&mc.common, study.header.seed, dims) }
    }

    /// The scenario of trial `trial`.
    pub fn spec(&self, trial: u64) -> TrialSpec {
        let s = self.study;
        let mc = &s.monte_carlo;
        let mut t = self.units.trial(trial);

        // Sampled population: kind and channel first (the fastest grid digits): an output, or one of
        // an actuator population's inputs.
        let sampled = (!mc.faults.is_empty()).then(|| {
            let k = t.digit(mc.faults.len());
            let channels = if mc.faults[k].inputs.is_empty() { &mc.outputs } else { &mc.faults[k].inputs };
            (k, channels[t.digit(channels.len())])
        });
        let size_pick = sampled.map(|(k, _)| mc.faults[k].size.draw(&mut t, DIM_SIZE));
        let (onset, noise_scale, noise_bin) = t.onset_and_noise(&mc.common);
        let (parameter_errors, parameter_error_bin) = t.parameter_errors(&mc.parameter_errors, DIM_PARAMETERS);

        let mut spec = TrialSpec {
            trial,
            noise_trial: self.units.noise_trial(trial),
            fault: TrialFaults::none(),
            noise_scale,
            noise_bin,
            parameter_errors,
            parameter_error_bin,
        };
        if t.fault_free {
            return spec;
        }
        match (sampled, size_pick) {
            (Some((k, channel)), Some(size)) => {
                spec.fault = TrialFaults::drawn(&mc.faults[k], &[channel], size, onset, |j| s.sensor_sigma[j]);
            }
            _ => {
                spec.fault = TrialFaults::fixed(&s.faults, &s.actuator_faults);
            }
        }
        spec
    }

    /// The factors a sensitivity design varies: those of the deck that trials draw, where [`Self::spec`]
    /// takes them. Faulty trials: fault kind and output (the first two grid digits), size, onset, noise
    /// scale, parameter errors; fault-free trials: noise scale and parameter errors. (With actuator
    /// populations the `output` digit picks the population's input.)
    pub fn sensitivity_parts(study: &LtiStudy) -> Vec<Part> {
        let mc = &study.monte_carlo;
        let mut shared = Factors::default();
        shared.add("noise_scale", Slot::Dim(DIM_NOISE), mc.common.noise_scale.is_sampled());
        for (k, pe) in mc.parameter_errors.iter().enumerate() {
            shared.add(&pe.name, Slot::Dim(DIM_PARAMETERS + k), pe.value.is_sampled());
        }
        let mut faulty = Factors::default();
        if !mc.faults.is_empty() {
            faulty.add("fault_kind", Slot::Digit(0), mc.faults.len() > 1);
            let channels = |f: &crate::fault::deck::FaultKindSpec| {
                if f.inputs.is_empty() { mc.outputs.len() } else { f.inputs.len() }
            };
            faulty.add("output", Slot::Digit(1), mc.faults.iter().any(|f| channels(f) > 1));
            faulty.add("size", Slot::Dim(DIM_SIZE), mc.faults.iter().any(|f| f.size.is_sampled()));
            faulty.add("onset_s", Slot::Dim(DIM_ONSET), mc.common.onset_s.is_sampled());
        }
        let has_faults = !mc.faults.is_empty() || !study.faults.is_empty() || !study.actuator_faults.is_empty();
        Factors::parts(has_faults.then_some(faulty), shared)
    }

    /// Whether any parameter error perturbs `target`.
    pub fn perturbs(&self, target: ModelTarget) -> bool {
        self.study.monte_carlo.parameter_errors.iter().any(|p| p.model == target)
    }
}
