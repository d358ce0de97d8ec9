//! From a trial index to its result: scenario, perturbed models, detector designs, simulation.
//! Designs and the sampled true plant are computed once when no parameter error touches them.

use crate::design::DesignError;
use crate::detector::DetectionFilter;
use crate::plant::{DiscreteLti, LtiPlant};
use crate::sampling::{ScenarioSampler, TrialSpec};
use crate::study::{ModelTarget, Study};

use super::{DetectorOutcome, Trace, run_trial};

/// One trial's scenario and, per detector configuration (deck order), its outcome or why its design
/// failed for this trial's design model.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResult {
    pub spec: TrialSpec,
    pub detectors: Vec<Result<DetectorOutcome, DesignError>>,
}

pub struct Engine<'a> {
    study: &'a Study,
    sampler: ScenarioSampler<'a>,
    nominal_truth: DiscreteLti,
    nominal_filters: Vec<Result<DetectionFilter, DesignError>>,
    perturb_truth: bool,
    perturb_design: bool,
}

impl<'a> Engine<'a> {
    pub fn new(study: &'a Study) -> Self {
        let sampler = ScenarioSampler::new(study);
        let perturb_truth = sampler.perturbs(ModelTarget::Plant);
        let perturb_design = sampler.perturbs(ModelTarget::Design);
        Engine {
            study,
            nominal_truth: study.plant.discretise(study.dt_s),
            nominal_filters: study.detectors.iter().map(|d| d.params.design(&study.design_plant, study.dt_s)).collect(),
            sampler,
            perturb_truth,
            perturb_design,
        }
    }

    /// The nominal designs (deck order), for reports and to fail fast on an infeasible deck.
    pub fn nominal_filters(&self) -> &[Result<DetectionFilter, DesignError>] {
        &self.nominal_filters
    }

    pub fn spec(&self, trial: u64) -> TrialSpec {
        self.sampler.spec(trial)
    }

    /// `base` with the trial's parameter errors on `target` applied.
    fn perturbed(&self, base: &LtiPlant, spec: &TrialSpec, target: ModelTarget) -> LtiPlant {
        let mut p = base.clone();
        for (pe, rel) in self.study.monte_carlo.parameter_errors.iter().zip(&spec.parameter_errors) {
            if pe.model != target {
                continue;
            }
            let m = if pe.matrix_b { &mut p.B } else { &mut p.A };
            for &(r, c) in &pe.entries {
                m[(r, c)] *= 1.0 + rel;
            }
        }
        p
    }

    fn filters(&self, spec: &TrialSpec) -> Vec<Result<DetectionFilter, DesignError>> {
        if !self.perturb_design {
            return self.nominal_filters.clone();
        }
        let design = self.perturbed(&self.study.design_plant, spec, ModelTarget::Design);
        self.study.detectors.iter().map(|d| d.params.design(&design, self.study.dt_s)).collect()
    }

    fn truth(&self, spec: &TrialSpec) -> std::borrow::Cow<'_, DiscreteLti> {
        if self.perturb_truth {
            let p = self.perturbed(&self.study.plant, spec, ModelTarget::Plant);
            std::borrow::Cow::Owned(p.discretise(self.study.dt_s))
        } else {
            std::borrow::Cow::Borrowed(&self.nominal_truth)
        }
    }

    /// Runs every detector configuration on trial `trial`.
    pub fn run(&self, trial: u64) -> TrialResult {
        let spec = self.spec(trial);
        let designs = self.filters(&spec);
        let mut ok: Vec<DetectionFilter> = designs.iter().filter_map(|d| d.as_ref().ok().cloned()).collect();
        let mut outcomes = run_trial(self.study, &self.truth(&spec), &spec, &mut ok, None).into_iter();
        let detectors =
            designs.into_iter().map(|d| d.map(|_| outcomes.next().expect("one outcome per filter"))).collect();
        TrialResult { spec, detectors }
    }

    /// Runs detector `detector` alone on trial `trial`, tracing every sample.
    pub fn simulate(
        &self,
        trial: u64,
        detector: usize,
        trace: &mut Trace,
    ) -> Result<(TrialSpec, DetectorOutcome), DesignError> {
        let spec = self.spec(trial);
        let mut filter = [self.filters(&spec).swap_remove(detector)?];
        let outcome = run_trial(self.study, &self.truth(&spec), &spec, &mut filter, Some(trace)).remove(0);
        Ok((spec, outcome))
    }
}
