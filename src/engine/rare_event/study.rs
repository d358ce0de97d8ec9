//! `fdimc rare-event` around the estimators of [`crate::engine::rare_event::estimators`]: options, shards, the results
//! folder and `merge`.
//!
//! A run's units are importance sampling's chunks of trials and splitting's replicas; each unit's
//! totals at each level go to `rare_event_parts.parquet` (exact), the estimate follows from the units
//! merged in order, so a shard (`--shard I/N`: a contiguous run of chunks, or of replicas) writes its
//! units and `fdimc merge` of all shards gives the table of a whole run to the bit. Every shard reruns
//! importance sampling's pilot (the same trials, the same mixture); only shard 0 counts its cost.
//! `rare_event.json` records what the units came from, for `merge`'s checks.

use std::path::{Path, PathBuf};

use polars::prelude::*;
use serde::{Deserialize, Serialize};

use crate::engine::rare_event::estimators::{
    Combined, IMPORTANCE_CHUNK, Importance, RareEventModel, SplitOptions, Totals, default_tails, pilot_trials,
    splitting,
};
use crate::engine::run::runner::{RunError, Shard, pol, read_record, write_atomically};

/// Which unbiased estimator `fdimc rare-event` runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Estimator {
    Importance,
    Splitting,
}

impl Estimator {
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Importance => "importance",
            Estimator::Splitting => "splitting",
        }
    }

    /// The largest value one unit can take ([`Combined::new`]): a replica's estimate is a product of
    /// fractions; an importance trial's weight is at most one over the mixture's plain share.
    pub fn unit_max(self) -> f64 {
        match self {
            Estimator::Importance => 1.0 / crate::engine::rare_event::estimators::PLAIN_SHARE,
            Estimator::Splitting => 1.0,
        }
    }
}

/// `fdimc rare-event`'s options, checked by the command line.
#[derive(Debug, Clone)]
pub struct RareEventOptions {
    pub estimator: Estimator,
    /// The detector to study (`None`: every one of the deck).
    pub detector: Option<String>,
    /// Threshold scales, ascending, > 0 (the deck's thresholds times each).
    pub levels: Vec<f64>,
    /// Importance sampling: trials (the first fifth the pilot's).
    pub trials: u64,
    /// Splitting: particles per replica and replicas.
    pub particles: usize,
    pub replicas: u64,
    pub shard: Shard,
    pub out: PathBuf,
    pub quiet: bool,
    /// The deck, for the folder's record.
    pub deck: PathBuf,
    /// `--flight-s`: also fly fault-free flights this long and compare them with the segment
    /// conversion ([`crate::engine::rare_event::flights`]).
    pub flight: Option<FlightOptions>,
    /// `--miss-before-hazard`: the faulty trials' probability of no detection within their time to
    /// hazard, by splitting in time, instead of false alarms.
    pub miss_before_hazard: bool,
}

/// `--flight-s F` and `--flight-trials N`: flights of `seconds` (a whole number of the deck's trials),
/// `trials` of them for importance sampling (splitting keeps its particles and replicas).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlightOptions {
    pub seconds: f64,
    pub trials: u64,
}

/// The folder of the flights' own run, under the segments' folder.
pub const FLIGHTS_DIR: &str = "flights";

/// `rare_event.json`: what a folder's units came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RareEventManifest {
    pub deck: PathBuf,
    pub deck_sha256: String,
    pub seed: u64,
    pub estimator: Estimator,
    pub levels: Vec<f64>,
    pub trials: u64,
    pub particles: usize,
    pub replicas: u64,
    pub shard_index: u64,
    pub shard_count: u64,
    /// The detectors studied, in order.
    pub detectors: Vec<String>,
    pub steps_per_trial: usize,
    /// A trial's duration (s), for the per-hour figures.
    pub trial_s: f64,
}

impl RareEventManifest {
    pub fn read(dir: &Path) -> Result<Self, RunError> {
        read_record(&dir.join("rare_event.json"), "a rare-event folder", "rare-event record")
    }

    fn write(&self, dir: &Path) -> Result<(), RunError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| RunError::Internal(e.to_string()))?;
        std::fs::create_dir_all(dir).map_err(|e| RunError::Internal(format!("{}: {e}", dir.display())))?;
        write_atomically(&dir.join("rare_event.json"), text.as_bytes())
    }

    /// Whether `other` is another shard of the same run.
    fn same_run(&self, other: &Self) -> bool {
        let strip = |m: &Self| RareEventManifest { shard_index: 0, deck: PathBuf::new(), ..m.clone() };
        strip(self) == strip(other)
    }
}

