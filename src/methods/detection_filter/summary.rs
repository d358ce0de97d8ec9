//! Statistics from `trials.parquet`, without re-simulating: thresholds, rates with intervals, delays,
//! detection-probability curves, paired comparisons of detector configurations.
//!
//! Thresholds (per detector configuration, `thresholds.csv`):
//! - per output: the smallest threshold that at most `floor(p n)` of the `n` calibration trials' largest
//!   |residual| exceed (so each output alone has false-alarm probability <= p on calibration data);
//! - whole detector: those per-output thresholds times one common factor, the smallest at which at most
//!   `floor(p n)` calibration trials alarm on any output: the detector's false-alarm probability is p.
//! Calibration trials are the fault-free trials (their whole duration); without any, the pre-onset
//! windows of all trials. `--thresholds F` applies thresholds calibrated on another run instead, and the
//! rates achieved here validate them on fresh trials.
//!
//! The summary evaluates every trial at two threshold sets: `deck` (the deck's thresholds, evaluated
//! online during the trial, with isolation) and `calibrated` (the whole-detector thresholds, evaluated
//! from the recorded pre-onset maxima and first-passage profiles; isolation needs the residual after
//! the alarm, so it is reported for `deck` only). Detection probability counts, among the faulty trials
//! of a group whose design succeeded, those with an alarm at or after the onset; the false-alarm rate
//! counts alarms before the onset (the whole trial when fault-free). Intervals are 95 % Wilson.

use std::path::Path;

use polars::prelude::*;

use crate::engine::intervals::{Z95, mcnemar_exact, wilson};
use crate::engine::output::write_table;
use crate::engine::runner::{Manifest, RunError, io, pol, write_parquet};
use crate::engine::schema::col;
use crate::engine::summary::{Calibration, alarm_time, calibrate, f64_col, list_col, read_slice, str_col};

/// Rows read at a time when evaluating (a multiple of the detector count is taken).
const EVAL_ROWS: usize = 8_192;

/// Thresholds of one detector configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorThresholds {
    pub detector: String,
    pub deck: Vec<f64>,
    /// Per output, each at the target false-alarm probability alone.
    pub per_output: Vec<f64>,
    /// Whole-detector thresholds (`per_output * scale`).
    pub whole: Vec<f64>,
    pub calibration_trials: u64,
    pub per_output_false_alarms: Vec<u64>,
    pub whole_false_alarms: u64,
}

/// What `summarize` wrote.
#[derive(Debug)]
pub struct SummaryReport {
    pub thresholds: Vec<DetectorThresholds>,
    pub calibration_source: String,
    pub summary: DataFrame,
    pub comparison: Option<DataFrame>,
    pub warnings: Vec<String>,
}

/// Warnings about failed designs and diverged filters, counted once per (trial, detector) from the
/// summary's `deck` rows (every threshold set holds the same trials).
pub fn health_warnings(summary: &DataFrame) -> Vec<String> {
    let deck_sum = |name: &str| -> u64 {
        let (Ok(set), Ok(values)) = (summary.column("thresholds"), summary.column(name)) else { return 0 };
        let (Ok(set), Ok(values)) = (set.str(), values.u64()) else { return 0 };
        (0..summary.height()).filter(|&i| set.get(i) == Some("deck")).filter_map(|i| values.get(i)).sum()
    };
    let mut warnings = Vec::new();
    let failures = deck_sum("design_failures");
    if failures > 0 {
        warnings.push(format!("{failures} trial x detector designs failed (design_error in trials.parquet)"));
    }
    let diverged = deck_sum("diverged");
    if diverged > 0 {
        warnings.push(format!("{diverged} trial x detector runs diverged (diverged_at_s in trials.parquet)"));
    }
    warnings
}

struct Columns {
    outputs: Vec<String>,
}

impl Columns {
    fn from_frame(df: &DataFrame) -> Columns {
        let outputs = df
            .get_column_names()
            .iter()
            .filter_map(|n| n.as_str().strip_prefix("pre_max_").map(str::to_string))
            .collect();
        Columns { outputs }
    }
}

