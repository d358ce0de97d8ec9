//! `safety.csv`: the two figures a safety case quotes, per detector at the thresholds in use, each with
//! its 95 % interval, the method that gave it and the assumptions it rests on, in words: the
//! false-alarm rate per flight hour (plain Monte Carlo over the fault-free flights, and the tail fit
//! where it gives one) and, with the deck's `time_to_hazard_s`, the probability that a fault is not
//! detected before it becomes hazardous.

use std::path::Path;

use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::tables::{Table, read_summary};
use crate::engine::results::tails::DetectorTail;
use crate::engine::results::text::{apart, significant};
use crate::engine::results::thresholds::{DECK, HourConversion, UNDERCOUNT_FLAG, per_flight_hour};
use crate::engine::run::runner::RunError;
use crate::engine::stats::intervals::{Z_ONE_SIDED_95, wilson};

pub const SAFETY_FILE: &str = "safety.csv";

/// What the figures rest on that the tables do not say: the flights' length and the sensor noise's law.
pub struct Setting<'a> {
    /// The flights' length (s): the hour's segments; `None`: figures per flight.
    pub flight_s: Option<f64>,
    /// The sensor noise as the run drew it, in words.
    pub noise: &'a str,
    /// `fdimc rare-event`'s tables in the run's folder, for the same deck.
    pub rare_event: Option<RareEventTables>,
    /// Per (detector, threshold set): the exact law's verdict on the segment conversion, where the
    /// kind knows the law for the run's deck.
    pub conversions: &'a [(String, &'static str, HourConversion)],
    /// The deck's SHA-256 and the fdimc that flew it, which each statement names.
    pub deck_sha256: &'a str,
    pub fdimc_version: &'a str,
    /// The recorded profiles' grid step (`monte_carlo.profile_resolution`; 0: every rise; `None`: a run
    /// written before the grid): how late an alarm replayed at other thresholds may be.
    pub profile_resolution: Option<f64>,
    /// The profiles keep the running maximum exactly at the time to hazard (the manifest's
    /// `profiles_exact_at_deadlines`): the replay is then exact whatever the grid.
    pub profiles_exact_at_deadlines: bool,
}

/// What a false-alarm figure does not cover, said in its statement.
const FALSE_ALARMS_LEAVE_OUT: &str = "model error beyond the deck's parameter errors, turbulence, coloured or \
     correlated noise and any sensor law the deck does not draw, faults, other flight lengths or starts";
/// What a missed-detection figure does not cover.
const MISSES_LEAVE_OUT: &str = "fault kinds, sizes and onsets outside the deck's populations, model error beyond \
     its parameter errors, noise the deck does not draw";

/// `rare_event/rare_event.csv` and, with `--flight-s`, `rare_event/per_hour.csv`; with
/// `--miss-before-hazard`, `rare_event/miss_before_hazard.csv`.
pub struct RareEventTables {
    pub rows: Option<DataFrame>,
    pub per_hour: Option<DataFrame>,
    pub miss: Option<DataFrame>,
}

/// The rare-event folder `dir/rare_event/`'s tables of the deck whose SHA-256 is `deck_sha256` (a
/// shard's folder has no table; another deck's figures would not be this run's): the false-alarm run's
/// (`rare_event.json` its record) and the miss-before-hazard run's (`miss_before_hazard.json`).
pub fn read_rare_event(dir: &Path, deck_sha256: &str) -> Result<Option<RareEventTables>, RunError> {
    use crate::engine::results::schema::rare_event_files::{MISS, MISS_RECORD, PER_HOUR, RECORD, TABLE};
    let folder = dir.join("rare_event");
    let of_this_deck = |record: &Path| -> Result<bool, RunError> {
        if !record.exists() {
            return Ok(false);
        }
        let bad = |e: String| RunError::Invalid(format!("{}: {e}", record.display()));
        let text = std::fs::read_to_string(record).map_err(|e| bad(e.to_string()))?;
        let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
        Ok(json["deck_sha256"].as_str() == Some(deck_sha256))
    };
    let (alarms, misses) = (of_this_deck(&folder.join(RECORD))?, of_this_deck(&folder.join(MISS_RECORD))?);
    if !alarms && !misses {
        return Ok(None);
    }
    let read = |name: &str, wanted: bool| {
        let p = folder.join(name);
        if wanted && p.exists() { read_summary(&p).map(Some) } else { Ok(None) }
    };
    Ok(Some(RareEventTables {
        rows: read(TABLE, alarms)?,
        per_hour: read(PER_HOUR, alarms)?,
        miss: read(MISS, misses)?,
    }))
}

