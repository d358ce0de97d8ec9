//! Thresholds for a false-alarm target per flight hour over whole flights (`fdimc flight-thresholds`,
//! issue 84): the target as asked, what a kind's search finds, and the files the command writes.
//!
//! An hour is `3600 / F` flights of `F` seconds, each begun with the filter on the truth and
//! independent of the others: `p_hour = 1 - (1 - p_flight)^(3600 / F)`
//! ([`crate::engine::results::thresholds::per_flight_hour`]); one flight of an hour is the hour.

use std::path::Path;

use polars::prelude::*;

use crate::engine::results::thresholds::per_flight_hour;
use crate::engine::run::runner::RunError;

/// `flight_thresholds.csv`: per detector and statistic, the thresholds found and what confirms them.
pub const FLIGHT_THRESHOLDS_FILE: &str = "flight_thresholds.csv";
/// `thresholds.csv`, in the shape of a run's (`summarize --thresholds` reads it): written only for
/// the detectors whose thresholds were confirmed.
pub const THRESHOLDS_FILE: &str = "thresholds.csv";

/// How a detector's target is shared among its statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Allocation {
    /// Each of `m` statistics the same share, `1 - (1 - p)^(1 / m)`: by Sidak's inequality the
    /// detector's probability is then at most `p`.
    Equal,
    /// The deck's thresholds times one scale: their ratios as the deck sets them.
    Deck,
}

impl Allocation {
    pub fn name(self) -> &'static str {
        match self {
            Allocation::Equal => "equal",
            Allocation::Deck => "deck",
        }
    }
}

/// A false-alarm target over whole flights.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightTarget {
    /// The target per flight hour, where it was asked so (else per flight).
    pub per_hour: Option<f64>,
    /// The probability of at least one false alarm in a flight.
    pub per_flight: f64,
    pub flight_s: f64,
    pub allocation: Allocation,
    /// The seed of the confirmation's draws (fresh: none of the search's; `None`: the deck's).
    pub seed: Option<u64>,
}

impl FlightTarget {
    /// The target `per_hour` over flights of `flight_s` seconds: per flight, the probability whose
    /// hour of independent flights is `per_hour`.
    pub fn per_hour(per_hour: f64, flight_s: f64, allocation: Allocation, seed: Option<u64>) -> Self {
        let per_flight = -((-per_hour).ln_1p() * (flight_s / 3600.0)).exp_m1();
        FlightTarget { per_hour: Some(per_hour), per_flight, flight_s, allocation, seed }
    }

    /// The target `per_flight` over flights of `flight_s` seconds.
    pub fn per_flight(per_flight: f64, flight_s: f64, allocation: Allocation, seed: Option<u64>) -> Self {
        FlightTarget { per_hour: None, per_flight, flight_s, allocation, seed }
    }

    /// A per-flight probability per flight hour.
    pub fn hour_of(&self, per_flight: f64) -> f64 {
        per_flight_hour(per_flight, self.flight_s)
    }
}

/// An estimate of the per-flight false-alarm probability at a detector's thresholds.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    pub value: f64,
    /// Its 95 % interval.
    pub lo: f64,
    pub hi: f64,
    /// Its one-sided 95 % upper bound.
    pub upper_95: f64,
    pub draws: usize,
}

/// A search over a deck's detectors: the thresholds found, and each detector it could not search with
/// why (a statistic other than `|residual|`, a filter whose error never settles).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FlightSearch {
    pub found: Vec<FoundThresholds>,
    pub skipped: Vec<String>,
}

/// One detector's thresholds for a [`FlightTarget`], found and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct FoundThresholds {
    pub detector: String,
    pub statistics: Vec<String>,
    pub deck_thresholds: Vec<f64>,
    pub thresholds: Vec<f64>,
    /// How the probability was estimated and confirmed, in words.
    pub method: String,
    /// Bounds on the per-flight probability at the thresholds that hold for the residual's law
    /// whatever the draws, and the inequalities that gave them.
    pub upper: f64,
    pub upper_from: String,
    pub lower: f64,
    pub lower_from: String,
    /// The search's last estimate, which set the thresholds.
    pub search: Estimate,
    /// The confirmation's, on fresh draws.
    pub confirmation: Estimate,
    /// The seed of the confirmation's draws (derived from the deck's or `--seed`'s).
    pub seed: u64,
    /// The confirmation's one-sided 95 % upper bound is below the per-flight target.
    pub confirmed: bool,
}

