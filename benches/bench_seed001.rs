//! Per-core cost of a method-001 trial on `studies/seed001_thrust.toml`: the launch vehicle's truth by
//! RK4, the 13-state EKF and the moving-horizon estimator at 100 Hz (the deck's two detectors share the
//! filter). Design and loss tables are built before the timing. Run: `cargo bench --bench bench_seed001`.

mod nonlinear;

use std::path::Path;

use fdimc::engine::run::runner::TrialSource;
use fdimc::engine::scenario::deck::FromDeck;
use fdimc::methods::thrust_loss::LaunchTrials;
use fdimc::methods::thrust_loss::study::LaunchStudy;

fn main() {
    let deck = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/seed001_thrust.toml");
    let study = LaunchStudy::load(&deck).expect("bundled deck");
    let trials = LaunchTrials::new(&study).expect("design");
    let detectors = study.detectors.len();
    nonlinear::report("seed001_thrust", study.header.duration_s, detectors, |t| trials.trial(t));
}
