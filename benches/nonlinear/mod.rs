//! What the nonlinear methods' benches share: trials of a bundled deck on one core, timed, and reported
//! as time per simulated second of flight.

use std::hint::black_box;
use std::time::{Duration, Instant};

/// Trials timed at least, and the time after which no new one starts.
const MIN_TRIALS: u64 = 8;
const BUDGET: Duration = Duration::from_secs(20);

/// Runs `trial(0)` untimed (first-touch costs), then trials 1, 2, .. until [`BUDGET`] is spent (at
/// least [`MIN_TRIALS`]), and prints the cost per trial and per simulated second of `flight_s`.
pub fn report<R>(name: &str, flight_s: f64, detectors: usize, trial: impl Fn(u64) -> R) {
    black_box(trial(0));
    let start = Instant::now();
    let mut trials = 0u64;
    while trials < MIN_TRIALS || start.elapsed() < BUDGET {
        trials += 1;
        black_box(trial(trials));
    }
    let per_trial_s = start.elapsed().as_secs_f64() / trials as f64;
    println!("{name}, one core, {trials} trials of {flight_s} s, {detectors} detectors each:");
    println!("  {:.1} ms per trial ({:.2} trials/s)", 1e3 * per_trial_s, 1.0 / per_trial_s);
    println!(
        "  {:.3} ms per simulated second of flight ({:.0}x real time)",
        1e3 * per_trial_s / flight_s,
        flight_s / per_trial_s
    );
}
