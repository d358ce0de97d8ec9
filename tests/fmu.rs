//! FMUs through the path a user's FMU takes: the test FMUs of `fmus/` are compiled and packed into real
//! `.fmu` archives (tests/support/build_fmus.rs), opened with `fdimc::fmu::Fmu::open` and stepped.
//! Reference values from FMPy 0.3.32 (an independent FMI simulator, BSD-2-Clause) were produced by
//! `scripts/fmpy_reference.py` on the same FMUs (fmus/README.md, "FMPy reference values").

#[path = "support/build_fmus.rs"]
mod build_fmus;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use fdimc::fmu::{Causality, Fmu, FmuError, Instance, Interface};
use fdimc::vehicles::longitudinal::{LongitudinalParams, derivatives};

/// The built FMUs, once per test process.
fn fmus() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("fdimc-test-fmus-{}", std::process::id()));
        build_fmus::build_all(Path::new(env!("CARGO_MANIFEST_DIR")), &dir).expect("the test FMUs build");
        dir
    })
}

fn open(name: &str) -> Fmu {
    Fmu::open(&fmus().join(format!("{name}.fmu"))).unwrap()
}

/// The aircraft's value references of the states, as the FMU names them.
fn vrs(fmu: &Fmu, names: &[&str]) -> Vec<u32> {
    names.iter().map(|n| fmu.description.variable(n).unwrap().value_reference).collect()
}

const STATES: [&str; 5] = ["V_m_s", "alpha_rad", "q_rad_s", "theta_rad", "h_m"];

/// Flies `instance` from t = 0 with the inputs held at elevator 0.02 rad, throttle 0.46, in steps of
/// 0.01 s, and returns the states at the steps `at` (step counts).
fn fly(fmu: &Fmu, instance: &mut Instance, at: &[usize]) -> Result<Vec<[f64; 5]>, FmuError> {
    let inputs = vrs(fmu, &["elevator_rad", "throttle"]);
    let states = vrs(fmu, &STATES);
    instance.set_real(&inputs, &[0.02, 0.46])?;
    instance.initialise(0.0, 10.0)?;
    let mut out = Vec::new();
    for k in 0..=*at.iter().max().unwrap() {
        if at.contains(&k) {
            let mut x = [0.0; 5];
            instance.get_real(&states, &mut x)?;
            out.push(x);
        }
        instance.step(k as f64 * 0.01, 0.01)?;
    }
    Ok(out)
}

/// FMPy, FMI 2.0 co-simulation of aircraft.fmu (its internal Euler step of 1e-3 s), elevator 0.02,
/// throttle 0.46, states at t = 0.5, 1, 2 s.
const FMPY_CS: [[f64; 5]; 3] = [
    [53.583920466744381, 0.045376794125924089, -0.003042055264560009, 0.048251145945704677, 1000.049280428889],
    [53.56953806903455, 0.04486607797260992, 0.0018493158776448433, 0.048088322807766155, 1000.1318582785906],
    [53.530930790772238, 0.045582643910343799, 0.0018169509891448282, 0.05038415250124148, 1000.341293875346],
];

/// FMPy, model exchange of aircraft.fmu with CVode at relative tolerance 1e-10: the exact trajectory
/// to about 1e-9.
const FMPY_ME_CVODE: [[f64; 5]; 3] = [
    [53.583923776488348, 0.045381878235326023, -0.0030371385467602595, 0.048253883516146616, 1000.0493030209418],
    [53.569532161994118, 0.04486763386528337, 0.0018385676787244923, 0.04809101976457273, 1000.1318768148362],
    [53.530915655820301, 0.045582093888145526, 0.0018193678217185926, 0.050383178182713401, 1000.3413940872622],
];