/// Calibrates (or reads) thresholds, evaluates every trial, writes `thresholds.csv`, `summary.csv`,
/// `summary.parquet`, `curves.csv`, `min_detectable.csv` and, with several detectors, `comparison.csv`.
pub fn summarize(dir: &Path, calibration: &Calibration) -> Result<SummaryReport, RunError> {
    let manifest = Manifest::read(dir)?;
    let trials_path = dir.join("trials.parquet");
    if !manifest.complete || !trials_path.exists() {
        return Err(RunError::Invalid(format!(
            "{}: the run is not complete: finish it with `fdimc run ... --resume`",
            dir.display()
        )));
    }
    let mut warnings = Vec::new();
    // A truncated or foreign file is bad input, not an internal error: check its footer first.
    let rows_on_disk = std::fs::File::open(&trials_path).map_err(io(&trials_path)).and_then(|f| {
        ParquetReader::new(f).num_rows().map_err(|e| {
            RunError::Invalid(format!("{}: not a readable Parquet file ({e}); re-run the study", trials_path.display()))
        })
    })?;
    if rows_on_disk as u64 != manifest.rows {
        return Err(RunError::Invalid(format!(
            "{}: holds {rows_on_disk} rows, its manifest.json says {}: re-run the study",
            trials_path.display(),
            manifest.rows
        )));
    }

    // Pass 1: calibration data (small: keys and pre-onset maxima).
    let head = read_slice(&trials_path, 0, 1, None)?;
    let cols = Columns::from_frame(&head);
    let outputs = cols.outputs.clone();
    let mut select = vec![col::DETECTOR.to_string(), col::KIND.to_string(), col::DESIGN_ERROR.to_string()];
    select.extend(outputs.iter().map(|o| col::pre_max(o)));
    let cal = read_slice(&trials_path, 0, manifest.rows as usize, Some(select))?;
    let detectors = &manifest.detectors;
    let det = str_col(&cal, col::DETECTOR, &trials_path)?;
    let kind = str_col(&cal, col::KIND, &trials_path)?;
    let design_error = str_col(&cal, col::DESIGN_ERROR, &trials_path)?;
    let pre: Vec<&Float64Chunked> =
        outputs.iter().map(|o| f64_col(&cal, &col::pre_max(o), &trials_path)).collect::<Result<_, _>>()?;
    let any_fault_free = (0..kind.len()).any(|i| kind.get(i) == Some(col::NO_FAULT));
    let calibration_source = match calibration {
        Calibration::File(f) => format!("thresholds from {}", f.display()),
        Calibration::Target(p) if any_fault_free => format!("calibrated at Pfa {p} on the fault-free trials"),
        Calibration::Target(p) => {
            warnings.push(
                "no fault-free trials: thresholds calibrated on the pre-onset windows (shorter than a whole trial)"
                    .into(),
            );
            format!("calibrated at Pfa {p} on the pre-onset windows")
        }
    };
    let from_file = match calibration {
        Calibration::File(f) => Some(read_thresholds(f)?),
        Calibration::Target(_) => None,
    };

    let mut thresholds = Vec::with_capacity(detectors.len());
    for (d_index, d) in detectors.iter().enumerate() {
        let rows: Vec<usize> = (0..cal.height())
            .filter(|&i| {
                det.get(i) == Some(d.as_str())
                    && design_error.get(i).is_none()
                    && (!any_fault_free || kind.get(i) == Some(col::NO_FAULT))
            })
            .collect();
        let n = rows.len() as u64;
        let values = |j: usize| rows.iter().map(|&i| pre[j].get(i).unwrap_or(f64::NAN)).collect::<Vec<f64>>();
        let deck = manifest.deck_thresholds.get(d_index).cloned().unwrap_or_default();
        let (per_output, whole) = match (&from_file, calibration) {
            (Some(file), _) => {
                let (_, per, whole) = file.iter().find(|(name, _, _)| name == d).cloned().ok_or_else(|| {
                    RunError::Invalid(format!(
                        "the thresholds file has no detector {d:?}: calibrate on a run of the same deck"
                    ))
                })?;
                if per.len() != outputs.len() {
                    return Err(RunError::Invalid(format!(
                        "the thresholds file has {} outputs for {d:?}, this run {}",
                        per.len(),
                        outputs.len()
                    )));
                }
                (per, whole)
            }
            (None, Calibration::Target(p)) => {
                if (n as f64) * p < 1.0 {
                    warnings.push(format!(
                        "detector {d}: {n} calibration trials cannot resolve Pfa {p} (needs >= {}): thresholds are the largest values seen",
                        (1.0 / p).ceil()
                    ));
                }
                let per: Vec<f64> = (0..outputs.len()).map(|j| calibrate(&mut values(j), *p).0).collect();
                let mut z: Vec<f64> = rows
                    .iter()
                    .map(|&i| {
                        (0..outputs.len()).map(|j| pre[j].get(i).unwrap_or(f64::NAN) / per[j]).fold(0.0, f64::max)
                    })
                    .collect();
                let (scale, _) = calibrate(&mut z, *p);
                (per.clone(), per.iter().map(|t| t * scale).collect())
            }
            (None, Calibration::File(_)) => unreachable!("file thresholds are read above"),
        };
        let per_output_false_alarms =
            (0..outputs.len()).map(|j| values(j).iter().filter(|&&v| v > per_output[j]).count() as u64).collect();
        let whole_false_alarms =
            rows.iter().filter(|&&i| (0..outputs.len()).any(|j| pre[j].get(i).unwrap_or(f64::NAN) > whole[j])).count()
                as u64;
        thresholds.push(DetectorThresholds {
            detector: d.clone(),
            deck,
            per_output,
            whole,
            calibration_trials: n,
            per_output_false_alarms,
            whole_false_alarms,
        });
    }
    drop(cal);
    write_thresholds(dir, &thresholds, &outputs, &calibration_source)?;

    // Pass 2: evaluate every row at both threshold sets, a slice at a time.
    let mut ev = Evaluated::default();
    let mut pairs = PairCounts::new(detectors.len());
    let height = manifest.rows as usize;
    let step = (EVAL_ROWS / detectors.len().max(1)).max(1) * detectors.len().max(1);
    let mut offset = 0;
    while offset < height {
        let df = read_slice(&trials_path, offset, step, None)?;
        evaluate_slice(&df, &trials_path, &outputs, detectors, &thresholds, &mut ev, &mut pairs)?;
        offset += step;
    }

    let evaluated = ev.into_frame().map_err(pol(&trials_path))?;
    let keys =
        ["thresholds", col::DETECTOR, col::KIND, col::OUTPUT, col::SIZE_BIN, col::NOISE_BIN, col::PARAM_ERROR_BIN];
    let mut summary = aggregate(&evaluated, &keys).map_err(pol(&trials_path))?;
    let curve_keys = ["thresholds", col::DETECTOR, col::KIND, col::OUTPUT, col::SIZE_BIN];
    let mut curves = aggregate(&evaluated, &curve_keys).map_err(pol(&trials_path))?;
    let mut min_detectable = min_detectable(&curves).map_err(pol(&trials_path))?;

    let out = |f: &str| dir.join(f);
    write_table(&mut summary, &out("summary.csv"))?;
    write_parquet(&mut summary, &out("summary.parquet"))?;
    write_table(&mut curves, &out("curves.csv"))?;
    write_table(&mut min_detectable, &out("min_detectable.csv"))?;
    let comparison = if detectors.len() > 1 {
        let mut c = pairs.into_frame(detectors).map_err(pol(&trials_path))?;
        write_table(&mut c, &out("comparison.csv"))?;
        Some(c)
    } else {
        None
    };
    warnings.extend(health_warnings(&summary));
    Ok(SummaryReport { thresholds, calibration_source, summary, comparison, warnings })
}