/// One unit of a run: a chunk of importance trials (`unit` its chunk index) or a splitting replica,
/// its totals per level and the samples it simulated; `pilot`: importance sampling's pilot, whose
/// samples count in the cost and whose totals do not in the estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    pub detector: String,
    pub unit: u64,
    pub pilot: bool,
    pub totals: Vec<Totals>,
    pub steps: u64,
}

/// Runs this shard's units of `opts` on `model` (detector `name`) with the study's `seed`.
pub fn estimate_parts<M: RareEventModel>(model: &M, name: &str, seed: u64, opts: &RareEventOptions) -> Vec<Part> {
    let n = model.steps() as u64;
    let part = |unit, pilot, totals, steps| Part { detector: name.to_string(), unit, pilot, totals, steps };
    match opts.estimator {
        Estimator::Importance => {
            let pilot = pilot_trials(opts.trials);
            let (first, last) = (pilot / IMPORTANCE_CHUNK, opts.trials.div_ceil(IMPORTANCE_CHUNK));
            let (a, b) = opts.shard.range(last - first);
            let trials = ((first + a) * IMPORTANCE_CHUNK).max(pilot)..((first + b) * IMPORTANCE_CHUNK).min(opts.trials);
            let bar =
                crate::engine::run::progress::Progress::new(name, pilot + (trials.end - trials.start), !opts.quiet);
            let run = Importance { model, seed, levels: &opts.levels, progress: &|k| bar.inc(k) };
            let mix = run.pilot(opts.trials, &default_tails());
            let chunks = run.chunks(trials.clone(), &mix);
            bar.finish();
            if !opts.quiet {
                eprintln!("{name}: {}", mix.describe());
            }
            let mut parts = Vec::new();
            if opts.shard.index == 0 {
                parts.push(part(u64::MAX, true, vec![Totals::default(); opts.levels.len()], pilot * n));
            }
            for (ch, t) in chunks {
                let span = ((ch + 1) * IMPORTANCE_CHUNK).min(trials.end) - (ch * IMPORTANCE_CHUNK).max(trials.start);
                parts.push(part(ch, false, t.levels, span * n));
            }
            parts
        }
        Estimator::Splitting => {
            let (a, b) = opts.shard.range(opts.replicas);
            let split = SplitOptions {
                seed,
                particles: opts.particles,
                replicas: (a..b).collect(),
                levels: opts.levels.clone(),
                max_iterations: opts.particles * 200,
            };
            let bar = crate::engine::run::progress::Progress::new(&format!("{name} (replicas)"), b - a, !opts.quiet);
            let results = splitting(model, &split, &|| bar.inc(1));
            bar.finish();
            results
                .into_iter()
                .map(|r| {
                    let totals = r
                        .estimates
                        .iter()
                        .map(|e| {
                            let mut t = Totals::default();
                            if let Some(e) = e {
                                t.add(*e);
                            }
                            t
                        })
                        .collect();
                    part(r.replica, false, totals, r.steps_simulated)
                })
                .collect()
        }
    }
}

/// One row of `rare_event.csv`: one detector at one threshold scale.
#[derive(Debug, Clone, PartialEq)]
pub struct RareEventRow {
    pub detector: String,
    pub estimator: Estimator,
    pub estimate: Combined,
    /// The splitting's particles per replica (0 for importance sampling).
    pub particles: usize,
    /// Samples simulated for this detector, and per trial.
    pub steps_simulated: u64,
    pub steps_per_trial: usize,
    pub trial_s: f64,
}

/// The table from the units: per detector (the manifest's order) and level, the units merged in
/// unit order.
pub fn rows(m: &RareEventManifest, parts: &[Part]) -> Vec<RareEventRow> {
    let mut out = Vec::new();
    for d in &m.detectors {
        let mut mine: Vec<&Part> = parts.iter().filter(|p| &p.detector == d).collect();
        mine.sort_by_key(|p| p.unit);
        let steps = mine.iter().map(|p| p.steps).sum();
        for (l, &level) in m.levels.iter().enumerate() {
            let mut t = Totals::default();
            for p in mine.iter().filter(|p| !p.pilot) {
                t.merge(&p.totals[l]);
            }
            out.push(RareEventRow {
                detector: d.clone(),
                estimator: m.estimator,
                estimate: Combined::new(level, &t, m.estimator.unit_max()),
                particles: if m.estimator == Estimator::Splitting { m.particles } else { 0 },
                steps_simulated: steps,
                steps_per_trial: m.steps_per_trial,
                trial_s: m.trial_s,
            });
        }
    }
    out
}

