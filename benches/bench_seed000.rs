//! Per-core cost of one bench-deck trial (`studies/bench_seed000.toml`: 30 s at 100 Hz, 5 states,
//! 6 noisy outputs, one detection filter) on three loops:
//! - `lane path`: what `fdimc run` does, [`LANES`] trials advanced together (records, alarms,
//!   profiles);
//! - `general path`: the same kind of trials one at a time (the reference the lane path is tested
//!   against);
//! - `plain nalgebra`: the floor the speed issue quotes, a per-trial nalgebra loop doing only the
//!   arithmetic and the six normal draws per step (no faults, no statistics, no records).
//!
//! The loops run interleaved, a few milliseconds each in turn, so that a virtual machine whose speed
//! drifts during the run (seen here: 1.2x to 2x within minutes) slows all of them alike and their
//! ratio stays meaningful. Run: `cargo bench --bench bench_seed000` (one core).

use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

use nalgebra::{SMatrix, SVector};
use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
use rand_distr::StandardNormal;

use fdimc::engine::scenario::deck::FromDeck;
use fdimc::methods::detection_filter::kernel::LANES;
use fdimc::methods::detection_filter::study::LtiStudy;
use fdimc::methods::detection_filter::trials::Engine;

const ROUNDS: usize = 480 / LANES;
/// One lane group per turn.
const TRIALS_PER_TURN: u64 = LANES as u64;

fn main() {
    let study =
        LtiStudy::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/bench_seed000.toml")).expect("bench deck");
    let engine = Engine::new(&study);
    let plain = PlainLoop::new(&study, &engine);

    let mut spent = [Duration::ZERO; 3];
    let mut next = 0u64;
    for _ in 0..ROUNDS {
        let first = next;
        next += TRIALS_PER_TURN;
        let t0 = Instant::now();
        black_box(engine.run_lanes(first, next));
        let t1 = Instant::now();
        for trial in first..next {
            black_box(engine.run(trial));
        }
        let t2 = Instant::now();
        for trial in first..next {
            black_box(plain.run(&study, trial));
        }
        let t3 = Instant::now();
        spent[0] += t1 - t0;
        spent[1] += t2 - t1;
        spent[2] += t3 - t2;
    }
    let trials = (ROUNDS as u64 * TRIALS_PER_TURN) as f64;
    let steps = study.header.steps as f64;
    println!("bench_seed000, one core, {trials} trials per loop, {} steps per trial", study.header.steps);
    for (name, d) in ["lane path", "general path", "plain nalgebra"].iter().zip(spent) {
        let per_trial_s = d.as_secs_f64() / trials;
        println!(
            "  {name:<15} {:8.1} us/trial {:6.1} ns/step {:8.0} trials/s  ({:.2}x plain nalgebra)",
            per_trial_s * 1e6,
            per_trial_s / steps * 1e9,
            1.0 / per_trial_s,
            spent[2].as_secs_f64() / d.as_secs_f64()
        );
    }
}

/// The reference loop on the bench deck's matrices.
struct PlainLoop {
    ad: SMatrix<f64, 5, 5>,
    bd: SMatrix<f64, 5, 2>,
    c: SMatrix<f64, 6, 5>,
    g: SMatrix<f64, 2, 6>,
    filter_ad: SMatrix<f64, 5, 5>,
    filter_bd: SMatrix<f64, 5, 2>,
    filter_k: SMatrix<f64, 5, 6>,
    sigma: SVector<f64, 6>,
}

impl PlainLoop {
    fn new(study: &LtiStudy, engine: &Engine) -> Self {
        let truth = study.plant.discretise(study.header.dt_s);
        let filter = engine.nominal_filters()[0].as_ref().expect("bench design");
        PlainLoop {
            ad: SMatrix::from_iterator(truth.Ad.iter().copied()),
            bd: SMatrix::from_iterator(truth.Bd.iter().copied()),
            c: SMatrix::from_iterator(truth.C.iter().copied()),
            g: SMatrix::from_iterator(study.output_feedback.iter().copied()),
            filter_ad: SMatrix::from_iterator(filter.model.Ad.iter().copied()),
            filter_bd: SMatrix::from_iterator(filter.model.Bd.iter().copied()),
            filter_k: SMatrix::from_iterator(filter.discrete.K.iter().copied()),
            sigma: SVector::from_iterator(study.sensor_sigma.iter().copied()),
        }
    }

    /// Largest |residual| of one trial.
    fn run(&self, study: &LtiStudy, trial: u64) -> f64 {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(trial);
        let (mut x, mut xhat) = (SVector::<f64, 5>::zeros(), SVector::<f64, 5>::zeros());
        let mut peak = 0.0f64;
        for k in 0..study.header.steps {
            let t = k as f64 * study.header.dt_s;
            let r = SVector::<f64, 2>::new(0.0, if (t / 8.0).fract() < 0.5 { 0.25 } else { -0.25 });
            let noise = SVector::<f64, 6>::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
            let y = self.c * x + self.sigma.component_mul(&noise);
            let u = r - self.g * y;
            let gamma = y - self.c * xhat;
            xhat = self.filter_ad * xhat + self.filter_bd * u + self.filter_k * gamma;
            x = self.ad * x + self.bd * u;
            peak = peak.max(gamma.amax());
        }
        peak
    }
}