/// Per-row evaluation results, in long form (one row per trial x detector x threshold set).
#[derive(Default)]
struct Evaluated {
    /// Distinct strings of the key columns; the columns hold indices into it (millions of rows).
    names: Vec<String>,
    thresholds: Vec<&'static str>,
    detector: Vec<u32>,
    kind: Vec<u32>,
    output: Vec<Option<u32>>,
    size_bin: Vec<Option<f64>>,
    noise_bin: Vec<f64>,
    param_error_bin: Vec<f64>,
    faulty: Vec<bool>,
    designed: Vec<bool>,
    diverged: Vec<bool>,
    false_alarm: Vec<bool>,
    detected: Vec<bool>,
    delay_s: Vec<Option<f64>>,
    iso_decided: Vec<bool>,
    iso_direction_ok: Vec<bool>,
    iso_max_ok: Vec<bool>,
}

impl Evaluated {
    fn intern(&mut self, s: &str) -> u32 {
        match self.names.iter().position(|n| n == s) {
            Some(i) => i as u32,
            None => {
                self.names.push(s.to_string());
                (self.names.len() - 1) as u32
            }
        }
    }

    fn into_frame(self) -> PolarsResult<DataFrame> {
        let names = &self.names;
        let name = |i: &u32| names[*i as usize].as_str();
        let strings = |name_: &str, v: &[u32]| Column::new(name_.into(), v.iter().map(name).collect::<Vec<&str>>());
        DataFrame::new_infer_height(vec![
            Column::new("thresholds".into(), self.thresholds),
            strings(col::DETECTOR, &self.detector),
            strings(col::KIND, &self.kind),
            Column::new(
                col::OUTPUT.into(),
                self.output.iter().map(|o| o.as_ref().map(name)).collect::<Vec<Option<&str>>>(),
            ),
            Column::new(col::SIZE_BIN.into(), self.size_bin),
            Column::new(col::NOISE_BIN.into(), self.noise_bin),
            Column::new(col::PARAM_ERROR_BIN.into(), self.param_error_bin),
            Column::new("faulty".into(), self.faulty),
            Column::new("designed".into(), self.designed),
            Column::new("diverged".into(), self.diverged),
            Column::new("false_alarm".into(), self.false_alarm),
            Column::new("detected".into(), self.detected),
            Column::new(col::DELAY_S.into(), self.delay_s),
            Column::new("iso_decided".into(), self.iso_decided),
            Column::new("iso_direction_ok".into(), self.iso_direction_ok),
            Column::new("iso_max_ok".into(), self.iso_max_ok),
        ])
    }
}