/// What a false-alarm row rests on: the hour's segments converted (each begun afresh), or whole flights
/// as long as the hour (or longer than a segment, flown through).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Basis {
    Conversion,
    WholeFlight,
    /// A missed-detection row: no conversion.
    Other,
}

#[derive(Default)]
struct Rows {
    /// `deck sha256 ..., fdimc ...`, the end of every statement.
    stamp: String,
    /// (detector, threshold set, the thresholds' values in words) of the rows to come.
    thresholds: Vec<(String, String, String)>,
    upper: Vec<f64>,
    basis: Vec<Basis>,
    role: Vec<Option<String>>,
    detector: Vec<String>,
    set: Vec<String>,
    figure: Vec<String>,
    value: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    method: Vec<String>,
    assumptions: Vec<String>,
    statement: Vec<String>,
}

impl Rows {
    /// A figure `v` (estimate, 95 % interval) with its one-sided 95 % upper bound where the method
    /// gives one (`None`: the interval's upper end, a 97.5 % one-sided bound).
    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        basis: Basis,
        detector: &str,
        set: &str,
        figure: &str,
        v: [f64; 3],
        upper: Option<f64>,
        method: String,
        assumptions: String,
    ) {
        let shown = apart(&[v[0], v[1], v[2], upper.unwrap_or(v[2])]);
        let bound = match upper {
            Some(_) => format!("one-sided 95 % upper bound {}", shown[3]),
            None => format!("upper bound {} (the interval's end: 97.5 % one-sided)", shown[3]),
        };
        let values = (self.thresholds.iter())
            .find(|(d, s, _)| d == detector && s == set)
            .map_or(String::new(), |(_, _, v)| format!(" ({v})"));
        let leave_out = if basis == Basis::Other { MISSES_LEAVE_OUT } else { FALSE_ALARMS_LEAVE_OUT };
        let statement = format!(
            "{detector} at the {set} thresholds{values}: {figure} {} (95 % interval [{}, {}]; {bound}), by {method}; \
             assuming {assumptions}; not covered: {leave_out}; {}",
            shown[0], shown[1], shown[2], self.stamp
        );
        self.upper.push(upper.unwrap_or(v[2]));
        self.basis.push(basis);
        self.role.push(None);
        self.detector.push(detector.into());
        self.set.push(set.into());
        self.figure.push(figure.into());
        self.value.push(v[0]);
        self.lo.push(v[1]);
        self.hi.push(v[2]);
        self.method.push(method);
        self.assumptions.push(assumptions);
        self.statement.push(statement);
    }

    /// Where the exact law gives `detector`'s conversion at the `set` thresholds: its converted rows
    /// there are a lower bound when the law's ratio exceeds [`UNDERCOUNT_FLAG`], else consistent with
    /// a whole flight; the statements say so.
    fn mark_by_law(&mut self, detector: &str, set: &str, h: &HourConversion, segment_s: f64) {
        for i in 0..self.detector.len() {
            if self.detector[i] != detector || self.set[i] != set || self.basis[i] != Basis::Conversion {
                continue;
            }
            self.role[i] = Some(if h.undercounts() {
                format!(
                    "a lower bound: the segment conversion under-counts here (by the residual's exact law, extremal \
                     index {} against it over an hour flown through: a mode of time constant {} s against {} s \
                     trials); estimate whole flights with fdimc rare-event DECK --flight-s 3600",
                    significant(h.ratio),
                    significant(h.slowest_time_constant_s),
                    significant(segment_s)
                )
            } else {
                format!(
                    "consistent with an hour flown through (by the residual's exact law, extremal index {})",
                    significant(h.ratio)
                )
            });
        }
    }

    /// Where `detector` has a whole-flight figure (at the deck's thresholds) and its extremal index
    /// `theta` against the segment conversion: the whole-flight rows are the figure, the converted ones
    /// at the deck's thresholds a lower bound when `theta` exceeds [`UNDERCOUNT_FLAG`] (else consistent
    /// with it), unless the exact law has judged them (an estimate does not overrule it; the index
    /// moves with the thresholds, so other sets are left alone); the statements say so.
    fn mark(&mut self, detector: &str, theta: f64) {
        for i in 0..self.detector.len() {
            if self.detector[i] != detector
                || (self.basis[i] == Basis::Conversion && (self.set[i] != DECK || self.role[i].is_some()))
            {
                continue;
            }
            let role = match self.basis[i] {
                Basis::WholeFlight => "the figure to quote (flights flown through, not restarted segments)".to_string(),
                Basis::Conversion if theta > UNDERCOUNT_FLAG => format!(
                    "a lower bound: the segment conversion under-counts here (extremal index {} > {UNDERCOUNT_FLAG}); \
                     quote the whole-flight figure",
                    significant(theta)
                ),
                Basis::Conversion => {
                    format!("consistent with the whole-flight figure (extremal index {})", significant(theta))
                }
                Basis::Other => continue,
            };
            self.role[i] = Some(role);
        }
    }

    /// Each row's statement, its role (where it has one) at the end.
    fn statements(&self) -> Vec<String> {
        (self.statement.iter().zip(&self.role))
            .map(|(s, r)| r.as_ref().map_or(s.clone(), |r| format!("{s} [{r}]")))
            .collect()
    }
}

