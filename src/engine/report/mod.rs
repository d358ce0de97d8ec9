//! `fdimc report DIR` for every kind of study: plots (SVG) and one self-contained HTML page in
//! `DIR/report/`, drawn from the shared outcome schema and the shared summary tables, then what the
//! method adds ([`KindReport::part`]).
//!
//! - `pd_size_<detector>_<kind>.svg`: Pd against fault size per target with 95 % Wilson bands, the
//!   minimum size with Pd >= 0.9 marked (calibrated thresholds where the kind calibrates, else the deck's);
//! - `delay_<detector>.svg`: detection-delay distributions per fault kind;
//! - `confusion_<detector>.svg`: the isolation (or classification) confusion matrix (`confusion.csv`);
//! - `false_alarms_<detector>.svg`: Pfa by noise and parameter-error bin with intervals (`summary`);
//! - `roc.svg` (kinds that record a detection statistic): Pd against Pfa as the whole-detector
//!   thresholds are scaled, the calibrated point marked;
//! - `trace_trial<N>.svg` (`--trials N`): the trial re-flown by the method's `simulate`;
//! - `report.html`: provenance, warnings, the tables for reading, every plot.
//!
//! Text is rendered with the bundled DejaVu Sans (`assets/fonts`), so output is the same on any machine.

pub mod html;
pub mod plots;
mod sensitivity;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::summary::Settings;
use crate::engine::results::tables::{bool_col, column_names, f64_col, read_summary, slices, str_col, u64_col};
use crate::engine::results::thresholds::{RecordedStatistics, read_thresholds};
use crate::engine::run::runner::{Manifest, RunError, io, read_parquet, write_atomically};
use crate::engine::stats::intervals::{Z95, wilson};

/// A plot of a kind's own record columns, per detector, over the flown faulty trials where they are set.
pub enum OwnPlot {
    /// `y` against `x`, one point per row (at most 4,000 per detector), e.g. an estimate's error against
    /// the true fault size.
    /// `diagonal`: draw y = x (both axes the same quantity), else y = 0 (y is an error).
    Scatter { file: &'static str, title: &'static str, x: &'static str, y: &'static str, diagonal: bool },
    /// The distribution of `column`.
    Histogram { file: &'static str, title: &'static str, column: &'static str },
}

/// One panel of a report's trace plot: `columns` are names of `simulate`'s trace table, `*` matching
/// any run of characters.
pub struct TracePanel {
    pub title: &'static str,
    pub columns: &'static [&'static str],
}

/// What a report wrote, for the CLI and tests.
#[derive(Debug, Default)]
pub struct Report {
    pub files: Vec<PathBuf>,
    pub warnings: Vec<String>,
    /// Which trials the traces show and why, when the report picked them (HTML).
    pub trace_note: String,
}

/// What a method adds to the shared report: plots it drew into `ReportContext::out` and sections of
/// the page (title, HTML).
#[derive(Debug, Default)]
pub struct ReportPart {
    pub files: Vec<PathBuf>,
    pub warnings: Vec<String>,
    pub sections: Vec<(String, String)>,
}

/// What a method's report part may read.
pub struct ReportContext<'a> {
    /// The results folder.
    pub dir: &'a Path,
    /// `dir/report/`, where plots go.
    pub out: &'a Path,
    pub manifest: &'a Manifest,
    /// `--trials`: trials to re-fly and draw.
    pub trials: &'a [u64],
}

impl ReportContext<'_> {
    /// The run's deck, for re-flying `--trials`: refused when missing or changed since the run.
    pub fn run_deck(&self) -> Result<PathBuf, RunError> {
        let deck = PathBuf::from(&self.manifest.deck);
        let same =
            crate::engine::run::runner::deck_sha256(&deck).map(|h| h == self.manifest.deck_sha256).unwrap_or(false);
        if !same {
            return Err(RunError::Invalid(format!(
                "--trials: {} is missing or changed since this run (SHA-256 differs): traces need the run's deck",
                deck.display()
            )));
        }
        Ok(deck)
    }
}

/// Per detector, from `trials.parquet`.
#[derive(Default)]
struct DetectorData {
    /// Largest statistic over its calibrated threshold on fault-free trials, before the end.
    z_fault_free: Vec<f64>,
    /// Delays per fault kind at the report's threshold set.
    delays: BTreeMap<String, Vec<f64>>,
}

/// What the report needs of a kind of study (its [`crate::engine::method::Method`] gives it).
pub struct KindReport<'a> {
    /// `manifest.json`'s `kind`, for messages.
    pub kind: &'a str,
    /// The kind records a detection statistic whose thresholds `summarize` calibrates.
    pub calibrates: bool,
    /// The kind's run trains classifiers and writes them beside its results (`classifiers.json`).
    pub trains_classifiers: bool,
    /// What the kind adds: its own plots and sections; one that draws `trace_trial<N>.svg` itself
    /// replaces the generic traces.
    pub part: Option<fn(&ReportContext) -> Result<ReportPart, RunError>>,
    /// The panels of `--trials N`: the columns of `simulate`'s trace each one draws.
    pub trace_panels: &'a [TracePanel],
    /// Plots of the kind's own `trials.parquet` columns.
    pub own_plots: &'a [OwnPlot],
}

/// Re-flies trial `trial` of the run whose manifest is given from its deck (checked unchanged,
/// [`ReportContext::run_deck`]) into the trace table `table` (the kind's `simulate`), with the
/// classifiers the run used, if any.
pub type Refly<'a> = dyn FnMut(&Path, &Manifest, u64, &Path, Option<&Path>) -> Result<(), RunError> + 'a;