#[test]
fn the_aircraft_fmu_describes_itself_with_units_ranges_and_both_interfaces() {
    let fmu = open("aircraft");
    let d = &fmu.description;
    assert_eq!((d.fmi_version.as_str(), d.n_states, d.n_event_indicators), ("2.0", 5, 0));
    assert!(d.model_exchange.is_some() && d.co_simulation.is_some());
    assert_eq!(d.names_of(&[Causality::Input]), ["elevator_rad", "throttle", "elevator_effectiveness"]);
    let throttle = d.variable("throttle").unwrap();
    assert_eq!((throttle.min, throttle.max), (Some(0.0), Some(1.0)));
    assert_eq!(d.variable("m_kg").unwrap().unit.as_deref(), Some("kg"));
    assert_eq!(d.variable("Cma").unwrap().start_f64(), Some(-0.683));
    assert_eq!(fmu.sha256.len(), 64);
    fmu.supports(Interface::ModelExchange).unwrap();
    let cs_only = open("aircraft_cs");
    let e = cs_only.supports(Interface::ModelExchange).unwrap_err().to_string();
    assert!(e.contains("aircraft_cs.fmu: the FMU has no model_exchange interface; it offers co_simulation"), "{e}");
    open("aircraft_fmi3").supports(Interface::ModelExchange).unwrap();
}

#[test]
fn fmi2_and_fmi3_co_simulation_reproduce_fmpy_to_the_bit() {
    for name in ["aircraft", "aircraft_fmi3"] {
        let fmu = open(name);
        let mut i = fmu.instantiate(Interface::CoSimulation, "cs").unwrap();
        let got = fly(&fmu, &mut i, &[50, 100, 200]).unwrap();
        assert_eq!(got, FMPY_CS, "{name}");
    }
}

#[test]
fn model_exchange_stepped_by_rk4_equals_the_native_equations_to_the_bit_and_cvode_closely() {
    let fmu = open("aircraft");
    let mut i = fmu.instantiate(Interface::ModelExchange, "me").unwrap();
    let got = fly(&fmu, &mut i, &[50, 100, 200]).unwrap();
    // The same equations in Rust, stepped by the same integrator from the FMU's initial state.
    let p = LongitudinalParams::default();
    let mut x = [53.6, 0.05, 0.0, 0.05, 1000.0];
    let mut rk4 = fdimc::fmu::integrator::Rk4::new(5);
    let mut native = Vec::new();
    for k in 0..=200 {
        if [50, 100, 200].contains(&k) {
            native.push(x);
        }
        rk4.step::<()>(&mut x, k as f64 * 0.01, 0.01, |_, s, dx| {
            dx.copy_from_slice(&derivatives(&p, &[s[0], s[1], s[2], s[3], s[4]], &[0.02, 0.46, 1.0]));
            Ok(())
        })
        .unwrap();
    }
    assert_eq!(got, native);
    // RK4 at 0.01 s against CVode at 1e-10: the integrator's error, far below the Euler CS's 1.5e-5.
    for (g, c) in got.iter().zip(&FMPY_ME_CVODE) {
        for j in 0..5 {
            assert!((g[j] - c[j]).abs() < 1e-8 * c[j].abs().max(1.0), "{}: {} vs {}", STATES[j], g[j], c[j]);
        }
    }
    assert!((got[2][0] - FMPY_CS[2][0]).abs() > 1e-6, "RK4 and the FMU's own Euler differ");
    // FMI 3.0's model exchange of the same model, through its own calls, flies the same bits.
    let fmi3 = open("aircraft_fmi3");
    let mut i = fmi3.instantiate(Interface::ModelExchange, "me3").unwrap();
    assert_eq!(fly(&fmi3, &mut i, &[50, 100, 200]).unwrap(), got);
}