/// What a miss before the hazard at thresholds other than the deck's leaves out in a run written by an
/// fdimc whose profiles had no exact point at the time to hazard: their alarm times are replayed from
/// the recorded profiles, whose grid may place one up to a grid step late, so a fault detected near the
/// end of its window can count as missed (nothing with the full profiles).
fn replayed_late(set: &str, setting: &Setting) -> String {
    match setting.profile_resolution {
        _ if set == DECK || setting.profiles_exact_at_deadlines => String::new(),
        Some(0.0) => String::new(),
        step => format!(
            "; at these thresholds the alarm times are replayed from the recorded profiles (grid step {}), which may \
             place a detection up to a grid step late: a fault detected near the end of its time to hazard may count \
             as missed, so the figure may be high (exact with monte_carlo.profile_resolution = 0)",
            step.map_or("2 %".to_string(), |s| format!("{} %", significant(100.0 * s)))
        ),
    }
}

/// The rows of `safety.csv` from `answer.csv`'s rows (the thresholds in use), `detectors.csv` (the
/// miss before the hazard), the tail fits and, where `fdimc rare-event` wrote into the run's folder,
/// its answers at the deck's thresholds.
pub fn safety(
    answer: &DataFrame,
    detectors: &DataFrame,
    tails: &[DetectorTail],
    setting: &Setting,
) -> PolarsResult<DataFrame> {
    let a = Table(answer);
    let (sets, names) = (a.strs("thresholds"), a.strs(col::DETECTOR));
    let (flights, alarms) = (a.u64s("fault_free_flights"), a.u64s("fault_free_false_alarms"));
    let (p, p_lo, p_hi) = (a.f64s("pfa_fault_free"), a.f64s("pfa_fault_free_lo"), a.f64s("pfa_fault_free_hi"));
    let d = Table(detectors);
    let (d_sets, d_names) = (d.strs("thresholds"), d.strs(col::DETECTOR));
    let (miss, miss_lo, miss_hi, hazard_units, missed) = (
        d.f64s("p_miss_before_hazard"),
        d.f64s("p_miss_before_hazard_lo"),
        d.f64s("p_miss_before_hazard_hi"),
        d.u64s("hazard_units"),
        d.u64s("missed_before_hazard"),
    );
    let per = |p: f64| setting.flight_s.map_or(p, |s| per_flight_hour(p, s));
    let unit = setting.flight_s.map_or("per flight (its length unknown)".to_string(), |s| {
        format!(
            "per flight hour: at least one false alarm in an hour of flight, the hour's {} trials of {s} s taken as \
             independent, each begun with the filter on the truth",
            significant(3600.0 / s)
        )
    });
    let figure = if setting.flight_s.is_some() { "false alarms per flight hour" } else { "false alarms per flight" };
    // A trial is a flight only where the run's flights are not segments of an hour.
    let trials_named = setting
        .flight_s
        .map_or("fault-free trials".to_string(), |s| format!("fault-free trials of {} s", significant(s)));
    let values = a.strs("threshold_values");
    let mut rows = Rows {
        stamp: format!(
            "deck sha256 {}, fdimc {}",
            &setting.deck_sha256[..setting.deck_sha256.len().min(16)],
            setting.fdimc_version
        ),
        thresholds: (0..answer.height()).map(|i| (names[i].clone(), sets[i].clone(), values[i].clone())).collect(),
        ..Rows::default()
    };
    for i in 0..answer.height() {
        let (name, set) = (names[i].as_str(), sets[i].as_str());
        if flights[i] > 0 {
            rows.push(
                Basis::Conversion,
                name,
                set,
                figure,
                [per(p[i]), per(p_lo[i]), per(p_hi[i])],
                Some(per(wilson(alarms[i], flights[i], Z_ONE_SIDED_95).1)),
                format!("plain Monte Carlo: {} alarming of {} {trials_named}", alarms[i], flights[i]),
                format!("{}; sensor noise {}", unit, setting.noise),
            );
        }
        if let Some(fit) =
            tails.iter().find(|t| t.detector == name && t.set == set).and_then(|t| t.at_set.map(|i| (t, i)))
        {
            let (t, at) = fit;
            let doubts = if t.concerns.is_empty() {
                String::new()
            } else {
                format!("; the fit's doubts: {}", t.concerns.join("; "))
            };
            rows.push(
                Basis::Conversion,
                name,
                set,
                figure,
                [per(at.estimate), per(at.lo), per(at.hi)],
                None,
                format!("a generalised Pareto fit to the tail of the {} {trials_named}' largest statistics", t.n),
                format!("{unit}; sensor noise {}; the fitted tail holds beyond the data{doubts}", setting.noise),
            );
        }
        let j = (0..detectors.height()).find(|&j| d_sets[j] == set && d_names[j] == name);
        if let Some(j) = j.filter(|&j| !miss[j].is_nan()) {
            rows.push(
                Basis::Other,
                name,
                set,
                "missed detection before the hazard",
                [miss[j], miss_lo[j], miss_hi[j]],
                Some(wilson(missed[j], hazard_units[j], Z_ONE_SIDED_95).1),
                format!("plain Monte Carlo: {} faulty trials", hazard_units[j]),
                format!(
                    "the deck's fault kinds, sizes and onsets as drawn, each kind's time to hazard (time_to_hazard_s), sensor noise {}{}",
                    setting.noise,
                    replayed_late(set, setting)
                ),
            );
        }
    }
    if let Some(segment_s) = setting.flight_s {
        for (detector, set, h) in setting.conversions {
            rows.mark_by_law(detector, set, h, segment_s);
        }
    }
    // The rare-event figures are at the deck's thresholds (its levels scale them), whichever set the
    // answer uses: one group per detector, after the figures in use.
    if let Some(re) = &setting.rare_event {
        let mut seen: Vec<&str> = Vec::new();
        for name in &names {
            if !seen.contains(&name.as_str()) {
                seen.push(name);
                rare_event_rows(&mut rows, name, re, setting.noise);
            }
        }
    }
    let statements = rows.statements();
    let r = rows;
    DataFrame::new_infer_height(vec![
        Column::new(col::DETECTOR.into(), r.detector),
        Column::new("thresholds".into(), r.set),
        Column::new("figure".into(), r.figure),
        Column::new("value".into(), r.value),
        Column::new("value_lo".into(), r.lo),
        Column::new("value_hi".into(), r.hi),
        Column::new("value_upper_95".into(), r.upper),
        Column::new("method".into(), r.method),
        Column::new("assumptions".into(), r.assumptions),
        Column::new("role".into(), r.role),
        Column::new("statement".into(), statements),
    ])
}

