//! From a trial index to its result: scenario, perturbed models, detector designs, simulation.
//! Designs and the sampled true plant are computed once when no parameter error touches them; designs
//! of a perturbed design model are kept per distinct set of its errors (a deck that lists error values
//! has few), up to [`DESIGN_CACHE`] of them.

use std::borrow::Cow;
use std::sync::Arc;

use crate::design::DesignError;
use crate::engine::scenario::deck::{Factor, ModelTarget};
use crate::lti::{DiscreteLti, LtiPlant};
use crate::methods::detection_filter::filter::DetectionFilter;
use crate::methods::detection_filter::scenario::{ScenarioSampler, TrialSpec};
use crate::methods::detection_filter::study::{LtiStudy, Perturbs};

use crate::engine::run::output::Trace;
use crate::methods::detection_filter::kernel::{
    FilterPatterns, LANES, LaneFilter, LanePlant, PlantPatterns, Vectors, with_form,
};
use crate::methods::detection_filter::kernel::{FilterStep, PlantStep};
use crate::methods::detection_filter::lanes::{LaneDetector, run_lanes};
use crate::methods::detection_filter::trial::{DetectorOutcome, FmuFailure, run_trial};

/// One trial's scenario and, per detector configuration (deck order), its outcome or why it has none.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResult {
    pub spec: TrialSpec,
    pub detectors: Vec<Result<DetectorOutcome, TrialFailure>>,
}

/// Why a detector configuration has no outcome in a trial (the record's `failure`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrialFailure {
    /// Its design failed for this trial's design model.
    #[error(transparent)]
    Design(#[from] DesignError),
    /// An FMU of the trial (its truth, controller or a detector) failed during it: every detector of
    /// the trial fails with it.
    #[error(transparent)]
    Fmu(FmuFailure),
    /// A failure as a worker process reported it, or the worker's own death (`run --fmu-processes`).
    #[error("{0}")]
    Reported(String),
    /// A diverged truth as a worker process reported it: when, and the failure's text.
    #[error("{why}")]
    Diverged { at_s: f64, why: String },
}

impl TrialFailure {
    /// When the trial's truth diverged (a failure that is also `diverged` in the records).
    pub fn diverged_at_s(&self) -> Option<f64> {
        match self {
            TrialFailure::Fmu(f) => f.diverged_at_s,
            TrialFailure::Diverged { at_s, .. } => Some(*at_s),
            TrialFailure::Design(_) | TrialFailure::Reported(_) => None,
        }
    }
}

pub struct Engine<'a> {
    study: &'a LtiStudy,
    sampler: ScenarioSampler<'a>,
    nominal_truth: DiscreteLti,
    /// Shared with the trials whose design model is not perturbed.
    nominal_designs: Vec<Design>,
    perturb_truth: bool,
    perturb_design: bool,
    plant_patterns: PlantPatterns,
    filter_patterns: Vec<FilterPatterns>,
    /// Lane forms of the nominal models, built once when no parameter error changes them per trial.
    lane_plant: Option<LanePlant>,
    lane_filters: Vec<Option<LaneFilter>>,
    /// Every detector's test is built in and no FMU flies: groups go on the lane path (decided once,
    /// not per group).
    on_lanes: bool,
    /// Designs of perturbed design models, by the bits of the trial's design-model errors: a design is
    /// a function of its model alone, so a kept one is the one the trial would compute. Kept only when
    /// every design-model error is fixed or listed (a range makes every trial's model new).
    keep_designs: bool,
    designs_seen: std::sync::RwLock<std::collections::HashMap<Vec<u64>, Vec<Design>>>,
}

/// How many distinct design models' designs an [`Engine`] keeps (listed errors: at most the product of
/// their counts).
pub const DESIGN_CACHE: usize = 4096;

/// A trial's design of one detector configuration: the nominal one when the design model is not
/// perturbed, else its own; shared, not copied (a design is a dozen matrices).
pub type Design = Result<Arc<DetectionFilter>, DesignError>;