#[test]
fn a_reset_instance_flies_the_same_trial_as_a_fresh_one() {
    let fmu = open("aircraft");
    for interface in [Interface::ModelExchange, Interface::CoSimulation] {
        let mut fresh = fmu.instantiate(interface, "fresh").unwrap();
        let first = fly(&fmu, &mut fresh, &[100]).unwrap();
        // A different trial in between: another mass, set before initialisation.
        fresh.reset().unwrap();
        fresh.set_real(&vrs(&fmu, &["m_kg"]), &[1400.0]).unwrap();
        let heavier = fly(&fmu, &mut fresh, &[100]).unwrap();
        assert_ne!(first, heavier, "{interface:?}: the mass changed the flight");
        fresh.reset().unwrap();
        assert_eq!(fly(&fmu, &mut fresh, &[100]).unwrap(), first, "{interface:?}");
    }
}

#[test]
fn an_fmu_error_at_a_known_time_fails_the_call_that_reaches_it_with_the_fmus_message() {
    let fmu = open("aircraft");
    for interface in [Interface::ModelExchange, Interface::CoSimulation] {
        let mut i = fmu.instantiate(interface, "failing").unwrap();
        i.set_real(&vrs(&fmu, &["fail_at_s"]), &[1.0]).unwrap();
        let e = fly(&fmu, &mut i, &[150]).unwrap_err();
        let FmuError::Failed(text) = e else { panic!("{e:?}") };
        assert!(text.contains("aircraft.fmu:") && text.contains("failing at t=1 as asked by fail_at_s"), "{text}");
        // ME: the step from 0.99 s reaches t = 1 s in its last RK4 stage; CS: the step from 1 s, in its
        // first internal Euler step.
        assert!(text.contains("at t = 1 s"), "{text}");
        let last_good_s = if interface == Interface::ModelExchange { 0.99 } else { 1.0 };
        assert!((i.time_s() - last_good_s).abs() < 1e-12, "{interface:?}: the steps before succeeded");
    }
}

#[test]
fn the_ewma_detector_fmu_gives_fmpys_statistic_and_channel() {
    let fmu = open("ewma_detector");
    let mut i = fmu.instantiate(Interface::CoSimulation, "det").unwrap();
    let inputs = vrs(&fmu, &["in_1", "in_2", "in_3"]);
    let stat = vrs(&fmu, &["statistic"]);
    let channel = vrs(&fmu, &["isolated_channel"]);
    i.initialise(0.0, 1.0).unwrap();
    // FMPy, constant inputs 1, -3, 0.5, lambda 0.05, ten steps of 0.01 s.
    let fmpy = [
        0.15000000000000002,
        0.29250000000000004,
        0.42787500000000006,
        0.55648125000000004,
        0.67865718750000004,
        0.79472432812500005,
        0.90498811171875004,
        1.0097387061328125,
        1.1092517708261718,
        1.2037891822848632,
    ];
    for (k, want) in fmpy.iter().enumerate() {
        i.set_real(&inputs, &[1.0, -3.0, 0.5]).unwrap();
        i.step(k as f64 * 0.01, 0.01).unwrap();
        let (mut s, mut c) = ([0.0], [0]);
        i.get_real(&stat, &mut s).unwrap();
        i.get_integer(&channel, &mut c).unwrap();
        assert_eq!((s[0], c[0]), (*want, 2), "step {}", k + 1);
    }
}