/// Discordant-pair counts of detector 0 against each other detector, per threshold set.
struct PairCounts {
    /// [set][other detector] -> (n faulty designed pairs, det0 only, other only, both, fault-free pairs, fa0 only, fa other only)
    counts: [Vec<[u64; 7]>; 2],
}

impl PairCounts {
    fn new(detectors: usize) -> Self {
        PairCounts { counts: [vec![[0; 7]; detectors], vec![[0; 7]; detectors]] }
    }

    fn into_frame(self, detectors: &[String]) -> PolarsResult<DataFrame> {
        let mut set = Vec::new();
        let mut a = Vec::new();
        let mut b = Vec::new();
        let mut cols: [Vec<u64>; 7] = Default::default();
        let mut pd_a = Vec::new();
        let mut pd_b = Vec::new();
        let mut p_det = Vec::new();
        let mut p_fa = Vec::new();
        for (s, name) in [(0, "deck"), (1, "calibrated")] {
            for (k, c) in self.counts[s].iter().enumerate().skip(1) {
                set.push(name);
                a.push(detectors[0].clone());
                b.push(detectors[k].clone());
                for (col, v) in cols.iter_mut().zip(c) {
                    col.push(*v);
                }
                let n = c[0].max(1) as f64;
                pd_a.push((c[1] + c[3]) as f64 / n);
                pd_b.push((c[2] + c[3]) as f64 / n);
                p_det.push(mcnemar_exact(c[1], c[2]));
                p_fa.push(mcnemar_exact(c[5], c[6]));
            }
        }
        let [n, a_only, b_only, both, n_ff, fa_a_only, fa_b_only] = cols;
        DataFrame::new_infer_height(vec![
            Column::new("thresholds".into(), set),
            Column::new("detector_a".into(), a),
            Column::new("detector_b".into(), b),
            Column::new("faulty_pairs".into(), n),
            Column::new("pd_a".into(), pd_a),
            Column::new("pd_b".into(), pd_b),
            Column::new("detected_by_a_only".into(), a_only),
            Column::new("detected_by_b_only".into(), b_only),
            Column::new("detected_by_both".into(), both),
            Column::new("mcnemar_p_detection".into(), p_det),
            Column::new("fault_free_pairs".into(), n_ff),
            Column::new("false_alarm_a_only".into(), fa_a_only),
            Column::new("false_alarm_b_only".into(), fa_b_only),
            Column::new("mcnemar_p_false_alarm".into(), p_fa),
        ])
    }
}