const PARTS: &str = "rare_event_parts.parquet";

fn write_parts(dir: &Path, levels: usize, parts: &[Part]) -> Result<(), RunError> {
    let path = dir.join(PARTS);
    let each = |f: &dyn Fn(&Part, usize) -> f64| -> Vec<f64> {
        parts.iter().flat_map(|p| (0..levels).map(move |l| (p, l))).map(|(p, l)| f(p, l)).collect()
    };
    let eachu = |f: &dyn Fn(&Part, usize) -> u64| -> Vec<u64> {
        parts.iter().flat_map(|p| (0..levels).map(move |l| (p, l))).map(|(p, l)| f(p, l)).collect()
    };
    let names: Vec<&str> = parts.iter().flat_map(|p| std::iter::repeat_n(p.detector.as_str(), levels)).collect();
    let pilots: Vec<bool> = parts.iter().flat_map(|p| std::iter::repeat_n(p.pilot, levels)).collect();
    let mut df = DataFrame::new_infer_height(vec![
        Column::new(crate::engine::results::schema::col::DETECTOR.into(), names),
        Column::new("unit".into(), eachu(&|p, _| p.unit)),
        Column::new("pilot".into(), pilots),
        Column::new("level_index".into(), eachu(&|_, l| l as u64)),
        Column::new("units".into(), eachu(&|p, l| p.totals[l].units)),
        Column::new("sum".into(), each(&|p, l| p.totals[l].sum)),
        Column::new("sum_squares".into(), each(&|p, l| p.totals[l].sum_squares)),
        Column::new("hits".into(), eachu(&|p, l| p.totals[l].hits)),
        Column::new("largest".into(), each(&|p, l| p.totals[l].largest)),
        Column::new("steps".into(), eachu(&|p, _| p.steps)),
    ])
    .map_err(pol(&path))?;
    Ok(crate::engine::run::output::write_table(&mut df, &path)?)
}

fn read_parts(dir: &Path, levels: usize) -> Result<Vec<Part>, RunError> {
    use crate::engine::results::tables::{bool_col, f64_col, read_slice, str_col, u64_col};
    let path = dir.join(PARTS);
    let df = read_slice(&path, 0, usize::MAX, None)?;
    let (name, unit, pilot) =
        (str_col(&df, "detector", &path)?, u64_col(&df, "unit", &path)?, bool_col(&df, "pilot", &path)?);
    let (units, sum) = (u64_col(&df, "units", &path)?, f64_col(&df, "sum", &path)?);
    let (squares, hits, steps) =
        (f64_col(&df, "sum_squares", &path)?, u64_col(&df, "hits", &path)?, u64_col(&df, "steps", &path)?);
    let largest = f64_col(&df, "largest", &path)?;
    let bad = || RunError::Invalid(format!("{}: damaged (a null or a short unit)", path.display()));
    let mut parts = Vec::new();
    let mut i = 0;
    while i < df.height() {
        let mut totals = Vec::with_capacity(levels);
        for r in i..i + levels {
            totals.push(Totals {
                units: units.get(r).ok_or_else(bad)?,
                sum: sum.get(r).ok_or_else(bad)?,
                sum_squares: squares.get(r).ok_or_else(bad)?,
                hits: hits.get(r).ok_or_else(bad)?,
                largest: largest.get(r).ok_or_else(bad)?,
            });
        }
        parts.push(Part {
            detector: name.get(i).ok_or_else(bad)?.to_string(),
            unit: unit.get(i).ok_or_else(bad)?,
            pilot: pilot.get(i).ok_or_else(bad)?,
            totals,
            steps: steps.get(i).ok_or_else(bad)?,
        });
        i += levels;
    }
    Ok(parts)
}

