//! The classifiers' `trials.parquet` (method 003): one row per (trial, classifier), by default `tree`
//! (the seed's bottom-up SVM decision tree) and `flat` (one-against-one), else the deck's
//! `[[classifier]]`s. The core columns of
//! [`crate::engine::results::schema`] come first, where `kind` is the true class (`normal`, `bias`, `gain`,
//! `stuck`; a `normal` trial is fault-free), `target` the faulty axis (`x`, `y`, `z`), `size` the bias
//! (m/s^2) or the gain factor and `size_bin` the centre of its third of the deck's range of \|bias\|
//! or \|factor - 1\|, `onset_s` the onset (nominal for normal trials), `noise_bin` the noise scale
//! itself, `isolated` the class the classifier names from its window (after the onset, or from the
//! alarm; an online classifier without an alarm names `normal`), alarms and delay
//! those of the residual detector (either classifier's rows), `failure` why the trial could not be
//! simulated or classified. Then:
//!
//! | column | meaning |
//! |---|---|
//! | `alarm_s` | the residual detector's first alarm at or after the onset |
//! | `unusable_accelerometer_samples` | samples the filter could not use (zero or non-finite) |
//! | `log_start_s` | replay decks only: the trial's segment start, log seconds from its first sample |
//! | `pre_max_residual_t`, `fp_t_s_residual_t`, `fp_v_residual_t` | the residual detector's statistic `T` recorded ([`STATISTIC`]): its largest value from `settle_s` to the onset (the whole normal trial) and its first-passage profile after the onset, so `summarize` calibrates its threshold and draws its ROC |

use std::borrow::Cow;

use polars::prelude::*;

use super::ekf_svm::FaultClass;
use super::trial::AccelTrialResult;
use crate::engine::results::schema::{CoreColumns, Outcome, StatisticColumns};

/// The recorded statistic: the residual detector's `T`.
pub const STATISTIC: &str = "residual_t";

/// The unit of a class's size.
fn size_unit(class: FaultClass) -> &'static str {
    match class {
        FaultClass::Bias => "m/s^2",
        FaultClass::Gain => crate::engine::results::schema::unit::GAIN_FACTOR,
        _ => crate::engine::results::schema::unit::NONE,
    }
}