/// Writes the report of the run in `dir`, drawing `trials` re-flown by `refly` from the deck the run used.
pub fn write_report(dir: &Path, trials: &[u64], method: &KindReport, refly: &mut Refly) -> Result<Report, RunError> {
    let manifest = Manifest::read(dir)?;
    if manifest.sensitivity.is_some() {
        return sensitivity::write(dir, &manifest);
    }
    let calibrates = method.calibrates;
    let mut needed = vec!["summary.parquet", "curves.csv", "min_detectable.csv", "detectors.csv"];
    if calibrates {
        needed.push("thresholds.csv");
    }
    for f in needed {
        if !dir.join(f).exists() {
            return Err(RunError::Invalid(format!(
                "{}: missing {f}: run `fdimc summarize {}` first",
                dir.display(),
                dir.display()
            )));
        }
    }
    let out = dir.join("report");
    std::fs::create_dir_all(&out).map_err(io(&out))?;
    plots::register_font();
    let mut report = Report::default();
    let set = if calibrates { "calibrated" } else { "deck" };
    let thresholds = if calibrates { read_thresholds(&dir.join("thresholds.csv"))?.detectors } else { Vec::new() };
    let data = gather(dir, &manifest, &thresholds)?;

    let curves = read_summary(&dir.join("curves.csv"))?;
    let min_det = read_summary(&dir.join("min_detectable.csv"))?;
    for d in &manifest.detectors {
        for kind in kinds_with_sizes(&curves, set, d)? {
            let file = out.join(format!("pd_size_{d}_{kind}.svg"));
            let unit = manifest.fault_size_units.get(&kind).cloned().unwrap_or_else(|| "deck units".into());
            plots::pd_against_size(&file, &curves, &min_det, set, d, &kind, &unit).map_err(internal(&file))?;
            report.files.push(file);
        }
    }
    if calibrates {
        let roc = read_roc(&dir.join("roc.csv"), &manifest.detectors)?;
        if roc.iter().any(|c| c.trials > 0 && c.points.iter().any(|p| !p.1.is_nan())) {
            let file = out.join("roc.svg");
            plots::roc(&file, &roc).map_err(internal(&file))?;
            report.files.push(file);
        } else {
            report.warnings.push("no ROC: it needs both fault-free and faulty trials".into());
        }
    }
    if calibrates {
        report.files.extend(tail_plots(dir, &out, &data)?);
    }
    let confusion = read_confusion(dir)?;
    let false_alarms = false_alarms_by_bin(dir, set)?;
    for d in &manifest.detectors {
        let dd = &data[d];
        if dd.delays.values().any(|v| !v.is_empty()) {
            let file = out.join(format!("delay_{d}.svg"));
            plots::delays(&file, d, set, &dd.delays).map_err(internal(&file))?;
            report.files.push(file);
        }
        if let Some(counts) = confusion.get(d).filter(|c| !c.is_empty()) {
            let file = out.join(format!("confusion_{d}.svg"));
            plots::confusion(&file, d, &manifest.outputs, counts).map_err(internal(&file))?;
            report.files.push(file);
        }
        if let Some(points) = false_alarms.get(d).filter(|p| plots::false_alarms_vary(p)) {
            let file = out.join(format!("false_alarms_{d}.svg"));
            plots::false_alarms(&file, d, set, points).map_err(internal(&file))?;
            report.files.push(file);
        }
    }

    let mut own_files = Vec::new();
    for plot in method.own_plots {
        own_files.push(own_plot(dir, &manifest, &out, plot)?);
    }
    report.files.extend(own_files.iter().cloned());

    // Without --trials, the trials a reader wants to see first, where the kind can draw traces and the
    // run's deck is there to re-fly them (asked-for traces refuse a missing deck; picked ones are skipped).
    let can_trace = !method.trace_panels.is_empty() || method.part.is_some();
    let deck_there = ReportContext { dir, out: &out, manifest: &manifest, trials: &[] }.run_deck().is_ok();
    let picked =
        if trials.is_empty() && can_trace && deck_there { representative_trials(dir, &manifest)? } else { Vec::new() };
    if trials.is_empty() && can_trace && !deck_there {
        report
            .warnings
            .push(format!("no traces: the run's deck {} is missing or changed since the run", manifest.deck));
    }
    let chosen: Vec<u64> = if trials.is_empty() { picked.iter().map(|p| p.0).collect() } else { trials.to_vec() };
    if !picked.is_empty() {
        let list: Vec<String> = picked.iter().map(|(t, why)| format!("{t} ({why})")).collect();
        report.trace_note = format!(
            " Trials picked for detector {} (give <code>--trials</code> for others): {}.",
            html::escape(&manifest.detectors[0]),
            list.join(", ")
        );
    }
    let context = ReportContext { dir, out: &out, manifest: &manifest, trials: &chosen };
    let part = match method.part {
        Some(own) => own(&context)?,
        None => ReportPart::default(),
    };
    if part.files.iter().all(|f| !f.to_string_lossy().contains("trace_trial")) {
        report.files.extend(traces(&context, method, refly)?);
    }
    report.files.extend(part.files.iter().cloned());
    report.warnings.extend(part.warnings.iter().cloned());

    let summary = read_parquet(&dir.join("summary.parquet"))?;
    report.warnings.extend(health_warnings(&summary));
    // What `summarize` was asked (its target Pfa) and warned of; a folder summarized by an older fdimc
    // has no settings, and the report checks the deck's target itself.
    let settings = Settings::read(dir)?;
    let mut shown = manifest.clone();
    match &settings {
        Some(s) => {
            shown.target_pfa = s.target_pfa.unwrap_or(manifest.target_pfa);
            report.warnings.extend(s.warnings.iter().map(|w| format!("summarize: {w}")));
        }
        None => {
            for (d, dd) in &data {
                let n = dd.z_fault_free.len();
                if calibrates && (n as f64) * manifest.target_pfa < 1.0 {
                    report.warnings.push(format!(
                        "detector {d}: {n} fault-free trials cannot resolve the target Pfa {} (needs {})",
                        manifest.target_pfa,
                        (1.0 / manifest.target_pfa).ceil()
                    ));
                }
            }
        }
    }

    let html = out.join("report.html");
    let page = page(dir, &shown, &report, &part.sections, &own_files, set, &false_alarms)?;
    write_atomically(&html, page.as_bytes())?;
    report.files.push(html);
    Ok(report)
}

