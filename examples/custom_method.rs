//! A kind of study added to fdimc from outside its crate: a scalar random walk measured by one noisy
//! sensor that may take a bias after an onset, watched by two-sided CUSUMs on a steady-state Kalman
//! filter's normalised innovation.
//!
//! This file is all a kind needs, written as a user's own crate would write it against the library:
//! its deck ([`RandomWalkStudy::load`]), its trials ([`Trials`]: the runner's [`TrialSource`]), its
//! records (the core columns of the outcome schema and the recorded statistic, so thresholds calibrate
//! after the run) and one [`Method`] value. `main` hands that value to fdimc's command line, and every
//! command then works on the kind's decks as on fdimc's own:
//!
//!     cargo run --release --example custom_method -- validate examples/random_walk.toml
//!     cargo run --release --example custom_method -- run examples/random_walk.toml --out /tmp/rw
//!     cargo run --release --example custom_method -- summarize /tmp/rw --target-pfa 0.01
//!     cargo run --release --example custom_method -- check /tmp/rw --baseline /tmp/rw/summary.csv
//!     cargo run --release --example custom_method -- report /tmp/rw
//!
//! docs/architecture.md ("Adding a kind") walks through it step by step.

use std::borrow::Cow;
use std::path::Path;

use fdimc::engine::method::{Inputs, Method, Opt, Study};
use fdimc::engine::report::TracePanel;
use fdimc::engine::results::schema::{CoreColumns, FirstPassage, Outcome, StatisticColumns, col, unit};
use fdimc::engine::results::summary_spec::{Isolates, SummarySpec};
use fdimc::engine::run::output::write_table;
use fdimc::engine::run::runner::{Manifest, RunError, RunOptions, RunReport, TrialSource, run};
use fdimc::engine::scenario::deck::{
    DeckError, Factor, FactorSpec, MonteCarlo, MonteCarloRules, MonteCarloSection, StudyHeader, StudySection,
    Validator, open_deck,
};
use fdimc::engine::scenario::draws::{DIM_SIZE, UnitSampler};
use fdimc::engine::scenario::streams::{Substream, trial_rng};
use polars::prelude::{Column, DataFrame, PolarsResult};
use rand::RngExt;
use rand_distr::StandardNormal;
use serde::Deserialize;

/// The kind, as the registry knows it: `[random_walk]` marks its decks.
static RANDOM_WALK: Method = Method {
    kind: "random_walk",
    marker: "random_walk",
    title: "scalar random walk, sensor bias, CUSUM (example)",
    options: &[Opt::Thresholds],
    load: |text, path| Ok(Box::new(RandomWalkStudy::load(text, path)?)),
    summary: SummarySpec {
        extra_keys: &[],
        isolates: Isolates::Target,
        extras: &[],
        paired_medians: &[],
        printed: &[],
    },
    report: None,
    trace_panels: &[
        TracePanel { title: "measurement and estimate", columns: &["y", "x_true", "x_estimate"] },
        TracePanel { title: "CUSUM statistics", columns: &["*_statistic"] },
    ],
    own_plots: &[],
    starter: ("examples/random_walk.toml", include_str!("random_walk.toml")),
    replay_starter: None,
    hour_laws: None,
    flight_thresholds: None,
};

fn main() -> std::process::ExitCode {
    fdimc::cli::main_with(&[&RANDOM_WALK])
}

/// The one sensor: its name is the recorded statistic's and the fault's target.
const OUTPUT: &str = "y";