impl FoundThresholds {
    /// The sentence to print: the thresholds, the figure per flight (and per hour) with its bound, the
    /// verdict.
    pub fn statement(&self, target: &FlightTarget) -> String {
        let c = &self.confirmation;
        let thresholds: Vec<String> =
            (self.statistics.iter().zip(&self.thresholds)).map(|(s, t)| format!("{s} {t:.6e}")).collect();
        let hour = match target.per_hour {
            Some(h) => format!(
                "; per flight hour {:.3e} (one-sided 95 % bound {:.3e}) against the target {h:.1e}",
                target.hour_of(c.value),
                target.hour_of(c.upper_95)
            ),
            None => String::new(),
        };
        format!(
            "{}: thresholds {}; per {} s flight {:.3e} [{:.3e}, {:.3e}] (one-sided 95 % bound {:.3e}, {} draws) \
             against the target {:.3e}{hour}; the exact law's bounds {:.3e} ({}) to {:.3e} ({}): {}",
            self.detector,
            thresholds.join(", "),
            target.flight_s,
            c.value,
            c.lo,
            c.hi,
            c.upper_95,
            c.draws,
            target.per_flight,
            self.lower,
            self.lower_from,
            self.upper,
            self.upper_from,
            if self.confirmed {
                "confirmed".to_string()
            } else {
                "NOT confirmed: the one-sided bound is above the target; nothing written as a calibration".to_string()
            }
        )
    }
}

/// The table of `flight_thresholds.csv`: a row per detector and statistic.
pub fn table(found: &[FoundThresholds], target: &FlightTarget) -> PolarsResult<DataFrame> {
    let rows: Vec<(&FoundThresholds, usize)> =
        found.iter().flat_map(|f| (0..f.statistics.len()).map(move |j| (f, j))).collect();
    let text = |name: &str, v: &dyn Fn(&FoundThresholds, usize) -> String| {
        Column::new(name.into(), rows.iter().map(|(f, j)| v(f, *j)).collect::<Vec<String>>())
    };
    let number = |name: &str, v: &dyn Fn(&FoundThresholds, usize) -> f64| {
        Column::new(name.into(), rows.iter().map(|(f, j)| v(f, *j)).collect::<Vec<f64>>())
    };
    let per_hour = |name: &str, v: &dyn Fn(&FoundThresholds) -> f64| {
        Column::new(
            name.into(),
            rows.iter().map(|(f, _)| target.per_hour.map(|_| target.hour_of(v(f)))).collect::<Vec<Option<f64>>>(),
        )
    };
    DataFrame::new_infer_height(vec![
        text("detector", &|f, _| f.detector.clone()),
        text("statistic", &|f, j| f.statistics[j].clone()),
        number("deck_threshold", &|f, j| f.deck_thresholds[j]),
        number("threshold", &|f, j| f.thresholds[j]),
        text("allocation", &|_, _| target.allocation.name().to_string()),
        number("flight_s", &|_, _| target.flight_s),
        Column::new("target_per_hour".into(), rows.iter().map(|_| target.per_hour).collect::<Vec<Option<f64>>>()),
        number("target_per_flight", &|_, _| target.per_flight),
        number("per_flight", &|f, _| f.confirmation.value),
        number("per_flight_lo", &|f, _| f.confirmation.lo),
        number("per_flight_hi", &|f, _| f.confirmation.hi),
        number("per_flight_upper_95", &|f, _| f.confirmation.upper_95),
        per_hour("per_hour", &|f| f.confirmation.value),
        per_hour("per_hour_upper_95", &|f| f.confirmation.upper_95),
        number("exact_lower", &|f, _| f.lower),
        text("exact_lower_from", &|f, _| f.lower_from.clone()),
        number("exact_upper", &|f, _| f.upper),
        text("exact_upper_from", &|f, _| f.upper_from.clone()),
        number("search_per_flight", &|f, _| f.search.value),
        Column::new("draws".into(), rows.iter().map(|(f, _)| f.confirmation.draws as u64).collect::<Vec<u64>>()),
        Column::new("seed".into(), rows.iter().map(|(f, _)| f.seed).collect::<Vec<u64>>()),
        text("method", &|f, _| f.method.clone()),
        Column::new("confirmed".into(), rows.iter().map(|(f, _)| f.confirmed).collect::<Vec<bool>>()),
    ])
}

/// The confirmed detectors' thresholds as a run's `thresholds.csv` (`summarize --thresholds` reads it):
/// per statistic the threshold found, as the statistic's and the detector's (the detector alarms when
/// any statistic passes its own); `None` where none was confirmed.
pub fn calibration(found: &[FoundThresholds], target: &FlightTarget) -> PolarsResult<Option<DataFrame>> {
    let confirmed: Vec<(&FoundThresholds, usize)> =
        (found.iter().filter(|f| f.confirmed)).flat_map(|f| (0..f.statistics.len()).map(move |j| (f, j))).collect();
    if confirmed.is_empty() {
        return Ok(None);
    }
    let source = format!(
        "fdimc flight-thresholds: {} over {} s flights, {} allocation, confirmed",
        match target.per_hour {
            Some(h) => format!("{h:e} per flight hour"),
            None => format!("{:e} per flight", target.per_flight),
        },
        target.flight_s,
        target.allocation.name()
    );
    let f64s =
        |v: &dyn Fn(&FoundThresholds, usize) -> f64| confirmed.iter().map(|(f, j)| v(f, *j)).collect::<Vec<f64>>();
    DataFrame::new_infer_height(vec![
        Column::new("detector".into(), confirmed.iter().map(|(f, _)| f.detector.as_str()).collect::<Vec<&str>>()),
        Column::new(
            "statistic".into(),
            confirmed.iter().map(|(f, j)| f.statistics[*j].as_str()).collect::<Vec<&str>>(),
        ),
        Column::new("deck_threshold".into(), f64s(&|f, j| f.deck_thresholds[j])),
        Column::new("per_statistic_threshold".into(), f64s(&|f, j| f.thresholds[j])),
        Column::new("detector_threshold".into(), f64s(&|f, j| f.thresholds[j])),
        Column::new("source".into(), confirmed.iter().map(|_| source.as_str()).collect::<Vec<&str>>()),
    ])
    .map(Some)
}