/// One tail plot per detector with a fit of its calibrated set (`tail.csv`, `tail_diagnostics.csv`;
/// none from a summary written before them).
fn tail_plots(dir: &Path, out: &Path, data: &BTreeMap<String, DetectorData>) -> Result<Vec<PathBuf>, RunError> {
    let (tail_path, diag_path) = (dir.join("tail.csv"), dir.join("tail_diagnostics.csv"));
    if !tail_path.exists() || !diag_path.exists() {
        return Ok(Vec::new());
    }
    let (tail, diag) = (read_summary(&tail_path)?, read_summary(&diag_path)?);
    let (t, g) = (crate::engine::results::tables::Table(&tail), crate::engine::results::tables::Table(&diag));
    let (dd, dset, chosen) = (g.strs("detector"), g.strs("thresholds"), g.f64s("chosen"));
    let (u, sigma, xi, q) =
        (g.f64s("fit_threshold_scale"), g.f64s("sigma"), g.f64s("xi"), g.f64s("fit_threshold_quantile"));
    let (td, tset, query, stat) = (t.strs("detector"), t.strs("thresholds"), t.strs("query"), t.strs("statistic"));
    let (pfa, scale, lo, hi) = (t.f64s("pfa"), t.f64s("scale"), t.f64s("scale_lo"), t.f64s("scale_hi"));
    let mut files = Vec::new();
    for (d, dd_data) in data {
        if dd_data.z_fault_free.is_empty() {
            continue;
        }
        let fit = (0..diag.height())
            .find(|&i| dd[i] == *d && dset[i] != "deck" && chosen[i] == 1.0)
            .map(|i| (u[i], sigma[i], xi[i], 1.0 - q[i]));
        // One statistic's rows: the factor on the thresholds is the same for every statistic.
        let targets: Vec<(f64, f64, f64, f64)> = (0..tail.height())
            .filter(|&i| td[i] == *d && tset[i] != "deck" && query[i] == "threshold_for_pfa")
            .filter(|&i| Some(&stat[i]) == stat.first())
            .map(|i| (pfa[i], scale[i], lo[i], hi[i]))
            .collect();
        let file = out.join(format!("tail_{d}.svg"));
        let plot = plots::TailPlot { detector: d, values: &dd_data.z_fault_free, fit, targets: &targets };
        plots::tail(&file, &plot).map_err(internal(&file))?;
        files.push(file);
    }
    Ok(files)
}

/// The first detector's first detected fault, first missed fault and first false alarm (those the run
/// has), each with why it was picked (all its reasons); trials in order, each once.
fn representative_trials(dir: &Path, manifest: &Manifest) -> Result<Vec<(u64, String)>, RunError> {
    let path = dir.join("trials.parquet");
    let select: Vec<String> =
        [col::TRIAL, col::DETECTOR, col::FAULT_FREE, col::DETECTED, col::FALSE_ALARM, col::FAILURE]
            .iter()
            .map(|c| c.to_string())
            .collect();
    let detector = manifest.detectors.first().map(String::as_str).unwrap_or_default();
    let mut found: [Option<u64>; 3] = [None; 3];
    for df in slices(&path, manifest.rows as usize, crate::engine::results::thresholds::SLICE_ROWS, &select) {
        if found.iter().all(Option::is_some) {
            break;
        }
        let df = df?;
        let (trial, det) = (u64_col(&df, col::TRIAL, &path)?, str_col(&df, col::DETECTOR, &path)?);
        let (fault_free, detected) = (bool_col(&df, col::FAULT_FREE, &path)?, bool_col(&df, col::DETECTED, &path)?);
        let (false_alarm, failure) = (bool_col(&df, col::FALSE_ALARM, &path)?, str_col(&df, col::FAILURE, &path)?);
        for i in 0..df.height() {
            if det.get(i) != Some(detector) || failure.get(i).is_some() {
                continue;
            }
            let (Some(t), Some(ff), Some(hit), Some(fa)) =
                (trial.get(i), fault_free.get(i), detected.get(i), false_alarm.get(i))
            else {
                continue;
            };
            for (slot, wanted) in found.iter_mut().zip([!ff && hit, !ff && !hit, fa]) {
                if wanted && slot.is_none() {
                    *slot = Some(t);
                }
            }
        }
    }
    // One trial can be two of them (a detected fault that also alarmed before its onset): listed once,
    // with both reasons.
    let mut picked: Vec<(u64, String)> = Vec::new();
    for (t, why) in found.into_iter().zip(["first detected fault", "first missed fault", "first false alarm"]) {
        let Some(t) = t else { continue };
        match picked.iter_mut().find(|p| p.0 == t) {
            Some(p) => p.1 = format!("{}, {why}", p.1),
            None => picked.push((t, why.to_string())),
        }
    }
    picked.sort_unstable();
    Ok(picked)
}

fn internal(file: &Path) -> impl FnOnce(String) -> RunError + '_ {
    move |e| RunError::Internal(format!("{}: {e}", file.display()))
}

fn polars_error(path: &Path) -> impl Fn(PolarsError) -> RunError + '_ {
    move |e| RunError::Invalid(format!("{}: {e}", path.display()))
}

/// Re-flies each of `ctx.trials` with `refly` (into a table next to the plot) and draws the columns of
/// the kind's trace panels.
fn traces(ctx: &ReportContext, method: &KindReport, refly: &mut Refly) -> Result<Vec<PathBuf>, RunError> {
    if ctx.trials.is_empty() {
        return Ok(Vec::new());
    }
    let deck = ctx.run_deck()?;
    if method.trace_panels.is_empty() {
        return Err(RunError::Invalid(format!("--trials: {} studies list no trace to draw", method.kind)));
    }
    let onsets = onsets(ctx.dir, ctx.manifest.rows, ctx.trials)?;
    // The classifiers the run used (written beside its results), not ones trained anew from the deck:
    // they differ when the run took `--classifiers` from another deck.
    let run_classifiers = method.trains_classifiers.then(|| ctx.dir.join("classifiers.json")).filter(|f| f.exists());
    let mut files = Vec::new();
    for &trial in ctx.trials {
        if trial >= ctx.manifest.trials {
            return Err(RunError::Invalid(format!(
                "--trials: trial {trial} is not in this run (0..{})",
                ctx.manifest.trials
            )));
        }
        let table = ctx.out.join(format!("trace_trial{trial}.parquet"));
        refly(&deck, ctx.manifest, trial, &table, run_classifiers.as_deref())?;
        let df = read_parquet(&table)?;
        let t_s = f64_col(&df, "t_s", &table)?.into_no_null_iter().collect::<Vec<_>>();
        let names: Vec<String> = df.get_column_names().iter().map(|n| n.to_string()).collect();
        let mut panels = Vec::new();
        for panel in method.trace_panels {
            let mut series = Vec::new();
            for name in names.iter().filter(|n| panel.columns.iter().any(|p| glob(p, n))) {
                let c = df.column(name).and_then(|c| c.cast(&DataType::Float64)).map_err(polars_error(&table))?;
                let v = c.f64().map_err(polars_error(&table))?;
                series.push((name.clone(), (0..v.len()).map(|i| v.get(i).unwrap_or(f64::NAN)).collect()));
            }
            if !series.is_empty() {
                panels.push((panel.title.to_string(), series));
            }
        }
        let file = ctx.out.join(format!("trace_trial{trial}.svg"));
        let title = format!("{}: trial {trial} as `fdimc simulate` re-flies it", ctx.manifest.study);
        plots::trace_panels(&file, &title, &t_s, &panels, onsets.get(&trial).copied()).map_err(internal(&file))?;
        files.push(file);
    }
    Ok(files)
}