#[test]
fn instances_on_four_threads_fly_independently() {
    let fmu = open("aircraft");
    let serial: Vec<_> = (0..4)
        .map(|k| {
            let mut i = fmu.instantiate(Interface::ModelExchange, "serial").unwrap();
            i.set_real(&vrs(&fmu, &["m_kg"]), &[1200.0 + 50.0 * k as f64]).unwrap();
            fly(&fmu, &mut i, &[100]).unwrap()
        })
        .collect();
    let parallel: Vec<_> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..4)
            .map(|k| {
                let fmu = &fmu;
                s.spawn(move || {
                    let mut i = fmu.instantiate(Interface::ModelExchange, "thread").unwrap();
                    i.set_real(&vrs(fmu, &["m_kg"]), &[1200.0 + 50.0 * k as f64]).unwrap();
                    fly(fmu, &mut i, &[100]).unwrap()
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(serial, parallel);
}

#[test]
fn an_fmu_without_a_binary_for_this_platform_is_refused_with_what_it_has() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("win.fmu");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).unwrap());
    let options = zip::write::SimpleFileOptions::default();
    zip.start_file("modelDescription.xml", options).unwrap();
    use std::io::Write;
    zip.write_all(&std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("fmus/aircraft/FMI2.xml")).unwrap())
        .unwrap();
    zip.start_file("binaries/win64/aircraft.dll", options).unwrap();
    zip.write_all(b"MZ").unwrap();
    zip.finish().unwrap();
    let e = Fmu::open(&path).unwrap_err().to_string();
    assert!(
        e.contains("win.fmu: no binary for this platform: expected binaries/linux64/aircraft.so; it has binaries/win64/aircraft.dll"),
        "{e}"
    );
}

/// The aircraft at level flight (53.6 m/s, fmus/README.md: theta = alpha, q = 0) on `file`'s
/// `interface`, elevator and throttle in, `outputs` out; and the exact Jacobian of the same equations
/// (dual numbers) over z = [x; elevator, throttle] at that trim.
fn aircraft_at_trim(
    file: &str,
    interface: Interface,
    outputs: &[&str],
) -> (fdimc::fmu::plant::FmuPlant, nalgebra::DMatrix<f64>) {
    use fdimc::dual::{Dual, value_and_jacobian};
    use fdimc::fmu::plant::{FmuPlant, PlantMapping};
    use nalgebra::SVector;
    let (alpha, elevator, throttle) = (0.0443566119725, 0.0211591440454, 0.459166130340);
    let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let parameters =
        [("V0_m_s", 53.6), ("alpha0_rad", alpha), ("theta0_rad", alpha)].map(|(n, v)| (n.to_string(), v)).to_vec();
    let mapping = PlantMapping {
        interface,
        fault_inputs: &[],
        inputs: &names(&["elevator_rad", "throttle"]),
        input_fields: &names(&["truth.inputs[0]", "truth.inputs[1]"]),
        outputs: &names(outputs),
        output_fields: &(0..outputs.len()).map(|k| format!("truth.outputs[{k}]")).collect::<Vec<_>>(),
        parameters: &parameters,
        input_trim: &[elevator, throttle],
        stop_s: 10.0,
        dt_s: 0.01,
    };
    let plant = FmuPlant::open(&fmus().join(file), "truth", &mapping).unwrap().unwrap();
    let p = LongitudinalParams::default();
    let z = SVector::<f64, 7>::from_column_slice(&[53.6, alpha, 0.0, alpha, 1000.0, elevator, throttle]);
    let (f0, jac) = value_and_jacobian(&z, |z: &SVector<Dual<7>, 7>| {
        let one = <Dual<7> as fdimc::dual::Real>::cst(1.0);
        SVector::<Dual<7>, 5>::from(derivatives(&p, &[z[0], z[1], z[2], z[3], z[4]], &[z[5], z[6], one]))
    });
    assert!(f0.amax() < 1e-9, "the trim is an equilibrium: {f0}");
    (plant, nalgebra::DMatrix::from_fn(5, 7, |r, c| jac[(r, c)]))
}