// ---- the deck -------------------------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Deck {
    study: StudySection,
    random_walk: PlantSection,
    monte_carlo: Option<MonteCarloSection>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PlantSection {
    process_sigma: f64,
    sensor_sigma: f64,
    detector: Vec<DetectorSection>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DetectorSection {
    name: String,
    drift: f64,
    threshold: f64,
}

/// `[monte_carlo]`'s own field.
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct MonteCarloOwn {
    bias_sigma: Option<FactorSpec>,
}

/// A CUSUM, validated.
#[derive(Debug, Clone)]
struct Cusum {
    name: String,
    drift: f64,
    threshold: f64,
}

/// A deck of this kind, validated: it cannot be invalid.
struct RandomWalkStudy {
    header: StudyHeader,
    /// Per sqrt(s), and sensor units.
    process_sigma: f64,
    sensor_sigma: f64,
    detectors: Vec<Cusum>,
    monte_carlo: MonteCarlo,
    /// The bias after the onset, in multiples of the sensor sigma.
    bias_sigma: Factor,
}

impl RandomWalkStudy {
    fn load(text: &str, path: &Path) -> Result<Self, DeckError> {
        let (deck, v, header): (Deck, Validator, StudyHeader) = open_deck(text, path, |d: &Deck| &d.study)?;
        let p = &deck.random_walk;
        let process_sigma = v.positive("random_walk.process_sigma", p.process_sigma)?;
        let sensor_sigma = v.positive("random_walk.sensor_sigma", p.sensor_sigma)?;
        v.detector_names("random_walk.detector", p.detector.iter().map(|d| d.name.as_str()))?;
        let mut detectors = Vec::new();
        for (i, d) in p.detector.iter().enumerate() {
            detectors.push(Cusum {
                name: d.name.clone(),
                drift: v.non_negative(&format!("random_walk.detector[{i}].drift"), d.drift)?,
                threshold: v.positive(&format!("random_walk.detector[{i}].threshold"), d.threshold)?,
            });
        }
        let rules = MonteCarloRules::sampled("random_walk decks", header.duration_s, RANDOM_WALK.calibrates());
        let (monte_carlo, own, _) = v.monte_carlo::<MonteCarloOwn, ()>(deck.monte_carlo, &rules, |_, _| Ok(()))?;
        let own = own.unwrap_or_default();
        let bias_sigma = v.factor("monte_carlo.bias_sigma", own.bias_sigma.as_ref(), Factor::Fixed(3.0))?;
        v.factor_within("monte_carlo.bias_sigma", &bias_sigma, |b| b > 0.0, "> 0 sensor sigmas")?;
        Ok(RandomWalkStudy { header, process_sigma, sensor_sigma, detectors, monte_carlo, bias_sigma })
    }

    /// The steady-state Kalman filter of the random walk: gain and innovation standard deviation.
    fn kalman(&self) -> (f64, f64) {
        let (q, r) = (self.process_sigma.powi(2) * self.header.dt_s, self.sensor_sigma.powi(2));
        // Riccati fixed point of the prediction variance: p = (p r / (p + r)) + q.
        let p = 0.5 * (q + (q * q + 4.0 * q * r).sqrt());
        (p / (p + r), (p + r).sqrt())
    }
}

// ---- one trial --------------------------------------------------------------------------------------

/// A trial's scenario: whether and when the sensor takes a bias, and the noise scale.
#[derive(Debug, Clone)]
struct Scenario {
    trial: u64,
    fault_free: bool,
    onset_s: f64,
    bias_sigma: f64,
    bias_bin: f64,
    noise_scale: f64,
    noise_bin: f64,
}

/// A detector's outcome in one trial, with its statistic's record: the largest value before the onset
/// (the whole trial when fault-free) and the first-passage profile after it.
#[derive(Debug, Clone, Default)]
struct CusumOutcome {
    false_alarm_s: Option<f64>,
    alarm_s: Option<f64>,
    pre_max: f64,
    profile_t_s: Vec<f64>,
    profile_value: Vec<f64>,
}

struct TrialResult {
    scenario: Scenario,
    outcomes: Vec<CusumOutcome>,
}

/// The deck's trials, as the runner asks for them.
struct Trials<'a> {
    study: &'a RandomWalkStudy,
    sampler: UnitSampler,
}

impl<'a> Trials<'a> {
    fn new(study: &'a RandomWalkStudy) -> Self {
        Trials { study, sampler: UnitSampler::for_study(&study.monte_carlo, study.header.seed, DIM_SIZE + 2) }
    }

    fn scenario(&self, trial: u64) -> Scenario {
        let mut draws = self.sampler.trial(trial);
        let (onset_s, noise_scale, noise_bin) = draws.onset_and_noise(&self.study.monte_carlo);
        let (bias_sigma, bias_bin) = draws.factor(&self.study.bias_sigma, DIM_SIZE);
        Scenario { trial, fault_free: draws.fault_free, onset_s, bias_sigma, bias_bin, noise_scale, noise_bin }
    }