/// `pattern` with `*` standing for any run of characters.
fn glob(pattern: &str, name: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == name;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !name.starts_with(first) || !name[first.len()..].ends_with(last) || name.len() < first.len() + last.len() {
        return false;
    }
    let mut rest = &name[first.len()..name.len() - last.len()];
    for p in &parts[1..parts.len() - 1] {
        match rest.find(p) {
            Some(i) => rest = &rest[i + p.len()..],
            None => return false,
        }
    }
    true
}

/// The fault onset of each of `trials` (from its rows in `trials.parquet`).
fn onsets(dir: &Path, rows: u64, trials: &[u64]) -> Result<BTreeMap<u64, f64>, RunError> {
    let path = dir.join("trials.parquet");
    let mut found = BTreeMap::new();
    let columns = vec![col::TRIAL.to_string(), col::ONSET_S.to_string()];
    for df in slices(&path, rows as usize, 65_536, &columns) {
        let df = df?;
        let t = df.column(col::TRIAL).and_then(|c| c.u64().cloned()).map_err(polars_error(&path))?;
        let onset = f64_col(&df, col::ONSET_S, &path)?;
        for i in 0..df.height() {
            if let (Some(t), Some(o)) = (t.get(i), onset.get(i))
                && trials.contains(&t)
            {
                found.insert(t, o);
            }
        }
    }
    Ok(found)
}

/// Failed designs and diverged runs, counted once per (trial, detector) from one threshold set's rows.
fn health_warnings(summary: &DataFrame) -> Vec<String> {
    let first_set = summary.column("thresholds").ok().and_then(|c| c.str().ok()).and_then(|c| c.get(0));
    let sum = |name: &str| -> u64 {
        let (Ok(set), Ok(values)) = (summary.column("thresholds"), summary.column(name)) else { return 0 };
        let (Ok(set), Ok(values)) = (set.str(), values.u64()) else { return 0 };
        (0..summary.height()).filter(|&i| set.get(i) == first_set).filter_map(|i| values.get(i)).sum()
    };
    let mut warnings = Vec::new();
    let failures = sum("failed");
    if failures > 0 {
        warnings.push(format!("{failures} trial x detector runs failed (failure in trials.parquet)"));
    }
    let truth_diverged = sum("truth_diverged");
    if truth_diverged > 0 {
        warnings.push(format!(
            "{truth_diverged} trial x detector runs had a truth that diverged or left its physical range \
             (truth_diverged in trials.parquet): in no rate and no calibration"
        ));
    }
    let diverged = sum("diverged");
    if diverged > 0 {
        warnings.push(format!("{diverged} trial x detector runs diverged (diverged in trials.parquet)"));
    }
    warnings
}

/// Fault kinds of detector `d` with at least two size bins in the curves of threshold set `set`.
fn kinds_with_sizes(curves: &DataFrame, set: &str, d: &str) -> Result<Vec<String>, RunError> {
    let f = curves
        .clone()
        .lazy()
        .filter(
            polars::prelude::col("thresholds")
                .eq(lit(set))
                .and(polars::prelude::col(col::DETECTOR).eq(lit(d)))
                .and(polars::prelude::col(col::SIZE_BIN).is_not_null()),
        )
        .group_by_stable([polars::prelude::col(col::KIND)])
        .agg([polars::prelude::col(col::SIZE_BIN).n_unique().alias("n")])
        .filter(polars::prelude::col("n").gt_eq(lit(2)))
        .collect()
        .map_err(|e| RunError::Internal(e.to_string()))?;
    let k = f.column(col::KIND).and_then(|c| c.str().cloned()).map_err(|e| RunError::Internal(e.to_string()))?;
    Ok((0..k.len()).filter_map(|i| k.get(i).map(str::to_string)).collect())
}

/// `confusion.csv` as counts per detector: (true target, named target) -> units.
fn read_confusion(dir: &Path) -> Result<BTreeMap<String, BTreeMap<(String, String), u64>>, RunError> {
    let path = dir.join("confusion.csv");
    let mut counts: BTreeMap<String, BTreeMap<(String, String), u64>> = BTreeMap::new();
    if !path.exists() {
        return Ok(counts);
    }
    let df = read_summary(&path)?;
    let t = crate::engine::results::tables::Table(&df);
    let (d, truth, named, n) = (t.strs(col::DETECTOR), t.strs("truth"), t.strs(col::ISOLATED), t.u64s("units"));
    for i in 0..df.height() {
        *counts.entry(d[i].clone()).or_default().entry((truth[i].clone(), named[i].clone())).or_default() += n[i];
    }
    Ok(counts)
}

/// Per detector: (noise bin, parameter-error bin, Pfa, lo, hi, fault-free trials flown) from the
/// summary's fault-free rows of threshold set `set`, summed over the kind's own bins.
fn false_alarms_by_bin(
    dir: &Path,
    set: &str,
) -> Result<BTreeMap<String, Vec<(f64, f64, f64, f64, f64, u64)>>, RunError> {
    let df = read_parquet(&dir.join("summary.parquet"))?;
    let t = crate::engine::results::tables::Table(&df);
    let (sets, d, kind) = (t.strs("thresholds"), t.strs(col::DETECTOR), t.strs(col::KIND));
    let (noise, perr) = (t.f64s(col::NOISE_BIN), t.f64s(col::PARAM_ERROR_BIN));
    let (trials, failed, alarms) = (t.u64s("trials"), t.u64s("failed"), t.u64s("false_alarms"));
    let mut sums: BTreeMap<String, BTreeMap<(u64, u64), (u64, u64)>> = BTreeMap::new();
    for i in 0..df.height() {
        if sets[i] != set || kind[i] != col::NO_FAULT {
            continue;
        }
        let key = (noise[i].to_bits(), perr[i].to_bits());
        let s = sums.entry(d[i].clone()).or_default().entry(key).or_default();
        s.0 += alarms[i];
        s.1 += trials[i] - failed[i];
    }
    Ok(sums
        .into_iter()
        .map(|(d, bins)| {
            let points = bins
                .into_iter()
                .filter(|(_, (_, n))| *n > 0)
                .map(|((nb, pb), (k, n))| {
                    let (lo, hi) = wilson(k, n, Z95);
                    (f64::from_bits(nb), f64::from_bits(pb), k as f64 / n as f64, lo, hi, n)
                })
                .collect();
            (d, points)
        })
        .collect())
}