#[test]
fn the_linearisation_at_trim_equals_the_analytic_jacobian_within_1e_6_and_directional_derivatives_to_rounding() {
    use fdimc::fmu::plant::Jacobian;
    let (plant, jac) = aircraft_at_trim("aircraft.fmu", Interface::ModelExchange, &["q_rad_s", "gamma_rad"]);
    assert_eq!(plant.output_trim, [0.0, 0.0]);
    let lin = plant.linearise_by(Jacobian::CentralDifferences).unwrap();
    assert!(lin.method.starts_with("central differences"), "{}", lin.method);
    let close = |got: f64, want: f64, what: String| {
        assert!((got - want).abs() <= 1e-6 * want.abs().max(1e-3), "{what}: {got} vs {want}");
    };
    for r in 0..5 {
        for c in 0..5 {
            close(lin.a[(r, c)], jac[(r, c)], format!("A[{r},{c}]"));
        }
        for c in 0..2 {
            close(lin.b[(r, c)], jac[(r, 5 + c)], format!("B[{r},{c}]"));
        }
    }
    // Outputs q and gamma = theta - alpha: C rows exactly these, no feedthrough.
    assert_eq!(lin.c.row(0).iter().map(|v| v.round()).collect::<Vec<_>>(), [0.0, 0.0, 1.0, 0.0, 0.0]);
    close(lin.c[(1, 1)], -1.0, "C[1,1]".into());
    close(lin.c[(1, 3)], 1.0, "C[1,3]".into());
    assert!(lin.d.amax() < 1e-9);
    // The short period is there: A's pitch-moment entry M_alpha (per rad) is strongly negative.
    assert!(lin.a[(2, 1)] < -8.0, "{}", lin.a);

    // The FMU provides directional derivatives (fmus/aircraft/model.c differentiates its equations by
    // hand): `linearise` takes them, and they are the dual numbers' Jacobian to rounding.
    let exact = plant.linearise().unwrap();
    assert!(exact.method.contains("directional derivatives"), "{}", exact.method);
    let within = |got: f64, want: f64, what: String| {
        assert!((got - want).abs() <= 1e-12 * want.abs().max(1.0), "{what}: {got} vs {want}");
    };
    for r in 0..5 {
        for c in 0..5 {
            within(exact.a[(r, c)], jac[(r, c)], format!("A[{r},{c}]"));
        }
        for c in 0..2 {
            within(exact.b[(r, c)], jac[(r, 5 + c)], format!("B[{r},{c}]"));
        }
    }
    assert_eq!(exact.c.row(0).iter().copied().collect::<Vec<_>>(), [0.0, 0.0, 1.0, 0.0, 0.0]);
    assert_eq!(exact.c.row(1).iter().copied().collect::<Vec<_>>(), [0.0, -1.0, 0.0, 1.0, 0.0]);
    assert_eq!(exact.d.amax(), 0.0);
}

#[test]
fn a_co_simulation_only_fmu_is_trimmed_as_its_model_exchange_twin() {
    // The trim only sets values before initialisation and reads derivatives after it: the
    // co-simulation-only export (as Simulink makes them) trims to the same point as model exchange.
    let mut found = Vec::new();
    for (name, interface) in [("aircraft", Interface::ModelExchange), ("aircraft_cs", Interface::CoSimulation)] {
        let fmu = open(name);
        let v = |n: &str| fmu.description.variable(n).unwrap().value_reference;
        let fixed = [(v("V0_m_s"), 53.6), (v("q0_rad_s"), 0.0), (v("h0_m"), 1000.0)];
        let free = [(v("throttle"), 0.6), (v("elevator_rad"), 0.0), (v("alpha0_rad"), 0.02), (v("theta0_rad"), 0.1)];
        let zero = [v("der(V_m_s)"), v("der(alpha_rad)"), v("der(q_rad_s)"), v("der(h_m)")];
        let problem = fdimc::fmu::trim::TrimProblem {
            interface,
            fixed: &fixed,
            free: &free,
            zero: &zero,
            stop_s: 10.0,
            tolerance: 1e-11,
        };
        let trim = fdimc::fmu::trim::solve(&fmu, &problem).unwrap();
        assert!(trim.residual.iter().all(|r| r.abs() <= 1e-11), "{name}: {:?}", trim.residual);
        assert!(trim.steps >= 2, "{name}: from a guess this far the trim takes Newton steps");
        found.push(trim.values);
    }
    // fmus/README.md's trim (Newton in Python), and the two interfaces agree.
    let want = [0.459166130340, 0.0211591440454, 0.0443566119725, 0.0443566119725];
    for values in &found {
        for (got, want) in values.iter().zip(want) {
            assert!((got - want).abs() < 1e-10, "{got} vs {want}");
        }
    }
    for (a, b) in found[0].iter().zip(&found[1]) {
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
    }
}