/// `fdimc rare-event`'s answers at the deck's thresholds (scale 1) for detector `name`: per flight hour
/// from its trials (the segment conversion), and, with `--flight-s`, measured over its flights and by
/// the conditional estimate on the exact law.
fn rare_event_rows(rows: &mut Rows, name: &str, re: &RareEventTables, noise: &str) {
    if let Some(miss) = &re.miss {
        let t = Table(miss);
        let (names, scales, answers) = (t.strs(col::DETECTOR), t.f64s("threshold_scale"), t.bools("answer"));
        let (replicas, particles) = (t.u64s("replicas"), t.u64s("particles"));
        let p = [t.f64s("p_miss_before_hazard"), t.f64s("p_miss_before_hazard_lo"), t.f64s("p_miss_before_hazard_hi")];
        for i in (0..miss.height()).filter(|&i| names[i] == name && scales[i] == 1.0 && answers[i]) {
            rows.push(
                Basis::Other,
                name,
                DECK,
                "missed detection before the hazard",
                [p[0][i], p[1][i], p[2][i]],
                None,
                format!(
                    "splitting in time: {} replicas of {} particles over the deck's faulty trials (rare_event/)",
                    replicas[i], particles[i]
                ),
                format!(
                    "the deck's fault kinds, sizes and onsets as drawn, each kind's time to hazard (time_to_hazard_s), sensor noise {noise}"
                ),
            );
        }
    }
    let Some(table) = &re.rows else { return };
    let figure = "false alarms per flight hour";
    let t = Table(table);
    let (names, scales, answers) = (t.strs(col::DETECTOR), t.f64s("threshold_scale"), t.bools("answer"));
    let (estimators, units, trial_s) = (t.strs("estimator"), t.u64s("units"), t.f64s("trial_s"));
    let hour = [t.f64s("pfa_per_flight_hour"), t.f64s("pfa_per_flight_hour_lo"), t.f64s("pfa_per_flight_hour_hi")];
    let method = |estimator: &str, units: u64, what: &str| match estimator {
        "splitting" => format!("adaptive multilevel splitting: {units} replicas over {what}"),
        _ => format!("importance sampling on the sensor noise: {units} weighted {what}"),
    };
    let mut whole_flight_index = None;
    for i in (0..table.height()).filter(|&i| names[i] == name && scales[i] == 1.0 && answers[i]) {
        rows.push(
            Basis::Conversion,
            name,
            DECK,
            figure,
            [hour[0][i], hour[1][i], hour[2][i]],
            None,
            method(&estimators[i], units[i], &format!("fault-free trials of {} s", significant(trial_s[i]))),
            format!(
                "the hour's {} segments of {} s taken as independent restarts; sensor noise {noise}",
                significant(3600.0 / trial_s[i]),
                significant(trial_s[i])
            ),
        );
        let Some(per_hour) = &re.per_hour else { continue };
        let f = Table(per_hour);
        let (f_names, f_scales, flight_s) = (f.strs(col::DETECTOR), f.f64s("threshold_scale"), f.f64s("flight_s"));
        let Some(j) = (0..per_hour.height()).find(|&j| f_names[j] == name && f_scales[j] == 1.0) else { continue };
        let triple = |c: &str| [f.f64s(c)[j], f.f64s(&format!("{c}_lo"))[j], f.f64s(&format!("{c}_hi"))[j]];
        let over = format!("fault-free flights of {} s", significant(flight_s[j]));
        let independence = if flight_s[j] == 3600.0 {
            "an hour flown whole, without restarts".to_string()
        } else {
            format!("flights of {} s, the hour's taken as independent", significant(flight_s[j]))
        };
        let theta = triple("extremal_index");
        // The whole flight against the conversion: measured over its flights where they answer, else
        // by the conditional estimate on the exact law.
        let conditional_theta = f.f64s("extremal_index_conditional").get(j).copied().unwrap_or(f64::NAN);
        let index = if f.bools("answer")[j] && theta[0].is_finite() { theta[0] } else { conditional_theta };
        if index.is_finite() {
            whole_flight_index = Some(index);
        }
        if f.bools("answer")[j] {
            rows.push(
                Basis::WholeFlight,
                name,
                DECK,
                figure,
                triple("pfa_per_flight_hour_flights"),
                None,
                method(&estimators[i], f.u64s("flight_units")[j], &over) + " (their own run: rare_event/flights/)",
                format!(
                    "{independence}; extremal index against the segment conversion {} [{}, {}]; sensor noise {noise}",
                    significant(theta[0]),
                    significant(theta[1]),
                    significant(theta[2])
                ),
            );
        }
        let conditional = triple("conditional_per_flight");
        if conditional[0] > 0.0 {
            rows.push(
                Basis::WholeFlight,
                name,
                DECK,
                figure,
                conditional.map(|p| per_flight_hour(p, flight_s[j])),
                None,
                format!("conditional Monte Carlo on the residual's exact Gaussian law over {over}"),
                format!(
                    "{independence}; the model exact (no parameter error), white Gaussian sensor noise, the |residual| test"
                ),
            );
        }
    }
    if let Some(theta) = whole_flight_index {
        rows.mark(name, theta);
    }
}