/// Each detector's ROC from `roc.csv` (written by `summarize`; none from a folder summarised before it
/// was).
fn read_roc(path: &Path, detectors: &[String]) -> Result<Vec<plots::RocCurve>, RunError> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let df = crate::engine::results::tables::read_summary(path)?;
    let det = str_col(&df, col::DETECTOR, path)?;
    let number = |name: &str| crate::engine::results::tables::numbers(&df, name, path);
    let (pfa, pd, trials) = (number("pfa")?, number("pd")?, number("trials")?);
    let calibrated = bool_col(&df, "calibrated", path)?;
    Ok(detectors
        .iter()
        .map(|d| {
            let rows: Vec<usize> = (0..df.height()).filter(|&i| det.get(i) == Some(d.as_str())).collect();
            plots::RocCurve {
                detector: d.clone(),
                points: rows.iter().map(|&i| (pfa[i], pd[i])).collect(),
                calibrated: rows.iter().find(|&&i| calibrated.get(i) == Some(true)).map(|&i| (pfa[i], pd[i])),
                trials: rows.iter().map(|&i| trials[i] as u64).min().unwrap_or(0),
            }
        })
        .collect())
}

/// Delays and ROC values per detector, streamed from `trials.parquet`. With calibrated `thresholds`
/// (kinds that record a statistic) delays are the first passage over them; otherwise the recorded delay.
fn gather(
    dir: &Path,
    m: &Manifest,
    thresholds: &[(String, Vec<f64>, Vec<f64>)],
) -> Result<BTreeMap<String, DetectorData>, RunError> {
    let path = dir.join("trials.parquet");
    let mut data: BTreeMap<String, DetectorData> =
        m.detectors.iter().map(|d| (d.clone(), DetectorData::default())).collect();
    let whole: BTreeMap<&str, &Vec<f64>> = thresholds.iter().map(|t| (t.0.as_str(), &t.2)).collect();
    let statistics: Vec<String> =
        column_names(&path)?.iter().filter_map(|n| n.strip_prefix(col::PRE_MAX_PREFIX).map(str::to_string)).collect();
    let by_statistic = !whole.is_empty() && !statistics.is_empty();
    let mut columns: Vec<String> =
        [col::DETECTOR, col::KIND, col::FAULT_FREE, col::FAILURE, col::ONSET_S, col::DELAY_S]
            .iter()
            .map(|s| s.to_string())
            .collect();
    if by_statistic {
        columns.extend(RecordedStatistics::columns(&statistics));
    }
    for df in slices(&path, m.rows as usize, 8_192, &columns) {
        let df = df?;
        let det = str_col(&df, col::DETECTOR, &path)?;
        let kind = str_col(&df, col::KIND, &path)?;
        let fault_free = bool_col(&df, col::FAULT_FREE, &path)?;
        let failure = str_col(&df, col::FAILURE, &path)?;
        let onset = f64_col(&df, col::ONSET_S, &path)?;
        let delay = f64_col(&df, col::DELAY_S, &path)?;
        let recorded =
            RecordedStatistics::read(&df, if by_statistic { &statistics } else { &[] }, m.detection_window_s, &path)?;
        for i in 0..df.height() {
            let (Some(d), Some(k)) = (det.get(i), kind.get(i)) else { continue };
            if failure.get(i).is_some() {
                continue;
            }
            let Some(dd) = data.get_mut(d) else { continue };
            // By `fault_free`, as the summary: a classifier's fault-free class has a name (`normal`).
            let is_fault_free = fault_free.get(i) == Some(true);
            if !by_statistic {
                if let (false, Some(t)) = (is_fault_free, delay.get(i)) {
                    dd.delays.entry(k.to_string()).or_default().push(t);
                }
                continue;
            }
            let Some(th) = whole.get(d) else { continue };
            let j_max = statistics.len().min(th.len());
            if is_fault_free {
                let z = (0..j_max).map(|j| recorded.pre[j][i] / th[j]).fold(0.0, f64::max);
                dd.z_fault_free.push(z);
                continue;
            }
            if let (Some(t), Some(t0)) = (recorded.first_alarm(i, &th[..j_max]), onset.get(i)) {
                dd.delays.entry(k.to_string()).or_default().push(t - t0);
            }
        }
    }
    Ok(data)
}

/// One of the method's own plots, from the flown faulty rows of `trials.parquet` where its columns are
/// set (at most 4,000 points per detector in a scatter).
fn own_plot(dir: &Path, m: &Manifest, out: &Path, plot: &OwnPlot) -> Result<PathBuf, RunError> {
    let path = dir.join("trials.parquet");
    let (name, columns): (&str, Vec<&str>) = match plot {
        OwnPlot::Scatter { file, x, y, .. } => (file, vec![x, y]),
        OwnPlot::Histogram { file, column, .. } => (file, vec![column]),
    };
    let mut select: Vec<String> = [col::DETECTOR, col::KIND, col::FAILURE].iter().map(|s| s.to_string()).collect();
    select.extend(columns.iter().map(|c| c.to_string()));
    let mut points: BTreeMap<String, Vec<(f64, f64)>> = m.detectors.iter().map(|d| (d.clone(), Vec::new())).collect();
    for df in slices(&path, m.rows as usize, 65_536, &select) {
        let df = df?;
        let (det, kind, failure) =
            (str_col(&df, col::DETECTOR, &path)?, str_col(&df, col::KIND, &path)?, str_col(&df, col::FAILURE, &path)?);
        let values: Vec<Vec<f64>> =
            columns.iter().map(|c| crate::engine::results::tables::numbers(&df, c, &path)).collect::<Result<_, _>>()?;
        for i in 0..df.height() {
            let (Some(d), Some(k)) = (det.get(i), kind.get(i)) else { continue };
            if k == col::NO_FAULT || failure.get(i).is_some() {
                continue;
            }
            let x = values[0][i];
            let y = values.get(1).map_or(0.0, |v| v[i]);
            let p = points.entry(d.to_string()).or_default();
            if x.is_finite() && y.is_finite() && (values.len() == 1 || p.len() < 4_000) {
                p.push((x, y));
            }
        }
    }
    let file = out.join(format!("{name}.svg"));
    let label = |c: &str| match m.fault_size_units.values().next() {
        Some(unit) if c == col::SIZE => format!("true fault size ({unit})"),
        _ => c.to_string(),
    };
    match plot {
        OwnPlot::Scatter { title, x, y, diagonal, .. } => {
            plots::scatter(&file, title, (&label(x), &label(y)), *diagonal, &points).map_err(internal(&file))?;
        }
        OwnPlot::Histogram { title, column, .. } => {
            let values = points.into_iter().map(|(d, p)| (d, p.into_iter().map(|v| v.0).collect())).collect();
            plots::frequencies(&file, title, column, "faulty", &values).map_err(internal(&file))?;
        }
    }
    Ok(file)
}

