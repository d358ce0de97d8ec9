//! Rare false alarms of a run: per detector and threshold set, the generalised Pareto fit
//! ([`crate::engine::stats::tail`]) of its calibration units' largest pre-onset statistic measured against the set's
//! thresholds (`r = max_j pre_max_j / threshold_j`: the unit alarms at thresholds scaled by `s` when
//! `r > s`). From it: the false-alarm probability at the set's thresholds (`s = 1`), and for the
//! calibrated set the thresholds for the per-flight-hour targets of a safety assessment (or per trial,
//! without a trial duration) with 95 % intervals; the upper end of a threshold's interval is a threshold
//! whose Pfa is at most the target with 97.5 % confidence, if the fitted law holds (where the fitted
//! shape is negative, the upper ends trust no shape below 0: `TailFit::survival_interval_conservative`).
//!
//! Tables: `tail.csv` (the figures, a row per statistic's threshold; where the kind knows the residual's
//! exact law, `hour_over_conversion`: how many times an hour flown through alarms as often as the
//! row's per-hour conversion says, above 1.5 a lower bound) and `tail_diagnostics.csv` (the fit over a
//! range of thresholds: shape with its interval, modified scale, mean excess).

use std::path::Path;

use polars::prelude::*;
use rayon::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::thresholds::DECK;
use crate::engine::results::thresholds::{
    DetectorThresholds, HourConversion, TopValues, for_each_slice, per_flight_hour, per_segment,
};
use crate::engine::run::output::write_table;
use crate::engine::run::runner::{Manifest, RunError, pol};
use crate::engine::stats::intervals::{Z95, wilson};
use crate::engine::stats::tail::{Interval, Stability, TailFit, exceedances_for, stability, stability_ks};

/// The per-flight-hour targets every summary gives thresholds for (the major, hazardous and
/// catastrophic levels of ARP4761 / AC 25.1309); per trial when the trial's duration is not known.
pub const TARGETS: [f64; 3] = [1e-5, 1e-7, 1e-9];

/// The tail of one detector's calibration units against one threshold set.
#[derive(Debug, Clone)]
pub struct DetectorTail {
    pub detector: String,
    /// `deck` or the calibrated (validation) set.
    pub set: &'static str,
    /// The set's threshold per statistic.
    pub base: Vec<f64>,
    /// Calibration units, and those alarming at the set's thresholds.
    pub n: u64,
    pub observed: u64,
    pub unit_duration_s: Option<f64>,
    pub fit: Option<TailFit>,
    /// The fit's shape with its interval.
    pub xi: Option<Interval>,
    pub stability: Vec<Stability>,
    /// Why the fit should not be trusted (empty: no reason found), or why there is none.
    pub concerns: Vec<String>,
    /// Pfa at the set's thresholds from the fit (`None`: no fit, or the thresholds lie below the fit
    /// threshold, where the observed rate is the answer).
    pub at_set: Option<Interval>,
    /// For the calibrated set: the scale of its thresholds per target.
    pub targets: Vec<Target>,
    /// The exact law's verdict on the per-hour conversion at the set's thresholds, where the kind
    /// knows it (filled by the summary: [`crate::engine::method::Method::hour_laws`]).
    pub hour: Option<HourConversion>,
}

#[derive(Debug, Clone)]
pub struct Target {
    /// Per trial.
    pub pfa: f64,
    /// The per-flight-hour target it was converted from.
    pub per_hour: Option<f64>,
    /// The factor on the set's thresholds.
    pub scale: Interval,
    /// The exact law's verdict on the conversion at the thresholds for the target (as [`DetectorTail::hour`]).
    pub hour: Option<HourConversion>,
    /// Why these thresholds in particular should not be trusted (the exact law against the fit).
    pub doubt: Option<String>,
}