#[allow(clippy::too_many_arguments)]
fn evaluate_slice(
    df: &DataFrame,
    file: &Path,
    outputs: &[String],
    detectors: &[String],
    thresholds: &[DetectorThresholds],
    ev: &mut Evaluated,
    pairs: &mut PairCounts,
) -> Result<(), RunError> {
    let det = str_col(df, col::DETECTOR, file)?;
    let kind = str_col(df, col::KIND, file)?;
    let output = str_col(df, col::OUTPUT, file)?;
    let size_bin = f64_col(df, col::SIZE_BIN, file)?;
    let onset = f64_col(df, col::ONSET_S, file)?;
    let noise_bin = f64_col(df, col::NOISE_BIN, file)?;
    let perr_bin = f64_col(df, col::PARAM_ERROR_BIN, file)?;
    let design_error = str_col(df, col::DESIGN_ERROR, file)?;
    let diverged = f64_col(df, col::DIVERGED_AT_S, file)?;
    let fa_s = f64_col(df, col::FALSE_ALARM_S, file)?;
    let alarm_s = f64_col(df, col::ALARM_S, file)?;
    let delay_s = f64_col(df, col::DELAY_S, file)?;
    let iso_dir = str_col(df, col::ISOLATED_BY_DIRECTION, file)?;
    let iso_max = str_col(df, col::ISOLATED_BY_MAX, file)?;
    let pre: Vec<&Float64Chunked> =
        outputs.iter().map(|o| f64_col(df, &col::pre_max(o), file)).collect::<Result<_, _>>()?;
    let fp_t: Vec<Vec<Vec<f64>>> =
        outputs.iter().map(|o| list_col(df, &col::fp_t(o), file)).collect::<Result<_, _>>()?;
    let fp_v: Vec<Vec<Vec<f64>>> =
        outputs.iter().map(|o| list_col(df, &col::fp_v(o), file)).collect::<Result<_, _>>()?;

    // Detection results of the current trial's detectors, for the paired counts: [set][detector].
    let nd = detectors.len();
    let mut trial_rows: [Vec<Option<(bool, bool)>>; 2] = [vec![None; nd], vec![None; nd]];
    for i in 0..df.height() {
        let d_name = det.get(i).unwrap_or_default();
        let d = detectors
            .iter()
            .position(|n| n == d_name)
            .ok_or_else(|| RunError::Invalid(format!("{}: unknown detector {d_name:?}", file.display())))?;
        let faulty = kind.get(i) != Some(col::NO_FAULT);
        let designed = design_error.get(i).is_none();
        let truth = output.get(i);
        for (s, set) in ["deck", "calibrated"].into_iter().enumerate() {
            let (fa, detected, delay, iso) = if !designed {
                (false, false, None, None)
            } else if s == 0 {
                let iso = iso_dir.get(i).map(|dir| (dir == truth.unwrap_or_default(), iso_max.get(i) == truth));
                (fa_s.get(i).is_some(), alarm_s.get(i).is_some(), delay_s.get(i), iso)
            } else {
                let th = &thresholds[d].whole;
                let fa = (0..outputs.len()).any(|j| pre[j].get(i).unwrap_or(f64::NAN) > th[j]);
                let alarm = alarm_time(&fp_t, &fp_v, i, th);
                (fa, alarm.is_some(), alarm.map(|t| t - onset.get(i).unwrap_or(f64::NAN)), None)
            };
            ev.thresholds.push(set);
            let (d_id, k_id) = (ev.intern(d_name), ev.intern(kind.get(i).unwrap_or_default()));
            let o_id = truth.map(|t| ev.intern(t));
            ev.detector.push(d_id);
            ev.kind.push(k_id);
            ev.output.push(o_id);
            ev.size_bin.push(size_bin.get(i));
            ev.noise_bin.push(noise_bin.get(i).unwrap_or(f64::NAN));
            ev.param_error_bin.push(perr_bin.get(i).unwrap_or(f64::NAN));
            ev.faulty.push(faulty);
            ev.designed.push(designed);
            ev.diverged.push(diverged.get(i).is_some());
            ev.false_alarm.push(fa);
            ev.detected.push(faulty && detected);
            ev.delay_s.push(if faulty { delay } else { None });
            ev.iso_decided.push(iso.is_some());
            ev.iso_direction_ok.push(iso.is_some_and(|x| x.0));
            ev.iso_max_ok.push(iso.is_some_and(|x| x.1));
            trial_rows[s][d] = designed.then_some((if faulty { detected } else { fa }, faulty));
        }
        // Rows of one trial are consecutive, one per detector in deck order.
        if d + 1 == nd {
            for s in 0..2 {
                if let Some((a, faulty)) = trial_rows[s][0] {
                    for k in 1..nd {
                        if let Some((b, _)) = trial_rows[s][k] {
                            let c = &mut pairs.counts[s][k];
                            if faulty {
                                c[0] += 1;
                                c[1] += (a && !b) as u64;
                                c[2] += (b && !a) as u64;
                                c[3] += (a && b) as u64;
                            } else {
                                c[4] += 1;
                                c[5] += (a && !b) as u64;
                                c[6] += (b && !a) as u64;
                            }
                        }
                    }
                }
                trial_rows[s].iter_mut().for_each(|r| *r = None);
            }
        }
    }
    Ok(())
}