/// A table file of the run for reading, or `None` when the run has none.
fn table_of(dir: &Path, name: &str, skip: &[&str]) -> Result<Option<String>, RunError> {
    let path = dir.join(name);
    if !path.exists() {
        return Ok(None);
    }
    let df = read_summary(&path)?;
    Ok((df.height() > 0).then(|| html::table(&df, skip)))
}

/// [`table_of`] with the columns `leading` first (those it has), so the rates a reader looks for are
/// not off-screen behind a scrollbar.
fn table_of_leading(dir: &Path, name: &str, leading: &[&str]) -> Result<Option<String>, RunError> {
    let path = dir.join(name);
    if !path.exists() {
        return Ok(None);
    }
    let df = read_summary(&path)?;
    if df.height() == 0 {
        return Ok(None);
    }
    let names: Vec<String> = df.get_column_names().iter().map(|n| n.to_string()).collect();
    let mut order: Vec<&str> = leading.iter().copied().filter(|l| names.iter().any(|n| n == l)).collect();
    order.extend(names.iter().map(String::as_str).filter(|n| !leading.contains(n)));
    let df = df.select(order).map_err(polars_error(&path))?;
    Ok(Some(html::table(&df, &[])))
}

/// A long table folded away under its name and row count; the page's figures stay in view.
fn folded(name: &str, table: String) -> String {
    if table.is_empty() {
        return table;
    }
    let rows = table.matches("<tr>").count().saturating_sub(1);
    format!("<details><summary><code>{name}</code>: {rows} rows</summary>\n{table}</details>\n")
}

