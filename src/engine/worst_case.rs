//! `fdimc worst-case`: the point of a deck's uncertainty box (its parameter errors, noise scale, fault
//! size and onset, each within the deck's range or list) where a detector does worst, by CMA-ES
//! (Hansen 2016, the `cmaes` crate: a derivative-free search for noisy, non-separable objectives that
//! needs no step size per coordinate), against random points of the same budget.
//!
//! A candidate is a point `u` of the unit box, one coordinate per factor the deck varies (the factor's
//! own unit draw: a range maps linearly, a list picks by it, exactly as the deck's trials map theirs;
//! [`crate::engine::scenario::deck::SearchPoint`]). It is judged on one batch of trials, the same
//! trials for every candidate (common random numbers: the same noise, fault kinds and components), so
//! candidates differ only in the point. The search runs in `R^d` and clamps to the box, so a vertex is
//! reachable. The best point of each search is then judged again on a fresh batch (trials no search
//! saw), with its 95 % interval, beside the deck as drawn on that batch.

use std::ops::Range;
use std::path::Path;

use polars::prelude::*;
use rand::{RngExt, SeedableRng};

use crate::engine::run::runner::{RunError, pol};

/// What makes a detector worse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Objective {
    /// Missed faults: 1 - Pd over faulty trials (deck thresholds).
    Pd,
    /// False alarms over fault-free trials.
    Pfa,
    /// The 90th percentile of the detection delay (s) over detected faults.
    DelayP90,
    /// Wrong isolation: 1 - the share of detected faults isolated to their true channel.
    Isolation,
}

impl Objective {
    pub fn parse(text: &str) -> Option<Objective> {
        match text {
            "pd" => Some(Objective::Pd),
            "pfa" => Some(Objective::Pfa),
            "delay_p90" => Some(Objective::DelayP90),
            "isolation" => Some(Objective::Isolation),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Objective::Pd => "pd",
            Objective::Pfa => "pfa",
            Objective::DelayP90 => "delay_p90",
            Objective::Isolation => "isolation",
        }
    }

    /// The quantity the search makes largest, in words.
    pub fn worse(self) -> &'static str {
        match self {
            Objective::Pd => "missed faults (1 - Pd)",
            Objective::Pfa => "false alarms (Pfa)",
            Objective::DelayP90 => "the 90th percentile of the detection delay (s)",
            Objective::Isolation => "wrong isolations (1 - the share isolated correctly)",
        }
    }

    /// Whether its trials are fault-free.
    pub fn fault_free(self) -> bool {
        self == Objective::Pfa
    }
}

/// A factor the search moves: the unit draw of dimension `dim`, and its value there.
pub struct Coordinate {
    pub name: String,
    pub dim: usize,
    pub lower: f64,
    pub upper: f64,
    /// The factor's value at a unit draw (as the deck's trials map theirs).
    pub value_at: Box<dyn Fn(f64) -> f64 + Sync>,
}

/// One judgement: the objective's value (larger is worse) with its 95 % interval, over `units`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Judged {
    pub value: f64,
    pub lo: f64,
    pub hi: f64,
    pub units: u64,
}

/// Judges a point (`None` per coordinate: drawn as the deck draws it) on a range of trials.
pub type Judge<'a> = dyn Fn(&[Option<f64>], Range<u64>) -> Result<Judged, RunError> + Sync + 'a;

/// `fdimc worst-case`'s options, checked by the command line.
#[derive(Debug, Clone)]
pub struct WorstCaseOptions {
    pub search: SearchOptions,
    /// The detector judged (`None`: the deck's first).
    pub detector: Option<String>,
    pub out: std::path::PathBuf,
    /// `--write-deck FILE`: the deck with the found point fixed.
    pub write_deck: Option<std::path::PathBuf>,
    pub deck: std::path::PathBuf,
    pub quiet: bool,
}

#[derive(Debug, Clone)]
pub struct SearchOptions {
    pub objective: Objective,
    /// Trials spent by each search (the candidates' batches together).
    pub budget: u64,
    /// Trials per candidate.
    pub batch: u64,
    /// Fresh trials for each confirmation.
    pub confirm: u64,
    pub seed: u64,
}

