//! Per flight hour measured over long flights (`fdimc rare-event --flight-s F`), against the segment
//! conversion.
//!
//! A study's trials are segments of T seconds, each starting its filter on the truth. The per-hour
//! figure everywhere else is the conversion `1 - (1 - p_T)^(3600 / T)`: the hour's segments taken as
//! independent restarts. A flight of F seconds (F a multiple of T) flies the same loop without a
//! restart, and the same estimator measures its probability `p_F` directly. They are linked by
//!
//! ```text
//! P(no alarm in F) = P(no alarm in T)^(theta F / T),   theta = ln(1 - p_F) / ((F / T) ln(1 - p_T))
//! ```
//!
//! the extremal index's form, with the restarted segment as the block: `theta = 1` where the flight's
//! segments behave as independent restarts (a white residual and a one-sample test), below 1 where
//! alarms cluster across segments (the conversion counts one excursion twice), above 1 where a
//! restarted segment is quieter than one in the middle of a flight (a slow filter's state error
//! grows from zero at each restart, so the conversion under-counts).

use std::path::Path;

use polars::prelude::*;

use crate::engine::rare_event::estimators::Combined;
use crate::engine::rare_event::study::RareEventRow;
use crate::engine::run::runner::{RunError, pol};
use crate::engine::stats::intervals::Z95;

pub use crate::engine::results::schema::rare_event_files::PER_HOUR as PER_HOUR_FILE;

/// One detector at one threshold scale: the segments' and the flights' estimates and what links them.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightComparison {
    pub detector: String,
    pub level: f64,
    pub segment_s: f64,
    pub flight_s: f64,
    pub segment: Combined,
    pub flight: Combined,
    /// The conditional Monte Carlo estimate on the residual's exact law ([`Conditional`]), where the
    /// deck is within what it assumes.
    pub conditional: Result<Conditional, String>,
}

/// Conditional Monte Carlo on the exact Gaussian law of the residual (the analytic false-alarm
/// module's), per segment and per flight: each `[estimate, lo, hi]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Conditional {
    pub segment: [f64; 3],
    pub flight: [f64; 3],
}

/// `1 - (1 - p)^m`, exact for small `p`.
fn power_of_survival(p: f64, m: f64) -> f64 {
    -((-p).ln_1p() * m).exp_m1()
}

/// `[estimate, lo, hi]` of a combined estimate.
fn triple(c: &Combined) -> [f64; 3] {
    [c.estimate, c.low, c.high]
}

/// `theta = ln(1 - p_flight) / (segments ln(1 - p_segment))` and its 95 % interval: the delta method
/// on `ln theta`, each estimate's relative standard error from its interval's half-width (`ln(1 - p)`
/// carries the relative error of `p` times `p / ((1 - p) |ln(1 - p)|)`, 1 for small p), the two
/// added in quadrature as if independent. The two runs share their seed (a flight's first segment
/// draws the noise of the segment trial of the same number): positively correlated, which makes the
/// interval conservative.
pub fn extremal_index(segment: [f64; 3], flight: [f64; 3], segments: f64) -> [f64; 3] {
    let log_survival = |p: f64| (-p).ln_1p();
    let relative_se = |[p, lo, hi]: [f64; 3]| (hi - lo) / (2.0 * Z95 * p) * p / ((1.0 - p) * -log_survival(p));
    let theta = log_survival(flight[0]) / (segments * log_survival(segment[0]));
    let se = relative_se(flight).hypot(relative_se(segment));
    [theta, theta * (-Z95 * se).exp(), theta * (Z95 * se).exp()]
}

impl FlightComparison {
    /// Segments per flight.
    pub fn segments(&self) -> f64 {
        self.flight_s / self.segment_s
    }

    /// The flight's probability from the segments taken as independent restarts, with the segments'
    /// interval carried through (the map is increasing).
    pub fn conversion(&self) -> [f64; 3] {
        triple(&self.segment).map(|p| power_of_survival(p, self.segments()))
    }

    /// Both estimates are answers (a hit, a narrow interval, no heavy unit).
    pub fn answer(&self) -> bool {
        self.segment.answer && self.flight.answer
    }

    /// The extremal index from the two simulations; NaN where either is not an answer.
    pub fn theta(&self) -> [f64; 3] {
        if !self.answer() {
            return [f64::NAN; 3];
        }
        extremal_index(triple(&self.segment), triple(&self.flight), self.segments())
    }

    /// The extremal index from the conditional estimates; NaN where there are none.
    pub fn theta_conditional(&self) -> [f64; 3] {
        match &self.conditional {
            Ok(c) if c.segment[0] > 0.0 && c.flight[0] > 0.0 => extremal_index(c.segment, c.flight, self.segments()),
            _ => [f64::NAN; 3],
        }
    }

    /// Per flight hour from the flights (exact for F = 3600 s; for other F the flights taken as
    /// independent, which is what F is chosen long enough to make true).
    pub fn per_hour_flights(&self) -> [f64; 3] {
        triple(&self.flight).map(|p| power_of_survival(p, 3600.0 / self.flight_s))
    }

    /// Per flight hour from the segments taken as independent restarts.
    pub fn per_hour_conversion(&self) -> [f64; 3] {
        triple(&self.segment).map(|p| power_of_survival(p, 3600.0 / self.segment_s))
    }
}