fn page(
    dir: &Path,
    m: &Manifest,
    r: &Report,
    own: &[(String, String)],
    own_files: &[PathBuf],
    set: &str,
    false_alarms: &BTreeMap<String, Vec<(f64, f64, f64, f64, f64, u64)>>,
) -> Result<String, RunError> {
    use html::escape;
    let figures = |prefix: &str| -> String {
        r.files
            .iter()
            .filter(|f| f.extension().is_some_and(|e| e == "svg"))
            .filter(|f| f.file_name().is_some_and(|n| n.to_string_lossy().starts_with(prefix)))
            .map(|f| html::figure(f))
            .collect()
    };
    let mut body = String::new();
    let mut section = |title: &str, intro: &str, content: String| {
        if !content.trim().is_empty() {
            body.push_str(&format!("<h2>{title}</h2>\n<p>{intro}</p>\n{content}\n"));
        }
    };
    section(
        "Safety figures",
        "The figures a safety case quotes, at the thresholds in use, each with its 95 % interval, the method \
         that gave it and the assumptions it rests on; <code>statement</code> is the sentence to quote. Table: \
         <code>safety.csv</code>.",
        table_of(dir, crate::engine::results::summary::safety::SAFETY_FILE, &["statement"])?.unwrap_or_default(),
    );
    section(
        "Detectors",
        &format!(
            "Over all fault sizes, per detector and threshold set; rates with 95 % Wilson intervals. \
             <code>flights</code>: every flight, <code>pfa</code> its false alarms before the onset (the answer \
             above counts fault-free flights). The report's plots use the <b>{set}</b> thresholds. Table: \
             <code>detectors.csv</code>."
        ),
        table_of_leading(dir, "detectors.csv", &["thresholds", "detector", "flights", "pfa", "faulty_units", "pd"])?
            .unwrap_or_default(),
    );
    section(
        "Thresholds",
        "Per statistic at the target false-alarm probability, and for the whole detector; achieved rates \
         with 95 % Wilson intervals. Table: <code>thresholds.csv</code>.",
        table_of(dir, "thresholds.csv", &[])?.unwrap_or_default(),
    );
    section(
        "Detection probability against fault size",
        "Per target, 95 % Wilson bands; a triangle marks the smallest size bin from which Pd &ge; 0.9. \
         Tables: <code>curves.csv</code>, <code>min_detectable.csv</code>.",
        figures("pd_size_") + &table_of(dir, "min_detectable.csv", &[])?.unwrap_or_default(),
    );
    section("ROC", "Calibrated point marked; the thresholds of every statistic scaled together.", figures("roc"));
    section(
        "Rare false alarms",
        "The fault-free units' largest statistic over the calibrated thresholds, and a generalised Pareto fit of \
         its upper tail: false-alarm probabilities below what the trials can show, and the thresholds for \
         per-flight-hour targets, with 95 % profile-likelihood intervals. They hold if the fitted law holds \
         beyond the data; <code>trust</code> says what the data say against it. The shape should stay put \
         over the thresholds of <code>tail_diagnostics.csv</code>. Table: <code>tail.csv</code>.",
        figures("tail_")
            + &folded(
                "tail.csv",
                table_of(dir, "tail.csv", &["pfa_per_hour_lo", "pfa_per_hour_hi", "estimate"])?.unwrap_or_default(),
            )
            + &folded("tail_diagnostics.csv", table_of(dir, "tail_diagnostics.csv", &[])?.unwrap_or_default()),
    );
    section(
        "Rare false alarms by simulation",
        "Written by <code>fdimc rare-event</code> into <code>rare_event/</code> (when it has been run): unbiased \
         estimates far below 1 / trials, by importance sampling or splitting, with 95 % intervals and the samples \
         plain Monte Carlo would need for the same interval. Compare with the tail fit above and, for linear \
         decks, the analytic answer. Table: <code>rare_event/rare_event.csv</code>.",
        table_of(
            dir,
            "rare_event/rare_event.csv",
            &["pfa_per_flight_hour_lo", "pfa_per_flight_hour_hi", "trial_s", "particles"],
        )?
        .unwrap_or_default()
            + &table_of(
                dir,
                "rare_event/per_hour.csv",
                &[
                    "pfa_per_flight_hour_flights_lo",
                    "pfa_per_flight_hour_flights_hi",
                    "pfa_per_flight_hour_conversion_lo",
                    "pfa_per_flight_hour_conversion_hi",
                    "conditional_per_segment_lo",
                    "conditional_per_segment_hi",
                ],
            )?
            .map(|t| {
                "<p>With <code>--flight-s F</code>: the same estimator over fault-free flights of F seconds, \
                 against the flight's segments taken as independent restarts (the conversion every per-hour figure \
                 otherwise rests on), and the extremal index that links them (1: the conversion holds; above: it \
                 under-counts, a restarted segment being quieter than one in flight; below: alarms cluster across \
                 segments). Table: <code>rare_event/per_hour.csv</code>.</p>"
                    .to_string()
                    + &t
            })
            .unwrap_or_default(),
    );
    section(
        "The worst point of the uncertainty box",
        "Written by <code>fdimc worst-case</code> into <code>worst_case/</code> (when it has been run): the point of \
         the deck's parameter errors, noise scale, fault size and onset where the objective is worst, found by \
         CMA-ES and by random points of the same budget, each judged on the same trials and confirmed on fresh \
         ones beside the deck as drawn (<code>confirmed</code> with its 95 % interval). Table: \
         <code>worst_case/worst_case.csv</code>.",
        table_of(dir, "worst_case/worst_case.csv", &["lower", "upper", "batch_trials"])?.unwrap_or_default(),
    );
    section(
        "Which factors matter (Sobol indices)",
        "Written by <code>fdimc sensitivity</code> into <code>sensitivity/</code> (when it has been run): the share \
         of each outcome's variance each factor explains alone (S1) and with its interactions (ST), with 95 % \
         bootstrap intervals; its bar charts are in <a href=\"../sensitivity/report/report.html\">its own report</a> \
         (after <code>fdimc report DIR/sensitivity</code>). Table: <code>sensitivity/sensitivity.csv</code>.",
        table_of(dir, "sensitivity/sensitivity.csv", &["part", "outcome_variance", "note", "sum_s1"])?
            .unwrap_or_default(),
    );
    section("Detection delay", "Per fault kind, detected trials only.", figures("delay_"));
    section(
        "Isolation",
        "Units of each true target by the target named (deck thresholds); <code>share_of_truth</code> on the \
         diagonal is each target's recall. Table: <code>confusion.csv</code>.",
        figures("confusion_") + &table_of(dir, "confusion.csv", &[])?.unwrap_or_default(),
    );
    let mut fa_table = String::new();
    for (d, points) in false_alarms {
        let frame = df!(
            "detector" => vec![d.clone(); points.len()],
            "noise_bin" => points.iter().map(|p| p.0).collect::<Vec<_>>(),
            "param_error_bin" => points.iter().map(|p| p.1).collect::<Vec<_>>(),
            "fault_free_trials" => points.iter().map(|p| p.5).collect::<Vec<_>>(),
            "pfa" => points.iter().map(|p| p.2).collect::<Vec<_>>(),
            "pfa_lo" => points.iter().map(|p| p.3).collect::<Vec<_>>(),
            "pfa_hi" => points.iter().map(|p| p.4).collect::<Vec<_>>(),
        )
        .map_err(|e| RunError::Internal(e.to_string()))?;
        fa_table.push_str(&html::table(&frame, &[]));
    }
    section(
        "False alarms by noise and parameter error",
        &format!(
            "Fault-free trials, {set} thresholds, 95 % Wilson intervals. Rows of <code>summary.csv</code> with kind none, summed."
        ),
        figures("false_alarms_") + &fa_table,
    );
    section(
        "Parameter errors, one at a time",
        "Each varied parameter's error in bins of its own (its listed values, or the deck's bins of its range; \
         <code>error_bin</code> the bin's centre), every threshold set, faulty units and fault-free flights \
         (<code>kind</code> <code>none</code>) apart: the derivative whose error moves Pd or Pfa is the one to model \
         better. Table: <code>parameter_errors.csv</code>.",
        folded(
            crate::engine::results::summary::PARAMETER_ERRORS_FILE,
            table_of_leading(
                dir,
                crate::engine::results::summary::PARAMETER_ERRORS_FILE,
                &["thresholds", "detector", "kind", "parameter", "error_bin", "units", "pd", "pfa"],
            )?
            .unwrap_or_default(),
        ),
    );
    section(
        "Paired comparison",
        "Every pair of detectors on the same trials: exact McNemar tests on the discordant trials, median delay \
         difference over trials both detected. Table: <code>comparison.csv</code>.",
        table_of(dir, "comparison.csv", &[])?.unwrap_or_default(),
    );
    section(
        &format!("What {} studies add", escape(&m.kind)),
        "The method's own record columns (<code>trials.parquet</code>), per detector.",
        own_files.iter().map(|f| html::figure(f)).collect(),
    );
    for (title, content) in own {
        section(&escape(title), "", content.clone());
    }
    section(
        "Traces",
        &format!("Re-flown from the run's deck with <code>fdimc simulate</code>.{}", r.trace_note),
        figures("trace_"),
    );
    Ok(shell(m, &answer_block(dir)?, &r.warnings, &body))
}

