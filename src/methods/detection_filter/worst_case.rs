//! `fdimc worst-case` on a detection-filter deck ([`crate::engine::worst_case`]): the deck's sampled
//! factors as the search's coordinates, a candidate judged on one detector's outcomes over a batch of
//! the deck's own trials with the candidate's point, and `--write-deck`.

use std::sync::Arc;

use rayon::prelude::*;

use super::scenario::DIM_PARAMETERS;
use super::study::LtiStudy;
use super::trials::Engine;
use crate::engine::method::select_detector;
use crate::engine::run::runner::RunError;
use crate::engine::scenario::deck::{Factor, SearchPoint};
use crate::engine::scenario::draws::{DIM_NOISE, DIM_ONSET, DIM_SIZE, value_at};
use crate::engine::stats::intervals::{Z95, wilson};
use crate::engine::worst_case::{Coordinate, Judged, Objective, WorstCaseOptions, search};
use crate::fault::deck::{FaultTarget, SizeSpec};

/// The factors the deck's trials draw that the objective can feel: the fault's size and onset (faulty
/// objectives), the noise scale and each parameter error.
fn coordinates(study: &LtiStudy, objective: Objective) -> Vec<Coordinate> {
    let mc = &study.monte_carlo;
    let mut out = Vec::new();
    let mut add = |name: String, dim: usize, f: &Factor| {
        let f = f.clone();
        let (lower, upper) = (value_at(&f, 0.0), value_at(&f, 1.0));
        out.push(Coordinate { name, dim, lower, upper, value_at: Box::new(move |u| value_at(&f, u)) });
    };
    if !objective.fault_free() {
        let sized: Vec<(&str, &Factor)> = (mc.faults.iter())
            .filter_map(|k| match &k.size {
                SizeSpec::Output(f) | SizeSpec::SensorSigma(f) if f.is_sampled() => Some((k.record_kind(), f)),
                _ => None,
            })
            .collect();
        match sized.as_slice() {
            [] => {}
            [(kind, f)] => add(format!("size_{kind}"), DIM_SIZE, f),
            // Several kinds: one coordinate, the position in each kind's own range.
            _ => add("size_position".into(), DIM_SIZE, &Factor::Range { lo: 0.0, hi: 1.0, bins: 1 }),
        }
        if mc.common.onset_s.is_sampled() {
            add("onset_s".into(), DIM_ONSET, &mc.common.onset_s);
        }
    }
    if mc.common.noise_scale.is_sampled() {
        add("noise_scale".into(), DIM_NOISE, &mc.common.noise_scale);
    }
    for (k, pe) in mc.parameter_errors.iter().enumerate().filter(|(_, pe)| pe.value.is_sampled()) {
        add(format!("perr_{}", pe.name), DIM_PARAMETERS + k, &pe.value);
    }
    out
}

/// The objective over outcomes of trials `trials` of `study` with `point`'s factors.
fn judge(
    study: &LtiStudy,
    detector: usize,
    objective: Objective,
    coordinates: &[Coordinate],
    point: &[Option<f64>],
    trials: std::ops::Range<u64>,
) -> Result<Judged, RunError> {
    let mut units = vec![None; DIM_PARAMETERS + study.monte_carlo.parameter_errors.len()];
    for (c, u) in coordinates.iter().zip(point) {
        units[c.dim] = *u;
    }
    let mut s = study.clone();
    s.monte_carlo.common.search_point = Some(Arc::new(SearchPoint { units, fault_free: Some(objective.fault_free()) }));
    let engine = Engine::new(&s);
    let seen: Vec<Option<(bool, f64, bool)>> = trials
        .into_par_iter()
        .map(|t| {
            let run = engine.run(t);
            let outcome = run.detectors[detector].as_ref().ok()?;
            let onset = run.spec.fault.onset_s;
            // The tracker records a detection only at or after the onset.
            let detection = outcome.detection;
            let correct = match (run.spec.fault.target(), outcome.isolated_by_max) {
                (Some(FaultTarget::Output(j)), Some(named)) => named == j,
                _ => false,
            };
            Some(match objective {
                Objective::Pfa => (outcome.false_alarm.is_some(), f64::NAN, false),
                _ => (detection.is_some(), detection.map_or(f64::NAN, |(t, _)| t - onset), correct),
            })
        })
        .collect();
    let seen: Vec<(bool, f64, bool)> = seen.into_iter().flatten().collect();
    let proportion = |k: usize, n: usize| {
        let (lo, hi) = wilson(k as u64, n as u64, Z95);
        Judged { value: if n == 0 { f64::NAN } else { k as f64 / n as f64 }, lo, hi, units: n as u64 }
    };
    Ok(match objective {
        Objective::Pfa => proportion(seen.iter().filter(|s| s.0).count(), seen.len()),
        Objective::Pd => proportion(seen.iter().filter(|s| !s.0).count(), seen.len()),
        Objective::Isolation => {
            let detected: Vec<_> = seen.iter().filter(|s| s.0).collect();
            proportion(detected.iter().filter(|s| !s.2).count(), detected.len())
        }
        Objective::DelayP90 => {
            let mut delays: Vec<f64> = seen.iter().filter(|s| s.0).map(|s| s.1).collect();
            delays.sort_by(f64::total_cmp);
            let n = delays.len();
            if n == 0 {
                Judged { value: f64::NAN, lo: f64::NAN, hi: f64::NAN, units: 0 }
            } else {
                // The order statistics around rank 0.9 n that hold the 90th percentile with 95 %
                // (the binomial count below it, normal approximation).
                let at = |r: f64| delays[(r.round().max(0.0) as usize).min(n - 1)];
                let (mid, spread) = (0.9 * n as f64, Z95 * (n as f64 * 0.09).sqrt());
                Judged { value: at(mid - 0.5), lo: at(mid - spread - 1.0), hi: at(mid + spread), units: n as u64 }
            }
        }
    })
}