/// The fit's figure at its thresholds for a target is doubted where the exact law's upper bound on a
/// trial's Pfa there is more than this many times the target per trial (a choice: Sidak's bound can
/// exceed the probability where alarms cluster, so a small excess proves nothing).
pub const EXACT_OVER_FIT_DOUBT: f64 = 2.0;

impl Target {
    /// The doubt the exact law's verdict `hour` at the thresholds casts on the fit, if any.
    pub fn doubt_from(&self, hour: &HourConversion) -> Option<String> {
        (hour.trial_upper > EXACT_OVER_FIT_DOUBT * self.pfa).then(|| {
            format!(
                "the residual's exact law puts a trial's Pfa at these thresholds at up to {:.3e} (Sidak's bound), \
                 {} times the {:.3e} the fit gives them: the fit may be far too low (fdimc flight-thresholds \
                 finds thresholds on the exact law)",
                hour.trial_upper,
                crate::engine::results::text::significant(hour.trial_upper / self.pfa),
                self.pfa
            )
        })
    }
}

/// Fits every detector's tail against the deck's thresholds (where the deck gives one per statistic)
/// and against `thresholds`' whole-detector set (named `set`).
pub fn tails(
    path: &Path,
    manifest: &Manifest,
    statistics: &[String],
    thresholds: &[DetectorThresholds],
    set: &'static str,
) -> Result<Vec<DetectorTail>, RunError> {
    let usable = |v: &[f64]| v.len() == statistics.len() && v.iter().all(|t| t.is_finite() && *t > 0.0);
    let mut bases: Vec<(usize, &'static str, Vec<f64>)> = Vec::new();
    for (d, t) in thresholds.iter().enumerate() {
        if usable(&t.deck) {
            bases.push((d, DECK, t.deck.clone()));
        }
        if usable(&t.whole) {
            bases.push((d, set, t.whole.clone()));
        }
    }
    let kept = |d: usize| exceedances_for(thresholds[d].calibration_units).map_or(1, |k| 2 * k + 1);
    let mut top: Vec<TopValues> = bases.iter().map(|(d, _, _)| TopValues::new(kept(*d))).collect();
    let mut observed = vec![0u64; bases.len()];
    let on_fault_free = thresholds.first().is_some_and(|t| t.on_fault_free_trials);
    for_each_slice(path, manifest.rows, manifest, statistics, on_fault_free, |s| {
        for (i, d) in s.detector.iter().enumerate() {
            let Some(d) = *d else { continue };
            for (b, (_, _, base)) in bases.iter().enumerate().filter(|(_, (bd, _, _))| *bd == d) {
                let r = (0..base.len()).map(|j| s.pre[j][i] / base[j]).fold(0.0, f64::max);
                observed[b] += (r > 1.0) as u64;
                top[b].push(r);
            }
        }
    })?;
    let tails = bases
        .into_par_iter()
        .zip(top)
        .zip(observed)
        .map(|(((d, set_name, base), top), observed)| {
            let t = &thresholds[d];
            let values = top.values();
            tail_of(t, set_name, base, observed, &values, set_name != DECK)
        })
        .collect();
    Ok(tails)
}

fn tail_of(
    t: &DetectorThresholds,
    set: &'static str,
    base: Vec<f64>,
    observed: u64,
    values: &[f64],
    with_targets: bool,
) -> DetectorTail {
    let n = t.calibration_units;
    let mut tail = DetectorTail {
        detector: t.detector.clone(),
        set,
        base,
        n,
        observed,
        unit_duration_s: t.unit_duration_s,
        fit: None,
        xi: None,
        stability: Vec::new(),
        concerns: Vec::new(),
        at_set: None,
        targets: Vec::new(),
        hour: None,
    };
    let Some(k) = exceedances_for(n) else {
        tail.concerns.push(format!(
            "no fit: {n} calibration units (needs >= {})",
            10 * crate::engine::stats::tail::MIN_EXCEEDANCES
        ));
        return tail;
    };
    let non_finite = values.iter().filter(|v| !v.is_finite()).count();
    let Some(fit) = TailFit::fit(values, n, k) else {
        tail.concerns.push(format!(
            "no fit: fewer than {} distinct values above the threshold",
            crate::engine::stats::tail::MIN_EXCEEDANCES
        ));
        return tail;
    };
    // The profile likelihoods below are most of a summary's time: independent, they run side by side.
    let targets = || {
        let targets = if with_targets { &TARGETS[..] } else { &[] };
        targets
            .par_iter()
            .filter_map(|&target| {
                let (pfa, per_hour) = match t.unit_duration_s {
                    Some(d) => (per_segment(target, d), Some(target)),
                    None => (target, None),
                };
                (pfa < fit.zeta()).then(|| Target {
                    pfa,
                    per_hour,
                    scale: fit.quantile_interval_conservative(pfa),
                    hour: None,
                    doubt: None,
                })
            })
            .collect()
    };
    let at_set = || (1.0 > fit.u).then(|| fit.survival_interval_conservative(1.0));
    let ((stable, at_set), targets) =
        rayon::join(|| rayon::join(|| stability(values, n, &stability_ks(k, values.len())), at_set), targets);
    (tail.stability, tail.at_set, tail.targets) = (stable, at_set, targets);
    tail.concerns = fit.concerns(&tail.stability, values);
    tail.xi = Some(tail.stability.iter().find(|s| s.k == fit.k()).map_or_else(|| fit.xi_interval(), |s| s.xi));
    if non_finite > 0 {
        tail.concerns.push(format!("{non_finite} units' statistic is not finite: left out of the fit"));
    }
    let wide = tail.at_set.iter().any(|i| i.lo <= 0.0 || i.hi / i.lo > 100.0)
        || tail.targets.iter().any(|x| !x.scale.hi.is_finite());
    if wide {
        tail.concerns
            .push("an interval spans more than two decades or is unbounded: the data cannot pin the tail there".into());
    }
    tail.fit = Some(fit);
    tail
}

/// Writes `tail.csv` and `tail_diagnostics.csv` (module docs) into `dir`.
pub fn write_tail_tables(dir: &Path, tails: &[DetectorTail], statistics: &[String]) -> Result<(), RunError> {
    let path = dir.join("tail.csv");
    let mut c = TailColumns::default();
    for t in tails {
        let fitted = t.at_set.is_some();
        let (rate, (lo, hi)) = (t.observed as f64 / t.n.max(1) as f64, wilson(t.observed, t.n, Z95));
        let at = t.at_set.unwrap_or(Interval { estimate: rate, lo, hi });
        let one = Interval { estimate: 1.0, lo: 1.0, hi: 1.0 };
        let estimate = if fitted { "tail fit" } else { "observed" };
        c.push(t, statistics, "pfa_at_thresholds", None, at, one, estimate, t.hour, None);
        for x in &t.targets {
            c.push(
                t,
                statistics,
                "threshold_for_pfa",
                x.per_hour,
                Interval { estimate: x.pfa, lo: x.pfa, hi: x.pfa },
                x.scale,
                "tail fit",
                x.hour,
                x.doubt.as_deref(),
            );
        }
    }
    let mut df = c.frame().map_err(pol(&path))?;
    write_table(&mut df, &path)?;

    let path = dir.join("tail_diagnostics.csv");
    let mut rows: (Vec<&str>, Vec<&str>, Vec<u64>, Vec<f64>, Vec<f64>) = Default::default();
    let mut shape: [Vec<f64>; 6] = Default::default();
    let mut chosen = Vec::new();
    for t in tails {
        for s in &t.stability {
            rows.0.push(&t.detector);
            rows.1.push(t.set);
            rows.2.push(s.k as u64);
            rows.3.push(s.u);
            rows.4.push(1.0 - s.k as f64 / t.n as f64);
            for (v, x) in
                shape.iter_mut().zip([s.xi.estimate, s.xi.lo, s.xi.hi, s.sigma, s.modified_scale, s.mean_excess])
            {
                v.push(x);
            }
            chosen.push(t.fit.as_ref().is_some_and(|f| f.k() == s.k));
        }
    }
    let [xi, xi_lo, xi_hi, sigma, modified, mean_excess] = shape;
    let mut df = DataFrame::new_infer_height(vec![
        Column::new(col::DETECTOR.into(), rows.0),
        Column::new("thresholds".into(), rows.1),
        Column::new("exceedances".into(), rows.2),
        Column::new("fit_threshold_scale".into(), rows.3),
        Column::new("fit_threshold_quantile".into(), rows.4),
        Column::new("xi".into(), xi),
        Column::new("xi_lo".into(), xi_lo),
        Column::new("xi_hi".into(), xi_hi),
        Column::new("sigma".into(), sigma),
        Column::new("modified_scale".into(), modified),
        Column::new("mean_excess".into(), mean_excess),
        Column::new("chosen".into(), chosen),
    ])
    .map_err(pol(&path))?;
    Ok(write_table(&mut df, &path)?)
}

/// `tail.csv`'s columns, a row per (detector, set, query, statistic).
#[derive(Default)]
struct TailColumns {
    text: [Vec<String>; 5],
    target_per_hour: Vec<Option<f64>>,
    pfa: [Vec<f64>; 3],
    per_hour: [Vec<Option<f64>>; 3],
    threshold: [Vec<f64>; 3],
    scale: [Vec<f64>; 3],
    counts: [Vec<u64>; 3],
    fit: [Vec<Option<f64>>; 4],
    trust: Vec<String>,
    hour_over_conversion: Vec<Option<f64>>,
}

impl TailColumns {
    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        t: &DetectorTail,
        statistics: &[String],
        query: &str,
        target_per_hour: Option<f64>,
        pfa: Interval,
        scale: Interval,
        estimate: &str,
        hour: Option<HourConversion>,
        doubt: Option<&str>,
    ) {
        let xi = t.xi;
        for (j, s) in statistics.iter().enumerate() {
            for (v, x) in self.text.iter_mut().zip([&t.detector, t.set, query, s, estimate]) {
                v.push(x.to_string());
            }
            self.target_per_hour.push(target_per_hour);
            for (v, x) in self.pfa.iter_mut().zip([pfa.estimate, pfa.lo, pfa.hi]) {
                v.push(x);
            }
            for (v, x) in self.per_hour.iter_mut().zip([pfa.estimate, pfa.lo, pfa.hi]) {
                v.push(t.unit_duration_s.map(|d| per_flight_hour(x, d)));
            }
            for (v, x) in self.threshold.iter_mut().zip([scale.estimate, scale.lo, scale.hi]) {
                v.push(t.base[j] * x);
            }
            for (v, x) in self.scale.iter_mut().zip([scale.estimate, scale.lo, scale.hi]) {
                v.push(x);
            }
            for (v, x) in self.counts.iter_mut().zip([t.observed, t.n, t.fit.as_ref().map_or(0, |f| f.k() as u64)]) {
                v.push(x);
            }
            let f = [t.fit.as_ref().map(|f| f.u), xi.map(|i| i.estimate), xi.map(|i| i.lo), xi.map(|i| i.hi)];
            for (v, x) in self.fit.iter_mut().zip(f) {
                v.push(x);
            }
            let concerns: Vec<&str> = t.concerns.iter().map(String::as_str).chain(doubt).collect();
            self.trust.push(if concerns.is_empty() { "ok".into() } else { concerns.join("; ") });
            self.hour_over_conversion.push(hour.map(|h| h.ratio));
        }
    }

    fn frame(self) -> PolarsResult<DataFrame> {
        let [detector, set, query, statistic, estimate] = self.text;
        let [pfa, pfa_lo, pfa_hi] = self.pfa;
        let [h, h_lo, h_hi] = self.per_hour;
        let [thr, thr_lo, thr_hi] = self.threshold;
        let [s, s_lo, s_hi] = self.scale;
        let [observed, trials, exceedances] = self.counts;
        let [u, xi, xi_lo, xi_hi] = self.fit;
        DataFrame::new_infer_height(vec![
            Column::new(col::DETECTOR.into(), detector),
            Column::new("thresholds".into(), set),
            Column::new("query".into(), query),
            Column::new("statistic".into(), statistic),
            Column::new("target_pfa_per_hour".into(), self.target_per_hour),
            Column::new("pfa".into(), pfa),
            Column::new("pfa_lo".into(), pfa_lo),
            Column::new("pfa_hi".into(), pfa_hi),
            Column::new("pfa_per_hour".into(), h),
            Column::new("pfa_per_hour_lo".into(), h_lo),
            Column::new("pfa_per_hour_hi".into(), h_hi),
            Column::new("threshold".into(), thr),
            Column::new("threshold_lo".into(), thr_lo),
            Column::new("threshold_hi".into(), thr_hi),
            Column::new("scale".into(), s),
            Column::new("scale_lo".into(), s_lo),
            Column::new("scale_hi".into(), s_hi),
            Column::new("estimate".into(), estimate),
            Column::new("observed_false_alarms".into(), observed),
            Column::new("trials".into(), trials),
            Column::new("exceedances".into(), exceedances),
            Column::new("fit_threshold_scale".into(), u),
            Column::new("xi".into(), xi),
            Column::new("xi_lo".into(), xi_lo),
            Column::new("xi_hi".into(), xi_hi),
            Column::new("trust".into(), self.trust),
            Column::new("hour_over_conversion".into(), self.hour_over_conversion),
        ])
    }
}

