//! Exact answers for the figures a safety case quotes (issue 82, item 1): the laws the tests and
//! `fdimc verify` hold fdimc's estimates to. Written apart from fdimc's estimators and sharing nothing
//! with them: this module imports nothing from the rest of the crate (`tests/layers.rs` checks it), only
//! nalgebra and statrs' `erfc`.
//!
//! - [`false_alarms`]: a linear filter's fault-free residual over a trial or a flight, bracketed by
//!   Sidak's and the second Bonferroni inequality;
//! - [`slow_mode`]: a residual with one slow mode (an AR(1) state error plus white noise), its miss
//!   before the hazard and its false alarms over a trial, a flight or an hour, on a grid;
//! - [`cusum`]: Page's CUSUM on a white residual, Brook and Evans' chain;
//! - [`fewest_covered`]: how many of a number of seeds 95 % intervals must cover.

pub mod cusum;
pub mod false_alarms;
pub mod slow_mode;

/// The fewest of `seeds` seeds whose 95 % intervals must hold a known value before the estimator is
/// suspect: with a true coverage of 95 % fewer are covered with probability under 0.005 (the binomial's
/// tail summed exactly). 5 of 8, 16 of 20, 34 of 40 (SciPy's `binom.sf` gives the same).
pub fn fewest_covered(seeds: u64) -> u64 {
    // P(misses = k) for k misses of `seeds` at 0.05, each from the last.
    let pmf =
        |k: u64| (0..k).fold(0.95f64.powi(seeds as i32), |p, i| p * (seeds - i) as f64 / (i + 1) as f64 * 0.05 / 0.95);
    let mut allowed = 0;
    while (allowed + 1..=seeds).map(pmf).sum::<f64>() >= 0.005 {
        allowed += 1;
    }
    seeds - allowed
}

/// `Phi(x)`, the standard normal's distribution function (for `x` well below 0 it keeps the tail's digits).
fn normal_cdf(x: f64) -> f64 {
    0.5 * statrs::function::erf::erfc(-x / std::f64::consts::SQRT_2)
}

/// The normal density at `x` of mean `mean` and standard deviation `sd`.
fn normal_pdf(x: f64, mean: f64, sd: f64) -> f64 {
    let z = (x - mean) / sd;
    (-0.5 * z * z).exp() / (sd * (2.0 * std::f64::consts::PI).sqrt())
}

#[cfg(test)]
mod tests {
    /// Against SciPy: the fewest k with `binom.sf(seeds - k, seeds, 0.05) < 0.005`.
    #[test]
    fn fewest_covered_matches_the_binomial_tail() {
        assert_eq!([8, 20, 40].map(super::fewest_covered), [5, 16, 34]);
    }
}
