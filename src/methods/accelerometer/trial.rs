//! Trials of an accelerometer study (method 003): training the classifiers on their own trials, and
//! each evaluation trial flown once and scored.
//!
//! Training ([`TrainedClassifiers::train`]): `trials_per_class` trials of each class from the training
//! seed (trial j, of class `j mod 4` and the `(j / 4) mod n`-th of the n training noise scales, draws
//! everything from stream j of that seed), the features of each trial's window after its onset (and,
//! for classifiers of the alarm's window, of the window from the residual detector's alarm), then each
//! classifier of the deck (by default the bottom-up SVM decision tree and the flat one-against-one SVM)
//! on its window's examples. All are saved together to a JSON file and loaded from it, so a study can
//! be evaluated on fresh trials (the study's seed) with exactly the classifiers a file holds.
//!
//! An evaluation trial: its class from the grid (the deck's classes cycled over the trial index, then the
//! noise scale), its fault, onset and sensor biases from the trial's fault stream, its sensor noise from
//! the sensor stream; the attitude EKF over the whole flight; then
//! - detection: the statistic `T` of the residual's windowed mean against the deck's threshold, from
//!   `settle_s` on: a false alarm before the onset (anywhere when the class is normal), a detection at
//!   or after it;
//! - classification: each classifier on the features of its window: after the true onset (an oracle),
//!   or from the alarm (online: a faulty trial's alarm at or after the onset, a normal trial's false
//!   alarm; without one the trial is called normal, as a system that classifies on alarm would).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::engine::results::schema::{RecordedStatistic, StatisticRecorder};
use crate::engine::run::runner::{RunError, write_atomically};
use crate::engine::scenario::streams::{Substream, fork, trial_rng};
use crate::methods::accelerometer::attitude::AttitudeHealth;
use crate::methods::accelerometer::ekf_svm::{
    Classifier, ClassifierWindow, Example, FaultClass, FeatureParams, ResidualTrace, SvmParams, TrainingData,
    detection_statistics, first_alarm, window_start,
};
use crate::methods::accelerometer::replay;
use crate::methods::accelerometer::study::AccelerometerStudy;

/// The classifiers of a study, trained on examples of the same training trials, as a file holds them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainedClassifiers {
    /// The study they were trained for, and on what.
    pub study: String,
    pub training_seed: u64,
    pub trials_per_class: usize,
    pub noise_scales: Vec<f64>,
    /// In the deck's `[[classifier]]` order.
    pub classifiers: Vec<TrainedClassifier>,
    /// What the classifiers trained on a log learnt from (the log, its training part, the signals
    /// debiased there; [`log_training`]): a file from another split, which could have seen the evaluated
    /// samples, is refused.
    #[serde(default)]
    pub log_training: Option<String>,
}

/// The log split `trained_on = "log"` classifiers of `study` learn from; `None` without any.
pub fn log_training(study: &AccelerometerStudy) -> Option<String> {
    let log = study.log.as_ref()?;
    let part = log.train?;
    if !study.classifiers.iter().any(|c| c.trained_on == TrainingData::Log) {
        return None;
    }
    let [from, to] = log.seconds(part);
    let debiased: Vec<&str> = log.removed_means.iter().map(|(name, _)| name.as_str()).collect();
    Some(format!(
        "{} {}, training part [{from:.3}, {to:.3}) s at dt {} s, debiased [{}]",
        log.file.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default(),
        log.origin,
        log.dt_s,
        debiased.join(", ")
    ))
}

/// One trained classifier with its name and window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainedClassifier {
    pub name: String,
    pub window: ClassifierWindow,
    /// Files written before replays had only simulation.
    #[serde(default)]
    pub trained_on: TrainingData,
    pub classifier: Classifier,
}

/// The residual detector on one trial: its statistic per sample, the first alarm before the onset (a
/// false alarm; anywhere after `settle_s` for the normal class) and the first at or after it, as sample
/// indices; and the statistic as recorded for thresholds set after the run: its largest value from
/// `settle_s` to the onset (to the end for the normal class) and its first-passage profile after the
/// onset ([`StatisticRecorder`]).
pub struct Alarms {
    pub statistics: Vec<f64>,
    pub false_alarm: Option<usize>,
    pub alarm: Option<usize>,
    pub recorded: RecordedStatistic,
}