/// The rows of `results` (trial order) for the classifiers `names` (the outcomes' order), an alarm
/// later than `detection_window_s` after the onset a late alarm; see the module docs.
pub fn frame(
    results: &[AccelTrialResult],
    names: &[&str],
    replay: bool,
    detection_window_s: f64,
) -> PolarsResult<DataFrame> {
    let n = results.len() * names.len();
    let mut core = CoreColumns::new(Vec::new(), n, detection_window_s);
    let mut statistics = StatisticColumns::new(&[STATISTIC.to_string()], n);
    let (mut alarm, mut unusable, mut log_start) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::new());
    for r in results {
        let s = &r.spec;
        let fault_free = s.class == FaultClass::Normal;
        for (d, name) in names.iter().enumerate() {
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
                truth_diverged: false,
                false_alarm_s: o.and_then(|o| o.false_alarm_s),
                delay_s: o.and_then(|o| o.alarm_s).filter(|_| !fault_free).map(|a| a - s.onset_s),
                isolated: predicted.map(|p| Cow::Borrowed(p.name())),
                isolated_correctly: predicted.map(|p| p == s.class),
                noise_scale: s.noise_scale,
                noise_bin: s.noise_scale,
                param_error_bin: 0.0,
                param_errors: &[],
            });
            statistics.push_recorded(0, o.map(|o| &o.statistic));
            alarm.push(o.and_then(|o| o.alarm_s));
            unusable.push(o.map(|o| o.health.unusable_measurement));
            log_start.push(s.log_start_s);
        }
    }
    let mut columns = core.finish();
    columns.push(Column::new("alarm_s".into(), alarm));
    columns.push(Column::new("unusable_accelerometer_samples".into(), unusable));
    if replay {
        columns.push(Column::new("log_start_s".into(), log_start));
    }
    columns.extend(statistics.finish());
    DataFrame::new_infer_height(columns)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::results::summary::hand_made::Summarized;
    use crate::methods::accelerometer::trial::{AccelOutcome, AccelTrialSpec};

    /// Both classifiers on four hand-made trials. Trial 0: a bias on x (0.3 m/s^2) alarmed after 0.2 s,
    /// "flat" calls it bias, "tree" gain; trial 1: normal, an alarm at 5 s (a false alarm of both), "flat"
    /// calls it normal, "tree" bias; trial 2: y stuck, alarmed after 0.5 s, both call it stuck; trial 3: a
    /// bias on x that could not be flown.
    #[test]
    fn summary_of_hand_made_accelerometer_trials() {
        use FaultClass::*;
        let spec = |trial: u64, class: FaultClass, axis: Option<usize>, size: f64| AccelTrialSpec {
            trial,
            class,
            axis,
            size,
            size_bin: if class == Bias { 0.275 } else { f64::NAN },
            onset_s: 10.0,
            noise_scale: 1.0,
            log_start_s: None,
        };
        // `predicted` is in the classifiers' order: tree, flat.
        let out = |tree, flat, alarm: Option<f64>, false_alarm: Option<f64>| AccelOutcome {
            predicted: vec![tree, flat],
            false_alarm_s: false_alarm,
            alarm_s: alarm,
            statistic: Default::default(),
            health: Default::default(),
        };
        let results = vec![
            AccelTrialResult { spec: spec(0, Bias, Some(0), 0.3), outcome: Ok(out(Gain, Bias, Some(10.2), None)) },
            AccelTrialResult {
                spec: spec(1, Normal, None, f64::NAN),
                outcome: Ok(out(Bias, Normal, Some(5.0), Some(5.0))),
            },
            AccelTrialResult {
                spec: spec(2, Stuck, Some(1), f64::NAN),
                outcome: Ok(out(Stuck, Stuck, Some(10.5), None)),
            },
            AccelTrialResult { spec: spec(3, Bias, Some(0), 0.3), outcome: Err("unusable".into()) },
        ];
        let df = frame(&results, &["tree", "flat"], false, f64::INFINITY).unwrap();
        assert_eq!(df.height(), 8);
        let s = Summarized::of(df, &super::super::METHOD, 4, &["tree", "flat"]);
        assert_eq!(s.summary.height(), 12, "3 kinds x 2 classifiers x the deck's and the calibrated thresholds");
        for detector in ["flat", "tree"] {
            let (bias, normal, stuck) = (s.row(detector, "bias"), s.row(detector, "normal"), s.row(detector, "stuck"));
            assert_eq!(["trials", "failed", "detected"].map(|c| s.count(c, bias)), [Some(2), Some(1), Some(1)]);
            assert_eq!(s.value("pd", bias), Some(1.0));
            assert_eq!((s.count("false_alarms", normal), s.value("pfa", normal)), (Some(1), Some(1.0)));
            assert_eq!(s.value("pd", normal), None, "no detection probability of the normal class");
            s.assert_close("delay_p50_s", stuck, 0.5);
            assert_eq!(s.count("isolated_correctly", stuck), Some(1), "both call the stuck axis stuck");
        }
        // Classification: flat is right on every flown trial, tree on the stuck one only.
        for (detector, bias_ok, normal_ok) in [("flat", 1, 1), ("tree", 0, 0)] {
            assert_eq!(s.count("isolated_correctly", s.row(detector, "bias")), Some(bias_ok), "{detector}");
            assert_eq!(s.count("isolated_correctly", s.row(detector, "normal")), Some(normal_ok), "{detector}");
            assert_eq!(
                s.count("isolation_decided", s.row(detector, "normal")),
                Some(1),
                "a classifier always names a class"
            );
        }
        let confusion = s.table("confusion.csv");
        let tree_bias = (0..confusion.height()).find(|&i| {
            let t = |n: &str| confusion.column(n).unwrap().str().unwrap().get(i).map(String::from);
            t("detector").as_deref() == Some("tree")
                && t("truth").as_deref() == Some("bias")
                && t("isolated").as_deref() == Some("gain")
        });
        assert!(tree_bias.is_some(), "tree's bias-as-gain in confusion.csv: {confusion}");
    }
}
