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
        for (pe, &rel) in self.study.monte_carlo.parameter_errors.iter().zip(&spec.parameter_errors) {
            if pe.model != target {
                continue;
            }
            let m = if pe.matrix_b { &mut p.B } else { &mut p.A };
            for &(r, c) in &pe.entries {
                if pe.absolute {
                    m[(r, c)] += rel;
                } else {
                    m[(r, c)] *= 1.0 + rel;
                }
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
        // Move the designed filters out (no second copy); keep each failed design's reason in its slot.
        let mut ok = Vec::with_capacity(self.study.detectors.len());
        let slots: Vec<Result<(), DesignError>> =
            self.filters(&spec).into_iter().map(|d| d.map(|f| ok.push(f))).collect();
        let mut outcomes = run_trial(self.study, &self.truth(&spec), &spec, &mut ok, None).into_iter();
        let detectors =
            slots.into_iter().map(|d| d.map(|()| outcomes.next().expect("one outcome per filter"))).collect();
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    const ROBUST: &str = include_str!("../../studies/seed000_robustness.toml");

    fn study(extra: &str) -> Study {
        Study::from_toml(&format!("{ROBUST}\n{extra}"), Path::new("robust.toml")).unwrap()
    }

    #[test]
    fn parameter_errors_scale_or_shift_the_listed_entries_of_the_chosen_model() {
        let s = study(
            "[[monte_carlo.parameter_error]]\nname = \"speed\"\nmodel = \"plant\"\nmatrix = \"a\"\n\
             entries = [[\"h_m\", \"theta_rad\"]]\nabsolute = 10.0\n",
        );
        let e = Engine::new(&s);
        let spec = e.spec(0);
        assert_eq!(spec.parameter_errors, vec![-0.2, -0.2, 10.0], "grid cell 0 of pitch_moment x elevator");
        let design = e.perturbed(&s.design_plant, &spec, ModelTarget::Design);
        assert_eq!(design.A[(2, 1)], -7.9101 * 0.8);
        assert_eq!(design.A[(2, 2)], -3.0241 * 0.8);
        assert_eq!(design.B[(2, 1)], -26.3821 * 0.8);
        assert_eq!(design.A[(4, 3)], 272.24, "the absolute error is on the true plant only");
        let truth = e.perturbed(&s.plant, &spec, ModelTarget::Plant);
        assert_eq!(truth.A[(4, 3)], 282.24);
        assert_eq!(truth.A[(2, 1)], -7.9101);
        // The gains follow the design model: recomputed, still assigning -1..-5 on it.
        let filters = e.filters(&spec);
        let k = &filters[0].as_ref().unwrap().continuous.K;
        assert!((k - &e.nominal_filters()[0].as_ref().unwrap().continuous.K).amax() > 1.0);
        let closed = &design.A - k * &design.C;
        assert!((closed[(2, 2)] + 3.0).abs() < 1e-9 && closed[(2, 1)].abs() < 1e-9);
    }

    #[test]
    fn latin_hypercube_puts_one_trial_in_each_stratum() {
        let mut s = study("");
        s.monte_carlo.trials = 240;
        let e = Engine::new(&s);
        let specs: Vec<TrialSpec> = (0..240).map(|t| e.spec(t)).collect();
        // Fault-free trials still draw their units; faulty ones carry the onset. Use all the faulty ones.
        let mut strata: Vec<usize> = specs
            .iter()
            .filter(|sp| sp.onset_s.is_finite())
            .map(|sp| ((sp.onset_s - 5.0) / 15.0 * 240.0) as usize)
            .collect();
        let faulty = strata.len();
        strata.sort();
        strata.dedup();
        assert_eq!(strata.len(), faulty, "two faulty trials share an onset stratum");
        let fault_free = 240 - faulty;
        assert!((30..=70).contains(&fault_free), "{fault_free} fault-free of 240 at fraction 0.2");
        // Kind is the fastest grid digit: each of the 4 kinds gets a quarter of the faulty trials.
        for kind in ["bias", "gain", "stuck", "total_failure"] {
            let n = specs.iter().filter(|sp| sp.kind == kind).count();
            assert!((n as f64 - faulty as f64 / 4.0).abs() <= 12.0, "{kind}: {n}");
        }
    }
}