/// Writes a run's (or a shard's) folder: its units and record; a whole run (or a merge) also the
/// table, printed, and returned (a shard's: empty).
pub fn write(dir: &Path, m: &RareEventManifest, parts: &[Part], quiet: bool) -> Result<Vec<RareEventRow>, RunError> {
    m.write(dir)?;
    write_parts(dir, m.levels.len(), parts)?;
    if m.shard_count > 1 {
        if !quiet {
            println!(
                "shard {}/{} of {} units written to {}; `fdimc merge` the {} shard folders for the table",
                m.shard_index,
                m.shard_count,
                parts.len(),
                dir.display(),
                m.shard_count
            );
        }
        return Ok(Vec::new());
    }
    let table = rows(m, parts);
    write_rows(dir, &table)?;
    print_rows(&table);
    Ok(table)
}

/// `fdimc merge` of rare-event shard folders: every shard of one run exactly once, into `out`.
pub fn merge(dirs: &[PathBuf], out: &Path) -> Result<(), RunError> {
    let mut shards = Vec::new();
    for d in dirs {
        shards.push((d, RareEventManifest::read(d)?));
    }
    shards.sort_by_key(|(_, m)| m.shard_index);
    let first = shards[0].1.clone();
    for (d, m) in &shards {
        if !m.same_run(&first) {
            return Err(RunError::Invalid(format!(
                "{}: from another rare-event run (deck, seed, estimator, levels, sizes or shard count differ from {})",
                d.display(),
                shards[0].0.display()
            )));
        }
    }
    let indices: Vec<u64> = shards.iter().map(|(_, m)| m.shard_index).collect();
    if indices != (0..first.shard_count).collect::<Vec<_>>() {
        return Err(RunError::Invalid(format!(
            "need shards 0..{} exactly once each, got {indices:?}",
            first.shard_count
        )));
    }
    let mut parts = Vec::new();
    for (d, m) in &shards {
        parts.extend(read_parts(d, m.levels.len())?);
    }
    let whole = RareEventManifest { shard_index: 0, shard_count: 1, ..first };
    write(out, &whole, &parts, false)?;
    println!("merged {} shards -> {}", shards.len(), out.join("rare_event.csv").display());
    Ok(())
}

/// Writes `rare_event.csv` to `dir`: per detector and threshold scale the estimate per trial and per
/// flight hour with 95 % intervals, its diagnostics, whether it is an answer, the cost in samples and
/// plain Monte Carlo's for the same interval (blank where it is not an answer).
fn write_rows(dir: &Path, rows: &[RareEventRow]) -> Result<(), RunError> {
    let path = dir.join("rare_event.csv");
    let hour = |r: &RareEventRow, p: f64| crate::engine::results::thresholds::per_flight_hour(p, r.trial_s);
    let f = |g: &dyn Fn(&RareEventRow) -> f64| rows.iter().map(g).collect::<Vec<f64>>();
    let mut df = DataFrame::new_infer_height(vec![
        Column::new(
            crate::engine::results::schema::col::DETECTOR.into(),
            rows.iter().map(|r| r.detector.as_str()).collect::<Vec<_>>(),
        ),
        Column::new("estimator".into(), rows.iter().map(|r| r.estimator.name()).collect::<Vec<_>>()),
        Column::new("threshold_scale".into(), f(&|r| r.estimate.level)),
        Column::new("answer".into(), rows.iter().map(|r| r.estimate.answer).collect::<Vec<_>>()),
        Column::new("pfa_per_trial".into(), f(&|r| r.estimate.estimate)),
        Column::new("pfa_per_trial_lo".into(), f(&|r| r.estimate.low)),
        Column::new("pfa_per_trial_hi".into(), f(&|r| r.estimate.high)),
        Column::new("relative_half_width".into(), f(&|r| r.estimate.relative_half_width)),
        Column::new("pfa_per_flight_hour".into(), f(&|r| hour(r, r.estimate.estimate))),
        Column::new("pfa_per_flight_hour_lo".into(), f(&|r| hour(r, r.estimate.low))),
        Column::new("pfa_per_flight_hour_hi".into(), f(&|r| hour(r, r.estimate.high))),
        Column::new("units".into(), rows.iter().map(|r| r.estimate.units).collect::<Vec<_>>()),
        Column::new("nonzero_units".into(), rows.iter().map(|r| r.estimate.hits).collect::<Vec<_>>()),
        Column::new("effective_units".into(), f(&|r| r.estimate.effective_units)),
        Column::new("largest_unit_share".into(), f(&|r| r.estimate.largest_share)),
        Column::new("particles".into(), rows.iter().map(|r| r.particles as u64).collect::<Vec<_>>()),
        Column::new("steps_simulated".into(), rows.iter().map(|r| r.steps_simulated).collect::<Vec<_>>()),
        Column::new(
            "plain_steps_same_precision".into(),
            f(&|r| r.estimate.plain_steps_same_precision(r.steps_per_trial)),
        ),
        Column::new("trial_s".into(), f(&|r| r.trial_s)),
    ])
    .map_err(pol(&path))?;
    Ok(crate::engine::run::output::write_table(&mut df, &path)?)
}

