//! Per-core cost of a method-002 trial on `studies/seed002_air_data.toml`: the flight profile and its
//! sensors, and the deck's dual-model UKF detectors at 100 Hz. Run: `cargo bench --bench bench_seed002`.

mod nonlinear;

use std::path::Path;

use fdimc::engine::run::runner::TrialSource;
use fdimc::engine::scenario::deck::FromDeck;
use fdimc::methods::air_data::AirDataTrials;
use fdimc::methods::air_data::study::AirDataStudy;

fn main() {
    let deck = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/seed002_air_data.toml");
    let study = AirDataStudy::load(&deck).expect("bundled deck");
    let trials = AirDataTrials::new(&study);
    let detectors = study.detectors.len();
    nonlinear::report("seed002_air_data", study.header.duration_s, detectors, |t| trials.trial(t));
}