impl<'a> Engine<'a> {
    pub fn new(study: &'a LtiStudy) -> Self {
        let sampler = ScenarioSampler::new(study);
        let perturb_truth = sampler.perturbs(ModelTarget::Plant);
        let perturb_design = sampler.perturbs(ModelTarget::Design);
        let nominal_truth = study.plant.discretise(study.header.dt_s);
        let nominal_designs: Vec<Design> = (study.detectors.iter())
            .map(|d| d.params.design(&study.design_plant, study.header.dt_s).map(Arc::new))
            .collect();
        let plant_patterns = PlantPatterns::new(&nominal_truth, &study.output_feedback, perturb_truth);
        let filter_patterns: Vec<FilterPatterns> = nominal_designs
            .iter()
            .map(|f| FilterPatterns::new(&study.design_plant, f.as_deref().ok(), perturb_design))
            .collect();
        let lane_plant = (!perturb_truth)
            .then(|| LanePlant::new(&plant_patterns, &[Some(&nominal_truth); LANES], &study.output_feedback));
        let lane_filters = nominal_designs
            .iter()
            .zip(&filter_patterns)
            .map(|(f, p)| match f {
                Ok(f) if !perturb_design => Some(LaneFilter::new(p, &[Some(&**f); LANES])),
                _ => None,
            })
            .collect();
        Engine {
            study,
            sampler,
            nominal_truth,
            nominal_designs,
            perturb_truth,
            perturb_design,
            plant_patterns,
            filter_patterns,
            lane_plant,
            lane_filters,
            on_lanes: study.fmus().is_empty()
                && !study.has_actuator_faults()
                && study.detectors.iter().all(|d| d.params.runs_on_lanes()),
            keep_designs: perturb_design
                && (study.monte_carlo.parameter_errors.iter())
                    .filter(|pe| pe.model == ModelTarget::Design)
                    .all(|pe| !matches!(pe.value, Factor::Range { .. })),
            designs_seen: Default::default(),
        }
    }

    /// The nominal designs (deck order), for reports and to fail fast on an infeasible deck.
    pub fn nominal_filters(&self) -> &[Design] {
        &self.nominal_designs
    }

    pub fn spec(&self, trial: u64) -> TrialSpec {
        self.sampler.spec(trial)
    }

    /// The detector configurations every trial flies.
    pub fn detectors(&self) -> usize {
        self.study.detectors.len()
    }

    /// `base` with the trial's parameter errors on `target` applied.
    fn perturbed(&self, base: &LtiPlant, spec: &TrialSpec, target: ModelTarget) -> LtiPlant {
        let mut p = base.clone();
        for (pe, &rel) in self.study.monte_carlo.parameter_errors.iter().zip(&spec.parameter_errors) {
            if pe.model != target {
                continue;
            }
            let Perturbs::Matrix(what) = &pe.what else { continue };
            let m = if what.matrix_b { &mut p.B } else { &mut p.A };
            for &(r, c) in &what.entries {
                if pe.absolute {
                    m[(r, c)] += rel;
                } else {
                    m[(r, c)] *= 1.0 + rel;
                }
            }
        }
        p
    }

    /// The trial's design of every detector configuration (deck order).
    fn designs(&self, spec: &TrialSpec) -> Vec<Design> {
        self.designs_of(spec, 0..self.study.detectors.len())
    }

    /// The trial's design of the detector configurations `which` (deck indices), in that order.
    fn designs_of(&self, spec: &TrialSpec, which: std::ops::Range<usize>) -> Vec<Design> {
        if !self.perturb_design {
            return self.nominal_designs[which].to_vec();
        }
        let key: Vec<u64> = (self.study.monte_carlo.parameter_errors.iter().zip(&spec.parameter_errors))
            .filter(|(pe, _)| pe.model == ModelTarget::Design)
            .map(|(_, e)| e.to_bits())
            .collect();
        if let Some(all) = self.designs_seen.read().expect("no panic while holding it").get(&key) {
            return all[which].to_vec();
        }
        let design = self.perturbed(&self.study.design_plant, spec, ModelTarget::Design);
        let all: Vec<Design> = (self.study.detectors.iter())
            .map(|d| d.params.design(&design, self.study.header.dt_s).map(Arc::new))
            .collect();
        let designs = all[which].to_vec();
        if self.keep_designs {
            let mut seen = self.designs_seen.write().expect("no panic while holding it");
            if seen.len() < DESIGN_CACHE {
                seen.insert(key, all);
            }
        }
        designs
    }

