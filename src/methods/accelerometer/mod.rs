//! Accelerometer studies (method 003): attitude-EKF residuals and SVM classifiers.

pub mod attitude;
pub mod commands;
pub mod ekf_svm;
pub mod imu;
pub mod records;
pub mod replay;
pub mod report;
pub mod starter;
pub mod study;
pub mod trial;

use std::path::Path;

use crate::engine::method::{Inputs, Method, Study};
use crate::engine::report::TracePanel;
use crate::engine::results::summary_spec::{Isolates, SummarySpec};
use crate::engine::run::runner::{Manifest, ModelFile, RunError, RunOptions, RunReport, TrialSource, run};
use crate::engine::scenario::deck::Factor;
use crate::engine::scenario::deck::FromDeck;
use crate::engine::scenario::draws::{GridDigits, draw};
use crate::engine::scenario::streams::{Substream, noise_rng, trial_rng};
use crate::fault::FaultMode;
use crate::methods::accelerometer::ekf_svm::{ClassifierWindow, FaultClass, ResidualSample};
use crate::methods::accelerometer::study::AccelerometerStudy;
use trial::*;

/// `manifest.json`'s kind of these studies.
pub const KIND: &str = "accelerometer";

/// Method 003: the registry's entry.
pub static METHOD: Method = Method {
    kind: KIND,
    marker: "imu",
    title: "attitude-EKF residuals and SVM classifiers, accelerometer faults (method 003)",
    options: study::OPTIONS,
    load: |text, path| Ok(Box::new(AccelerometerStudy::from_toml(text, path)?)),
    summary: SummarySpec { extra_keys: &[], isolates: Isolates::Kind, extras: &[], paired_medians: &[], printed: &[] },
    report: Some(report::report_part),
    trace_panels: &[
        TracePanel { title: "attitude-EKF residual (unit gravity direction, 1)", columns: &["residual_*"] },
        TracePanel { title: "detection statistic", columns: &["detection_statistic"] },
        TracePanel { title: "alarm", columns: &["alarm"] },
    ],
    own_plots: &[],
    starter: ("studies/ci_seed003.toml", include_str!("../../../studies/ci_seed003.toml")),
    replay_starter: Some(starter::replay_deck),
    hour_laws: None,
    flight_thresholds: None,
};

impl Study for AccelerometerStudy {
    crate::study_accessors!(monte_carlo);
    fn validate(&self) -> Result<(), RunError> {
        commands::validate(self)
    }
    fn simulate(&self, trial: u64, detector: Option<&str>, out: &Path, inputs: Inputs) -> Result<(), RunError> {
        if let Some(name) = detector {
            return Err(RunError::Invalid(format!(
                "--detector {name:?}: an accelerometer trial is classified by every classifier ({}) at once; leave it out",
                self.classifiers.iter().map(|c| c.name.as_str()).collect::<Vec<_>>().join(", ")
            )));
        }
        commands::simulate(self, trial, out, inputs.classifiers)
    }
    fn run(&self, opts: &RunOptions, inputs: Inputs) -> Result<RunReport, RunError> {
        // Classifiers from a file, from the folder being resumed, or trained now; written beside the
        // results once the run has started, so a refused run leaves the folder as it was.
        let beside = opts.out_dir.join("classifiers.json");
        let (classifiers, write_beside) = match inputs.classifiers {
            Some(file) => (TrainedClassifiers::load(file, self)?, true),
            None if opts.resume && beside.exists() => (TrainedClassifiers::load(&beside, self)?, false),
            None => {
                if !inputs.quiet {
                    eprintln!(
                        "training the classifiers on {} trials per class (seed {})",
                        self.training.trials_per_class, self.training.seed
                    );
                }
                let trained = TrainedClassifiers::train(self)
                    .map_err(|e| RunError::Invalid(format!("{}: {e}", self.header.path.display())))?;
                (trained, true)
            }
        };
        if let (Some(log), false) = (&self.log, inputs.quiet) {
            eprintln!("{}", commands::log_line(log));
        }
        let trials = AccelerometerTrials::new(self, &classifiers);
        let report = run(&trials, opts)?;
        if write_beside {
            classifiers.save(&beside)?;
        }
        if let Some(replay) = &self.replay {
            if !inputs.quiet {
                for line in commands::replay_lines(replay) {
                    eprintln!("{line}");
                }
            }
            let text = serde_json::to_string_pretty(replay).map_err(|e| RunError::Internal(e.to_string()))?;
            crate::engine::run::runner::write_atomically(
                &opts.out_dir.join("fault_free_replay.json"),
                text.as_bytes(),
            )?;
        }
        Ok(report)
    }
    fn train(&self, out: Option<&Path>) -> Result<(), RunError> {
        commands::train(self, out)
    }
}

