//! `safety.csv`: the two figures a safety case quotes, per detector at the thresholds in use, each with
//! its 95 % interval, the method that gave it and the assumptions it rests on, in words: the
//! false-alarm rate per flight hour (plain Monte Carlo over the fault-free flights, and the tail fit
//! where it gives one) and, with the deck's `time_to_hazard_s`, the probability that a fault is not
//! detected before it becomes hazardous.

use polars::prelude::*;

use crate::engine::results::schema::col;
use crate::engine::results::tables::Table;
use crate::engine::results::tails::DetectorTail;
use crate::engine::results::text::{rate_interval, significant};
use crate::engine::results::thresholds::per_flight_hour;

pub const SAFETY_FILE: &str = "safety.csv";

/// What the figures rest on that the tables do not say: the flights' length and the sensor noise's law.
pub struct Setting<'a> {
    /// The flights' length (s): the hour's segments; `None`: figures per flight.
    pub flight_s: Option<f64>,
    /// The sensor noise as the run drew it, in words.
    pub noise: &'a str,
}

#[derive(Default)]
struct Rows {
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
    fn push(&mut self, detector: &str, set: &str, figure: &str, v: [f64; 3], method: String, assumptions: String) {
        let statement = format!(
            "{detector} at the {set} thresholds: {figure} {} (95 %), by {method}; assuming {assumptions}",
            rate_interval(v[0], v[1], v[2])
        );
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
}

/// The rows of `safety.csv` from `answer.csv`'s rows (the thresholds in use), `detectors.csv` (the
/// miss before the hazard) and the tail fits.
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
    let (miss, miss_lo, miss_hi, hazard_units) = (
        d.f64s("p_miss_before_hazard"),
        d.f64s("p_miss_before_hazard_lo"),
        d.f64s("p_miss_before_hazard_hi"),
        d.u64s("hazard_units"),
    );
    let per = |p: f64| setting.flight_s.map_or(p, |s| per_flight_hour(p, s));
    let unit = setting.flight_s.map_or("per flight (its length unknown)".to_string(), |s| {
        format!("the hour's {} flights of {s} s taken as independent", significant(3600.0 / s))
    });
    let figure = if setting.flight_s.is_some() { "false alarms per flight hour" } else { "false alarms per flight" };
    let mut rows = Rows::default();
    for i in 0..answer.height() {
        let (name, set) = (names[i].as_str(), sets[i].as_str());
        if flights[i] > 0 {
            rows.push(
                name,
                set,
                figure,
                [per(p[i]), per(p_lo[i]), per(p_hi[i])],
                format!("plain Monte Carlo: {} alarming of {} fault-free flights", alarms[i], flights[i]),
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
                name,
                set,
                figure,
                [per(at.estimate), per(at.lo), per(at.hi)],
                format!("a generalised Pareto fit to the tail of the {} fault-free flights' largest statistics", t.n),
                format!("{unit}; sensor noise {}; the fitted tail holds beyond the data{doubts}", setting.noise),
            );
        }
        let j = (0..detectors.height()).find(|&j| d_sets[j] == set && d_names[j] == name);
        if let Some(j) = j.filter(|&j| !miss[j].is_nan()) {
            rows.push(
                name,
                set,
                "missed detection before the hazard",
                [miss[j], miss_lo[j], miss_hi[j]],
                format!("plain Monte Carlo: {} faulty flights", hazard_units[j]),
                format!(
                    "the deck's fault kinds, sizes and onsets as drawn, each kind's time to hazard (time_to_hazard_s), sensor noise {}",
                    setting.noise
                ),
            );
        }
    }
    let r = rows;
    DataFrame::new_infer_height(vec![
        Column::new(col::DETECTOR.into(), r.detector),
        Column::new("thresholds".into(), r.set),
        Column::new("figure".into(), r.figure),
        Column::new("value".into(), r.value),
        Column::new("value_lo".into(), r.lo),
        Column::new("value_hi".into(), r.hi),
        Column::new("method".into(), r.method),
        Column::new("assumptions".into(), r.assumptions),
        Column::new("statement".into(), r.statement),
    ])
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