/// The answer block at the top of the page, from `answer.csv`: per detector at the thresholds in use,
/// the false-alarm probability on fault-free flights, Pd overall and per fault kind, the delays, the
/// smallest detectable faults and where the thresholds came from. Empty for a folder summarized by an
/// older fdimc (it says how to get one).
pub(crate) fn answer_block(dir: &Path) -> Result<String, RunError> {
    use crate::engine::results::tables::Table;
    use html::escape;
    let path = dir.join(crate::engine::results::summary::answer::ANSWER_FILE);
    if !path.exists() {
        return Ok(format!(
            "<div id=\"answer\"><h2>Answer</h2><p>No <code>answer.csv</code>: run <code>fdimc summarize {}</code> for it.</p></div>\n",
            escape(&dir.display().to_string())
        ));
    }
    let df = read_summary(&path)?;
    let t = Table(&df);
    let (sets, names, sources, values) =
        (t.strs("thresholds"), t.strs("detector"), t.strs("threshold_source"), t.strs("threshold_values"));
    let (flights, alarms, faulty) =
        (t.u64s("fault_free_flights"), t.u64s("fault_free_false_alarms"), t.u64s("faulty_units"));
    let (pfa, pd) = (t.rates("pfa_fault_free"), t.rates("pd"));
    let delay = t.delays("delay_p50_s", "delay_p90_s");
    let (per_kind, detectable) = (t.strs("pd_by_fault"), t.strs("min_size_pd90"));
    let hazard = t.strs("p_miss_before_hazard");
    let cell = |s: &str| if s.is_empty() { "-".to_string() } else { escape(s) };
    let list = |s: &str| if s.is_empty() { "-".to_string() } else { escape(s).replace("; ", "<br>") };
    let mut rows = String::new();
    for i in 0..df.height() {
        let quiet = if flights[i] > 0 {
            format!("{}<br><small>{} of {}</small>", pfa[i], alarms[i], flights[i])
        } else {
            "-".into()
        };
        let caught = if faulty[i] > 0 { format!("{}<br><small>of {}</small>", pd[i], faulty[i]) } else { "-".into() };
        rows.push_str(&format!(
            "<tr><th>{}</th><td>{quiet}</td><td>{caught}</td><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\"><small>{}</small></td></tr>\n",
            escape(&names[i]),
            delay[i],
            if hazard[i].is_empty() {
                list(&per_kind[i])
            } else {
                format!("{}<br><small>not detected before the hazard:</small><br>{}", list(&per_kind[i]), list(&hazard[i]))
            },
            list(&detectable[i]),
            cell(&values[i]),
        ));
    }
    let set = sets.first().cloned().unwrap_or_default();
    let source = sources.first().cloned().unwrap_or_default();
    Ok(format!(
        "<div id=\"answer\"><h2>Answer</h2>\n<p>At the <b>{}</b> thresholds ({}); rates with 95 % Wilson intervals. \
         Table: <code>answer.csv</code>.</p>\n<table class=\"answer\">\n<tr><th>detector</th><th>Pfa on fault-free flights</th>\
         <th>Pd, all faults</th><th>delay p50/p90</th><th>Pd by fault</th><th>smallest fault with Pd &ge; 0.9</th><th>thresholds</th></tr>\n{rows}</table></div>\n",
        escape(&set),
        escape(&source)
    ))
}

/// The page around a report's sections: the answer (none for a sensitivity run), the warnings, then
/// the provenance of the run.
fn shell(m: &Manifest, answer: &str, warnings: &[String], body: &str) -> String {
    use html::escape;
    let warnings = if warnings.is_empty() {
        "<p>None.</p>".to_string()
    } else {
        format!("<ul>{}</ul>", warnings.iter().map(|w| format!("<li>{}</li>", escape(w))).collect::<String>())
    };
    format!(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>fdimc report: {study}</title>
<style>body{{font-family:sans-serif;max-width:1300px;margin:1em auto;padding:0 1em}}h1{{margin:0.3em 0}}
table{{border-collapse:collapse;font-size:85%;margin:0.5em 0}}td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}}
.same{{font-size:85%;color:#444}}.left td{{text-align:left}}.answer td{{white-space:nowrap}}.answer td.l{{text-align:left;max-width:24em;white-space:normal}}.answer small{{color:#555}}figure{{display:inline-block;margin:0.5em}}img{{max-width:100%}}code{{background:#f4f4f4}}</style></head>
<body>
<h1>fdimc report: {study}</h1>
{answer}<h2>Warnings</h2>
{warnings}
<h2>Provenance</h2>
<table class="left">
<tr><th>kind</th><td>{kind}</td></tr>
<tr><th>deck</th><td><code>{deck}</code></td></tr>
<tr><th>deck SHA-256</th><td><code>{sha}</code></td></tr>
<tr><th>seed</th><td>{seed}</td></tr>
<tr><th>trials</th><td>{trials}</td></tr>
<tr><th>detectors</th><td>{detectors}</td></tr>
<tr><th>target Pfa</th><td>{pfa}</td></tr>
<tr><th>fdimc</th><td>{version}</td></tr>
<tr><th>command</th><td><code>{cmd}</code></td></tr>
</table>
{body}</body></html>
"#,
        study = escape(&m.study),
        kind = escape(&m.kind),
        deck = escape(&m.deck),
        sha = m.deck_sha256,
        seed = m.seed,
        trials = m.trials,
        detectors = escape(&m.detectors.join(", ")),
        pfa = if m.target_pfa > 0.0 { m.target_pfa.to_string() } else { "- (the kind calibrates no threshold)".into() },
        version = escape(&m.fdimc_version),
        cmd = escape(&m.command_line.join(" ")),
    )
}

#[cfg(test)]
mod tests {
    use super::glob;

    /// Trial 1 is both the first detected fault and the first false alarm of detector "a": listed once
    /// with both reasons; detector "b"'s rows and a failed row are passed over.
    #[test]
    fn representative_trials_merge_the_reasons_of_one_trial() {
        use super::*;
        let mut df = df!(
            col::TRIAL => [0u64, 0, 1, 1, 2, 3],
            col::DETECTOR => ["a", "b", "a", "b", "a", "a"],
            col::FAULT_FREE => [false, false, false, true, false, false],
            col::DETECTED => [true, true, true, false, false, false],
            col::FALSE_ALARM => [false, true, true, false, false, false],
            col::FAILURE => [Some("diverged"), None, None, None, None, None],
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        crate::engine::run::runner::write_parquet(&mut df, &dir.path().join("trials.parquet")).unwrap();
        let manifest = Manifest { rows: 6, detectors: vec!["a".into(), "b".into()], ..Manifest::unstarted() };
        let picked = representative_trials(dir.path(), &manifest).unwrap();
        assert_eq!(
            picked,
            [(1, "first detected fault, first false alarm".to_string()), (2, "first missed fault".to_string())]
        );
    }

    #[test]
    fn trace_column_patterns() {
        assert!(glob("r_*", "r_alpha_rad") && !glob("r_*", "yhat_alpha"));
        assert!(glob("*_p_*", "emmae_p_rudder") && !glob("*_p_*", "emmae_rudder_estimate_rad"));
        assert!(glob("*_test_statistic", "patent_alpha_rad_test_statistic") && glob("alarm", "alarm"));
        assert!(!glob("a*a", "a"));
    }
}