    fn truth(&self, spec: &TrialSpec) -> Cow<'_, DiscreteLti> {
        if self.perturb_truth {
            let p = self.perturbed(&self.study.plant, spec, ModelTarget::Plant);
            Cow::Owned(p.discretise(self.study.header.dt_s))
        } else {
            Cow::Borrowed(&self.nominal_truth)
        }
    }

    /// Runs trial `spec` on the one-trial path with the given designs of the given detector
    /// configurations (deck indices); `trace` records the first.
    fn run_one<'d>(
        &self,
        spec: &TrialSpec,
        filters: impl Iterator<Item = (usize, &'d DetectionFilter)>,
        trace: Option<&mut Trace>,
    ) -> Result<Vec<DetectorOutcome>, FmuFailure> {
        let s = self.study;
        let plant = PlantStep::new(&self.plant_patterns, &[Some(&*self.truth(spec))], &s.output_feedback);
        let filters: Vec<(&DetectionFilter, FilterStep)> =
            filters.map(|(d, design)| (design, FilterStep::new(&self.filter_patterns[d], &[Some(design)]))).collect();
        run_trial(s, &plant, spec, &filters, trace)
    }

    /// Trial `spec`'s true plant and detector `detector`'s design for the one-trial path.
    pub fn one_trial_models(
        &self,
        spec: &TrialSpec,
        detector: usize,
    ) -> Result<(PlantStep, DetectionFilter, FilterStep), DesignError> {
        let plant = PlantStep::new(&self.plant_patterns, &[Some(&*self.truth(spec))], &self.study.output_feedback);
        // Only this detector's design (a perturbed model's designs are kept for the next trial of it).
        let design = Arc::unwrap_or_clone(self.designs_of(spec, detector..detector + 1).remove(0)?);
        let step = FilterStep::new(&self.filter_patterns[detector], &[Some(&design)]);
        Ok((plant, design, step))
    }

    /// Runs every detector configuration on trial `trial`, one trial at a time (the general path).
    pub fn run(&self, trial: u64) -> TrialResult {
        let spec = self.spec(trial);
        let designs = self.designs(&spec);
        let ok = designs.iter().enumerate().filter_map(|(d, f)| Some((d, f.as_deref().ok()?)));
        let detectors = match self.run_one(&spec, ok, None) {
            Ok(outcomes) => {
                let mut outcomes = outcomes.into_iter();
                designs
                    .into_iter()
                    .map(|d| match d {
                        Ok(_) => Ok(outcomes.next().expect("one outcome per designed filter")),
                        Err(e) => Err(TrialFailure::Design(e)),
                    })
                    .collect()
            }
            Err(e) => designs
                .into_iter()
                .map(|d| Err(d.err().map_or_else(|| TrialFailure::Fmu(e.clone()), TrialFailure::Design)))
                .collect(),
        };
        TrialResult { spec, detectors }
    }

    /// Trials `first..end` (at most [`LANES`]): on the lane path when every detector's test is built
    /// in, else one at a time (a user's test is a trait object); the results are the same.
    pub fn run_group(&self, first: u64, end: u64) -> Vec<TrialResult> {
        if self.on_lanes { self.run_lanes(first, end) } else { (first..end).map(|t| self.run(t)).collect() }
    }

    /// Runs every detector configuration on trials `first..end` (at most [`LANES`]) together on the
    /// lane path: the same results as [`run`](Self::run) on each trial, several times faster.
    pub fn run_lanes(&self, first: u64, end: u64) -> Vec<TrialResult> {
        let s = self.study;
        assert!(s.detectors.iter().all(|d| d.params.runs_on_lanes()), "a test the lanes do not run");
        let specs: Vec<TrialSpec> = (first..end).map(|t| self.spec(t)).collect();
        let lane = |l: usize| (l < specs.len()).then_some(l);
        let truths: Vec<Cow<'_, DiscreteLti>> =
            if self.perturb_truth { specs.iter().map(|sp| self.truth(sp)).collect() } else { Vec::new() };
        let own_plant;
        let plant = match &self.lane_plant {
            Some(p) => p,
            None => {
                let lanes: [_; LANES] = std::array::from_fn(|l| lane(l).map(|l| &*truths[l]));
                own_plant = LanePlant::new(&self.plant_patterns, &lanes, &s.output_feedback);
                &own_plant
            }
        };
        let designs: Vec<Vec<Design>> = specs.iter().map(|sp| self.designs(sp)).collect();
        let own_filters: Vec<Option<LaneFilter>> = (0..s.detectors.len())
            .map(|d| {
                self.lane_filters[d].is_none().then(|| {
                    let lanes: [_; LANES] =
                        std::array::from_fn(|l| lane(l).and_then(|l| designs[l][d].as_deref().ok()));
                    LaneFilter::new(&self.filter_patterns[d], &lanes)
                })
            })
            .collect();
        let detectors: Vec<LaneDetector> = (0..s.detectors.len())
            .map(|d| LaneDetector {
                filter: self.lane_filters[d].as_ref().or(own_filters[d].as_ref()).expect("shared or own"),
                designs: std::array::from_fn(|l| lane(l).and_then(|l| designs[l][d].as_deref().ok())),
                params: &s.detectors[d].params,
            })
            .collect();
        let mut outcomes: Vec<std::vec::IntoIter<Option<DetectorOutcome>>> =
            run_lanes(s, plant, &specs, &detectors).into_iter().map(Vec::into_iter).collect();
        let designs_ok: Vec<Vec<Result<(), DesignError>>> = designs
            .iter()
            .map(|ds| ds.iter().map(|d| d.as_ref().map(|_| ()).map_err(Clone::clone)).collect())
            .collect();
        specs
            .into_iter()
            .zip(designs_ok)
            .map(|(spec, ds)| {
                let detectors = ds
                    .into_iter()
                    .zip(outcomes.iter_mut())
                    .map(|(d, o)| {
                        let outcome = o.next().expect("one entry per trial");
                        d.map(|()| outcome.expect("a designed lane has an outcome")).map_err(TrialFailure::Design)
                    })
                    .collect();
                TrialResult { spec, detectors }
            })
            .collect()
    }

    /// Runs detector `detector` alone on trial `trial`, tracing every sample.
    pub fn simulate(
        &self,
        trial: u64,
        detector: usize,
        trace: &mut Trace,
    ) -> Result<(TrialSpec, DetectorOutcome), TrialFailure> {
        let spec = self.spec(trial);
        let designs = self.designs(&spec);
        let design = designs[detector].as_deref().map_err(|e| TrialFailure::Design(e.clone()))?;
        let outcome =
            self.run_one(&spec, std::iter::once((detector, design)), Some(trace)).map_err(TrialFailure::Fmu)?.remove(0);
        Ok((spec, outcome))
    }
}