/// What one trial flies.
#[derive(Debug, Clone, PartialEq)]
pub enum TrialPlan<'a> {
    Simulated(crate::methods::accelerometer::imu::ImuScenarioParams),
    /// `log`'s segment from grid sample `start`, with `faults` (onsets from the segment's start).
    Replayed {
        log: &'a crate::engine::logs::log_source::ReplayLog,
        start: usize,
        faults: Vec<crate::fault::ChannelFault>,
    },
}

impl TrialPlan<'_> {
    pub fn faults(&self) -> &[crate::fault::ChannelFault] {
        match self {
            TrialPlan::Simulated(scenario) => &scenario.faults,
            TrialPlan::Replayed { faults, .. } => faults,
        }
    }
}

/// The runner's view of an accelerometer study with its trained classifiers.
pub struct AccelerometerTrials<'a> {
    study: &'a AccelerometerStudy,
    classifiers: &'a TrainedClassifiers,
}

impl<'a> AccelerometerTrials<'a> {
    pub fn new(study: &'a AccelerometerStudy, classifiers: &'a TrainedClassifiers) -> Self {
        AccelerometerTrials { study, classifiers }
    }

    /// The scenario of trial `trial` and what it flies: a simulated scenario, or a segment of the log
    /// with the fault injected ([`replay`]).
    fn draw(&self, trial: u64) -> (AccelTrialSpec, TrialPlan<'a>) {
        let s = self.study;
        let mut grid = GridDigits::new(trial);
        let class = s.classes[grid.next(s.classes.len())];
        let (noise_scale, _) = draw(&s.monte_carlo.noise_scale, 0.0, &mut |n| grid.next(n));
        let mut rng = trial_rng(s.header.seed, trial, Substream::Fault);
        let (plan, onset_s) = match &s.log {
            None => {
                let (mut scenario, onset_s) = s.design.draw_trial(class, &mut rng);
                scenario.noise_scale = noise_scale;
                (TrialPlan::Simulated(scenario), onset_s)
            }
            Some(log) => {
                let r = replay::draw(&s.design.ranges, log.evaluate, s.header.steps, class, &mut rng);
                (TrialPlan::Replayed { log, start: r.start, faults: r.fault.into_iter().collect() }, r.onset_s)
            }
        };
        let fault = plan.faults().first();
        let ranges = &s.design.ranges;
        let third = |magnitude: f64, r: [f64; 2]| {
            let width = (r[1] - r[0]) / 3.0;
            r[0] + width * (((magnitude - r[0]) / width).floor().clamp(0.0, 2.0) + 0.5)
        };
        let (size, size_bin) = match fault.map(|f| f.mode) {
            Some(FaultMode::Bias { bias }) => (bias, third(bias.abs(), ranges.bias_mps2)),
            Some(FaultMode::Gain { factor }) => (factor, third((factor - 1.0).abs(), ranges.gain_deviation)),
            _ => (f64::NAN, f64::NAN),
        };
        let log_start_s = match &plan {
            TrialPlan::Replayed { log, start, .. } => Some(*start as f64 * log.dt_s),
            TrialPlan::Simulated(_) => None,
        };
        let axis = fault.map(|f| f.channel);
        let spec = AccelTrialSpec { trial, class, axis, size, size_bin, onset_s, noise_scale, log_start_s };
        (spec, plan)
    }