/// A search's result: its best point (unit coordinates), its value on the search batch, and on the
/// fresh batch; the candidates judged.
#[derive(Debug, Clone)]
pub struct Found {
    pub search: &'static str,
    pub point: Vec<f64>,
    pub on_search: Judged,
    pub confirmed: Judged,
    pub candidates: u64,
}

/// The two searches and the deck as drawn, all confirmed on one fresh batch.
#[derive(Debug, Clone)]
pub struct WorstCase {
    pub cmaes: Found,
    pub random: Found,
    pub as_drawn: Judged,
}

/// Runs CMA-ES and the random search of the same budget over `coordinates`, then confirms both.
pub fn search(coordinates: &[Coordinate], judge: &Judge, opts: &SearchOptions) -> Result<WorstCase, RunError> {
    let d = coordinates.len();
    let candidates = (opts.budget / opts.batch).max(2);
    let batch = 0..opts.batch;
    let units = |x: &[f64]| -> Vec<Option<f64>> { x.iter().map(|v| Some(v.clamp(0.0, 1.0))).collect() };
    let failure = std::sync::Mutex::new(None::<RunError>);
    let evaluate = |x: &[f64]| -> f64 {
        match judge(&units(x), batch.clone()) {
            Ok(j) => j.value,
            Err(e) => {
                failure.lock().expect("not poisoned").get_or_insert(e);
                f64::NAN
            }
        }
    };
    // CMA-ES minimises: the negated objective. One coordinate is searched as two (the second unused):
    // the crate's covariance update needs two dimensions.
    let dims = d.max(2);
    let mut best = (f64::NEG_INFINITY, vec![0.5; d], 0u64);
    {
        let mut judged = 0u64;
        let objective = |x: &cmaes::DVector<f64>| -> f64 {
            judged += 1;
            let v = evaluate(&x.as_slice()[..d]);
            if v > best.0 {
                best = (v, x.as_slice()[..d].to_vec(), judged);
            }
            if v.is_nan() { f64::INFINITY } else { -v }
        };
        let mut cma = cmaes::CMAESOptions::new(vec![0.5; dims], 0.3)
            .max_function_evals(candidates as usize)
            .seed(opts.seed)
            .build(objective)
            .map_err(|e| RunError::Internal(format!("CMA-ES options: {e:?}")))?;
        cma.run();
    }
    if let Some(e) = failure.lock().expect("not poisoned").take() {
        return Err(e);
    }
    let fresh = opts.batch..opts.batch + opts.confirm;
    let confirm = |point: &[f64]| judge(&units(point), fresh.clone());
    let cma_point: Vec<f64> = best.1.iter().map(|v| v.clamp(0.0, 1.0)).collect();
    let cma_found = Found {
        search: "cmaes",
        on_search: judge(&units(&cma_point), batch.clone())?,
        confirmed: confirm(&cma_point)?,
        point: cma_point,
        candidates,
    };
    // Random points of the same budget, on the same batch.
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(opts.seed ^ 0x7261_6e64_6f6d);
    let mut random_best: Option<(Judged, Vec<f64>)> = None;
    for _ in 0..candidates {
        let point: Vec<f64> = (0..d).map(|_| rng.random::<f64>()).collect();
        let j = judge(&units(&point), batch.clone())?;
        if random_best.as_ref().is_none_or(|(b, _)| j.value > b.value) {
            random_best = Some((j, point));
        }
    }
    let (on_search, point) = random_best.expect("at least two candidates");
    let random = Found { search: "random", confirmed: confirm(&point)?, on_search, point, candidates };
    let as_drawn = judge(&vec![None; d], fresh)?;
    Ok(WorstCase { cmaes: cma_found, random, as_drawn })
}

/// Whether a unit coordinate sits on a bound of its box.
fn at_bound(u: f64) -> &'static str {
    if u <= 1e-6 {
        "lower"
    } else if u >= 1.0 - 1e-6 {
        "upper"
    } else {
        ""
    }
}