/// The lines `summarize` prints for the tails: per detector and set, the fit and its figures.
pub fn print_tails(tails: &[DetectorTail]) {
    if tails.is_empty() {
        return;
    }
    println!("  rare false alarms (generalised Pareto fit of the calibration units' largest statistic; tail.csv):");
    let g = |x: f64| format!("{x:.2e}");
    for t in tails {
        let head = format!("    {} vs {} thresholds:", t.detector, t.set);
        let Some(fit) = &t.fit else {
            println!("{head} {}/{} alarm; {}", t.observed, t.n, t.concerns.join("; "));
            continue;
        };
        let per_hour = |i: Interval| {
            t.unit_duration_s.map_or(String::new(), |d| {
                let h = |p| g(per_flight_hour(p, d));
                format!(", {} [{}, {}] per flight hour", h(i.estimate), h(i.lo), h(i.hi))
            })
        };
        let at = t.at_set.map_or_else(
            || format!("observed {}/{} (the thresholds lie inside the data)", t.observed, t.n),
            |i| {
                format!(
                    "Pfa {} [{}, {}] per trial{} (observed {}/{})",
                    g(i.estimate),
                    g(i.lo),
                    g(i.hi),
                    per_hour(i),
                    t.observed,
                    t.n
                )
            },
        );
        let shape = t.xi.map_or(format!("{:.3}", fit.xi), |i| format!("{:.3} [{:.3}, {:.3}]", i.estimate, i.lo, i.hi));
        println!("{head} fit on the {} largest of {}, shape {shape}; {at}", fit.k(), t.n);
        for x in &t.targets {
            let asked = x.per_hour.map_or(format!("{} per trial", g(x.pfa)), |h| format!("{} per flight hour", g(h)));
            println!(
                "      for {asked}: thresholds x {:.3} [{:.3}, {}]",
                x.scale.estimate,
                x.scale.lo,
                if x.scale.hi.is_finite() { format!("{:.3}", x.scale.hi) } else { "unbounded".into() }
            );
        }
        for c in &t.concerns {
            println!("      do not trust: {c}");
        }
    }
}