/// Pairs the segment run's rows with the flight run's (the same detectors and levels, in order).
/// `conditional(detector, level)`: the conditional estimates of one detector at one scale.
pub fn compare(
    segments: &[RareEventRow],
    flights: &[RareEventRow],
    conditional: &dyn Fn(&str, f64) -> Result<Conditional, String>,
) -> Result<Vec<FlightComparison>, RunError> {
    if segments.len() != flights.len() {
        return Err(RunError::Internal(format!("{} segment rows, {} flight rows", segments.len(), flights.len())));
    }
    segments
        .iter()
        .zip(flights)
        .map(|(s, f)| {
            if s.detector != f.detector || s.estimate.level != f.estimate.level {
                return Err(RunError::Internal(format!(
                    "segment row {} at {} against flight row {} at {}",
                    s.detector, s.estimate.level, f.detector, f.estimate.level
                )));
            }
            Ok(FlightComparison {
                detector: s.detector.clone(),
                level: s.estimate.level,
                segment_s: s.trial_s,
                flight_s: f.trial_s,
                segment: s.estimate.clone(),
                flight: f.estimate.clone(),
                conditional: conditional(&s.detector, s.estimate.level),
            })
        })
        .collect()
}

/// Writes `per_hour.csv` to `dir`.
pub fn write(dir: &Path, rows: &[FlightComparison]) -> Result<(), RunError> {
    let path = dir.join(PER_HOUR_FILE);
    let f = |g: &dyn Fn(&FlightComparison) -> f64| rows.iter().map(g).collect::<Vec<f64>>();
    let three = |name: &str, g: &dyn Fn(&FlightComparison) -> [f64; 3]| {
        let values: Vec<[f64; 3]> = rows.iter().map(g).collect();
        ["", "_lo", "_hi"]
            .iter()
            .enumerate()
            .map(|(i, suffix)| {
                Column::new(format!("{name}{suffix}").into(), values.iter().map(|v| v[i]).collect::<Vec<_>>())
            })
            .collect::<Vec<_>>()
    };
    let conditional =
        |r: &FlightComparison, pick: fn(&Conditional) -> [f64; 3]| r.conditional.as_ref().map_or([f64::NAN; 3], pick);
    let mut columns = vec![
        Column::new(
            crate::engine::results::schema::col::DETECTOR.into(),
            rows.iter().map(|r| r.detector.as_str()).collect::<Vec<_>>(),
        ),
        Column::new("threshold_scale".into(), f(&|r| r.level)),
        Column::new("segment_s".into(), f(&|r| r.segment_s)),
        Column::new("flight_s".into(), f(&|r| r.flight_s)),
        Column::new("answer".into(), rows.iter().map(|r| r.answer()).collect::<Vec<_>>()),
        Column::new("segment_units".into(), rows.iter().map(|r| r.segment.units).collect::<Vec<_>>()),
        Column::new("flight_units".into(), rows.iter().map(|r| r.flight.units).collect::<Vec<_>>()),
    ];
    columns.extend(three("pfa_per_segment", &|r| triple(&r.segment)));
    columns.extend(three("pfa_per_flight", &|r| triple(&r.flight)));
    columns.extend(three("pfa_per_flight_conversion", &|r| r.conversion()));
    columns.extend(three("extremal_index", &|r| r.theta()));
    columns.extend(three("pfa_per_flight_hour_flights", &|r| r.per_hour_flights()));
    columns.extend(three("pfa_per_flight_hour_conversion", &|r| r.per_hour_conversion()));
    columns.extend(three("conditional_per_segment", &|r| conditional(r, |c| c.segment)));
    columns.extend(three("conditional_per_flight", &|r| conditional(r, |c| c.flight)));
    columns.extend(three("extremal_index_conditional", &|r| r.theta_conditional()));
    columns.push(Column::new(
        "conditional_note".into(),
        rows.iter().map(|r| r.conditional.as_ref().err().cloned().unwrap_or_default()).collect::<Vec<_>>(),
    ));
    let mut df = DataFrame::new_infer_height(columns).map_err(pol(&path))?;
    Ok(crate::engine::run::output::write_table(&mut df, &path)?)
}

/// The comparison on stdout, one line per detector and level.
pub fn print(rows: &[FlightComparison]) {
    use crate::engine::results::text::{rate_interval, significant};
    let Some(first) = rows.first() else { return };
    println!(
        "per flight of {} s, measured over flights against {} segments of {} s taken as independent restarts:",
        first.flight_s,
        significant(first.segments()),
        first.segment_s
    );
    for r in rows {
        let [c, c_lo, c_hi] = r.conversion();
        let [t, t_lo, t_hi] = r.theta();
        let theta = if r.answer() {
            format!("extremal index {} [{}, {}]", significant(t), significant(t_lo), significant(t_hi))
        } else {
            "extremal index: not an answer (see the two runs' tables)".into()
        };
        println!(
            "  {} x{}: flights {}; conversion {}; {theta}",
            r.detector,
            r.level,
            rate_interval(r.flight.estimate, r.flight.low, r.flight.high),
            rate_interval(c, c_lo, c_hi),
        );
        if let Ok(k) = &r.conditional {
            let [t, t_lo, t_hi] = r.theta_conditional();
            println!(
                "    conditional estimate on the exact law: flights {}, segments {}; extremal index {} [{}, {}]",
                rate_interval(k.flight[0], k.flight[1], k.flight[2]),
                rate_interval(k.segment[0], k.segment[1], k.segment[2]),
                significant(t),
                significant(t_lo),
                significant(t_hi)
            );
        }
    }
    if rows.iter().any(|r| !r.flight.answer && r.conditional.is_ok()) {
        println!(
            "(where the flights' simulation is not an answer, the conditional estimate is: over long flights \
             importance sampling's weights spread, its mixture averaging over every sample; more flights, or \
             a shorter --flight-s to measure the extremal index)"
        );
    }
    println!(
        "(extremal index: ln(1 - p_flight) / (segments x ln(1 - p_segment)); 1: the segments behave as \
         independent restarts; below 1: alarms cluster across segments; above 1: a restarted segment is \
         quieter than one in flight. Its interval: the delta method, the two runs taken as independent)"
    );
}
