//! `fdimc flight-thresholds` for detection filters (issue 84): thresholds whose false-alarm
//! probability over a whole flight meets a target, on the fault-free residual's exact law
//! ([`super::false_alarms`]: the model exact, white Gaussian noise, the `|residual|` test, the filter
//! started on the truth).
//!
//! 1. Sidak's bound over the flight, `1 - prod_k prod_j (1 - 2 Q(T_j / sigma_j(k)))` from the
//!    per-sample standard deviations in closed form, is solved for the thresholds: each output's
//!    equal share of the target, or one scale of the deck's thresholds.
//! 2. Where alarms cluster (a slow mode, several outputs that see one error) the bound is above the
//!    probability: the conditional Monte Carlo estimate at those thresholds gives the ratio, and the
//!    bound is solved again for the target over it, until the ratio settles (within 2 %, at most
//!    [`ROUNDS`] rounds).
//! 3. The search aims at [`AIM`] of the target; the thresholds are then confirmed by fresh draws of
//!    the conditional estimate (another seed), whose one-sided 95 % upper bound must lie below the
//!    target. The exact law's bounds at the thresholds (Sidak or Hunter above, Bonferroni or de Caen
//!    below) are reported beside it.
#![allow(non_snake_case)]

use super::false_alarms::{AnalyticFalseAlarms, CONDITIONAL_SEED, HourSpread, analytic_false_alarms};
use super::study::LtiStudy;
use crate::engine::results::flight_thresholds::{Allocation, Estimate, FlightSearch, FlightTarget, FoundThresholds};
use crate::engine::run::runner::RunError;

/// The share of the target the search aims at, leaving room for the confirmation's interval (a
/// choice, not a paper's).
pub const AIM: f64 = 0.9;
/// The longest flight, in samples: the law keeps a few matrices per sample.
pub const MAX_FLIGHT_SAMPLES: f64 = 1e6;
/// The search's rounds of correcting Sidak's bound by the conditional estimate, at most.
pub const ROUNDS: u64 = 4;

/// [`crate::engine::method::Method::flight_thresholds`] of detection-filter decks: the deck in `text`
/// (read from `path`), detector `detector` or every one. A deck that flies an FMU is refused before it
/// is loaded (its residual's law is not the linear model's, and loading would run the FMU here).
pub fn for_deck(
    text: &str,
    path: &std::path::Path,
    detector: Option<&str>,
    target: &FlightTarget,
) -> Result<FlightSearch, RunError> {
    use crate::engine::scenario::deck::FromDeck;
    let invalid = |e: crate::engine::scenario::deck::DeckError| RunError::Invalid(e.to_string());
    let deck = crate::engine::scenario::deck::parse_deck::<super::deck::Deck>(text, path).map_err(invalid)?;
    if deck.flies_fmu() {
        return Err(RunError::Invalid(format!(
            "{}: flies an FMU (truth, controller or detector): its residual's law is not the linear model's, so \
             no exact law finds its thresholds; estimate per flight with fdimc rare-event {} --flight-s F --levels ... \
             and read per_hour.csv",
            path.display(),
            path.display()
        )));
    }
    let study = LtiStudy::from_toml(text, path).map_err(invalid)?;
    let names: Vec<&str> = study.detectors.iter().map(|d| d.name.as_str()).collect();
    let chosen: Vec<usize> = match detector {
        None => (0..names.len()).collect(),
        Some(name) => vec![names.iter().position(|n| *n == name).ok_or_else(|| {
            RunError::Invalid(format!("{}: no detector {name:?} (the deck has {})", path.display(), names.join(", ")))
        })?],
    };
    // One detector's search at a time, each using every worker for its draws. Unnamed, a detector the
    // exact law does not cover is skipped (said why); named, or none covered, it is refused.
    let mut search = FlightSearch::default();
    for d in chosen {
        match find(&study, d, target) {
            Ok(found) => search.found.push(found),
            Err(e) if detector.is_none() => search.skipped.push(e),
            Err(e) => return Err(RunError::Invalid(format!("{}: {e}", path.display()))),
        }
    }
    if search.found.is_empty() {
        return Err(RunError::Invalid(format!(
            "{}: no detector the residual's exact law covers: {}",
            path.display(),
            search.skipped.join("; ")
        )));
    }
    Ok(search)
}

