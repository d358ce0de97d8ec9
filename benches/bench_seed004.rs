//! Per-core cost of a method-004 trial on `studies/seed004_monte_carlo.toml`: the 6-DoF truth by RK4
//! and 4 banks of 6 (strong-tracking) EKFs at 100 Hz; then the cost of one filter's likelihood in each
//! form (the seed's claim for its fast probabilities, section 2.6). Run: `cargo bench --bench bench_seed004`.

mod nonlinear;

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use fdimc::engine::run::runner::TrialSource;
use fdimc::engine::scenario::deck::FromDeck;
use fdimc::estimation::{Innovation, LikelihoodForm};
use fdimc::methods::surface_bank::SurfaceTrials;
use fdimc::methods::surface_bank::study::SurfaceStudy;
use nalgebra::{SMatrix, SVector};

fn main() {
    let deck = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/seed004_monte_carlo.toml");
    let study = SurfaceStudy::load(&deck).expect("bundled deck");
    let trials = SurfaceTrials::new(&study);
    let banks = study.banks.len();
    nonlinear::report("seed004_monte_carlo", study.header.duration_s, banks, |t| trials.trial(t));
    likelihoods();
}

/// ns per `log_likelihood` call on a 5-component innovation (the bank's outputs), as a filter hands it
/// over: `S^-1` and `det S` already computed for its gain, so the Gaussian pays only the quadratic form.
fn likelihoods() {
    const CALLS: u32 = 20_000_000;
    let covariance = SMatrix::<f64, 5, 5>::from_fn(|i, j| if i == j { 0.1 + 0.02 * i as f64 } else { 0.003 });
    let covariance = covariance * covariance.transpose();
    // Eight innovations in turn, so that no call is hoisted out of the loop.
    let innovations: Vec<Innovation<5>> = (0..8)
        .map(|k| Innovation {
            gamma: SVector::<f64, 5>::from_fn(|i, _| 0.05 * (i as f64 - 2.0) + 1e-3 * k as f64),
            S: covariance,
            S_inverse: covariance.try_inverse(),
            S_determinant: Some(covariance.determinant()),
        })
        .collect();
    println!("one filter's likelihood, 5 outputs, {CALLS} calls each:");
    for (name, form) in [
        ("gaussian", LikelihoodForm::Gaussian),
        ("euclidean_norm", LikelihoodForm::EuclideanNorm),
        ("euclidean_norm_1d", LikelihoodForm::EuclideanNormOneDimensional),
    ] {
        let start = Instant::now();
        let mut sum = 0.0;
        for k in 0..CALLS {
            sum += form.log_likelihood(black_box(&innovations[(k & 7) as usize]));
        }
        black_box(sum);
        println!("  {name:<18} {:.1} ns per call", start.elapsed().as_secs_f64() * 1e9 / f64::from(CALLS));
    }
}