    /// Trial `trial`, handing the residual samples to `on_trace` (for traces).
    pub fn run_trial_with(&self, trial: u64, on_trace: impl FnOnce(&[ResidualSample], &[f64])) -> AccelTrialResult {
        let s = self.study;
        let (spec, plan) = self.draw(trial);
        let dt_s = s.header.dt_s;
        let mut rng = noise_rng(s.header.seed, trial, Substream::SensorNoise);
        let outcome = (|| {
            let (trace, tuned_scale) = match plan {
                TrialPlan::Simulated(scenario) => {
                    s.design.simulate_tuned(scenario, &s.detection, &mut rng, |r| r.clone())
                }
                TrialPlan::Replayed { log, start, faults } => {
                    let ekf = s.design.ekf_for(spec.noise_scale);
                    replay::replay_trace(log, start, s.header.steps, &faults, &ekf).map(|t| (t, spec.noise_scale))
                }
            }
            .map_err(|e| e.to_string())?;
            let example = s.design.example(&trace, spec.onset_s, spec.class).map_err(|e| e.to_string())?;
            let alarms = Alarms::of(s, &trace, spec.class, spec.onset_s, tuned_scale);
            on_trace(&trace.samples, &alarms.statistics);
            let online = match alarms.online_window(spec.class) {
                Some(k) => Some(s.design.example_at(&trace, k, spec.class).map_err(|e| e.to_string())?),
                None => None,
            };
            let predicted = self
                .classifiers
                .classifiers
                .iter()
                .map(|c| match (c.window, &online) {
                    (ClassifierWindow::Onset, _) => c.classifier.classify(&example.features),
                    (ClassifierWindow::Alarm, Some(at_alarm)) => c.classifier.classify(&at_alarm.features),
                    // No alarm, nothing to classify: the system carries on as healthy.
                    (ClassifierWindow::Alarm, None) => Ok(FaultClass::Normal),
                })
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| e.to_string())?;
            let at = |k: usize| k as f64 * dt_s;
            Ok(AccelOutcome {
                predicted,
                false_alarm_s: alarms.false_alarm.map(at),
                alarm_s: alarms.alarm.map(at),
                statistic: alarms.recorded,
                health: trace.health,
            })
        })();
        AccelTrialResult { spec, outcome }
    }
}

impl TrialSource for AccelerometerTrials<'_> {
    type Result = AccelTrialResult;
    fn trial(&self, trial: u64) -> AccelTrialResult {
        self.run_trial_with(trial, |_, _| ())
    }
    fn manifest(&self) -> Manifest {
        let s = self.study;
        let ranges = &s.design.ranges;
        Manifest {
            // A 20 s trial costs a few milliseconds: 512 make a part file of about a second.
            chunk_trials: 512,
            outputs: ["accel_x", "accel_y", "accel_z"].iter().map(|a| a.to_string()).collect(),
            // The residual detector's threshold on T, the same for every classifier's rows.
            deck_thresholds: vec![vec![s.detection.threshold]; s.classifiers.len()],
            fault_size_units: [
                ("bias".to_string(), "m/s^2 (bin: |bias|)".to_string()),
                ("gain".to_string(), crate::engine::results::schema::unit::GAIN_DEVIATION_BINS.to_string()),
            ]
            .into(),
            // Thirds of the deck's ranges of |bias| and |factor - 1| (see `draw`).
            fault_size_bins: [("bias", ranges.bias_mps2), ("gain", ranges.gain_deviation)]
                .map(|(kind, [lo, hi])| (kind.to_string(), Factor::Range { lo, hi, bins: 3 }.bin_edges()))
                .into(),
            sensor_noise: s.log.as_ref().map(|l| format!("the recorded noise of {} (replayed)", l.file.display())),
            // The replayed log, as an FMU truth is recorded: a resume with another log is refused.
            models: (s.log.iter())
                .map(|l| ModelFile { file: l.file.display().to_string(), sha256: l.sha256.clone() })
                .collect(),
            ..Manifest::of(KIND, &s.header, &s.monte_carlo, s.classifiers.iter().map(|c| c.name.as_str()))
        }
    }
    fn frame(&self, results: &[AccelTrialResult]) -> polars::prelude::PolarsResult<polars::prelude::DataFrame> {
        let names: Vec<&str> = self.classifiers.classifiers.iter().map(|c| c.name.as_str()).collect();
        records::frame(results, &names, self.study.log.is_some(), self.study.monte_carlo.detection_window_s)
    }
}