/// Group counts, rates with Wilson intervals, delay percentiles.
fn aggregate(evaluated: &DataFrame, keys: &[&str]) -> PolarsResult<DataFrame> {
    use polars::prelude::col as c;
    let count = |name: &str| c(name).cast(DataType::UInt64).sum().alias(name);
    let mut df = evaluated
        .clone()
        .lazy()
        .group_by(keys.iter().map(|k| c(*k)).collect::<Vec<_>>())
        .agg([
            len().cast(DataType::UInt64).alias("trials"),
            (lit(1u64) - c("designed").cast(DataType::UInt64)).sum().alias("design_failures"),
            count("diverged"),
            count("false_alarm"),
            count("detected"),
            c("faulty").first().alias("faulty"),
            c(col::DELAY_S).quantile(lit(0.5), QuantileMethod::Linear).alias("delay_p50_s"),
            c(col::DELAY_S).quantile(lit(0.9), QuantileMethod::Linear).alias("delay_p90_s"),
            c(col::DELAY_S).quantile(lit(0.99), QuantileMethod::Linear).alias("delay_p99_s"),
            count("iso_decided"),
            count("iso_direction_ok"),
            count("iso_max_ok"),
        ])
        .sort(
            keys.iter().map(|k| k.to_string()).collect::<Vec<_>>(),
            SortMultipleOptions::default().with_nulls_last(true),
        )
        .collect()?;

    let get =
        |df: &DataFrame, n: &str| -> PolarsResult<Vec<u64>> { Ok(df.column(n)?.u64()?.into_no_null_iter().collect()) };
    let trials = get(&df, "trials")?;
    let failures = get(&df, "design_failures")?;
    let detected = get(&df, "detected")?;
    let fa = get(&df, "false_alarm")?;
    let iso_n = get(&df, "iso_decided")?;
    let iso_ok = get(&df, "iso_direction_ok")?;
    let iso_max = get(&df, "iso_max_ok")?;
    let faulty_col = df.column("faulty")?.bool()?.clone();
    let faulty: Vec<bool> = (0..faulty_col.len()).map(|i| faulty_col.get(i).unwrap_or(false)).collect();
    let designed: Vec<u64> = trials.iter().zip(&failures).map(|(t, f)| t - f).collect();
    let rate = |k: &[u64], n: &[u64], keep: &dyn Fn(usize) -> bool| -> [Vec<Option<f64>>; 3] {
        let mut out: [Vec<Option<f64>>; 3] = Default::default();
        for i in 0..k.len() {
            let (lo, hi) = wilson(k[i], n[i], Z95);
            let ok = keep(i) && n[i] > 0;
            out[0].push(ok.then(|| k[i] as f64 / n[i] as f64));
            out[1].push(ok.then_some(lo));
            out[2].push(ok.then_some(hi));
        }
        out
    };
    let [pd, pd_lo, pd_hi] = rate(&detected, &designed, &|i| faulty[i]);
    let [pfa, pfa_lo, pfa_hi] = rate(&fa, &designed, &|_| true);
    let [iso, iso_lo, iso_hi] = rate(&iso_ok, &iso_n, &|_| true);
    let iso_by_max: Vec<Option<f64>> =
        iso_max.iter().zip(&iso_n).map(|(k, n)| (*n > 0).then(|| *k as f64 / *n as f64)).collect();
    let missed: Vec<Option<u64>> =
        detected.iter().zip(&designed).zip(&faulty).map(|((d, n), f)| f.then(|| n - d)).collect();
    df.drop_in_place("faulty")?;
    for (name, v) in
        [("pd", pd), ("pd_lo", pd_lo), ("pd_hi", pd_hi), ("pfa", pfa), ("pfa_lo", pfa_lo), ("pfa_hi", pfa_hi)]
    {
        df.with_column(Column::new(name.into(), v))?;
    }
    df.with_column(Column::new("missed".into(), missed))?;
    for (name, v) in [
        ("isolation_accuracy", iso),
        ("isolation_lo", iso_lo),
        ("isolation_hi", iso_hi),
        ("isolation_by_max_accuracy", iso_by_max),
    ] {
        df.with_column(Column::new(name.into(), v))?;
    }
    df.rename("false_alarm", "false_alarms".into())?;
    df.rename("iso_decided", "isolation_decided".into())?;
    df.rename("iso_direction_ok", "isolated_correctly".into())?;
    df.drop_in_place("iso_max_ok")?;
    Ok(df)
}

/// Smallest fault (by magnitude: |size|, or |factor - 1| for gain) whose size bin has Pd >= 0.9 (point
/// estimate, and with the Wilson lower bound >= 0.9), per (thresholds, detector, kind, output).
fn min_detectable(curves: &DataFrame) -> PolarsResult<DataFrame> {
    let s = |n: &str| curves.column(n).and_then(|c| c.str().cloned());
    let (set, det, kind, out) = (s("thresholds")?, s(col::DETECTOR)?, s(col::KIND)?, s(col::OUTPUT)?);
    let size = curves.column(col::SIZE_BIN)?.f64()?.clone();
    let pd = curves.column("pd")?.f64()?.clone();
    let lo = curves.column("pd_lo")?.f64()?.clone();
    type Key = (String, String, String, String);
    // Per key: (magnitude, size) of the smallest qualifying bin, point estimate and lower bound.
    let mut rows: Vec<(Key, Option<(f64, f64)>, Option<(f64, f64)>)> = Vec::new();
    for i in 0..curves.height() {
        let (Some(k), Some(o), Some(sz)) = (kind.get(i), out.get(i), size.get(i)) else { continue };
        if k == col::NO_FAULT {
            continue;
        }
        let key: Key =
            (set.get(i).unwrap_or_default().into(), det.get(i).unwrap_or_default().into(), k.into(), o.into());
        let idx = match rows.iter().position(|r| r.0 == key) {
            Some(p) => p,
            None => {
                rows.push((key, None, None));
                rows.len() - 1
            }
        };
        let magnitude = if k == "gain" { (sz - 1.0).abs() } else { sz.abs() };
        let better = |cur: Option<(f64, f64)>| cur.is_none_or(|(m, _)| magnitude < m);
        if pd.get(i).is_some_and(|p| p >= 0.9) && better(rows[idx].1) {
            rows[idx].1 = Some((magnitude, sz));
        }
        if lo.get(i).is_some_and(|p| p >= 0.9) && better(rows[idx].2) {
            rows[idx].2 = Some((magnitude, sz));
        }
    }
    let key = |f: fn(&Key) -> &String| rows.iter().map(|r| f(&r.0).clone()).collect::<Vec<_>>();
    DataFrame::new_infer_height(vec![
        Column::new("thresholds".into(), key(|k| &k.0)),
        Column::new(col::DETECTOR.into(), key(|k| &k.1)),
        Column::new(col::KIND.into(), key(|k| &k.2)),
        Column::new(col::OUTPUT.into(), key(|k| &k.3)),
        Column::new("min_size_pd90".into(), rows.iter().map(|r| r.1.map(|x| x.1)).collect::<Vec<_>>()),
        Column::new("min_size_pd90_lower_bound".into(), rows.iter().map(|r| r.2.map(|x| x.1)).collect::<Vec<_>>()),
    ])
}

