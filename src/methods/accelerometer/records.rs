//! The trial-record table of accelerometer studies (`trials.parquet` of method 003): one row per
//! (trial, classifier), `tree` (the seed's bottom-up SVM decision tree) and `flat` (one-against-one).
//!
//! | column | meaning |
//! |---|---|
//! | `trial`, `detector` | trial index (its random streams), classifier |
//! | `kind`, `axis` | the true class (`normal`, `bias`, `gain`, `stuck`) and the faulty axis (`x`, `y`, `z`) |
//! | `size`, `size_bin` | the bias (m/s^2) or the gain factor; the centre of its third of the deck's range of \|bias\| or \|factor - 1\| |
//! | `onset_s`, `noise_scale`, `noise_bin` | the onset (nominal for normal trials), the factor on the white-noise sigmas (its own group label) |
//! | `failure` | why the trial could not be simulated or classified (null: it was) |
//! | `predicted`, `correct` | the class the classifier names from the window after the onset, whether it is the true one |
//! | `false_alarm_s`, `alarm_s`, `delay_s` | the residual detector: first alarm before the onset (anywhere for normal trials), first at or after it, and its delay |
//! | `unusable_accelerometer_samples` | samples the filter could not use (zero or non-finite) |

use polars::prelude::*;

use crate::engine::schema::col as common;
use crate::methods::accelerometer::ekf_svm::FaultClass;
use crate::methods::accelerometer::trial::{AccelTrialResult, DETECTORS};

/// Column names of this table beyond those it shares with the LTI records.
pub mod col {
    pub const AXIS: &str = "axis";
    pub const FAILURE: &str = "failure";
    pub const PREDICTED: &str = "predicted";
    pub const CORRECT: &str = "correct";
}

/// The rows of `results` (trial order); see the module docs.
pub fn frame(results: &[AccelTrialResult]) -> PolarsResult<DataFrame> {
    let n = results.len() * DETECTORS.len();
    let mut trial = Vec::with_capacity(n);
    let mut detector = Vec::with_capacity(n);
    let (mut kind, mut axis) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut size, mut size_bin, mut onset, mut noise) = (vec![], vec![], vec![], vec![]);
    let (mut failure, mut predicted, mut correct) = (vec![], vec![], vec![]);
    let (mut false_alarm, mut alarm, mut delay, mut unusable) = (vec![], vec![], vec![], vec![]);
    for r in results {
        let s = &r.spec;
        for (d, name) in DETECTORS.iter().enumerate() {
            let o = r.outcome.as_ref().ok();
            trial.push(s.trial);
            detector.push(*name);
            kind.push(s.class.name());
            axis.push(s.axis.map(|a| ["x", "y", "z"][a]));
            size.push(s.size.is_finite().then_some(s.size));
            size_bin.push(s.size_bin.is_finite().then_some(s.size_bin));
            onset.push(s.onset_s);
            noise.push(s.noise_scale);
            failure.push(r.outcome.as_ref().err().cloned());
            let p: Option<FaultClass> = o.map(|o| o.predicted[d]);
            predicted.push(p.map(FaultClass::name));
            correct.push(p.map(|p| p == s.class));
            false_alarm.push(o.and_then(|o| o.false_alarm_s));
            alarm.push(o.and_then(|o| o.alarm_s));
            delay.push(o.and_then(|o| o.alarm_s).map(|a| a - s.onset_s));
            unusable.push(o.map(|o| o.health.unusable_measurement));
        }
    }
    DataFrame::new_infer_height(vec![
        Column::new(common::TRIAL.into(), trial),
        Column::new(common::DETECTOR.into(), detector),
        Column::new(common::KIND.into(), kind),
        Column::new(col::AXIS.into(), axis),
        Column::new(common::SIZE.into(), size),
        Column::new(common::SIZE_BIN.into(), size_bin),
        Column::new(common::ONSET_S.into(), onset),
        Column::new(common::NOISE_SCALE.into(), noise.clone()),
        Column::new(common::NOISE_BIN.into(), noise),
        Column::new(col::FAILURE.into(), failure),
        Column::new(col::PREDICTED.into(), predicted),
        Column::new(col::CORRECT.into(), correct),
        Column::new(common::FALSE_ALARM_S.into(), false_alarm),
        Column::new(common::ALARM_S.into(), alarm),
        Column::new(common::DELAY_S.into(), delay),
        Column::new("unusable_accelerometer_samples".into(), unusable),
    ])
}
