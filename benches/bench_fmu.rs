//! The cost per step of an FMU plant against the same equations in Rust, one trial at a time with the
//! same integrator (fdimc's RK4 at 0.01 s): the 5-state aircraft and the 11-state actuated aircraft of
//! `fmus/` (model exchange: fdimc's RK4 calls the FMU's derivatives four times per step), and the
//! aircraft's co-simulation interface (its own fixed-step solver) for comparison.
//! Run: `cargo bench --bench bench_fmu` (builds the test FMUs into a temporary folder first).
//!
//! Interleaved: each round times one 20 s trial of every variant in turn, so a busy machine slows all
//! alike; the report gives the median over the rounds.

#[path = "../tests/support/build_fmus.rs"]
mod build_fmus;

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use fdimc::fmu::integrator::Rk4;
use fdimc::fmu::{Fmu, Interface};
use fdimc::vehicles::{actuated, longitudinal};

const DT_S: f64 = 0.01;
const STEPS: usize = 2000;
const ROUNDS: usize = 41;

/// One trial: the plant from `x0` under a 0.02 rad elevator square wave (period 8 s) about the trim.
fn elevator(k: usize, trim: f64) -> f64 {
    let t = k as f64 * DT_S;
    trim + if (t % 8.0) < 4.0 { 0.02 } else { -0.02 }
}

const ELEVATOR_TRIM: f64 = 0.0211591440454;
const THROTTLE_TRIM: f64 = 0.459166130340;

fn native_aircraft(rk: &mut Rk4) -> f64 {
    let p = longitudinal::LongitudinalParams::default();
    let mut x = [53.6, 0.0443566119725, 0.0, 0.0443566119725, 1000.0];
    for k in 0..STEPS {
        let u = [elevator(k, ELEVATOR_TRIM), THROTTLE_TRIM, 1.0];
        rk.step::<()>(&mut x, k as f64 * DT_S, DT_S, |_, s, dx| {
            dx.copy_from_slice(&longitudinal::derivatives(&p, &[s[0], s[1], s[2], s[3], s[4]], &u));
            Ok(())
        })
        .unwrap();
    }
    x[2]
}

fn native_actuated(rk: &mut Rk4, x0: &[f64; 11]) -> f64 {
    let p = actuated::ActuatedParams::default();
    let mut x = *x0;
    for k in 0..STEPS {
        let u = [elevator(k, ELEVATOR_TRIM), THROTTLE_TRIM, 1.0];
        rk.step::<()>(&mut x, k as f64 * DT_S, DT_S, |_, s, dx| {
            let s: &[f64; 11] = s.try_into().unwrap();
            dx.copy_from_slice(&actuated::derivatives(&p, s, &u));
            Ok(())
        })
        .unwrap();
    }
    x[2]
}

/// One trial on an FMU instance: reset, trim inputs, initialise, then per step set the inputs and step.
fn fmu_trial(i: &mut fdimc::fmu::Instance, inputs: &[u32]) -> f64 {
    i.reset().unwrap();
    i.set_real(inputs, &[ELEVATOR_TRIM, THROTTLE_TRIM]).unwrap();
    i.initialise(0.0, STEPS as f64 * DT_S).unwrap();
    for k in 0..STEPS {
        i.set_real(inputs, &[elevator(k, ELEVATOR_TRIM), THROTTLE_TRIM]).unwrap();
        i.step(k as f64 * DT_S, DT_S).unwrap();
    }
    i.time_s()
}

fn vrs(fmu: &Fmu, names: &[&str]) -> Vec<u32> {
    names.iter().map(|n| fmu.description.variable(n).unwrap().value_reference).collect()
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    build_fmus::build_all(root, dir.path()).unwrap();
    let aircraft = Fmu::open(&dir.path().join("aircraft.fmu")).unwrap();
    let actuated_fmu = Fmu::open(&dir.path().join("aircraft_actuated.fmu")).unwrap();
    let aircraft_inputs = vrs(&aircraft, &["elevator_rad", "throttle"]);
    let actuated_inputs = vrs(&actuated_fmu, &["elevator_cmd_rad", "throttle_cmd"]);
    let mut me5 = aircraft.instantiate(Interface::ModelExchange, "bench").unwrap();
    let mut cs5 = aircraft.instantiate(Interface::CoSimulation, "bench").unwrap();
    let mut me11 = actuated_fmu.instantiate(Interface::ModelExchange, "bench").unwrap();
    // The native 11-state model starts where the FMU does.
    me11.set_real(&actuated_inputs, &[ELEVATOR_TRIM, THROTTLE_TRIM]).unwrap();
    me11.initialise(0.0, 20.0).unwrap();
    let x0: [f64; 11] = me11.states().unwrap().try_into().unwrap();
    let (mut rk5, mut rk11) = (Rk4::new(5), Rk4::new(11));

    let mut times: [Vec<f64>; 5] = Default::default();
    let mut time = |slot: usize, f: &mut dyn FnMut() -> f64| {
        let start = Instant::now();
        black_box(f());
        times[slot].push(start.elapsed().as_secs_f64() / STEPS as f64);
    };
    for _ in 0..ROUNDS {
        time(0, &mut || native_aircraft(&mut rk5));
        time(1, &mut || fmu_trial(&mut me5, &aircraft_inputs));
        time(2, &mut || fmu_trial(&mut cs5, &aircraft_inputs));
        time(3, &mut || native_actuated(&mut rk11, &x0));
        time(4, &mut || fmu_trial(&mut me11, &actuated_inputs));
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2] * 1e9
    };
    let m: Vec<f64> = times.iter_mut().map(median).collect();
    println!("cost per 0.01 s step, one trial at a time, median of {ROUNDS} interleaved 20 s trials:");
    println!(
        "  aircraft, 5 states:  Rust + RK4 {:>8.0} ns   FMU model exchange + the same RK4 {:>8.0} ns   ratio {:.2}",
        m[0],
        m[1],
        m[1] / m[0]
    );
    println!("  aircraft, 5 states:  FMU co-simulation (its own solver) {:>8.0} ns", m[2]);
    println!(
        "  actuated, 11 states: Rust + RK4 {:>8.0} ns   FMU model exchange + the same RK4 {:>8.0} ns   ratio {:.2}",
        m[3],
        m[4],
        m[4] / m[3]
    );
}