fn write_thresholds(
    dir: &Path,
    thresholds: &[DetectorThresholds],
    outputs: &[String],
    source: &str,
) -> Result<(), RunError> {
    let path = dir.join("thresholds.csv");
    let mut detector = Vec::new();
    let mut output = Vec::new();
    let mut deck = Vec::new();
    let mut per_output = Vec::new();
    let mut whole = Vec::new();
    let mut n = Vec::new();
    let mut fa = Vec::new();
    let mut pfa = Vec::new();
    let mut lo = Vec::new();
    let mut hi = Vec::new();
    for t in thresholds {
        let rows = outputs.iter().enumerate().map(|(j, o)| {
            (o.clone(), t.deck.get(j).copied(), Some(t.per_output[j]), Some(t.whole[j]), t.per_output_false_alarms[j])
        });
        let all = std::iter::once(("all".to_string(), None, None, None, t.whole_false_alarms));
        for (o, d, p, w, k) in rows.chain(all) {
            let (l, h) = wilson(k, t.calibration_trials, Z95);
            detector.push(t.detector.clone());
            output.push(o);
            deck.push(d);
            per_output.push(p);
            whole.push(w);
            n.push(t.calibration_trials);
            fa.push(k);
            pfa.push((t.calibration_trials > 0).then(|| k as f64 / t.calibration_trials as f64));
            lo.push(l);
            hi.push(h);
        }
    }
    let height = detector.len();
    let mut df = DataFrame::new_infer_height(vec![
        Column::new(col::DETECTOR.into(), detector),
        Column::new(col::OUTPUT.into(), output),
        Column::new("deck_threshold".into(), deck),
        Column::new("per_output_threshold".into(), per_output),
        Column::new("detector_threshold".into(), whole),
        Column::new("calibration_trials".into(), n),
        Column::new("false_alarms".into(), fa),
        Column::new("pfa_achieved".into(), pfa),
        Column::new("pfa_lo".into(), lo),
        Column::new("pfa_hi".into(), hi),
        Column::new("source".into(), vec![source; height]),
    ])
    .map_err(pol(&path))?;
    Ok(write_table(&mut df, &path)?)
}

/// Reads `thresholds.csv`: per detector, (per-output thresholds, whole-detector thresholds) in output order.
#[allow(clippy::type_complexity)]
pub fn read_thresholds(path: &Path) -> Result<Vec<(String, Vec<f64>, Vec<f64>)>, RunError> {
    let df = CsvReadOptions::default()
        .with_has_header(true)
        .try_into_reader_with_file_path(Some(path.into()))
        .and_then(|r| r.finish())
        .map_err(|e| RunError::Invalid(format!("{}: cannot read thresholds ({e})", path.display())))?;
    let bad = |what: &str| RunError::Invalid(format!("{}: not an fdimc thresholds.csv ({what})", path.display()));
    let det = df.column(col::DETECTOR).and_then(|c| c.str().cloned()).map_err(|_| bad("no detector column"))?;
    let out = df.column(col::OUTPUT).and_then(|c| c.str().cloned()).map_err(|_| bad("no output column"))?;
    let per = df
        .column("per_output_threshold")
        .and_then(|c| c.cast(&DataType::Float64))
        .map_err(|_| bad("no per_output_threshold"))?;
    let whole = df
        .column("detector_threshold")
        .and_then(|c| c.cast(&DataType::Float64))
        .map_err(|_| bad("no detector_threshold"))?;
    let (per, whole) =
        (per.f64().map_err(|_| bad("per_output_threshold"))?, whole.f64().map_err(|_| bad("detector_threshold"))?);
    let mut result: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::new();
    for i in 0..df.height() {
        if out.get(i) == Some("all") {
            continue;
        }
        let d = det.get(i).ok_or_else(|| bad("empty detector"))?.to_string();
        let (p, w) =
            (per.get(i).ok_or_else(|| bad("empty threshold"))?, whole.get(i).ok_or_else(|| bad("empty threshold"))?);
        if !(p.is_finite() && w.is_finite() && p > 0.0 && w > 0.0) {
            return Err(bad(&format!("row {}: thresholds must be finite and > 0", i + 1)));
        }
        match result.iter_mut().find(|r| r.0 == d) {
            Some(r) => {
                r.1.push(p);
                r.2.push(w);
            }
            None => result.push((d, vec![p], vec![w])),
        }
    }
    Ok(result)
}