/// The thresholds of detector `detector` of `study` for `target`, or why its residual's law is not
/// the exact one (then nothing can be found this way).
pub fn find(study: &LtiStudy, detector: usize, target: &FlightTarget) -> Result<FoundThresholds, String> {
    let d = &study.detectors[detector];
    let filter = d.params.design(&study.design_plant, study.header.dt_s).map_err(|e| format!("{}: {e}", d.name))?;
    let sensor_sigma = super::false_alarms::exact_law_sensor_sigma(study, &filter)
        .map_err(|e| format!("{}: not the exact law's setting: {e}", d.name))?;
    let (Ad, Kd, C) = (&filter.model.Ad, &filter.discrete.K, &filter.model.C);
    let process = &study.process_sigma_per_step;
    let dt_s = study.header.dt_s;
    let samples = (target.flight_s / dt_s).round();
    if !(1.0..=MAX_FLIGHT_SAMPLES).contains(&samples) {
        return Err(format!(
            "--flight-s {}: {samples} samples at the deck's dt_s {dt_s}; allowed 1 to {MAX_FLIGHT_SAMPLES:.0}",
            target.flight_s
        ));
    }
    let samples = samples as usize;
    let spread = HourSpread::reaching(Ad, Kd, C, &sensor_sigma, process, 1, dt_s, samples).ok_or_else(|| {
        format!(
            "{}: the filter's error dynamics are unstable or undamped: its residual has no law over a flight",
            d.name
        )
    })?;
    let deck: Vec<f64> = filter.thresholds.iter().copied().collect();
    let ny = deck.len();
    let sidak = |t: &[f64]| -> f64 { -(0..ny).map(|j| spread.log_no_alarm(j, t[j], samples)).sum::<f64>().exp_m1() };
    let solve = |aim: f64| -> Vec<f64> {
        let log_none = (-aim.min(0.5)).ln_1p();
        match target.allocation {
            Allocation::Equal => (0..ny)
                .map(|j| {
                    let scale = spread.settled()[j];
                    root(|t| spread.log_no_alarm(j, t, samples) - log_none / ny as f64, scale)
                })
                .collect(),
            Allocation::Deck => {
                let at = |c: f64| -> Vec<f64> { deck.iter().map(|t| t * c).collect() };
                let c = root(
                    |c| (0..ny).map(|j| spread.log_no_alarm(j, deck[j] * c, samples)).sum::<f64>() - log_none,
                    1.0,
                );
                at(c)
            }
        }
    };
    let law = |t: &[f64], seed: u64| -> AnalyticFalseAlarms {
        analytic_false_alarms(Ad, Kd, C, &sensor_sigma, process, t, samples, seed)
    };
    // Rounds: Sidak's bound over the estimate's ratio to it.
    let mut ratio = 1.0;
    let mut thresholds = solve(AIM * target.per_flight);
    let mut search = law(&thresholds, CONDITIONAL_SEED);
    for round in 1..=ROUNDS {
        let r = (search.conditional / sidak(&thresholds)).clamp(1e-6, 1.0);
        if (r / ratio - 1.0).abs() < 0.02 {
            break;
        }
        ratio = r;
        thresholds = solve(AIM * target.per_flight / ratio);
        search = law(&thresholds, CONDITIONAL_SEED.wrapping_add(round));
    }
    // Fresh draws: a seed none of the search's used.
    // The confirmation's draws: from the deck's (or --seed's) seed, on the conditional estimate's streams
    // with a mark the search's seeds (CONDITIONAL_SEED and the next few) do not carry.
    let seed = target.seed.unwrap_or(study.header.seed) ^ 0xc0ff_1a7e_5eed;
    let check = law(&thresholds, seed);
    let estimate = |a: &AnalyticFalseAlarms| Estimate {
        value: a.conditional,
        lo: a.conditional_lo,
        hi: a.conditional_hi,
        upper_95: a.conditional_upper_95,
        draws: a.conditional_draws,
    };
    let (upper, upper_from) = if check.hunter_upper < check.sidak_upper {
        (check.hunter_upper, "Hunter")
    } else {
        (check.sidak_upper, "Sidak")
    };
    Ok(FoundThresholds {
        detector: d.name.clone(),
        statistics: study.plant.output_names.clone(),
        deck_thresholds: deck,
        method: format!(
            "the residual's exact law over the flight: Sidak's bound solved for {} % of the target, corrected by \
             the conditional Monte Carlo estimate's ratio to it; confirmed by {} fresh draws",
            100.0 * AIM,
            check.conditional_draws
        ),
        upper,
        upper_from: upper_from.to_string(),
        lower: check.lower,
        lower_from: check.lower_from(),
        search: estimate(&search),
        confirmation: estimate(&check),
        seed,
        confirmed: check.conditional_upper_95 < target.per_flight,
        thresholds,
    })
}

/// The `x > 0` where the increasing `f` crosses 0, starting from the scale `x0 > 0`: bracketed by
/// doubling and halving, then bisected to 1e-12 of `x`.
fn root(f: impl Fn(f64) -> f64, x0: f64) -> f64 {
    let (mut lo, mut hi) = (x0, x0);
    while f(hi) < 0.0 && hi < 1e300 {
        hi *= 2.0;
    }
    while !(f(lo) < 0.0) && lo > 1e-300 {
        lo /= 2.0;
    }
    while hi - lo > 1e-12 * hi {
        let mid = 0.5 * (lo + hi);
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::deck::FromDeck;

    /// On a residual without memory (gain 0, the plant's own pole: the residual is the sensor noise),
    /// Sidak's bound is the probability: `1 - (1 - 2 Q(T))^N` solved by hand gives the threshold, and
    /// the confirmation is the same number (one event per draw).
    #[test]
    fn a_white_residual_gets_the_threshold_of_its_closed_form() {
        let deck = include_str!("../../../tests/data/white_residual.toml");
        let study = LtiStudy::from_toml(deck, std::path::Path::new("white_residual.toml")).unwrap();
        let target = FlightTarget::per_flight(1e-7, 2.0, Allocation::Equal, None);
        let found = find(&study, 0, &target).unwrap();
        // 200 samples of N(0, 1): 1 - (1 - 2 Q(T))^200 = 0.9e-7 <=> 2 Q(T) = 1 - (1 - 0.9e-7)^(1/200).
        let per_sample = -((-0.9e-7f64).ln_1p() / 200.0).exp_m1();
        let t = root(|t| per_sample - 2.0 * crate::engine::stats::intervals::normal_sf(t), 1.0);
        assert!((found.thresholds[0] / t - 1.0).abs() < 1e-9, "{} vs {t}", found.thresholds[0]);
        assert!((6.23..6.24).contains(&t), "{t}");
        assert!((found.confirmation.value / 0.9e-7 - 1.0).abs() < 1e-6, "{found:?}");
        assert!(found.confirmed && found.lower > 0.99 * 0.9e-7 && found.upper <= 0.9e-7 * (1.0 + 1e-9), "{found:?}");
    }
}
