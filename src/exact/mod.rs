//! Exact answers for the figures a safety case quotes (issue 82, item 1): the laws the tests and
//! `fdimc verify` hold fdimc's estimates to. Written apart from fdimc's estimators and sharing nothing
//! with them: this module imports nothing from the rest of the crate (`tests/layers.rs` checks it), only
//! nalgebra and statrs' `erfc`.
//!
//! - [`false_alarms`]: a linear filter's fault-free residual over a trial or a flight, bracketed by
//!   Sidak's and the second Bonferroni inequality;
//! - [`slow_mode`]: a residual with one slow mode (an AR(1) state error plus white noise), its miss
//!   before the hazard and its false alarms over a trial, a flight or an hour, on a grid;
//! - [`cusum`]: Page's CUSUM on a white residual, Brook and Evans' chain.

pub mod cusum;
pub mod false_alarms;
pub mod slow_mode;

/// `Phi(x)`, the standard normal's distribution function (for `x` well below 0 it keeps the tail's digits).
fn normal_cdf(x: f64) -> f64 {
    0.5 * statrs::function::erf::erfc(-x / std::f64::consts::SQRT_2)
}

/// The normal density at `x` of mean `mean` and standard deviation `sd`.
fn normal_pdf(x: f64, mean: f64, sd: f64) -> f64 {
    let z = (x - mean) / sd;
    (-0.5 * z * z).exp() / (sd * (2.0 * std::f64::consts::PI).sqrt())
}