/// Writes `flight_thresholds.csv` and, for the confirmed detectors, `thresholds.csv` into `dir`
/// (each whole or not at all); a stale `thresholds.csv` of an earlier search is removed when none is
/// confirmed now. Returns the files written.
pub fn write(dir: &Path, found: &[FoundThresholds], target: &FlightTarget) -> Result<Vec<String>, RunError> {
    use crate::engine::run::output::write_table;
    std::fs::create_dir_all(dir).map_err(crate::engine::run::runner::io(dir))?;
    let pol = |file: &Path| {
        let file = file.to_path_buf();
        move |source| RunError::Polars { file, source }
    };
    let path = dir.join(FLIGHT_THRESHOLDS_FILE);
    let mut df = table(found, target).map_err(pol(&path))?;
    write_table(&mut df, &path)?;
    let mut written = vec![path.display().to_string()];
    let calibration_path = dir.join(THRESHOLDS_FILE);
    match calibration(found, target).map_err(pol(&calibration_path))? {
        Some(mut df) => {
            write_table(&mut df, &calibration_path)?;
            written.push(calibration_path.display().to_string());
        }
        None if calibration_path.exists() => {
            std::fs::remove_file(&calibration_path).map_err(crate::engine::run::runner::io(&calibration_path))?
        }
        None => {}
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn found(detector: &str, upper_95: f64, confirmed: bool) -> FoundThresholds {
        let estimate = Estimate { value: 0.8e-7, lo: 0.7e-7, hi: 0.9e-7, upper_95, draws: 100 };
        FoundThresholds {
            detector: detector.into(),
            statistics: vec!["p".into(), "q".into()],
            deck_thresholds: vec![1.0, 2.0],
            thresholds: vec![3.0, 4.0],
            method: "test".into(),
            upper: 0.9e-7,
            upper_from: "Sidak".into(),
            lower: 0.7e-7,
            lower_from: "Bonferroni S1 - S2".into(),
            search: estimate.clone(),
            confirmation: estimate,
            seed: 7,
            confirmed,
        }
    }

    /// An hour of 10 flights of 360 s at 1e-6 per hour is 1e-7 per flight (to 1e-12), and back.
    #[test]
    fn a_per_hour_target_is_the_hours_flights_taken_as_independent() {
        let t = FlightTarget::per_hour(1e-6, 360.0, Allocation::Equal, None);
        // Python's -expm1(0.1 * log1p(-1e-6)), free of the cancellation of 1 - (1 - 1e-6)^0.1.
        assert!((t.per_flight / 1.0000004500002851e-07 - 1.0).abs() < 1e-12, "{}", t.per_flight);
        assert!((t.per_flight / 1e-7 - 1.0).abs() < 1e-6);
        assert!((t.hour_of(t.per_flight) / 1e-6 - 1.0).abs() < 1e-12);
        assert_eq!(FlightTarget::per_hour(1e-7, 3600.0, Allocation::Deck, None).per_flight, 1e-7);
    }

    /// Only confirmed detectors go into `thresholds.csv`; with none confirmed nothing is written as a
    /// calibration and an earlier search's file is removed, while `flight_thresholds.csv` says why.
    #[test]
    fn an_unconfirmed_detector_is_no_calibration() {
        let target = FlightTarget::per_flight(1e-7, 30.0, Allocation::Equal, None);
        let (yes, no) = (found("a", 0.95e-7, true), found("b", 1.2e-7, false));
        assert!(no.statement(&target).contains("NOT confirmed: the one-sided bound is above the target"));
        assert!(yes.statement(&target).ends_with(": confirmed"), "{}", yes.statement(&target));
        let dir = tempfile::tempdir().unwrap();
        let written = write(dir.path(), &[yes.clone(), no.clone()], &target).unwrap();
        assert_eq!(written.len(), 2);
        let calibration =
            crate::engine::results::thresholds::read_thresholds(&dir.path().join(THRESHOLDS_FILE)).unwrap();
        assert_eq!(calibration.detectors, vec![("a".to_string(), vec![3.0, 4.0], vec![3.0, 4.0])]);
        let table = std::fs::read_to_string(dir.path().join(FLIGHT_THRESHOLDS_FILE)).unwrap();
        assert_eq!(table.lines().count(), 5, "{table}");
        let written = write(dir.path(), &[no], &target).unwrap();
        assert_eq!(written.len(), 1);
        assert!(!dir.path().join(THRESHOLDS_FILE).exists());
    }
}
