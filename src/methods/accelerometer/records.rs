//! The classifiers' `trials.parquet` (method 003): one row per (trial, classifier), `tree` (the seed's
//! bottom-up SVM decision tree) and `flat` (one-against-one). The core columns of
//! [`crate::engine::schema`] come first, where `kind` is the true class (`normal`, `bias`, `gain`,
//! `stuck`; a `normal` trial is fault-free), `target` the faulty axis (`x`, `y`, `z`), `size` the bias
//! (m/s^2) or the gain factor and `size_bin` the centre of its third of the deck's range of \|bias\|
//! or \|factor - 1\|, `onset_s` the onset (nominal for normal trials), `noise_bin` the noise scale
//! itself, `isolated` the class the classifier names from the window after the onset, alarms and delay
//! those of the residual detector (either classifier's rows), `failure` why the trial could not be
//! simulated or classified. Then:
//!
//! | column | meaning |
//! |---|---|
//! | `alarm_s` | the residual detector's first alarm at or after the onset |
//! | `unusable_accelerometer_samples` | samples the filter could not use (zero or non-finite) |

use std::borrow::Cow;

use polars::prelude::*;

use super::ekf_svm::FaultClass;
use super::trial::{AccelTrialResult, DETECTORS};
use crate::engine::schema::{CoreColumns, Outcome};

/// The unit of a class's size.
fn size_unit(class: FaultClass) -> &'static str {
    match class {
        FaultClass::Bias => "m/s^2",
        FaultClass::Gain => crate::fault::deck::unit::GAIN_FACTOR,
        _ => crate::fault::deck::unit::NONE,
    }
}

/// The rows of `results` (trial order); see the module docs.
pub fn frame(results: &[AccelTrialResult]) -> PolarsResult<DataFrame> {
    let n = results.len() * DETECTORS.len();
    let mut core = CoreColumns::new(Vec::new(), n);
    let (mut alarm, mut unusable) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for r in results {
        let s = &r.spec;
        let fault_free = s.class == FaultClass::Normal;
        for (d, name) in DETECTORS.iter().enumerate() {
            let o = r.outcome.as_ref().ok();
            let predicted: Option<FaultClass> = o.map(|o| o.predicted[d]);
            core.push(Outcome {
                trial: s.trial,
                detector: name,
                kind: s.class.name(),
                target: s.axis.map(|a| Cow::Borrowed(["x", "y", "z"][a])),
                size: Some(s.size),
                size_unit: size_unit(s.class),
                size_bin: Some(s.size_bin),
                onset_s: Some(s.onset_s),
                fault_free,
                failure: r.outcome.as_ref().err().cloned(),
                diverged: o.is_some_and(|o| o.health.filter.non_finite > 0),
                false_alarm_s: o.and_then(|o| o.false_alarm_s),
                delay_s: o.and_then(|o| o.alarm_s).filter(|_| !fault_free).map(|a| a - s.onset_s),
                isolated: predicted.map(|p| Cow::Borrowed(p.name())),
                isolated_correctly: predicted.map(|p| p == s.class),
                noise_scale: s.noise_scale,
                noise_bin: s.noise_scale,
                param_error_bin: 0.0,
                param_errors: &[],
            });
            alarm.push(o.and_then(|o| o.alarm_s));
            unusable.push(o.map(|o| o.health.unusable_measurement));
        }
    }
    let mut columns = core.finish();
    columns.push(Column::new("alarm_s".into(), alarm));
    columns.push(Column::new("unusable_accelerometer_samples".into(), unusable));
    DataFrame::new_infer_height(columns)
}