    /// Flies trial `trial`; `each` sees every sample (time, truth, measurement, estimate, statistics).
    fn fly(&self, trial: u64, mut each: impl FnMut(f64, f64, f64, f64, &[f64])) -> TrialResult {
        let s = self.study;
        let scenario = self.scenario(trial);
        let noise = self.sampler.noise_trial(trial);
        let mut sensor = trial_rng(s.header.seed, noise, Substream::SensorNoise);
        let mut process = trial_rng(s.header.seed, noise, Substream::ProcessNoise);
        let (gain, innovation_sigma) = s.kalman();
        let step_sigma = s.process_sigma * s.header.dt_s.sqrt();
        let (mut x, mut estimate) = (0.0, 0.0);
        let mut g = vec![(0.0f64, 0.0f64); s.detectors.len()];
        let mut statistic = vec![0.0; s.detectors.len()];
        let mut outcomes = vec![CusumOutcome::default(); s.detectors.len()];
        // The first-passage profile on the run's grid (`monte_carlo.profile_resolution`).
        let mut passages = vec![FirstPassage::new(s.monte_carlo.profile); s.detectors.len()];
        for k in 0..s.header.steps {
            let t = k as f64 * s.header.dt_s;
            let after_onset = !scenario.fault_free && t >= scenario.onset_s;
            let bias = if after_onset { scenario.bias_sigma * s.sensor_sigma } else { 0.0 };
            let v: f64 = sensor.sample(StandardNormal);
            let y = x + scenario.noise_scale * s.sensor_sigma * v + bias;
            let e = (y - estimate) / innovation_sigma;
            estimate += gain * (y - estimate);
            for (j, d) in s.detectors.iter().enumerate() {
                let (up, down) = &mut g[j];
                *up = (*up + e - d.drift).max(0.0);
                *down = (*down - e - d.drift).max(0.0);
                let a = up.max(*down);
                statistic[j] = a;
                let o = &mut outcomes[j];
                if after_onset {
                    passages[j].observe(t, a, &mut o.profile_t_s, &mut o.profile_value);
                    if a > d.threshold && o.alarm_s.is_none() {
                        o.alarm_s = Some(t);
                    }
                } else {
                    o.pre_max = o.pre_max.max(a);
                    if a > d.threshold && o.false_alarm_s.is_none() {
                        o.false_alarm_s = Some(t);
                    }
                }
            }
            each(t, x, y, estimate, &statistic);
            let w: f64 = process.sample(StandardNormal);
            x += step_sigma * w;
        }
        for (o, p) in outcomes.iter_mut().zip(&passages) {
            p.close(&mut o.profile_t_s, &mut o.profile_value);
        }
        TrialResult { scenario, outcomes }
    }
}

impl TrialSource for Trials<'_> {
    type Result = TrialResult;

    fn trial(&self, trial: u64) -> TrialResult {
        self.fly(trial, |_, _, _, _, _| {})
    }

    fn manifest(&self) -> Manifest {
        let s = self.study;
        let mut fault_size_bins = Default::default();
        s.bias_sigma.add_bins_to("bias", &mut fault_size_bins);
        Manifest {
            outputs: vec![OUTPUT.into()],
            deck_thresholds: s.detectors.iter().map(|d| vec![d.threshold]).collect(),
            fault_size_units: [("bias".to_string(), unit::SENSOR_SIGMA.to_string())].into(),
            fault_size_bins,
            ..Manifest::of(RANDOM_WALK.kind, &s.header, &s.monte_carlo, s.detectors.iter().map(|d| d.name.as_str()))
        }
    }

    fn frame(&self, results: &[TrialResult]) -> PolarsResult<DataFrame> {
        let s = self.study;
        let rows = results.len() * s.detectors.len();
        let mut core = CoreColumns::new(std::iter::empty(), rows, s.monte_carlo.detection_window_s);
        let mut statistics = StatisticColumns::new(&[OUTPUT.to_string()], rows);
        for r in results {
            let sc = &r.scenario;
            for (d, o) in s.detectors.iter().zip(&r.outcomes) {
                // The CUSUM names the one sensor when it alarms after the onset.
                let isolated = o.alarm_s.map(|_| Cow::Borrowed(OUTPUT));
                core.push(Outcome {
                    trial: sc.trial,
                    detector: &d.name,
                    kind: if sc.fault_free { col::NO_FAULT } else { "bias" },
                    target: (!sc.fault_free).then_some(Cow::Borrowed(OUTPUT)),
                    size: (!sc.fault_free).then_some(sc.bias_sigma),
                    size_unit: if sc.fault_free { unit::NONE } else { unit::SENSOR_SIGMA },
                    size_bin: (!sc.fault_free).then_some(sc.bias_bin),
                    onset_s: (!sc.fault_free).then_some(sc.onset_s),
                    fault_free: sc.fault_free,
                    failure: None,
                    diverged: false,
                    truth_diverged: false,
                    false_alarm_s: o.false_alarm_s,
                    delay_s: o.alarm_s.map(|t| t - sc.onset_s),
                    isolated_correctly: isolated.as_ref().map(|_| true),
                    isolated,
                    noise_scale: sc.noise_scale,
                    noise_bin: sc.noise_bin,
                    param_error_bin: 0.0,
                    param_errors: &[],
                });
                statistics.push(0, Some(o.pre_max), &o.profile_t_s, &o.profile_value);
            }
        }
        let mut columns: Vec<Column> = core.finish();
        columns.extend(statistics.finish());
        DataFrame::new_infer_height(columns)
    }
}

