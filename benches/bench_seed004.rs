//! Per-core cost of a method-004 trial on `studies/seed004_monte_carlo.toml`: the 6-DoF truth by RK4
//! and 4 banks of 6 (strong-tracking) EKFs at 100 Hz. Run: `cargo bench --bench bench_seed004`.

mod nonlinear;

use std::path::Path;

use fdimc::engine::run::runner::TrialSource;
use fdimc::engine::scenario::deck::FromDeck;
use fdimc::methods::surface_bank::SurfaceTrials;
use fdimc::methods::surface_bank::study::SurfaceStudy;

fn main() {
    let deck = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/seed004_monte_carlo.toml");
    let study = SurfaceStudy::load(&deck).expect("bundled deck");
    let trials = SurfaceTrials::new(&study);
    let banks = study.banks.len();
    nonlinear::report("seed004_monte_carlo", study.header.duration_s, banks, |t| trials.trial(t));
}