/// Where the lane path and the one-trial path part, with the lanes in vector form `form` (one of
/// [`Vectors::available`]): `fdimc verify`'s check and the tests' that the lanes are only a faster way
/// to the same records. Trials `0..trials` of `study`'s detectors that run on lanes, in lane groups (a
/// ragged group of 3 first, so idle lanes too, then groups of [`LANES`]), against each trial run alone.
/// Returns the outcomes compared and the first that differs, described (`None`: all equal, field by
/// field; the specs as text, where NaN sizes compare).
pub fn lane_path_against_one_trial(study: &LtiStudy, trials: u64, form: Vectors) -> (u64, Option<String>) {
    let mut s = study.clone();
    s.monte_carlo.common.trials = trials;
    // The lanes run the built-in tests only (run_group sends the others one trial at a time).
    s.detectors.retain(|d| d.params.runs_on_lanes());
    let e = Engine::new(&s);
    let lanes = with_form(form, || {
        let mut lanes = Vec::new();
        let mut first = 0;
        while first < trials {
            let end = (first + if first == 0 { 3 } else { LANES as u64 }).min(trials);
            lanes.extend(e.run_lanes(first, end));
            first = end;
        }
        lanes
    });
    let mut compared = 0;
    for (t, lane) in (0..trials).zip(&lanes) {
        let one = e.run(t);
        if format!("{:?}", lane.spec) != format!("{:?}", one.spec) {
            return (
                compared,
                Some(format!("trial {t}: the specs differ:\nlanes    {:?}\none trial {:?}", lane.spec, one.spec)),
            );
        }
        for (d, (a, b)) in lane.detectors.iter().zip(&one.detectors).enumerate() {
            compared += 1;
            let (a, b) = match (a, b) {
                (Ok(a), Ok(b)) => (a, b),
                (Err(_), Err(_)) => continue,
                _ => return (compared, Some(format!("trial {t} detector {d}: a design failed on one path only"))),
            };
            if a != b {
                let brief = |o: &DetectorOutcome| {
                    let profile: Vec<_> = o.profile_value.iter().map(|p| (p.len(), p.last().copied())).collect();
                    format!(
                        "pre {:?}\nprofile (points, last) {profile:?}\nfa {:?} det {:?} iso {:?}/{:?} div {:?}",
                        o.pre_onset_max_abs_residual,
                        o.false_alarm,
                        o.detection,
                        o.isolated_by_max,
                        o.isolated_by_direction,
                        o.diverged_at_s
                    )
                };
                return (
                    compared,
                    Some(format!("trial {t} detector {d} ({form:?}):\nlanes    {}\none trial {}", brief(a), brief(b))),
                );
            }
        }
    }
    (compared, None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::deck::FromDeck;
    use std::path::Path;

    const ROBUST: &str = include_str!("../../../studies/seed000_robustness.toml");

    fn study(extra: &str) -> LtiStudy {
        LtiStudy::from_toml(&format!("{ROBUST}\n{extra}"), Path::new("robust.toml")).unwrap()
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
        let filters = e.designs(&spec);
        let k = &filters[0].as_ref().unwrap().continuous.as_ref().unwrap().K;
        assert!((k - &e.nominal_filters()[0].as_ref().unwrap().continuous.as_ref().unwrap().K).amax() > 1.0);
        let closed = &design.A - k * &design.C;
        assert!((closed[(2, 2)] + 3.0).abs() < 1e-9 && closed[(2, 1)].abs() < 1e-9);
    }

    /// The Kalman baseline where its model is true (process noise as designed, no model error, noise
    /// scale 1): its windowed statistic, read every 10th sample after a 2 s transient (disjoint windows),
    /// exceeds the chi-square(60) quantile at 0.01 per window in a share whose 95 % Wilson interval holds
    /// 0.01, over 20 fault-free trials (5,600 windows).
    #[test]
    fn the_kalman_window_statistic_false_alarm_rate_is_the_requested_one() {
        let cut = ROBUST.find("# Aerodynamic coefficients of the design model").unwrap();
        let deck = ROBUST[..cut]
            .replace("fault_free_fraction = 0.2 ", "fault_free_fraction = 1.0 ")
            .replace("noise_scale = { values = [1.0, 2.0] }", "")
            .replace(
                "sensor_sigma = [0.1, 0.002, 0.005, 0.002, 0.002, 0.5]",
                "sensor_sigma = [0.1, 0.002, 0.005, 0.002, 0.002, 0.5]\nprocess_sigma_per_step = [0.01, 0.001, 0.001, 0.001, 0.01]",
            );
        let s = LtiStudy::from_toml(&deck, Path::new("kalman.toml")).unwrap();
        let k = s.detectors.iter().position(|d| d.name == "kalman").unwrap();
        let quantile = s.detectors[k].params.thresholds[0];
        assert!((quantile - 88.379).abs() < 1e-3, "chi-square(60) 0.99 quantile: {quantile}");
        let e = Engine::new(&s);
        let (mut windows, mut over) = (0u64, 0u64);
        for trial in 0..20 {
            let mut trace = Trace::default();
            let (spec, outcome) = e.simulate(trial, k, &mut trace).unwrap();
            assert!(spec.fault.faults.is_empty() && outcome.diverged_at_s.is_none());
            let stat = &trace.float_columns.iter().find(|(n, _)| n == "stat_v_m_s").unwrap().1;
            for v in stat.iter().skip(200 + 9).step_by(10) {
                windows += 1;
                over += (*v > quantile) as u64;
            }
        }
        let (lo, hi) = crate::engine::stats::intervals::wilson(over, windows, crate::engine::stats::intervals::Z95);
        assert_eq!(windows, 5_600);
        assert!(lo <= 0.01 && 0.01 <= hi, "{over} of {windows} windows over the quantile: [{lo}, {hi}]");
    }

    /// The robustness deck lists 5 x 5 design-model errors: one design set per model its trials meet
    /// serves them all, and a trial flown after hundreds of others (its designs kept) is the trial a
    /// fresh engine flies.
    #[test]
    fn designs_kept_per_design_model_give_the_fresh_trials() {
        let s = study("");
        let warm = Engine::new(&s);
        let results: Vec<TrialResult> =
            (0..400).step_by(LANES).flat_map(|t| warm.run_group(t, (t + LANES as u64).min(400))).collect();
        let mut models: Vec<Vec<u64>> =
            results.iter().map(|r| r.spec.parameter_errors.iter().map(|e| e.to_bits()).collect()).collect();
        models.sort();
        models.dedup();
        assert!(models.len() > 1 && models.len() <= 25);
        assert_eq!(warm.designs_seen.read().unwrap().len(), models.len(), "one kept design set per model");
        for t in [0, 137, 399] {
            // Debug text: a fault-free spec's NaN size is not equal to itself.
            assert_eq!(format!("{:?}", Engine::new(&s).run(t)), format!("{:?}", results[t as usize]), "trial {t}");
        }
        // Errors drawn from a range: every trial's model is new, nothing is kept.
        let ranged = LtiStudy::from_toml(
            &ROBUST
                .replace("relative = { values = [-0.2, -0.1, 0.0, 0.1, 0.2] }", "relative = { range = [-0.2, 0.2] }"),
            Path::new("ranged.toml"),
        )
        .unwrap();
        let e = Engine::new(&ranged);
        e.run_group(0, LANES as u64);
        assert!(e.designs_seen.read().unwrap().is_empty());
    }

    #[test]
    fn latin_hypercube_puts_one_trial_in_each_stratum() {
        let mut s = study("");
        s.monte_carlo.common.trials = 240;
        let e = Engine::new(&s);
        let specs: Vec<TrialSpec> = (0..240).map(|t| e.spec(t)).collect();
        // Fault-free trials still draw their units; faulty ones carry the onset. Use all the faulty ones.
        let mut strata: Vec<usize> = specs
            .iter()
            .filter(|sp| sp.fault.onset_s.is_finite())
            .map(|sp| ((sp.fault.onset_s - 5.0) / 15.0 * 240.0) as usize)
            .collect();
        let faulty = strata.len();
        strata.sort();
        strata.dedup();
        assert_eq!(strata.len(), faulty, "two faulty trials share an onset stratum");
        let fault_free = 240 - faulty;
        assert!((30..=70).contains(&fault_free), "{fault_free} fault-free of 240 at fraction 0.2");
        // Kind is the fastest grid digit: each of the 4 kinds gets a quarter of the faulty trials.
        for kind in ["bias", "gain", "stuck", "total_failure"] {
            let n = specs.iter().filter(|sp| sp.fault.kind == kind).count();
            assert!((n as f64 - faulty as f64 / 4.0).abs() <= 12.0, "{kind}: {n}");
        }
    }

    /// Every trial of `deck` (plus `extra` deck lines), on both paths: identical results.
    fn assert_paths_agree(deck: &str, extra: &str, trials: u64, form: Vectors) {
        let s = LtiStudy::from_toml(&format!("{deck}\n{extra}"), Path::new("deck.toml")).unwrap();
        let lane_detectors = s.detectors.iter().filter(|d| d.params.runs_on_lanes()).count() as u64;
        let (compared, differs) = lane_path_against_one_trial(&s, trials, form);
        assert_eq!(differs, None);
        assert_eq!(compared, trials * lane_detectors);
    }

    /// In each vector form this CPU runs (its widest and every narrower one), printed: a form the
    /// machine lacks is not checked here, and the line says which were.
    #[test]
    fn lane_path_gives_the_one_trial_results_on_the_bench_and_ci_decks() {
        let forms = Vectors::available();
        for &form in forms {
            assert_paths_agree(include_str!("../../../studies/bench_seed000.toml"), "", 40, form);
            assert_paths_agree(include_str!("../../../studies/ci_seed000.toml"), "", 40, form);
        }
        println!("lane loops checked in the forms {forms:?} (this CPU's widest: {:?})", forms[0]);
    }

    #[test]
    fn lane_path_gives_the_one_trial_results_under_model_errors_faults_and_divergence() {
        // Design-model errors (per-trial designs), true-plant errors (one making some plants so
        // unstable that the residuals overflow: divergence), process noise, every fault kind.
        let extra = "[[monte_carlo.parameter_error]]\nname = \"speed\"\nmodel = \"plant\"\nmatrix = \"a\"\n\
                     entries = [[\"h_m\", \"theta_rad\"]]\nrelative = { range = [-0.3, 0.3] }\n\
                     [[monte_carlo.parameter_error]]\nname = \"unstable\"\nmodel = \"plant\"\nmatrix = \"a\"\n\
                     entries = [[\"q_rad_s\", \"q_rad_s\"]]\nabsolute = { range = [0.0, 60.0] }\n\
                     [[monte_carlo.fault]]\nkind = \"drift\"\nsize = { range = [0.001, 0.01] }\n\
                     [[monte_carlo.fault]]\nkind = \"oscillation\"\nfrequency_hz = 0.5\nsize = { range = [0.01, 0.1] }\n\
                     [monte_carlo.time_to_hazard_s]\nbias = 0.7\ndrift = 2.5\n";
        // A detection window and times to hazard: the profiles' exact points at both, in both paths.
        let deck = ROBUST
            .replace("[noise]", "[noise]\nprocess_sigma_per_step = [0.001, 0.0001, 0.0001, 0.0001, 0.01]")
            .replace("[monte_carlo]\n", "[monte_carlo]\ndetection_window_s = 4.0\n");
        assert!(deck.contains("detection_window_s = 4.0"));
        assert!(deck.contains("process_sigma_per_step"));
        let s = LtiStudy::from_toml(&format!("{deck}\n{extra}"), Path::new("deck.toml")).unwrap();
        // All four detectors, the CUSUM and the Kalman chi-square test included, run on the lanes.
        let kinds: Vec<&str> =
            s.detectors.iter().filter(|d| d.params.runs_on_lanes()).map(|d| d.params.kind()).collect();
        assert_eq!(kinds, ["detection_filter", "detection_filter", "cusum", "kalman_chi2"]);
        let diverged =
            (0..48).filter(|&t| Engine::new(&s).run(t).detectors[0].as_ref().unwrap().diverged_at_s.is_some());
        assert!((5..40).contains(&diverged.count()), "some trials diverge, not all");
        assert_paths_agree(&deck, extra, 48, Vectors::detect());
    }

    /// Student-t sensor noise on two channels: the lanes draw each lane's scales as the one-trial path
    /// does (records identical), the scales move the residuals, and only the Student-t channels are
    /// scaled (the Gaussian channels draw nothing from the scales' stream).
    #[test]
    fn heavy_tailed_sensor_noise_is_the_same_on_both_paths() {
        let ci = include_str!("../../../studies/ci_seed000.toml");
        // Output 3 draws the small log's roll-rate gyro residuals (the empirical law's quantile map).
        let laws = "sensor_law = [\"gaussian\", \"student_t(3)\", \"student_t(5.5)\", \
                    { log = \"studies/logs/sample_log_small.ulg\", field = \"gyro_rad[0]\" }, \"gaussian\", \"gaussian\"]";
        let deck = ci.replace("[noise]\n", &format!("[noise]\n{laws}\n"));
        assert!(deck.contains("student_t(3)"));
        assert_paths_agree(&deck, "", 24, Vectors::detect());
        let tailed = LtiStudy::from_toml(&deck, Path::new("t.toml")).unwrap();
        let gaussian = LtiStudy::from_toml(ci, Path::new("g.toml")).unwrap();
        let pre =
            |s: &LtiStudy| Engine::new(s).run(0).detectors[0].as_ref().unwrap().pre_onset_max_abs_residual.clone();
        assert_ne!(pre(&tailed), pre(&gaussian), "the Student-t channels move the residuals");
        let mut scales =
            crate::engine::scenario::streams::tail_scales(&tailed.sensor_law, tailed.header.seed, 0).unwrap();
        for _ in 0..100 {
            for j in 0..6 {
                assert_eq!(scales.scale(j) == 1.0, !(1..=2).contains(&j), "channel {j}: scaled only where Student-t");
                // Gaussian channels pass their draw; the empirical one maps it (odd, so 0 stays 0).
                let z = 0.7;
                let shaped = scales.shape(j, z);
                if j == 0 || j >= 4 {
                    assert_eq!(shaped, z);
                }
                if j == 3 {
                    assert!(shaped != z && shaped > 0.0 && scales.shape(j, -z) == -shaped, "{shaped}");
                }
            }
        }
    }
}