impl Alarms {
    /// The alarms of `trace`, a trial of `class` at `noise_scale` with its fault from `onset_s`.
    pub fn of(
        study: &AccelerometerStudy,
        trace: &ResidualTrace,
        class: FaultClass,
        onset_s: f64,
        noise_scale: f64,
    ) -> Alarms {
        let statistics =
            detection_statistics(&trace.samples, &study.design.detection_for(&study.detection, noise_scale));
        let threshold = study.detection.threshold;
        let settle = window_start(study.settle_s, 0.0, trace.dt_s);
        let onset = window_start(onset_s, 0.0, trace.dt_s);
        let (false_alarm, alarm) = if class == FaultClass::Normal {
            (first_alarm(&statistics, threshold, settle), None)
        } else {
            (
                first_alarm(&statistics, threshold, settle).filter(|&k| k < onset),
                first_alarm(&statistics, threshold, onset),
            )
        };
        // The same windows as the alarms: before the onset from settle_s (all of a normal trial), after it.
        let pre_end = if class == FaultClass::Normal { statistics.len() } else { onset.min(statistics.len()) };
        let mut recorder = StatisticRecorder::new(study.monte_carlo.profile);
        statistics.get(settle.min(pre_end)..pre_end).unwrap_or(&[]).iter().for_each(|&t| recorder.before_onset(t));
        if class != FaultClass::Normal {
            for (k, &t) in statistics.iter().enumerate().skip(onset) {
                recorder.after_onset(k as f64 * trace.dt_s, t);
            }
        }
        Alarms { statistics, false_alarm, alarm, recorded: recorder.finish() }
    }

    /// Where an online classifier's window starts: the alarm (a normal trial's false alarm); none
    /// without one.
    pub fn online_window(&self, class: FaultClass) -> Option<usize> {
        if class == FaultClass::Normal { self.false_alarm } else { self.alarm }
    }
}

impl TrainedClassifiers {
    /// Trains every classifier of the study on its training trials (module docs): the onset window of
    /// each trial, and for online classifiers the window from the alarm (a faulty trial the detector
    /// misses gives none; a normal trial its false alarm's window, or without one its nominal onset's).
    pub fn train(study: &AccelerometerStudy) -> Result<TrainedClassifiers, String> {
        let t = &study.training;
        let needs = |source: TrainingData, window: ClassifierWindow| {
            study.classifiers.iter().any(|c| c.trained_on == source && c.window == window)
        };
        let classes = FaultClass::ALL.len() as u64;
        let designs: Vec<_> = t
            .noise_scales
            .iter()
            .map(|&noise_scale| {
                let mut design = study.design.clone();
                design.scenario.noise_scale = noise_scale;
                design
            })
            .collect();
        // Training trial j of each source: its class, the filter's output, its onset and noise scale.
        let simulated = |j: u64, class: FaultClass| -> Result<(ResidualTrace, f64, f64), String> {
            let design = &designs[((j / classes) % designs.len() as u64) as usize];
            let mut rng = trial_rng(t.seed, j, Substream::Scenario);
            let (scenario, onset_s) = design.draw_trial(class, &mut rng);
            let (trace, tuned_scale) =
                design.simulate_tuned(scenario, &study.detection, &mut rng, fork).map_err(|e| e.to_string())?;
            Ok((trace, onset_s, tuned_scale))
        };
        let replayed = |j: u64, class: FaultClass| -> Result<(ResidualTrace, f64, f64), String> {
            let log = study.log.as_ref().ok_or("no log to train on")?;
            let part = log.train.ok_or("the log has no training part (log.train_s)")?;
            let mut rng = trial_rng(t.seed, j, Substream::Scenario);
            let r = replay::draw(&study.design.ranges, part, study.header.steps, class, &mut rng);
            let faults: Vec<_> = r.fault.into_iter().collect();
            let trace = replay::replay_trace(log, r.start, study.header.steps, &faults, &study.design.ekf_for(1.0))
                .map_err(|e| e.to_string())?;
            Ok((trace, r.onset_s, 1.0))
        };
        let mut examples: Vec<((TrainingData, ClassifierWindow), Vec<Example>)> = Vec::new();
        for source in [TrainingData::Simulation, TrainingData::Log] {
            let (onset, online) = (needs(source, ClassifierWindow::Onset), needs(source, ClassifierWindow::Alarm));
            if !(onset || online) {
                continue;
            }
            let (mut at_onset, mut at_alarm) = (Vec::with_capacity(4 * t.trials_per_class), Vec::new());
            for j in 0..classes * t.trials_per_class as u64 {
                let class = FaultClass::ALL[(j % classes) as usize];
                let what = |e: String| format!("training trial {j} ({}, {}): {e}", class.name(), source.name());
                let (trace, onset_s, noise_scale) = match source {
                    TrainingData::Simulation => simulated(j, class),
                    TrainingData::Log => replayed(j, class),
                }
                .map_err(what)?;
                at_onset.push(study.design.example(&trace, onset_s, class).map_err(|e| what(e.to_string()))?);
                if online {
                    let alarms = Alarms::of(study, &trace, class, onset_s, noise_scale);
                    let start = match (alarms.online_window(class), class) {
                        (Some(k), _) => Some(k),
                        (None, FaultClass::Normal) => Some(window_start(onset_s, 0.0, trace.dt_s)),
                        (None, _) => None,
                    };
                    if let Some(k) = start {
                        at_alarm.push(study.design.example_at(&trace, k, class).map_err(|e| what(e.to_string()))?);
                    }
                }
            }
            examples.push(((source, ClassifierWindow::Onset), at_onset));
            examples.push(((source, ClassifierWindow::Alarm), at_alarm));
        }
        let classifiers = study
            .classifiers
            .iter()
            .map(|spec| {
                let key = (spec.trained_on, spec.window);
                let (_, examples) =
                    examples.iter().find(|(k, _)| *k == key).expect("examples of every classifier's key");
                let svm = SvmParams { balanced: spec.balanced, ..t.svm };
                let classifier = Classifier::train(spec.scheme, examples, study.design.features, svm).map_err(|e| {
                    format!(
                        "training {} ({} window, on {}): {e}",
                        spec.name,
                        spec.window.name(),
                        spec.trained_on.name()
                    )
                })?;
                Ok(TrainedClassifier {
                    name: spec.name.clone(),
                    window: spec.window,
                    trained_on: spec.trained_on,
                    classifier,
                })
            })
            .collect::<Result<Vec<_>, String>>()?;
        Ok(TrainedClassifiers {
            study: study.header.name.clone(),
            training_seed: t.seed,
            trials_per_class: t.trials_per_class,
            noise_scales: t.noise_scales.clone(),
            classifiers,
            log_training: log_training(study),
        })
    }