pub fn print(dir: &Path, s: &SummaryReport) -> Result<(), RunError> {
    println!("  thresholds: {}", s.calibration_source);
    for t in &s.thresholds {
        let pfa =
            if t.calibration_trials > 0 { t.whole_false_alarms as f64 / t.calibration_trials as f64 } else { f64::NAN };
        println!(
            "    {}: [{}] (Pfa achieved {:.4} on {} calibration trials)",
            t.detector,
            t.whole.iter().map(|v| format!("{v:.4}")).collect::<Vec<_>>().join(", "),
            pfa,
            t.calibration_trials
        );
    }
    use polars::prelude::*;
    let internal = |e: PolarsError| RunError::Internal(e.to_string());
    let overall = s
        .summary
        .clone()
        .lazy()
        .filter(col("kind").neq(lit("none")))
        .group_by_stable([col("thresholds"), col("detector"), col("kind")])
        .agg([(col("trials") - col("design_failures")).sum().alias("n"), col("detected").sum().alias("detected")])
        .sort(["thresholds", "detector", "kind"], Default::default())
        .collect()
        .map_err(internal)?;
    println!("  detection probability over all sizes (see summary.csv for groups):");
    let text = |n: &str| overall.column(n).and_then(|c| c.str().cloned()).map_err(internal);
    let count = |n: &str| overall.column(n).and_then(|c| c.u64().cloned()).map_err(internal);
    let (set, det, kind, n, detected) =
        (text("thresholds")?, text("detector")?, text("kind")?, count("n")?, count("detected")?);
    for i in 0..overall.height() {
        let (n, k) = (n.get(i).unwrap_or(0), detected.get(i).unwrap_or(0));
        println!(
            "    {:<10} {:<12} {:<14} {:>6}/{:<6} = {:.3}",
            set.get(i).unwrap_or(""),
            det.get(i).unwrap_or(""),
            kind.get(i).unwrap_or(""),
            k,
            n,
            k as f64 / n.max(1) as f64
        );
    }
    for w in &s.warnings {
        println!("  warning: {w}");
    }
    let mut files = vec!["thresholds.csv", "summary.csv", "summary.parquet", "curves.csv", "min_detectable.csv"];
    if s.comparison.is_some() {
        files.push("comparison.csv");
    }
    println!("  wrote {} in {}", files.join(", "), dir.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_detectable_size_is_the_smallest_fault_magnitude_reaching_pd_90() {
        let n = 6;
        let curves = DataFrame::new_infer_height(vec![
            Column::new("thresholds".into(), vec!["calibrated"; n]),
            Column::new(col::DETECTOR.into(), vec!["d"; n]),
            Column::new(col::KIND.into(), vec!["gain", "gain", "gain", "bias", "bias", "bias"]),
            Column::new(col::OUTPUT.into(), vec!["q"; n]),
            Column::new(col::SIZE_BIN.into(), vec![0.6, 0.8, 0.95, 1.0, 5.0, 9.0]),
            Column::new("pd".into(), vec![1.0, 0.95, 0.3, 0.2, 0.95, 1.0]),
            Column::new("pd_lo".into(), vec![0.97, 0.85, 0.2, 0.1, 0.91, 0.97]),
        ])
        .unwrap();
        let m = min_detectable(&curves).unwrap();
        let point: Vec<Option<f64>> = m.column("min_size_pd90").unwrap().f64().unwrap().iter().collect();
        let lower: Vec<Option<f64>> = m.column("min_size_pd90_lower_bound").unwrap().f64().unwrap().iter().collect();
        // Gain 0.8 is a smaller fault than 0.6; its lower bound misses 0.9, so the bound needs 0.6.
        assert_eq!(point, [Some(0.8), Some(5.0)]);
        assert_eq!(lower, [Some(0.6), Some(5.0)]);
    }

    #[test]
    fn health_warnings_count_each_trial_once() {
        let summary = DataFrame::new_infer_height(vec![
            Column::new("thresholds".into(), ["deck", "deck", "calibrated", "calibrated"]),
            Column::new("design_failures".into(), [2u64, 1, 2, 1]),
            Column::new("diverged".into(), [0u64, 0, 0, 0]),
        ])
        .unwrap();
        assert_eq!(health_warnings(&summary), ["3 trial x detector designs failed (design_error in trials.parquet)"]);
    }
}
