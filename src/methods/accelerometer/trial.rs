//! Trials of an accelerometer study (method 003): training the classifiers on their own trials, and
//! each evaluation trial flown once and scored.
//!
//! Training ([`TrainedClassifiers::train`]): `trials_per_class` trials of each class from the training
//! seed (trial j, of class `j mod 4` and the `(j / 4) mod n`-th of the n training noise scales, draws
//! everything from stream j of that seed), the features of each
//! trial's window after its onset, then the bottom-up SVM decision tree and the flat one-against-one SVM
//! on the same examples. Both are saved together to a JSON file and loaded from it, so a study can be
//! evaluated on fresh trials (the study's seed) with exactly the classifiers a file holds.
//!
//! An evaluation trial: its class from the grid (the deck's classes cycled over the trial index, then the
//! noise scale), its fault, onset and sensor biases from the trial's fault stream, its sensor noise from
//! the sensor stream; the attitude EKF over the whole flight; then
//! - classification: both classifiers on the features of the window the training used;
//! - detection: the statistic `T` of the residual's windowed mean against the deck's threshold, from
//!   `settle_s` on: a false alarm before the onset (anywhere when the class is normal), a detection at
//!   or after it.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::engine::runner::{RunError, write_atomically};
use crate::engine::streams::{Substream, trial_rng};
use crate::methods::accelerometer::attitude::AttitudeHealth;
use crate::methods::accelerometer::ekf_svm::{Classifier, FaultClass, FeatureParams, Scheme};
use crate::methods::accelerometer::study::AccelerometerStudy;

/// The two classifiers of a study, trained on the same examples, as a file holds them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainedClassifiers {
    /// The study they were trained for, and on what.
    pub study: String,
    pub training_seed: u64,
    pub trials_per_class: usize,
    pub noise_scales: Vec<f64>,
    /// The bottom-up SVM decision tree (the seed's method).
    pub tree: Classifier,
    /// One binary SVM per pair of classes, majority vote.
    pub flat: Classifier,
}

/// The detectors of a study: the classifier schemes.
pub const DETECTORS: [&str; 2] = ["tree", "flat"];

impl TrainedClassifiers {
    /// Trains both classifiers on the study's training trials (module docs).
    pub fn train(study: &AccelerometerStudy) -> Result<TrainedClassifiers, String> {
        let t = &study.training;
        let mut examples = Vec::with_capacity(4 * t.trials_per_class);
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
        for j in 0..classes * t.trials_per_class as u64 {
            let class = FaultClass::ALL[(j % classes) as usize];
            let design = &designs[((j / classes) % designs.len() as u64) as usize];
            let mut rng = trial_rng(t.seed, j, Substream::Scenario);
            let example = design
                .draw_example(class, &mut rng)
                .map_err(|e| format!("training trial {j} ({}): {e}", class.name()))?;
            examples.push(example);
        }
        let train = |scheme| {
            Classifier::train(scheme, &examples, study.design.features, t.svm).map_err(|e| format!("training: {e}"))
        };
        Ok(TrainedClassifiers {
            study: study.header.name.clone(),
            training_seed: t.seed,
            trials_per_class: t.trials_per_class,
            noise_scales: t.noise_scales.clone(),
            tree: train(Scheme::Tree)?,
            flat: train(Scheme::OneVsOne)?,
        })
    }

    /// Writes both classifiers to `path` (a temporary file, then a rename).
    pub fn save(&self, path: &Path) -> Result<(), RunError> {
        let text = serde_json::to_string(self).map_err(|e| RunError::Internal(e.to_string()))?;
        write_atomically(path, text.as_bytes())
    }

    /// Reads classifiers written by [`TrainedClassifiers::save`]; a file that is not one is the user's
    /// input to fix.
    /// Reads classifiers `fdimc train` wrote, refusing ones whose features are not `study`'s (another
    /// sample period or window would fail every trial, or worse, classify different features).
    pub fn load(path: &Path, study: &AccelerometerStudy) -> Result<TrainedClassifiers, RunError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| RunError::Invalid(format!("{}: cannot read the classifiers ({e})", path.display())))?;
        let trained: TrainedClassifiers = serde_json::from_str(&text).map_err(|e| {
            RunError::Invalid(format!("{}: not classifiers written by `fdimc train` ({e})", path.display()))
        })?;
        let wanted = study.design.features;
        if let Some(c) = [&trained.tree, &trained.flat].into_iter().find(|c| c.features != wanted) {
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

    pub(crate) fn get(&self, detector: usize) -> &Classifier {
        if detector == 0 { &self.tree } else { &self.flat }
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
}

/// How one trial went.
#[derive(Debug, Clone, PartialEq)]
pub struct AccelOutcome {
    /// Predicted class per detector ([`DETECTORS`] order).
    pub predicted: [FaultClass; 2],
    pub false_alarm_s: Option<f64>,
    pub alarm_s: Option<f64>,
    pub health: AttitudeHealth,
}

/// A trial's scenario and both classifiers' outcome, or why it could not be flown.
pub type AccelTrialResult = crate::engine::runner::TrialResult<AccelTrialSpec, AccelOutcome>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::deck::FromDeck;
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
            tree: empty_classifier(),
            flat: empty_classifier(),
        };
        let trials = AccelerometerTrials::new(&study, &classifiers);
        let r = &study.design.ranges;
        for i in 0..400u64 {
            let (spec, scenario) = trials.draw(i);
            assert_eq!(format!("{spec:?}"), format!("{:?}", trials.draw(i).0), "a function of the trial index");
            assert_eq!(spec.class, FaultClass::ALL[(i % 4) as usize], "trial {i}");
            assert_eq!(spec.noise_scale, [1.0, 2.0][(i / 4 % 2) as usize], "trial {i}");
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
        Classifier::train(Scheme::OneVsOne, &examples, FeatureParams::seed(), SvmParams::seed()).unwrap()
    }
}