    /// Writes both classifiers to `path` (a temporary file, then a rename).
    pub fn save(&self, path: &Path) -> Result<(), RunError> {
        let text = serde_json::to_string(self).map_err(|e| RunError::Internal(e.to_string()))?;
        write_atomically(path, text.as_bytes())
    }

    /// Reads classifiers `fdimc train` wrote ([`TrainedClassifiers::save`]), refusing a file that is not
    /// one, one for another list of classifiers, or one whose features are not `study`'s (another sample
    /// period or window would fail every trial, or worse, classify different features): the user's input
    /// to fix.
    pub fn load(path: &Path, study: &AccelerometerStudy) -> Result<TrainedClassifiers, RunError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| RunError::Invalid(format!("{}: cannot read the classifiers ({e})", path.display())))?;
        let trained: TrainedClassifiers = serde_json::from_str(&text).map_err(|e| {
            RunError::Invalid(format!("{}: not classifiers written by `fdimc train` ({e})", path.display()))
        })?;
        let names: Vec<String> =
            trained.classifiers.iter().map(|c| format!("{} (on {})", c.name, c.trained_on.name())).collect();
        let deck_names: Vec<String> =
            study.classifiers.iter().map(|c| format!("{} (on {})", c.name, c.trained_on.name())).collect();
        if names != deck_names {
            return Err(RunError::Invalid(format!(
                "{}: holds the classifiers [{}], but {} declares [{}]: train for this deck (`fdimc train {}`)",
                path.display(),
                names.join(", "),
                study.header.path.display(),
                deck_names.join(", "),
                study.header.path.display()
            )));
        }
        let split = log_training(study);
        if trained.log_training != split {
            let say = |s: &Option<String>| s.clone().unwrap_or_else(|| "no log".into());
            return Err(RunError::Invalid(format!(
                "{}: trained on the log split {}, but {} trains on {}: train for this deck (`fdimc train {}`)",
                path.display(),
                say(&trained.log_training),
                study.header.path.display(),
                say(&split),
                study.header.path.display()
            )));
        }
        let wanted = study.design.features;
        if let Some(c) = trained.classifiers.iter().map(|c| &c.classifier).find(|c| c.features != wanted) {
            let f = |p: &FeatureParams| format!("{} samples every {} s", p.window_len, p.dt_s);
            return Err(RunError::Invalid(format!(
                "{}: trained for {:?} on windows of {}, but {} computes windows of {}: train for this deck (`fdimc train {}`)",
                path.display(),
                trained.study,
                f(&c.features),
                study.header.path.display(),
                f(&wanted),
                study.header.path.display()
            )));
        }
        Ok(trained)
    }
}

