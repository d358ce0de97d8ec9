//! Per-core cost of one robustness-deck trial (`studies/seed000_robustness.toml`: 30 s at 100 Hz, four
//! detectors on every trial: two eigenvalue sets, the CUSUM and the Kalman chi-square test, each
//! designed on the trial's design model) on the two paths of the engine:
//! - `lane path`: what `fdimc run` does, [`LANES`] trials advanced together, every detector of the deck
//!   on the lanes (issue 48);
//! - `one at a time`: the same trials on the general path (the reference the lane path is tested
//!   against, and what every trial of this deck took while one of its tests was not on the lanes).
//!
//! Both engines are warmed on the same trials first (each keeps the designs of the deck's 25 design
//! models), then the loops run interleaved, a lane group each in turn, so that a virtual machine whose
//! speed drifts slows both alike. Run: `cargo bench --bench bench_robustness` (one core). The whole
//! deck side by side with an older binary: docs/performance.md.

use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

use fdimc::engine::scenario::deck::FromDeck;
use fdimc::methods::detection_filter::kernel::LANES;
use fdimc::methods::detection_filter::study::LtiStudy;
use fdimc::methods::detection_filter::trials::Engine;

const ROUNDS: u64 = 120 / LANES as u64;

fn main() {
    let study = LtiStudy::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/seed000_robustness.toml"))
        .expect("robustness deck");
    let engine = Engine::new(&study);
    let lanes = LANES as u64;
    // Warm: every design model the measured trials meet, on both paths (one engine serves both).
    for first in (0..ROUNDS * lanes).step_by(LANES) {
        black_box(engine.run_group(first, first + lanes));
    }
    let mut spent = [Duration::ZERO; 2];
    for round in 0..ROUNDS {
        let (first, end) = (round * lanes, (round + 1) * lanes);
        let t0 = Instant::now();
        black_box(engine.run_lanes(first, end));
        let t1 = Instant::now();
        for trial in first..end {
            black_box(engine.run(trial));
        }
        spent[0] += t1 - t0;
        spent[1] += t1.elapsed();
    }
    let trials = (ROUNDS * lanes) as f64;
    println!("bench_robustness, one core, {trials} trials per loop, 4 detectors per trial");
    for (name, d) in ["lane path", "one at a time"].iter().zip(spent) {
        let per_trial_s = d.as_secs_f64() / trials;
        println!(
            "  {name:<14} {:8.1} us/trial {:8.0} trials/s  ({:.2}x the lane path's time)",
            per_trial_s * 1e6,
            1.0 / per_trial_s,
            d.as_secs_f64() / spent[0].as_secs_f64()
        );
    }
}
