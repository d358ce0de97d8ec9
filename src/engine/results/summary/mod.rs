//! The one summary of every kind of study, from `trials.parquet` without re-simulating, in memory that
//! does not grow with the trial count: the file is read a slice at a time, every table is a set of
//! counts (exact) and quantile sketches ([`crate::engine::stats::quantiles`]: exact to 4,096 values per group) that
//! the slices add to, and the paired comparison forgets each trial once the next begins.
//!
//! Threshold sets: `deck` (the alarms, delays and isolation the trial recorded at the deck's thresholds
//! or decision rule) and, for kinds that record a detection statistic, `calibrated` (the whole-detector
//! thresholds of [`crate::engine::results::thresholds`], evaluated from the recorded pre-onset maxima and first-passage
//! profiles; isolation needs the signals after the alarm, so it is the deck's only).
//!
//! Rates are over the units flown to the end (`failure` null): Pd is `detected / flown` in faulty
//! groups, Pfa `false_alarms / flown`, isolation accuracy `isolated_correctly / isolation_decided`;
//! each with its 95 % Wilson interval. Written to the results folder:
//!
//! | file | one row per | what |
//! |---|---|---|
//! | `summary.csv`, `summary.parquet` | thresholds x detector x kind x target x size bin x noise bin x parameter-error bin (x the kind's own bins) | the key columns, then `trials` (units), `failed`, `diverged`, `truth_diverged`, `false_alarms`, `detected`, `missed`, `late_alarms`, `isolation_decided`, `isolated_correctly`, Pd, Pfa and isolation accuracy with intervals, delay p50/p90/p99, then the kind's own aggregates |
//! | `curves.csv` | thresholds x detector x kind x target x size bin | the same counts and rates (noise and parameter-error bins pooled): Pd against fault size |
//! | `min_detectable.csv` | thresholds x detector x kind x target | the smallest fault (by \|size\|, or \|factor - 1\| for gain) whose size bin has Pd >= 0.9, and whose Wilson lower bound is >= 0.9 |
//! | `detectors.csv` | thresholds x detector | over the faulty units: Pd, isolation, delays, the kind's aggregates; over every trial once (its first unit): flights, failures, false alarms, Pfa |
//! | `confusion.csv` | detector x truth x isolated | at the deck's thresholds: units, and their share of the truth's units (truth: the faulty target, or the kind for classifiers) |
//! | `comparison.csv` | thresholds x pair of detectors | [`crate::engine::stats::paired`] |
//! | `thresholds.csv` | detector x statistic (+ `all`) | kinds with a statistic: [`crate::engine::results::thresholds`] |
//! | `answer.csv` | detector | the answer at a glance, at the thresholds in use: [`answer`] |
//! | `parameter_errors.csv` | thresholds x detector x (fault or none) x parameter error x its bin | decks with parameter errors: each one's own bins (its listed values, or the deck's bins of its range), the counts and rates as `summary.csv`'s, so that the derivative that drives the misses shows |
//!
//! The parts, in the order data flows: `aggregate.rs` (what the slices add to: interned names, a unit's
//! result, a group's counts and sketches, the run's aggregates), `tables.rs` (the tables from the
//! aggregates), `written.rs` (what was written, the settings left in `summarize.json`), `print.rs` (what
//! the commands print) and `precision.rs` (the stopping rule of `run --precision`); this file reads the
//! run slice by slice and writes the tables.

mod aggregate;
pub mod answer;
mod precision;
mod print;
pub mod safety;
mod tables;
mod written;

pub use precision::{PRECISION_RATES, PrecisionMonitor, PrecisionStatus};
pub use print::{console_warnings, print, set_verbose};
pub use written::{CALIBRATED, CALIBRATIONS_DIR, SETTINGS_FILE, Settings, Summary, VALIDATION, VALIDATION_DIR};

use std::collections::HashMap;
use std::path::Path;

use polars::prelude::*;

use crate::engine::results::roc::Roc;
use crate::engine::results::schema::col;
use crate::engine::results::summary_spec::{Extra, SummarySpec};
use crate::engine::results::tables::{column_names, complete_run, for_each_slice_read_ahead, slices};
use crate::engine::results::text::significant;
use crate::engine::results::thresholds::{
    Calibration, DECK, DetectorThresholds, HourConversion, RecordedStatistics, SLICE_ROWS, thresholds, write_thresholds,
};
use crate::engine::run::output::write_table;
use crate::engine::run::runner::{RunError, pol, write_parquet};