/// One evaluation trial's scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct AccelTrialSpec {
    pub trial: u64,
    pub class: FaultClass,
    /// Faulty axis (0 x, 1 y, 2 z); `None` for the normal class.
    pub axis: Option<usize>,
    /// The bias (m/s^2) or the gain factor; NaN for normal and stuck.
    pub size: f64,
    /// Centre of the size's third of its range (|bias|, or |factor - 1|); NaN without a size.
    pub size_bin: f64,
    /// The onset, nominal for the normal class.
    pub onset_s: f64,
    pub noise_scale: f64,
    /// A replayed trial's segment start, log seconds from its first sample (`None`: simulated).
    pub log_start_s: Option<f64>,
}

/// How one trial went.
#[derive(Debug, Clone, PartialEq)]
pub struct AccelOutcome {
    /// Predicted class per classifier (the deck's order).
    pub predicted: Vec<FaultClass>,
    pub false_alarm_s: Option<f64>,
    pub alarm_s: Option<f64>,
    /// The residual statistic `T` as recorded for thresholds set after the run.
    pub statistic: RecordedStatistic,
    pub health: AttitudeHealth,
}

/// A trial's scenario and both classifiers' outcome, or why it could not be flown.
pub type AccelTrialResult = crate::engine::run::runner::TrialResult<AccelTrialSpec, AccelOutcome>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::deck::FromDeck;
    use crate::fault::FaultMode;
    use crate::methods::accelerometer::AccelerometerTrials;

    /// The bundled deck's grid: the four classes fastest, then the two noise scales; every faulty class
    /// carries its fault on the drawn axis, its size in its third of the range, its onset in the range.
    #[test]
    fn classes_and_noise_cycle_and_faults_match_their_class() {
        let study = AccelerometerStudy::bundled("seed003_accelerometer.toml");
        let classifiers = TrainedClassifiers {
            study: study.header.name.clone(),
            training_seed: 0,
            trials_per_class: 0,
            noise_scales: vec![1.0],
            classifiers: ["tree", "flat"]
                .map(|name| TrainedClassifier {
                    name: name.into(),
                    window: ClassifierWindow::Onset,
                    trained_on: TrainingData::Simulation,
                    classifier: empty_classifier(),
                })
                .into(),
            log_training: None,
        };
        let trials = AccelerometerTrials::new(&study, &classifiers);
        let r = &study.design.ranges;
        for i in 0..400u64 {
            let (spec, plan) = trials.draw(i);
            assert_eq!(format!("{spec:?}"), format!("{:?}", trials.draw(i).0), "a function of the trial index");
            assert_eq!(spec.class, FaultClass::ALL[(i % 4) as usize], "trial {i}");
            assert_eq!(spec.noise_scale, [1.0, 2.0][(i / 4 % 2) as usize], "trial {i}");
            let crate::methods::accelerometer::TrialPlan::Simulated(scenario) = plan else { panic!("simulated") };
            assert_eq!(scenario.noise_scale, spec.noise_scale);
            assert!((r.onset_s[0]..r.onset_s[1]).contains(&spec.onset_s));
            let fault = scenario.faults.first();
            match spec.class {
                FaultClass::Normal => assert!(fault.is_none() && spec.axis.is_none() && spec.size.is_nan()),
                FaultClass::Bias => {
                    let b = spec.size.abs();
                    assert!((r.bias_mps2[0]..r.bias_mps2[1]).contains(&b));
                    assert!((spec.size_bin - b).abs() <= (r.bias_mps2[1] - r.bias_mps2[0]) / 6.0 + 1e-12);
                    assert_eq!(fault.map(|f| f.mode), Some(FaultMode::Bias { bias: spec.size }));
                }
                FaultClass::Gain => {
                    let d = (spec.size - 1.0).abs();
                    assert!((r.gain_deviation[0]..r.gain_deviation[1]).contains(&d));
                    assert!((spec.size_bin - d).abs() <= (r.gain_deviation[1] - r.gain_deviation[0]) / 6.0 + 1e-12);
                }
                FaultClass::Stuck => assert_eq!(fault.map(|f| f.mode), Some(FaultMode::Stuck { value: None })),
            }
            assert_eq!(fault.map(|f| f.channel), spec.axis);
        }
    }

    /// A classifier trained on two tiny separable clusters: the grid test never classifies.
    fn empty_classifier() -> Classifier {
        use crate::methods::accelerometer::ekf_svm::{Example, FEATURE_COUNT, FeatureParams, SvmParams};
        let examples: Vec<Example> = (0..8)
            .map(|k| Example {
                features: [if k < 4 { 0.0 } else { 1.0 } + 0.01 * k as f64; FEATURE_COUNT],
                class: if k < 4 { FaultClass::Normal } else { FaultClass::Bias },
            })
            .collect();
        use crate::methods::accelerometer::ekf_svm::Scheme;
        Classifier::train(Scheme::OneVsOne, &examples, FeatureParams::seed(), SvmParams::seed()).unwrap()
    }
}