/// `fdimc worst-case` on `study`: searches, writes `worst_case.csv` (and, with `--write-deck`, the
/// deck at the found point), prints.
pub fn run(study: &LtiStudy, opts: &WorstCaseOptions) -> Result<(), RunError> {
    let path = study.header.path.display();
    if !study.fmus().is_empty() {
        return Err(RunError::Invalid(format!("{path}: worst-case searches linear decks (this one flies an FMU)")));
    }
    let names: Vec<&str> = study.detectors.iter().map(|d| d.name.as_str()).collect();
    let detector = select_detector(&study.header, &names, opts.detector.as_deref())?.unwrap_or(0);
    let objective = opts.search.objective;
    let has_faults = !study.monte_carlo.faults.is_empty() || !study.faults.is_empty();
    if !objective.fault_free() && !has_faults {
        return Err(RunError::Invalid(format!(
            "{path}: --objective {} needs faults; this deck flies none",
            objective.name()
        )));
    }
    let coordinates = coordinates(study, objective);
    if coordinates.is_empty() {
        return Err(RunError::Invalid(format!(
            "{path}: nothing to search for --objective {}: the deck draws no range or list of parameter errors, \
             noise scale{}",
            objective.name(),
            if objective.fault_free() { "" } else { ", fault size or onset" }
        )));
    }
    let judge = |point: &[Option<f64>], trials| judge(study, detector, objective, &coordinates, point, trials);
    let found = search(&coordinates, &judge, &opts.search)?;
    crate::engine::worst_case::write(&opts.out, &coordinates, &found, &opts.search)?;
    if let Some(file) = &opts.write_deck {
        write_deck(study, &opts.deck, file, &coordinates, &found.cmaes.point)?;
        if !opts.quiet {
            println!("wrote {} (the deck at the found point: fdimc simulate, run, report --trials)", file.display());
        }
    }
    if !opts.quiet {
        println!("detector {}", names[detector]);
        crate::engine::worst_case::print(&coordinates, &found, &opts.search);
    }
    Ok(())
}

/// `--write-deck FILE`: the deck `deck` with each searched factor fixed at `point`'s value (a size
/// coordinate sets every sized fault kind at its own value there) and the study renamed
/// `<name>_worst_case`; TOML as `toml` writes it (the deck's comments are not kept).
fn write_deck(
    study: &LtiStudy,
    deck: &std::path::Path,
    file: &std::path::Path,
    coordinates: &[Coordinate],
    point: &[f64],
) -> Result<(), RunError> {
    use toml::Value;
    let text = crate::engine::scenario::deck::read_deck(deck)?;
    let bad = |e: String| RunError::Invalid(format!("{}: {e}", deck.display()));
    let mut table: toml::Table = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let name = format!("{}_worst_case", study.header.name);
    if let Some(Value::Table(s)) = table.get_mut("study") {
        s.insert("name".into(), Value::String(name));
    }
    let Some(Value::Table(mc)) = table.get_mut("monte_carlo") else {
        return Err(bad("no [monte_carlo] section".into()));
    };
    for (c, u) in coordinates.iter().zip(point) {
        let value = (c.value_at)(*u);
        match c.name.as_str() {
            "onset_s" | "noise_scale" => {
                mc.insert(c.name.clone(), Value::Float(value));
            }
            name if name.starts_with("perr_") => {
                let Some(Value::Array(errors)) = mc.get_mut("parameter_error") else { continue };
                for e in errors.iter_mut().filter_map(Value::as_table_mut) {
                    if e.get("name").and_then(Value::as_str) == Some(&name["perr_".len()..]) {
                        let key = if e.contains_key("absolute") { "absolute" } else { "relative" };
                        e.insert(key.into(), Value::Float(value));
                    }
                }
            }
            _ => {
                // A size: each sized kind at its own value for this unit draw.
                let Some(Value::Array(kinds)) = mc.get_mut("fault") else { continue };
                for (k, spec) in kinds.iter_mut().filter_map(Value::as_table_mut).zip(&study.monte_carlo.faults) {
                    if let SizeSpec::Output(f) | SizeSpec::SensorSigma(f) = &spec.size
                        && f.is_sampled()
                    {
                        let key = if k.contains_key("size_sigma") { "size_sigma" } else { "size" };
                        k.insert(key.into(), Value::Float(value_at(f, *u)));
                    }
                }
            }
        }
    }
    let header = format!(
        "# Written by fdimc worst-case from {}: its searched factors fixed at the worst point found.\n\n",
        deck.display()
    );
    let body = toml::to_string(&table).map_err(|e| RunError::Internal(e.to_string()))?;
    crate::engine::run::runner::write_atomically(file, (header + &body).as_bytes())
}