/// The rows as a table on stdout: an answer's estimate and interval; otherwise the interval (one-sided
/// with no hit) and why it is not an answer.
fn print_rows(rows: &[RareEventRow]) {
    println!(
        "{:<16} {:>6} {:>11} {:>25} {:>7} {:>11} {:>12} {:>10}",
        "detector", "scale", "Pfa/trial", "95 % interval", "+-rel", "Pfa/hour", "samples", "vs plain"
    );
    for r in rows {
        let e = &r.estimate;
        let plain = e.plain_steps_same_precision(r.steps_per_trial) / r.steps_simulated as f64;
        let cell = |v: f64, text: String| if v.is_finite() { text } else { "-".into() };
        println!(
            "{:<16} {:>6} {:>11} [{:>10.3e}, {:>10.3e}] {:>7} {:>11} {:>12} {:>10}",
            r.detector,
            e.level,
            if e.answer { format!("{:.3e}", e.estimate) } else { "no answer".into() },
            e.low,
            e.high,
            cell(e.relative_half_width, format!("{:.1}%", 100.0 * e.relative_half_width)),
            if e.answer {
                format!("{:.3e}", crate::engine::results::thresholds::per_flight_hour(e.estimate, r.trial_s))
            } else {
                "-".into()
            },
            r.steps_simulated,
            cell(plain, if plain < 1e6 { format!("{plain:.0}x") } else { format!("{plain:.1e}x") }),
        );
    }
    for r in rows.iter().filter(|r| !r.estimate.answer) {
        let e = &r.estimate;
        let other = match r.estimator {
            Estimator::Importance => "splitting, if the statistic has memory (a CUSUM, a window, a coloured residual)",
            Estimator::Splitting => "importance sampling, if one sample's noise makes an alarm (a white residual)",
        };
        let unit = if r.estimator == Estimator::Splitting { "replicas" } else { "trials" };
        let why = if e.hits == 0 {
            format!("no {unit} hit: Pfa per trial at most {:.2e} (one-sided 95 %)", e.high)
        } else if e.largest_share > crate::engine::rare_event::estimators::ANSWER_LARGEST_SHARE {
            format!(
                "one of the {} non-zero {unit} carries {:.0} % of the estimate (effective {unit} {:.1}): the interval cannot be trusted",
                e.hits,
                100.0 * e.largest_share,
                e.effective_units
            )
        } else {
            format!(
                "the interval is +-{:.0} % ({} of {} {unit} non-zero)",
                100.0 * e.relative_half_width,
                e.hits,
                e.units
            )
        };
        println!("not an answer: {} at {}: {why}; more trials, or {other}", r.detector, e.level);
    }
    println!(
        "(95 % intervals: Student's t over {}; an answer: +-{:.0} % at most, no unit over {:.0} % of the \
         estimate; per flight hour: independent trial-long segments; \"vs plain\": samples plain Monte Carlo \
         needs for the same interval, over those simulated)",
        match rows.first().map(|r| r.estimator) {
            Some(Estimator::Splitting) => "the splitting's independent replicas",
            _ => "the trials' weighted alarms",
        },
        100.0 * crate::engine::rare_event::estimators::ANSWER_RELATIVE_HALF_WIDTH,
        100.0 * crate::engine::rare_event::estimators::ANSWER_LARGEST_SHARE,
    );
}

/// `miss_before_hazard.csv` under a rare-event folder, and its record (the deck, its SHA-256, the seed
/// and the options).
pub use crate::engine::results::schema::rare_event_files::{MISS as MISS_FILE, MISS_RECORD};