/// The analytic model's eigenvalues of `a` (sorted by real, then imaginary part).
fn eigenvalues(a: &nalgebra::DMatrix<f64>) -> Vec<(f64, f64)> {
    let mut e: Vec<(f64, f64)> = a.complex_eigenvalues().iter().map(|z| (z.re, z.im)).collect();
    e.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.total_cmp(&y.1)));
    e
}

#[test]
fn a_model_identified_from_pulse_responses_has_the_jacobians_modes_and_markov_parameters() {
    use fdimc::fmu::identify::identify;
    // Outputs q, gamma = theta - alpha and h (without h the altitude, an integrator nothing feeds
    // back from, would not be observable: four states, not five), inputs elevator and throttle.
    let names = ["q_rad_s", "gamma_rad", "h_m"];
    let outputs = names.map(str::to_string);
    let (me, jac) = aircraft_at_trim("aircraft.fmu", Interface::ModelExchange, &names);
    let (a, b) = (jac.columns(0, 5).into_owned(), jac.columns(5, 2).into_owned());
    let c = nalgebra::DMatrix::from_row_slice(
        3,
        5,
        &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
    );
    let want = eigenvalues(&a);
    // On model exchange (fdimc's RK4 at 0.01 s): the modes and C A^k B to the integrator's and the
    // pulses' accuracy.
    let found = identify(&me, 5, 0.01, &outputs).unwrap();
    let l = &found.linearisation;
    assert!(l.method.starts_with("aircraft.fmu's pulse responses about the trim by ERA: 5 states"), "{}", l.method);
    // The fit is limited by the aircraft's nonlinearity at the validation amplitude (1e-3 rad of elevator,
    // 1e-3 of throttle), not by the model: 99.8 to 99.9 %.
    assert!(found.fit_percent.iter().all(|&f| f > 99.5), "{:?}", found.fit_percent);
    for (got, want) in eigenvalues(&l.a).iter().zip(&want) {
        let off = ((got.0 - want.0).powi(2) + (got.1 - want.1).powi(2)).sqrt();
        assert!(off <= 1e-5 * (want.0.hypot(want.1)).max(0.1), "eigenvalue {got:?} against {want:?}");
    }
    let (mut ak_b, mut lk_b) = (b.clone(), l.b.clone());
    for k in 0..3 {
        let (markov, identified) = (&c * &ak_b, &l.c * &lk_b);
        let off = (&markov - &identified).amax();
        assert!(off <= 1e-5 * markov.amax(), "C A^{k} B: {identified} against {markov}");
        (ak_b, lk_b) = (&a * ak_b, &l.a * lk_b);
    }
    assert!(l.d.amax() < 1e-9, "no feedthrough: {}", l.d);

    // The co-simulation-only export integrates with its own forward Euler at 1e-3 s: the modes it
    // flies are the analytic ones to about lambda h / 2, here under 0.5 %.
    let (cs, _) = aircraft_at_trim("aircraft_cs.fmu", Interface::CoSimulation, &names);
    let found = identify(&cs, 5, 0.01, &outputs).unwrap();
    assert!(found.fit_percent.iter().all(|&f| f > 99.5), "{:?}", found.fit_percent);
    for (got, want) in eigenvalues(&found.linearisation.a).iter().zip(&want) {
        let off = ((got.0 - want.0).powi(2) + (got.1 - want.1).powi(2)).sqrt();
        assert!(off <= 5e-3 * (want.0.hypot(want.1)).max(0.1), "eigenvalue {got:?} against {want:?}");
    }
}