use aggregate::{Aggregates, Counts};
use tables::{
    KeyColumns, confusion_table, detector_table, group_table, min_detectable, with_bin_edges, with_calibration,
    with_size_unit,
};

/// The exact law's verdict on the per-hour conversion for a detector (its index in the run) at
/// thresholds (one per statistic, named): a kind's [`crate::engine::method::Method::hour_laws`] on
/// the run's deck.
pub type HourLaw<'a> = &'a dyn Fn(usize, &[String], &[f64]) -> Option<HourConversion>;

/// Reads the run in `dir`, writes the tables of the module docs and returns what `print` shows.
/// `calibration` applies to kinds that record statistics (default: the deck's target Pfa); `law`, where
/// given, checks the per-flight-hour conversion at every threshold set's values.
pub fn summarize(
    dir: &Path,
    spec: &SummarySpec,
    calibration: Option<&Calibration>,
    law: Option<HourLaw>,
) -> Result<Summary, RunError> {
    let (manifest, path) = complete_run(dir)?;
    let columns = column_names(&path)?;
    let statistics: Vec<String> =
        columns.iter().filter_map(|c| c.strip_prefix(col::PRE_MAX_PREFIX)).map(str::to_string).collect();
    let mut warnings = Vec::new();
    let thresholds = if statistics.is_empty() {
        None
    } else {
        let asked = calibration.is_some();
        let calibration = calibration.cloned().unwrap_or_else(|| Calibration::of_deck(&manifest));
        Some(thresholds(&path, &manifest, &statistics, &calibration, asked, &mut warnings)?)
    };
    let validating = matches!(calibration, Some(Calibration::File(_)));
    let set = thresholds.as_ref().map(|_| if validating { VALIDATION } else { CALIBRATED });
    let sets: Vec<&'static str> = [Some(DECK), set].into_iter().flatten().collect();
    // The run's own tables are at the deck's calibration; any other is written apart.
    let dir_out = match calibration {
        Some(Calibration::File(_)) => dir.join(VALIDATION_DIR),
        Some(c) => dir.join(CALIBRATIONS_DIR).join(c.folder_name()),
        None => dir.to_path_buf(),
    };
    std::fs::create_dir_all(&dir_out).map_err(crate::engine::run::runner::io(&dir_out))?;

    // Only the columns the tables read.
    let mut select: Vec<String> = [
        col::TRIAL,
        col::DETECTOR,
        col::KIND,
        col::TARGET,
        col::SIZE_BIN,
        col::ONSET_S,
        col::FAULT_FREE,
        col::FAILURE,
        col::DIVERGED,
        col::FALSE_ALARM,
        col::DETECTED,
        col::DELAY_S,
        col::LATE_ALARM_S,
        col::ISOLATED,
        col::ISOLATED_CORRECTLY,
        col::NOISE_BIN,
        col::PARAM_ERROR_BIN,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let own = spec
        .extra_keys
        .iter()
        .copied()
        .chain(spec.extras.iter().filter_map(Extra::column))
        .chain(spec.paired_medians.iter().copied());
    for c in own {
        if !select.iter().any(|s| s == c) {
            select.push(c.to_string());
        }
    }
    if thresholds.is_some() {
        for s in &statistics {
            select.extend([col::pre_max(s), col::fp_t(s), col::fp_v(s)]);
        }
    }
    for c in &select {
        if !columns.contains(c) {
            return Err(RunError::Invalid(format!(
                "{}: has no column {c:?}: not a {} run of this fdimc (re-run the study)",
                path.display(),
                manifest.kind
            )));
        }
    }

    // Runs of an fdimc before the column have none (their diverged truths are in `diverged`).
    if columns.iter().any(|c| c == col::TRUTH_DIVERGED) {
        select.push(col::TRUTH_DIVERGED.to_string());
    }
    let mut agg = Aggregates::new(spec, sets.clone(), &manifest.detectors);
    agg.parameters = parameter_bins(&path, &manifest, &columns)?;
    agg.hazard_times = manifest.time_to_hazard_s.clone();
    select.extend(agg.parameters.iter().map(|p| p.column.clone()));
    // The ROC's counts come from the same slices: the first-passage profiles are decoded once.
    let mut roc = match &thresholds {
        Some((t, _)) => Some(Roc::new(&path, &manifest, &statistics, t)?),
        None => None,
    };
    let mut main_pass = || {
        std::thread::scope(|scope| {
            // The ROC counts each slice on a thread of its own while the summary counts it: the same
            // slices in the same order, so the same counts.
            let (to_roc, roc_slices) =
                std::sync::mpsc::sync_channel::<std::sync::Arc<(DataFrame, RecordedStatistics)>>(1);
            let path = &path;
            let roc_thread = roc.as_mut().map(|roc| {
                scope.spawn(move || roc_slices.into_iter().try_for_each(|s| roc.add_slice(&s.0, &s.1, path)))
            });
            let read = for_each_slice_read_ahead(path, manifest.rows as usize, SLICE_ROWS, &select, |df| {
                let recorded = match &thresholds {
                    Some(_) => Some(RecordedStatistics::read(&df, &statistics, manifest.detection_window_s, path)?),
                    None => None,
                };
                let calibrated = thresholds.as_ref().zip(recorded.as_ref()).map(|((t, _), r)| (t.as_slice(), r));
                agg.add_slice(&df, path, calibrated)?;
                if let (Some(_), Some(recorded)) = (&roc_thread, recorded)
                    && to_roc.send(std::sync::Arc::new((df, recorded))).is_err()
                {
                    // The ROC's thread stopped on an error, which its join returns: stop reading.
                    return Err(RunError::Internal("the ROC's thread stopped".into()));
                }
                Ok(())
            });
            drop(to_roc);
            let counted = match roc_thread {
                Some(t) => t.join().map_err(|_| RunError::Internal("the ROC's thread panicked".into()))?,
                None => Ok(()),
            };
            counted.and(read)
        })
    };
    // The tail fits need only the thresholds: they run beside the pass over the records.
    let fit_tails = || match (&thresholds, set) {
        (Some((t, _)), Some(set)) => crate::engine::results::tails::tails(&path, &manifest, &statistics, t, set),
        _ => Ok(Vec::new()),
    };
    let (fitted_tails, pass) = std::thread::scope(|scope| {
        let fits = scope.spawn(fit_tails);
        let pass = main_pass();
        (fits.join(), pass)
    });
    pass?;
    let mut tails = fitted_tails.map_err(|_| RunError::Internal("the tail fits' thread panicked".into()))??;

    let mut key_names: Vec<String> =
        ["thresholds", col::DETECTOR, col::KIND, col::TARGET, col::SIZE_BIN, col::NOISE_BIN, col::PARAM_ERROR_BIN]
            .iter()
            .map(|s| s.to_string())
            .collect();
    key_names.extend(spec.extra_keys.iter().map(|s| s.to_string()));
    let mut text = vec![true, true, true, true, false, false, false];
    text.extend(spec.extra_keys.iter().map(|_| false));
    let keys = KeyColumns { names: key_names, text };
    // The detector's name in tables: its index in the key becomes its interned name.
    let mut names = std::mem::take(&mut agg.names);
    let detector_ids: Vec<u32> = manifest.detectors.iter().map(|d| names.id(Some(d))).collect();
    let groups: Vec<(Vec<u64>, Counts)> = agg
        .groups
        .drain()
        .map(|(mut k, c)| {
            k[1] = detector_ids[k[1] as usize] as u64;
            (k, c)
        })
        .collect();
    let mut summary = group_table(&groups, &keys, &names, &sets, spec, true).map_err(pol(&path))?;

    let mut by_parameter = if agg.parameters.is_empty() {
        None
    } else {
        let groups: Vec<(Vec<u64>, Counts)> = std::mem::take(&mut agg.by_parameter)
            .into_iter()
            .map(|(mut k, c)| {
                k[1] = detector_ids[k[1] as usize] as u64;
                (k, c)
            })
            .collect();
        let keys = KeyColumns {
            names: ["thresholds", col::DETECTOR, col::KIND, "parameter", "error_bin"].map(String::from).to_vec(),
            text: vec![true, true, true, true, false],
        };
        Some(group_table(&groups, &keys, &names, &sets, spec, false).map_err(pol(&path))?)
    };
    let mut curves_map: HashMap<Vec<u64>, Counts> = HashMap::new();
    for (k, c) in &groups {
        curves_map.entry(k[..5].to_vec()).or_insert_with(|| Counts::new(spec.extras.len())).merge(c);
    }
    let curve_groups: Vec<(Vec<u64>, Counts)> = curves_map.into_iter().collect();
    let curve_keys = KeyColumns { names: keys.names[..5].to_vec(), text: keys.text[..5].to_vec() };
    let mut curves = group_table(&curve_groups, &curve_keys, &names, &sets, spec, false).map_err(pol(&path))?;
    let mut min_detectable = min_detectable(&curves, &manifest.fault_size_units).map_err(pol(&path))?;
    for df in [&mut summary, &mut curves, &mut min_detectable] {
        with_size_unit(df, &manifest.fault_size_units).map_err(pol(&path))?;
    }
    let bins = &manifest.fault_size_bins;
    for df in [&mut summary, &mut curves] {
        with_bin_edges(df, col::SIZE_BIN, bins).map_err(pol(&path))?;
    }
    for centre in ["min_size_pd90", "min_size_pd90_lower_bound"] {
        with_bin_edges(&mut min_detectable, centre, bins).map_err(pol(&path))?;
    }

    let mut detectors = detector_table(&agg, &sets, spec).map_err(pol(&path))?;
    let target_pfa = thresholds.as_ref().and_then(|(t, _)| t.first().and_then(|t| t.target_pfa));
    let confidence = thresholds.as_ref().and_then(|(t, _)| t.first().and_then(|t| t.confidence));
    for df in [&mut summary, &mut curves, &mut min_detectable, &mut detectors].into_iter().chain(by_parameter.as_mut())
    {
        with_calibration(df, target_pfa, confidence).map_err(pol(&path))?;
    }
    let mut confusion = confusion_table(&agg, &names).map_err(pol(&path))?;

    let out = |f: &str| dir_out.join(f);
    let mut files = Vec::new();
    let mut conversions = Vec::new();
    if let (Some((t, source)), Some(set)) = (&thresholds, set) {
        write_thresholds(&dir_out, t, &statistics, source)?;
        files.push("thresholds.csv");
        let hour_at = |detector: &str, values: &[f64]| hour_at(law, &manifest, &statistics, detector, values);
        for tail in &mut tails {
            tail.hour = hour_at(&tail.detector, &tail.base);
            let base = tail.base.clone();
            for x in tail.targets.iter_mut().filter(|x| x.per_hour.is_some()) {
                x.hour = hour_at(&tail.detector, &base.iter().map(|b| b * x.scale.estimate).collect::<Vec<_>>());
                x.doubt = x.hour.as_ref().and_then(|h| x.doubt_from(h));
            }
            // One warning per detector: the targets whose thresholds the exact law doubts.
            let doubted: Vec<(f64, f64, f64)> = (tail.targets.iter())
                .filter(|x| x.doubt.is_some())
                .filter_map(|x| Some((x.per_hour?, x.hour?.trial_upper, x.pfa)))
                .collect();
            if !doubted.is_empty() {
                let each: Vec<String> = (doubted.iter())
                    .map(|(h, upper, pfa)| {
                        format!("{h:e} per hour up to {upper:.3e} ({} times)", significant(upper / pfa))
                    })
                    .collect();
                warnings.push(format!(
                    "tail.csv's thresholds of {} for per-flight-hour targets may be far too low by the residual's exact \
                     law (it puts a trial's Pfa at them far above what the fit gives, by Sidak's bound, an upper bound \
                     loose where alarms cluster within a trial: {}; trust in tail.csv): fdimc flight-thresholds finds \
                     thresholds on the exact law",
                    tail.detector,
                    each.join(", ")
                ));
            }
            let low: Vec<String> = (tail.targets.iter())
                .filter_map(|x| x.hour.filter(HourConversion::undercounts).zip(x.per_hour))
                .map(|(h, p)| format!("{} at {p:e} per hour", significant(h.ratio)))
                .collect();
            if !low.is_empty() {
                warnings.push(format!(
                    "tail.csv's thresholds of {} for per-flight-hour targets convert from trials, and by the residual's \
                     exact law an hour flown through alarms more often at them (extremal index {}): too low for their \
                     targets (hour_over_conversion in tail.csv)",
                    tail.detector,
                    low.join(", ")
                ));
            }
        }
        conversions = conversions_of(t, set, &hour_at);
        for (detector, set, h) in conversions.iter().filter(|(_, _, h)| h.undercounts()) {
            warnings.push(format!(
                "{detector} at the {set} thresholds: the per-flight-hour figures converted from {} s trials \
                 under-count false alarms about {} times by the residual's exact law (a mode of time constant {} s): \
                 lower bounds, not figures to quote (safety.csv); estimate whole flights with \
                 `fdimc rare-event {} --flight-s 3600`",
                significant(manifest.trial_duration_s.unwrap_or(f64::NAN)),
                significant(h.ratio),
                significant(h.slowest_time_constant_s),
                manifest.deck
            ));
        }
        // A doubt about a figure the fit gives is a warning; the fit's details are tail.csv's (and
        // `--verbose`'s). At thresholds inside the data the fit gives no figure to doubt.
        for tail in tails.iter().filter(|t| !t.concerns.is_empty() && (t.at_set.is_some() || !t.targets.is_empty())) {
            warnings.push(format!(
                "rare false alarms of {} at the {} thresholds: do not trust the tail fit's figures ({}); tail.csv",
                tail.detector,
                tail.set,
                tail.concerns.join("; ")
            ));
        }
        crate::engine::results::tails::write_tail_tables(&dir_out, &tails, &statistics)?;
        files.extend(["tail.csv", "tail_diagnostics.csv"]);
        let points = roc.take().map(Roc::points).unwrap_or_default();
        crate::engine::results::roc::write_roc(&dir_out, &points, target_pfa, confidence, validating)?;
        files.push("roc.csv");
    }
    let mut answer = {
        let set_name = answer::set_in_use(&detectors);
        let named = |v: &[f64]| crate::engine::results::text::named(&statistics, v);
        let (values, source): (Vec<(String, String)>, String) = match &thresholds {
            Some((t, source)) if set_name != DECK => {
                (t.iter().map(|t| (t.detector.clone(), named(&t.whole))).collect(), source.clone())
            }
            Some((t, _)) => (t.iter().map(|t| (t.detector.clone(), named(&t.deck))).collect(), "the deck's".into()),
            None => (Vec::new(), "the deck's decision rule".into()),
        };
        answer::answer(&set_name, &values, &source, &summary, &detectors, &min_detectable).map_err(pol(&path))?
    };
    write_table(&mut answer, &out(answer::ANSWER_FILE))?;
    files.push(answer::ANSWER_FILE);
    let noise = manifest.sensor_noise.clone().unwrap_or_else(|| "Gaussian (the kind's model)".to_string());
    let rare_event = safety::read_rare_event(dir, &manifest.deck_sha256)?;
    let setting = safety::Setting {
        flight_s: manifest.trial_duration_s,
        noise: &noise,
        rare_event,
        conversions: &conversions,
        deck_sha256: &manifest.deck_sha256,
        fdimc_version: &manifest.fdimc_version,
        profile_resolution: manifest.profile_resolution,
        profiles_exact_at_deadlines: manifest.profiles_exact_at_deadlines,
    };
    let mut safety = safety::safety(&answer, &detectors, &tails, &setting).map_err(pol(&path))?;
    write_table(&mut safety, &out(safety::SAFETY_FILE))?;
    files.push(safety::SAFETY_FILE);
    if let Some(df) = &mut by_parameter {
        write_table(df, &out(PARAMETER_ERRORS_FILE))?;
        files.push(PARAMETER_ERRORS_FILE);
    }
    write_table(&mut summary, &out("summary.csv"))?;
    write_parquet(&mut summary, &out("summary.parquet"))?;
    write_table(&mut curves, &out("curves.csv"))?;
    write_table(&mut min_detectable, &out("min_detectable.csv"))?;
    write_table(&mut detectors, &out("detectors.csv"))?;
    write_table(&mut confusion, &out("confusion.csv"))?;
    files.extend(crate::engine::run::output::SUMMARY_TABLES);
    if manifest.detectors.len() > 1 {
        let mut all: Option<DataFrame> = None;
        for (set, pairs) in sets.iter().zip(std::mem::take(&mut agg.pairs)) {
            let mut df = pairs.finish().map_err(pol(&path))?;
            let height = df.height();
            df.insert_column(0, Column::new("thresholds".into(), vec![*set; height])).map_err(pol(&path))?;
            with_calibration(&mut df, target_pfa, confidence).map_err(pol(&path))?;
            match &mut all {
                Some(a) => {
                    a.vstack_mut(&df).map_err(pol(&path))?;
                }
                None => all = Some(df),
            }
        }
        if let Some(mut c) = all {
            write_table(&mut c, &out("comparison.csv"))?;
            files.push("comparison.csv");
        }
    }

    // Failures and divergence, counted once per unit (every threshold set holds the same units).
    let per_detector = &agg.per_detector[..manifest.detectors.len()];
    let (units, failed, diverged) =
        per_detector.iter().fold((0, 0, 0), |(n, f, d), (u, _, _)| (n + u.units, f + u.failed, d + u.diverged));
    // A truth is the trial's, shared by its detectors: counted in flights, once.
    let truth_diverged = per_detector.iter().map(|(_, _, flights)| flights.truth_diverged).max().unwrap_or(0);
    if failed > 0 {
        warnings.push(format!("{failed} trial x detector units were not flown to the end (failure in trials.parquet)"));
    }
    if truth_diverged > 0 {
        warnings.push(format!(
            "{truth_diverged} trials' truth diverged or left its physical range (truth_diverged in trials.parquet, \
             failure says where and how): left out of every rate and calibration"
        ));
    }
    if diverged > 0 {
        warnings.push(format!(
            "{diverged} trial x detector units diverged (diverged in trials.parquet): a filter's residual became \
             non-finite; the units count in the rates"
        ));
    }
    let settings = Settings {
        thresholds: set.map(str::to_string),
        target_pfa,
        confidence,
        source: thresholds.as_ref().map(|(_, s)| s.clone()),
        warnings: warnings.clone(),
    };
    let json = serde_json::to_string_pretty(&settings).map_err(|e| RunError::Internal(e.to_string()))?;
    let settings_path = out(SETTINGS_FILE);
    crate::engine::run::runner::write_atomically(&settings_path, json.as_bytes())?;
    files.push(SETTINGS_FILE);
    Ok(Summary {
        statistics,
        thresholds,
        tails,
        summary,
        detectors,
        confusion,
        answer,
        safety,
        warnings,
        files,
        out_dir: dir_out,
        set,
        units,
        failed_units: failed,
    })
}

/// `parameter_errors.csv`: the units by each parameter error's own bins.
pub const PARAMETER_ERRORS_FILE: &str = "parameter_errors.csv";

/// The bins of each parameter error the run records (`perr_<name>` columns): the deck's bins of a
/// range (the manifest's `parameter_error_bins`), else its listed values when it has a few, else
/// [`aggregate::PARAMETER_BINS`] equal bins over the values recorded (a first pass over those columns
/// alone; a run of an fdimc that did not record the deck's bins).
fn parameter_bins(
    path: &Path,
    manifest: &crate::engine::run::runner::Manifest,
    columns: &[String],
) -> Result<Vec<aggregate::ParameterBins>, RunError> {
    let perr: Vec<String> = columns.iter().filter(|c| c.starts_with(col::PERR_PREFIX)).cloned().collect();
    if perr.is_empty() {
        return Ok(Vec::new());
    }
    let mut seen: Vec<(Vec<u64>, f64, f64)> = vec![(Vec::new(), f64::INFINITY, f64::NEG_INFINITY); perr.len()];
    for df in slices(path, manifest.rows as usize, SLICE_ROWS, &perr) {
        let df = df?;
        for (c, s) in perr.iter().zip(seen.iter_mut()) {
            for v in crate::engine::results::tables::f64_col(&df, c, path)?.iter().flatten() {
                (s.1, s.2) = (s.1.min(v), s.2.max(v));
                if s.0.len() <= aggregate::LISTED_VALUES_MAX && !s.0.contains(&v.to_bits()) {
                    s.0.push(v.to_bits());
                }
            }
        }
    }
    Ok(perr
        .iter()
        .zip(seen)
        .map(|(c, (distinct, lo, hi))| {
            let name = c[col::PERR_PREFIX.len()..].to_string();
            let deck = manifest.parameter_error_bins.get(&name).filter(|e| !e.is_empty());
            let span = match deck {
                Some(edges) => Some((edges[0][0], edges[edges.len() - 1][1], edges.len())),
                // The drawn values' span rounded to 2 digits of its width: the deck's range, as drawn
                // values come within a hair of its ends (-0.19994 .. 0.19997 for -0.2 .. 0.2).
                None => (distinct.len() > aggregate::LISTED_VALUES_MAX).then(|| {
                    let q = 10f64.powi((hi - lo).log10().floor() as i32 - 1);
                    ((lo / q).round() * q, (hi / q).round() * q, aggregate::PARAMETER_BINS)
                }),
            };
            aggregate::ParameterBins { name, column: c.clone(), span }
        })
        .collect())
}

/// Summaries of hand-made records for the kinds' tests: written, summarised and read back.
#[cfg(test)]
pub mod hand_made {
    use polars::prelude::*;

    use crate::engine::method::Method;
    use crate::engine::results::summary_spec::SummarySpec;
    use crate::engine::results::tables::read_summary;
    use crate::engine::run::runner::{Manifest, write_parquet};

    /// A results folder with `trials.parquet` from hand-made rows and the tables `summarize` wrote.
    pub struct Summarized {
        pub dir: tempfile::TempDir,
        pub summary: DataFrame,
    }

    /// The manifest of a hand-made run of `method`: `trials` trials flown by `detectors`.
    pub fn manifest(method: &Method, trials: u64, detectors: &[&str]) -> Manifest {
        Manifest {
            kind: method.kind.into(),
            trials,
            detectors: detectors.iter().map(|d| d.to_string()).collect(),
            ..Manifest::unstarted()
        }
    }

    impl Summarized {
        /// [`Summarized::new`] under [`manifest`], by `method`'s summary.
        pub fn of(records: DataFrame, method: &Method, trials: u64, detectors: &[&str]) -> Self {
            Summarized::new(records, manifest(method, trials, detectors), &method.summary)
        }

        /// Writes `records` under `manifest` (its rows and completeness set here), summarises them by
        /// `spec` and reads `summary.csv` back.
        pub fn new(mut records: DataFrame, manifest: Manifest, spec: &SummarySpec) -> Self {
            let dir = tempfile::tempdir().unwrap();
            write_parquet(&mut records, &dir.path().join("trials.parquet")).unwrap();
            Manifest { rows: records.height() as u64, complete: true, ..manifest }.write(dir.path()).unwrap();
            super::summarize(dir.path(), spec, None, None).unwrap();
            let summary = read_summary(&dir.path().join("summary.csv")).unwrap();
            Summarized { dir, summary }
        }

        pub fn table(&self, name: &str) -> DataFrame {
            read_summary(&self.dir.path().join(name)).unwrap()
        }

        /// Table `name`'s rows at the deck's thresholds (all of them in a table without sets).
        pub fn deck_table(&self, name: &str) -> DataFrame {
            let df = self.table(name);
            match df.column("thresholds") {
                Ok(sets) => {
                    let mask = sets.str().unwrap().equal("deck");
                    df.filter(&mask).unwrap()
                }
                Err(_) => df,
            }
        }

        fn text(&self, column: &str, i: usize) -> Option<String> {
            self.summary.column(column).unwrap().str().unwrap().get(i).map(String::from)
        }

        /// The row of `detector` and fault kind `kind` at the deck's thresholds (one per pair in these tests).
        pub fn row(&self, detector: &str, kind: &str) -> usize {
            let at = |i: usize, c: &str, v: &str| self.text(c, i).as_deref() == Some(v);
            (0..self.summary.height())
                .find(|&i| at(i, "thresholds", "deck") && at(i, "detector", detector) && at(i, "kind", kind))
                .unwrap_or_else(|| panic!("no row {detector}/{kind}: {}", self.summary))
        }

        pub fn count(&self, column: &str, row: usize) -> Option<u64> {
            self.summary.column(column).unwrap().cast(&DataType::UInt64).unwrap().u64().unwrap().get(row)
        }

        pub fn value(&self, column: &str, row: usize) -> Option<f64> {
            self.summary.column(column).unwrap().cast(&DataType::Float64).unwrap().f64().unwrap().get(row)
        }

        /// `column` at `row` is `want` to rounding (a median, an interpolated quantile).
        pub fn assert_close(&self, column: &str, row: usize, want: f64) {
            let got = self.value(column, row);
            assert!(got.is_some_and(|g| (g - want).abs() < 1e-12), "{column} row {row}: {got:?}, want {want}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::tables::{min_detectable, with_bin_edges};
    use super::*;
    use crate::engine::results::schema::unit;
    use crate::engine::scenario::deck::Factor;

    /// A gain's smallest detectable fault: by `|factor - 1|` where the bins are factors (0.9 is missed,
    /// 1.3 is nearer 1 than 0.6), by the bin itself where the bins are already deviations (the
    /// accelerometer's: every bin detected, the smallest wins).
    #[test]
    fn a_gains_smallest_detectable_bin_follows_what_its_bins_are() {
        let curves = |bins: [f64; 3], pd: [f64; 3]| {
            df!(
                "thresholds" => ["deck"; 3],
                col::DETECTOR => ["d"; 3],
                col::KIND => ["gain"; 3],
                col::TARGET => ["x"; 3],
                col::SIZE_BIN => bins,
                "pd" => pd,
                "pd_lo" => pd,
            )
            .unwrap()
        };
        let smallest = |df: &DataFrame, units: &std::collections::BTreeMap<String, String>| {
            let m = min_detectable(df, units).unwrap();
            m.column("min_size_pd90").unwrap().f64().unwrap().get(0)
        };
        let factors = curves([0.6, 0.9, 1.3], [1.0, 0.5, 1.0]);
        let none = Default::default();
        assert_eq!(smallest(&factors, &none), Some(1.3));
        let deviations = curves([0.0917, 0.175, 0.2583], [1.0, 1.0, 1.0]);
        let units = [("gain".to_string(), unit::GAIN_DEVIATION_BINS.to_string())].into();
        assert_eq!(smallest(&deviations, &units), Some(0.0917));
        assert_eq!(smallest(&deviations, &none), Some(0.2583), "read as factors, the largest is nearest 1");

        // A blank says why.
        let missed = min_detectable(&curves([3.0, 7.0, 11.0], [0.2, 0.6, 0.85]), &none).unwrap();
        let note = missed.column("min_size_note").unwrap().str().unwrap().get(0).map(String::from);
        assert_eq!(note.as_deref(), Some("no size bin reaches Pd 0.9: the largest size flown, 11, has Pd 0.850"));
        assert_eq!(
            min_detectable(&factors, &none).unwrap().column("min_size_note").unwrap().str().unwrap().get(0),
            None
        );
    }

    /// Each centre gets the edges of its kind's bin: a range of 2-20 in 3 bins, a second population of
    /// the same kind in 0-1 in 2 bins, a listed size (its own bin), a kind without bins, a fault-free row.
    #[test]
    fn bin_centres_get_their_kinds_edges() {
        let mut bins = Default::default();
        Factor::Range { lo: 2.0, hi: 20.0, bins: 3 }.add_bins_to("bias", &mut bins);
        Factor::Range { lo: 0.0, hi: 1.0, bins: 2 }.add_bins_to("bias", &mut bins);
        Factor::Values(vec![4.0]).add_bins_to("drift", &mut bins);
        assert_eq!(bins["bias"], vec![[2.0, 8.0], [8.0, 14.0], [14.0, 20.0], [0.0, 0.5], [0.5, 1.0]]);
        assert!(!bins.contains_key("drift"), "a listed size has no bins");
        let mut df = df!(
            col::KIND => ["bias", "bias", "bias", "drift", "stuck", "none"],
            col::SIZE_BIN => [Some(11.0), Some(0.25), Some(17.0 + 1e-14), Some(4.0), Some(3.0), None],
        )
        .unwrap();
        with_bin_edges(&mut df, col::SIZE_BIN, &bins).unwrap();
        let edges = |name: &str| df.column(name).unwrap().f64().unwrap().iter().collect::<Vec<_>>();
        assert_eq!(edges("size_bin_lo"), [Some(8.0), Some(0.0), Some(14.0), Some(4.0), Some(3.0), None]);
        assert_eq!(edges("size_bin_hi"), [Some(14.0), Some(0.5), Some(20.0), Some(4.0), Some(3.0), None]);
    }
}

/// The exact law's verdict for `detector` of the run at `values` (one per statistic), where `law` is
/// given, the run's trials have a duration and the values are thresholds.
fn hour_at(
    law: Option<HourLaw>,
    manifest: &crate::engine::run::runner::Manifest,
    statistics: &[String],
    detector: &str,
    values: &[f64],
) -> Option<HourConversion> {
    let law = law?;
    manifest.trial_duration_s?;
    if values.len() != statistics.len() || !values.iter().all(|v| v.is_finite() && *v > 0.0) {
        return None;
    }
    let d = manifest.detectors.iter().position(|n| n == detector)?;
    law(d, statistics, values).filter(|h| h.ratio.is_finite())
}

/// Per detector and threshold set in use (the deck's, and `set`'s whole-detector thresholds), the
/// exact law's verdict on the conversion where `hour_at` gives one.
fn conversions_of(
    thresholds: &[DetectorThresholds],
    set: &'static str,
    hour_at: &dyn Fn(&str, &[f64]) -> Option<HourConversion>,
) -> Vec<(String, &'static str, HourConversion)> {
    let mut out = Vec::new();
    for t in thresholds {
        for (name, values) in [(DECK, &t.deck), (set, &t.whole)] {
            if let Some(h) = hour_at(&t.detector, values) {
                out.push((t.detector.clone(), name, h));
            }
        }
    }
    out
}