/// The statements on the console.
pub fn print(safety: &DataFrame) {
    if safety.height() == 0 {
        return;
    }
    println!("  safety figures (safety.csv; to quote with their assumptions):");
    for s in Table(safety).strs("statement") {
        println!("    {s}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With a whole-flight figure, the flights' rows are the figure and the converted ones a lower
    /// bound above an extremal index of 1.5 (the 2.737), consistent with it below; another
    /// detector's rows and a missed-detection row are left alone.
    #[test]
    fn rows_say_which_is_the_figure_and_which_a_lower_bound() {
        let mut rows = Rows::default();
        let push = |rows: &mut Rows, basis, detector: &str| {
            rows.push(
                basis,
                detector,
                "deck",
                "false alarms per flight hour",
                [1e-4, 5e-5, 2e-4],
                None,
                "m".into(),
                "a".into(),
            )
        };
        push(&mut rows, Basis::Conversion, "a");
        push(&mut rows, Basis::WholeFlight, "a");
        push(&mut rows, Basis::Other, "a");
        push(&mut rows, Basis::Conversion, "b");
        push(&mut rows, Basis::Conversion, "c");
        rows.mark("a", 2.737);
        rows.mark("c", 1.2);
        assert!(
            rows.role[0]
                .as_deref()
                .unwrap()
                .starts_with("a lower bound: the segment conversion under-counts here (extremal index 2.737 > 1.5)"),
            "{:?}",
            rows.role
        );
        assert_eq!(
            rows.role[1].as_deref(),
            Some("the figure to quote (flights flown through, not restarted segments)")
        );
        assert_eq!((rows.role[2].as_deref(), rows.role[3].as_deref()), (None, None));
        assert_eq!(rows.role[4].as_deref(), Some("consistent with the whole-flight figure (extremal index 1.2)"));
        assert!(rows.statements()[0].ends_with("quote the whole-flight figure]"), "{}", rows.statements()[0]);
    }

    /// The exact law judges the converted rows at the thresholds it was computed for: a lower bound
    /// above 1.5 (the lateral deck's 2.555), consistent below; a later whole-flight figure (at the
    /// deck's thresholds) does not overrule it, and judges only the deck's rows the law left.
    #[test]
    fn the_exact_law_marks_the_converted_rows_at_its_thresholds() {
        let mut rows = Rows::default();
        for (detector, set) in
            [("d", "deck"), ("d", "calibrated"), ("e", "calibrated"), ("f", "deck"), ("f", "calibrated")]
        {
            let v = [1e-2, 5e-3, 2e-2];
            rows.push(
                Basis::Conversion,
                detector,
                set,
                "false alarms per flight hour",
                v,
                None,
                "m".into(),
                "a".into(),
            );
        }
        let slow = HourConversion { ratio: 2.555, slowest_time_constant_s: 16.665, trial_upper: f64::NAN };
        rows.mark_by_law("d", "deck", &slow, 10.0);
        rows.mark_by_law("d", "calibrated", &slow, 10.0);
        rows.mark_by_law(
            "e",
            "calibrated",
            &HourConversion { ratio: 1.1, slowest_time_constant_s: 1.0, trial_upper: f64::NAN },
            10.0,
        );
        let lower = "a lower bound: the segment conversion under-counts here (by the residual's exact law, extremal \
                     index 2.555 against it over an hour flown through: a mode of time constant 16.66 s against 10 s \
                     trials)";
        assert!(rows.role[1].as_deref().unwrap().starts_with(lower), "{:?}", rows.role[1]);
        assert_eq!(
            rows.role[2].as_deref(),
            Some("consistent with an hour flown through (by the residual's exact law, extremal index 1.1)")
        );
        rows.mark("d", 1.2);
        rows.mark("f", 1.2);
        for i in [0, 1] {
            assert!(rows.role[i].as_deref().unwrap().starts_with(lower), "{:?}", rows.role[i]);
        }
        assert_eq!(rows.role[3].as_deref(), Some("consistent with the whole-flight figure (extremal index 1.2)"));
        assert_eq!(rows.role[4], None);
        assert!(rows.statements()[1].contains("[a lower bound"), "{}", rows.statements()[1]);
    }
}