/// Writes `miss_before_hazard.json`: what the table came from.
pub fn write_miss_record(dir: &Path, opts: &RareEventOptions, seed: u64) -> Result<(), RunError> {
    let record = serde_json::json!({
        "deck": opts.deck,
        "deck_sha256": crate::engine::run::runner::deck_sha256(&opts.deck)?,
        "seed": seed,
        "estimator": "splitting in time",
        "levels": opts.levels,
        "particles": opts.particles,
        "replicas": opts.replicas,
    });
    std::fs::create_dir_all(dir).map_err(|e| RunError::Internal(format!("{}: {e}", dir.display())))?;
    write_atomically(&dir.join(MISS_RECORD), record.to_string().as_bytes())
}

/// One row of `miss_before_hazard.csv`: one detector at one threshold scale.
#[derive(Debug, Clone, PartialEq)]
pub struct MissRow {
    pub detector: String,
    /// Over the replicas: each one splitting in time's product of surviving fractions.
    pub estimate: Combined,
    pub particles: usize,
    pub steps_simulated: u64,
    pub steps_per_trial: usize,
}

/// Writes `miss_before_hazard.csv` to `dir`.
pub fn write_miss(dir: &Path, rows: &[MissRow]) -> Result<(), RunError> {
    let path = dir.join(MISS_FILE);
    std::fs::create_dir_all(dir).map_err(|e| RunError::Internal(format!("{}: {e}", dir.display())))?;
    let f = |g: &dyn Fn(&MissRow) -> f64| rows.iter().map(g).collect::<Vec<f64>>();
    let mut df = DataFrame::new_infer_height(vec![
        Column::new(
            crate::engine::results::schema::col::DETECTOR.into(),
            rows.iter().map(|r| r.detector.as_str()).collect::<Vec<_>>(),
        ),
        Column::new("estimator".into(), vec!["splitting in time"; rows.len()]),
        Column::new("threshold_scale".into(), f(&|r| r.estimate.level)),
        Column::new("answer".into(), rows.iter().map(|r| r.estimate.answer).collect::<Vec<_>>()),
        Column::new("p_miss_before_hazard".into(), f(&|r| r.estimate.estimate)),
        Column::new("p_miss_before_hazard_lo".into(), f(&|r| r.estimate.low)),
        Column::new("p_miss_before_hazard_hi".into(), f(&|r| r.estimate.high)),
        Column::new("relative_half_width".into(), f(&|r| r.estimate.relative_half_width)),
        Column::new("replicas".into(), rows.iter().map(|r| r.estimate.units).collect::<Vec<_>>()),
        Column::new("nonzero_replicas".into(), rows.iter().map(|r| r.estimate.hits).collect::<Vec<_>>()),
        Column::new("largest_unit_share".into(), f(&|r| r.estimate.largest_share)),
        Column::new("particles".into(), rows.iter().map(|r| r.particles as u64).collect::<Vec<_>>()),
        Column::new("steps_simulated".into(), rows.iter().map(|r| r.steps_simulated).collect::<Vec<_>>()),
        Column::new(
            "plain_steps_same_precision".into(),
            f(&|r| r.estimate.plain_steps_same_precision(r.steps_per_trial)),
        ),
    ])
    .map_err(pol(&path))?;
    Ok(crate::engine::run::output::write_table(&mut df, &path)?)
}

/// The rows on stdout.
pub fn print_miss(rows: &[MissRow]) {
    use crate::engine::results::text::rate_interval;
    for r in rows {
        let e = &r.estimate;
        let plain = e.plain_steps_same_precision(r.steps_per_trial) / r.steps_simulated as f64;
        let verdict = if e.answer {
            format!("+-{:.0} %, {plain:.1}x fewer samples than plain trials", 100.0 * e.relative_half_width)
        } else if e.hits == 0 {
            format!("not an answer: no replica got a particle through (at most {:.2e}, one-sided 95 %)", e.high)
        } else {
            format!(
                "not an answer: +-{:.0} %, the largest replica {:.0} % of the estimate; more replicas or particles",
                100.0 * e.relative_half_width,
                100.0 * e.largest_share
            )
        };
        println!(
            "{} x{}: P(no detection within the time to hazard) {} over {} replicas of {} particles ({verdict})",
            r.detector,
            e.level,
            rate_interval(e.estimate, e.low, e.high),
            e.units,
            r.particles
        );
    }
}