/// Writes `worst_case.csv` to `dir`: per search (cmaes, random, and the deck as drawn) and coordinate,
/// the point against its bounds, and the objective on the search batch and confirmed on the fresh one.
pub fn write(dir: &Path, coordinates: &[Coordinate], w: &WorstCase, opts: &SearchOptions) -> Result<(), RunError> {
    let path = dir.join("worst_case.csv");
    std::fs::create_dir_all(dir).map_err(|e| RunError::Internal(format!("{}: {e}", dir.display())))?;
    let mut rows: Vec<(&str, &Coordinate, Option<f64>, Option<Judged>, Judged, u64)> = Vec::new();
    for f in [&w.cmaes, &w.random] {
        for (c, u) in coordinates.iter().zip(&f.point) {
            rows.push((f.search, c, Some(*u), Some(f.on_search), f.confirmed, f.candidates));
        }
    }
    for c in coordinates {
        rows.push(("as_drawn", c, None, None, w.as_drawn, 0));
    }
    let f = |g: &dyn Fn(&(&str, &Coordinate, Option<f64>, Option<Judged>, Judged, u64)) -> f64| {
        rows.iter().map(g).collect::<Vec<f64>>()
    };
    let nan = f64::NAN;
    let mut df = DataFrame::new_infer_height(vec![
        Column::new("search".into(), rows.iter().map(|r| r.0).collect::<Vec<_>>()),
        Column::new("coordinate".into(), rows.iter().map(|r| r.1.name.as_str()).collect::<Vec<_>>()),
        Column::new("lower".into(), f(&|r| r.1.lower)),
        Column::new("upper".into(), f(&|r| r.1.upper)),
        Column::new("value".into(), f(&|r| r.2.map_or(nan, |u| (r.1.value_at)(u)))),
        Column::new("position".into(), f(&|r| r.2.unwrap_or(nan))),
        Column::new("at_bound".into(), rows.iter().map(|r| r.2.map_or("", at_bound)).collect::<Vec<_>>()),
        Column::new("objective".into(), vec![opts.objective.name(); rows.len()]),
        Column::new("on_search_batch".into(), f(&|r| r.3.map_or(nan, |j| j.value))),
        Column::new("confirmed".into(), f(&|r| r.4.value)),
        Column::new("confirmed_lo".into(), f(&|r| r.4.lo)),
        Column::new("confirmed_hi".into(), f(&|r| r.4.hi)),
        Column::new("confirm_units".into(), rows.iter().map(|r| r.4.units).collect::<Vec<_>>()),
        Column::new("candidates".into(), rows.iter().map(|r| r.5).collect::<Vec<_>>()),
        Column::new("batch_trials".into(), vec![opts.batch; rows.len()]),
        Column::new("budget_trials".into(), rows.iter().map(|r| r.5 * opts.batch).collect::<Vec<_>>()),
    ])
    .map_err(pol(&path))?;
    Ok(crate::engine::run::output::write_table(&mut df, &path)?)
}

/// The result on stdout.
pub fn print(coordinates: &[Coordinate], w: &WorstCase, opts: &SearchOptions) {
    use crate::engine::results::text::significant;
    println!("worst case of {} over {} coordinates:", opts.objective.worse(), coordinates.len());
    for f in [&w.cmaes, &w.random] {
        let point: Vec<String> = coordinates
            .iter()
            .zip(&f.point)
            .map(|(c, u)| {
                let bound = at_bound(*u);
                let at = if bound.is_empty() { String::new() } else { format!(" ({bound} bound)") };
                format!("{} {}{at}", c.name, significant((c.value_at)(*u)))
            })
            .collect();
        println!(
            "  {:<7} {}: {} on its batch; confirmed on {} fresh units {} [{}, {}] ({} candidates of {} trials)",
            f.search,
            point.join(", "),
            significant(f.on_search.value),
            f.confirmed.units,
            significant(f.confirmed.value),
            significant(f.confirmed.lo),
            significant(f.confirmed.hi),
            f.candidates,
            opts.batch
        );
    }
    let a = &w.as_drawn;
    println!(
        "  the deck as drawn, on the same fresh units: {} [{}, {}]",
        significant(a.value),
        significant(a.lo),
        significant(a.hi)
    );
    let worse = w.cmaes.confirmed.lo > a.hi;
    println!(
        "  {}",
        if worse {
            "the found point is significantly worse than the deck as drawn (the intervals do not overlap)"
        } else {
            "no point found significantly worse than the deck as drawn (the intervals overlap)"
        }
    );
}