// ---- the commands -----------------------------------------------------------------------------------

impl Study for RandomWalkStudy {
    fn header(&self) -> &StudyHeader {
        &self.header
    }

    fn seed_and_trials(&mut self) -> (&mut u64, &mut u64) {
        (&mut self.header.seed, &mut self.monte_carlo.trials)
    }

    fn monte_carlo(&mut self) -> &mut MonteCarlo {
        &mut self.monte_carlo
    }

    fn validate(&self) -> Result<(), RunError> {
        self.header.print_valid();
        let (gain, innovation_sigma) = self.kalman();
        println!(
            "plant       random walk, {} per sqrt(s); sensor sigma {}; Kalman gain {gain:.4}, innovation sigma {innovation_sigma:.4}",
            self.process_sigma, self.sensor_sigma
        );
        for d in &self.detectors {
            println!("detector    {}: two-sided CUSUM, drift {}, threshold {}", d.name, d.drift, d.threshold);
        }
        let mc = &self.monte_carlo;
        println!(
            "trials      {} ({:.0} % fault-free), bias {} sensor sigmas from onset {} s, target Pfa {}",
            mc.trials,
            100.0 * mc.fault_free_fraction,
            self.bias_sigma,
            mc.onset_s,
            mc.target_pfa
        );
        Ok(())
    }

    fn simulate(&self, trial: u64, detector: Option<&str>, out: &Path, _: Inputs) -> Result<(), RunError> {
        let names: Vec<&str> = self.detectors.iter().map(|d| d.name.as_str()).collect();
        let keep = fdimc::engine::method::select_detector(&self.header, &names, detector)?;
        let (mut t_s, mut truth, mut y, mut estimate) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut statistics = vec![Vec::new(); names.len()];
        let result = Trials::new(self).fly(trial, |t, x, m, e, stat| {
            t_s.push(t);
            truth.push(x);
            y.push(m);
            estimate.push(e);
            for (column, a) in statistics.iter_mut().zip(stat) {
                column.push(*a);
            }
        });
        let mut columns = vec![
            Column::new("t_s".into(), t_s),
            Column::new("x_true".into(), truth),
            Column::new("y".into(), y),
            Column::new("x_estimate".into(), estimate),
        ];
        for (j, column) in statistics.into_iter().enumerate().filter(|(j, _)| keep.is_none_or(|k| k == *j)) {
            columns.push(Column::new(format!("{}_statistic", names[j]).into(), column));
        }
        let mut df = DataFrame::new_infer_height(columns).map_err(|e| RunError::Internal(e.to_string()))?;
        write_table(&mut df, out).map_err(|e| RunError::Invalid(e.to_string()))?;
        let sc = &result.scenario;
        match sc.fault_free {
            true => println!("trial {trial}: fault-free"),
            false => println!("trial {trial}: bias of {:.2} sensor sigmas from {:.2} s", sc.bias_sigma, sc.onset_s),
        }
        for (d, o) in self.detectors.iter().zip(&result.outcomes) {
            println!("  {}: false alarm at {:?} s, detection at {:?} s", d.name, o.false_alarm_s, o.alarm_s);
        }
        println!("wrote {}", out.display());
        Ok(())
    }

    fn run(&self, opts: &RunOptions, _: Inputs) -> Result<RunReport, RunError> {
        run(&Trials::new(self), opts)
    }
}
