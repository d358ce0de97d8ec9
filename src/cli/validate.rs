use std::path::Path;

use crate::cli::{CliError, design_error};
use crate::engine::deck::{StudyKind, deck_kind};
use crate::methods::accelerometer::study::AccelerometerStudy;
use crate::methods::air_data::study::AirDataStudy;
use crate::methods::detection_filter::study::{Shape, Study};
use crate::methods::surface_bank::actuator::ActuatorFaultKind;
use crate::methods::surface_bank::stmmae::BankParams;
use crate::methods::surface_bank::study::SurfaceStudy;
use crate::methods::surface_bank::uav::{AerosondeParams, SURFACE_NAMES, trim};
use crate::methods::thrust_loss::study::LaunchStudy;

pub fn exec(deck: &Path) -> Result<(), CliError> {
    let text = crate::engine::deck::read_deck(deck)?;
    match deck_kind(&text) {
        StudyKind::SurfaceBank => return surfaces(&SurfaceStudy::from_toml(&text, deck)?),
        StudyKind::AirData => return air_data(&AirDataStudy::from_toml(&text, deck)?),
        StudyKind::ThrustLoss => return launch(&LaunchStudy::from_toml(&text, deck)?),
        StudyKind::Accelerometer => return accelerometer(&AccelerometerStudy::from_toml(&text, deck)?),
        StudyKind::DetectionFilter => {}
    }
    let study = Study::from_toml(&text, deck)?;
    let mut filters = Vec::with_capacity(study.detectors.len());
    for d in &study.detectors {
        filters.push(d.params.design(&study.design_plant, study.dt_s).map_err(|e| design_error(deck, &d.name, e))?);
    }
    let p = &study.plant;
    let ranks = p
        .structural_ranks()
        .ok_or_else(|| CliError::Internal("SVD of the controllability/observability matrix failed".into()))?;
    let list = |v: &[String]| v.join(", ");
    let nums = |v: &[f64]| v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(", ");

    println!("{}: valid", deck.display());
    println!(
        "study       {} (seed {}, {} s at dt {} s = {} samples)",
        study.name, study.seed, study.duration_s, study.dt_s, study.steps
    );
    println!("plant       {} states [{}]", p.n_states(), list(&p.state_names));
    println!("            {} inputs [{}]", p.n_inputs(), list(&p.input_names));
    println!("            {} outputs [{}]", p.n_outputs(), list(&p.output_names));
    println!(
        "            rank ctrb(A, B) = {} of {}, rank obsv(A, C) = {} of {}",
        ranks.controllability_rank, ranks.states, ranks.observability_rank, ranks.states
    );
    let same = study.design_plant.A == p.A && study.design_plant.B == p.B;
    println!(
        "design      {}",
        if same { "on the true plant" } else { "on a design model that differs from the true plant" }
    );
    if study.output_feedback.amax() > 0.0 {
        println!("controller  u = r - G y, G =");
        print!("{}", indent(&format!("{:.6}", study.output_feedback)));
    } else {
        println!("controller  none (open loop)");
    }
    for e in &study.excitations {
        let shape = match e.shape {
            Shape::Square { period_s } => format!("square, period {period_s} s"),
            Shape::Sine { period_s } => format!("sine, period {period_s} s"),
            Shape::Step => "step".to_string(),
        };
        println!("excitation  {}: {shape}, amplitude {}, from {} s", p.input_names[e.input], e.amplitude, e.start_s);
    }
    println!("noise       sensor sigma [{}]", nums(study.sensor_sigma.as_slice()));
    if study.process_sigma_per_step.amax() > 0.0 {
        println!("            process sigma per step [{}]", nums(study.process_sigma_per_step.as_slice()));
    }
    for (d, filter) in study.detectors.iter().zip(&filters) {
        let params = &d.params;
        println!(
            "detector    {}: detection_filter, eigenvalues [{}] 1/s on {} fault directions",
            d.name,
            nums(&params.eigenvalues_per_s),
            params.fault_directions.ncols()
        );
        println!("            thresholds [{}]", nums(params.thresholds.as_slice()));
        println!(
            "            isolation: mean residual {} s to {} s after the alarm",
            params.isolation_delay_s,
            params.isolation_delay_s + params.isolation_window_s
        );
        println!(
            "            closed-loop eigenvalues [{}], eigenvector condition {:.3}",
            filter
                .continuous
                .closed_loop_eigenvalues
                .iter()
                .map(|e| format!("{:.6}", e.re))
                .collect::<Vec<_>>()
                .join(", "),
            filter.continuous.eigenvector_condition
        );
    }
    let mc = &study.monte_carlo;
    println!(
        "monte carlo {} trials, fault-free fraction {}, sampler {:?}, target Pfa {}",
        mc.trials, mc.fault_free_fraction, mc.sampler, mc.target_pfa
    );
    if !mc.faults.is_empty() {
        let outs: Vec<&str> = mc.outputs.iter().map(|&j| p.output_names[j].as_str()).collect();
        println!(
            "            faults on [{}], onset {:?}, noise scale {:?}",
            outs.join(", "),
            mc.onset_s,
            mc.noise_scale
        );
        for f in &mc.faults {
            println!("            fault kind {}: size {:?}", f.kind.name(), f.size);
        }
    }
    for pe in &mc.parameter_errors {
        let how = if pe.absolute { "absolute" } else { "relative" };
        println!("            parameter error {} on the {:?} model: {how} {:?}", pe.name, pe.model, pe.value);
    }
    if study.faults.is_empty() && mc.faults.is_empty() {
        println!("faults      none");
    }
    for f in &study.faults {
        let size = f.mode.size();
        let size = if size.is_nan() { String::new() } else { format!(" {size}") };
        println!("fault       {} {}{} from {} s", p.output_names[f.channel], f.mode.name(), size, f.onset_s);
    }
    Ok(())
}

pub(super) fn indent(s: &str) -> String {
    s.lines().filter(|l| !l.trim().is_empty()).map(|l| format!("            {l}\n")).collect()
}

/// The resolved control-surface study (method 004).
fn surfaces(study: &SurfaceStudy) -> Result<(), CliError> {
    println!("{}: valid", study.path.display());
    let samples = (study.duration_s / study.dt_s).round();
    println!(
        "study       {} (seed {}, {} s at dt {} s = {samples} samples)",
        study.name, study.seed, study.duration_s, study.dt_s
    );
    println!(
        "airframe    aerosonde trimmed at {} m/s, {} m; wind NED {:?} m/s",
        study.trim_airspeed_mps, study.trim_altitude_m, study.wind_ned_mps
    );
    // Stuck positions and square-wave centres are absolute: the trim says how far from it they are.
    let (_, surfaces, throttle) = trim(&AerosondeParams::default(), study.trim_airspeed_mps, study.trim_altitude_m)
        .map_err(|e| CliError::Invalid(format!("{}: airframe: {e}", study.path.display())))?;
    let trim_text: Vec<String> =
        SURFACE_NAMES.iter().zip(surfaces).map(|(n, s)| format!("{n} {:.2}", s.to_degrees())).collect();
    println!("trim        surfaces (deg) {}; throttle {throttle:.3}", trim_text.join(", "));
    let n = &study.sensors;
    println!(
        "sensors     gyro variance {} rad^2/s^2, flow angles {} rad^2, airspeed {} m^2/s^2, attitude sigma {} rad",
        n.gyro_variance_rad2_s2, n.flow_angle_variance_rad2, n.airspeed_variance_m2_s2, n.attitude_sigma_rad
    );
    for (from_s, sp) in &study.setpoints {
        println!(
            "setpoint    from {from_s} s: {} m/s, {} m, roll {:.1} deg",
            sp.va_mps,
            sp.altitude_m,
            sp.roll_rad.to_degrees()
        );
    }
    for f in &study.faults {
        let what = match f.kind {
            ActuatorFaultKind::Stuck { position_rad } => format!("stuck at {:.1} deg", position_rad.to_degrees()),
            ActuatorFaultKind::Oscillation { low_rad, high_rad, period_s } => format!(
                "square wave {:.1}..{:.1} deg, period {period_s} s",
                low_rad.to_degrees(),
                high_rad.to_degrees()
            ),
            ActuatorFaultKind::LossOfEffectiveness { effectiveness } => format!("effectiveness {effectiveness}"),
        };
        let until = f.end_s.map_or("the end".to_string(), |e| format!("{e} s"));
        println!("fault       {}: {what}, from {} s to {until}", SURFACE_NAMES[f.surface], f.onset_s);
    }
    for (name, p) in &study.banks {
        let BankParams { covariance, likelihood, .. } = p;
        println!(
            "bank        {name}: {covariance:?} covariance, {likelihood:?} likelihood, R_W {:?}/s, R_V {:?}, rho {}, beta {}",
            p.process_variance_per_s, p.measurement_variance, p.rho, p.beta
        );
    }
    let mc = &study.monte_carlo;
    println!(
        "monte carlo {} trials, fault-free fraction {}, sampler {:?}, noise scale {:?}",
        mc.trials, mc.fault_free_fraction, mc.sampler, mc.noise_scale
    );
    if mc.faults.is_empty() {
        println!("            every faulty trial flies the faults above");
    } else {
        let surfaces: Vec<&str> = mc.surfaces.iter().map(|&j| SURFACE_NAMES[j]).collect();
        let lasting = mc.fault_duration_s.as_ref().map_or("to the end".to_string(), |d| format!("{d:?} s"));
        println!(
            "            one fault per faulty trial on [{}], onset {:?} s, lasting {lasting}",
            surfaces.join(", "),
            mc.onset_s
        );
        for f in &mc.faults {
            println!("            fault kind {}: {f:?}", f.name());
        }
    }
    for pe in &mc.parameter_errors {
        println!(
            "            parameter error {} on the {:?} airframe: [{}] scaled by 1 + {:?}",
            pe.name,
            pe.model,
            pe.coefficients.join(", "),
            pe.relative
        );
    }
    Ok(())
}

/// The resolved air-data study (method 002).
fn air_data(study: &AirDataStudy) -> Result<(), CliError> {
    println!("{}: valid", study.path.display());
    let samples = (study.duration_s / study.dt_s).round();
    println!(
        "study       {} (seed {}, {} s at dt {} s = {samples} samples)",
        study.name, study.seed, study.duration_s, study.dt_s
    );
    let p = &study.profile;
    println!(
        "flight      profile {:?}: {} m/s, alpha {:.1} deg, pitch {:.1} deg, {} manoeuvre segments",
        study.profile_name,
        p.airspeed_mps,
        p.alpha_rad.to_degrees(),
        p.pitch_rad.to_degrees(),
        p.segments.len()
    );
    let n = &study.noise;
    println!(
        "sensors     gyro {:.3} deg/s, accelerometer {} m/s^2, attitude {:.3} deg; airspeed {} m/s, alpha {:.3} deg, beta {:.3} deg",
        n.gyro_std_rad_s.to_degrees(),
        n.accelerometer_std_mps2,
        n.attitude_std_rad.to_degrees(),
        n.airspeed_std_mps,
        n.alpha_std_rad.to_degrees(),
        n.beta_std_rad.to_degrees()
    );
    let w = &study.wind;
    println!(
        "wind        steady NED {:?} m/s, gust {} m/s (time constant {:.1} s)",
        w.steady_ned_mps, w.gust_std_mps, w.gust_time_constant_s
    );
    for d in &study.detectors {
        let q = &d.params;
        println!(
            "detector    {}: dual_ukf, isolation P_fa {} over {} sample(s) (threshold {:.3}), declare {} held {} s, clear {}, isolated set read {} s after a declaration",
            d.name,
            q.false_alarm_probability,
            q.isolation_window,
            crate::methods::air_data::dual_ukf::chi_square_threshold(
                q.isolation_window as u32,
                q.false_alarm_probability
            ),
            q.declare_probability,
            q.declare_hold_s,
            q.clear_probability,
            d.isolation_delay_s
        );
    }
    let names = study.output_names();
    for f in &study.faults {
        println!("fault       {} {} {} from {} s", names[f.channel], f.mode.name(), f.mode.size(), f.onset_s);
    }
    let mc = &study.monte_carlo;
    println!(
        "monte carlo {} trials, fault-free fraction {}, sampler {:?}, onset {:?} s, noise scale {:?}, gust {:?} m/s",
        mc.trials, mc.fault_free_fraction, mc.sampler, mc.onset_s, mc.noise_scale, mc.gust_std_mps
    );
    let sets: Vec<String> = mc.output_sets.iter().map(|s| crate::methods::air_data::records::sensor_set(s)).collect();
    println!("            sensor sets [{}]", sets.join(", "));
    for f in &mc.faults {
        println!("            fault kind {}: size {:?}", f.kind.name(), f.size);
    }
    if mc.faults.is_empty() {
        println!("            every faulty trial flies the faults above");
    }
    Ok(())
}

/// The resolved launch-vehicle study (method 001).
fn launch(study: &LaunchStudy) -> Result<(), CliError> {
    println!("{}: valid", study.path.display());
    let c = &study.config;
    println!(
        "study       {} (seed {}, {} s at dt {} s = {} samples)",
        study.name,
        study.seed,
        study.duration_s,
        c.dt_s,
        (study.duration_s / c.dt_s).round()
    );
    let p = &c.params;
    println!(
        "vehicle     medium_launcher: {:.0} t at lift-off, 4 engines of {:.0} kN at sea level, thrust/weight {:.2}",
        p.liftoff_mass_kg / 1000.0,
        p.engine_thrust_n(0.0) / 1000.0,
        4.0 * p.engine_thrust_n(0.0) / (p.liftoff_mass_kg * p.gravity_mps2)
    );
    for g in &study.gusts {
        println!(
            "gust        {:?} {} m/s from {} s for {} s (1 - cosine; the filter knows no wind)",
            g.axis, g.amplitude_mps, g.start_s, g.duration_s
        );
    }
    for d in &study.detectors {
        let m = &d.params.mhe;
        println!(
            "detector    {}: ekf_mhe, N {}, D {} sample(s), F {} (R = F^2), V = {} I, threshold |fhat| {:e}; loss table at {:?} s from losses {:?} %",
            d.name,
            m.window_n,
            m.interval_samples,
            m.fault_intensity,
            m.window_variance,
            d.params.threshold_fhat,
            d.loss_table.onsets_s,
            d.loss_table.losses_percent
        );
    }
    if let Some(f) = &study.fault {
        println!("fault       engine {} loses {} % from {} s", f.engine + 1, f.loss_percent, f.onset_s);
    }
    let mc = &study.monte_carlo;
    println!(
        "monte carlo {} trials, fault-free fraction {}, sampler {:?}, target Pfa {}, engines {:?}",
        mc.trials,
        mc.fault_free_fraction,
        mc.sampler,
        mc.target_pfa,
        mc.engines.iter().map(|e| e + 1).collect::<Vec<_>>()
    );
    println!(
        "            loss {:?} %, onset {:?} s, noise scale {:?}, gust scale {:?}; detection within {} s of the onset",
        mc.loss_percent, mc.onset_s, mc.noise_scale, mc.gust_scale, mc.detection_window_s
    );
    Ok(())
}

/// The resolved accelerometer study (method 003).
fn accelerometer(study: &AccelerometerStudy) -> Result<(), CliError> {
    let d = &study.design;
    println!("{}: valid", study.path.display());
    println!(
        "study       {} (seed {}, {} s at dt {} s)",
        study.name, study.seed, d.scenario.duration_s, d.scenario.dt_s
    );
    let n = &d.scenario.noise;
    println!(
        "imu         gyro noise {:.3} deg/s (bias spread {:.3}), accelerometer noise {} m/s^2 (bias spread {})",
        n.gyro_noise_std_rad_s.to_degrees(),
        n.gyro_bias_std_rad_s.to_degrees(),
        n.accel_noise_std_mps2,
        n.accel_bias_std_mps2
    );
    let r = &d.ranges;
    println!(
        "faults      bias |{:?}| m/s^2, gain |factor - 1| {:?}, stuck at the reading at onset; onset {:?} s; axis and sign drawn",
        r.bias_mps2, r.gain_deviation, r.onset_s
    );
    println!("features    {} samples from {} s after the onset", d.features.window_len, d.window_delay_s);
    let t = &study.training;
    println!(
        "training    {} trials per class from seed {} at noise scales {:?}; SVM {:?}, C {}",
        t.trials_per_class, t.seed, t.noise_scales, t.svm.kernel, t.svm.c
    );
    println!(
        "detection   T over {} samples, threshold {}, counted from {} s",
        study.detection.window, study.detection.threshold, study.settle_s
    );
    let classes: Vec<&str> = study.classes.iter().map(|c| c.name()).collect();
    println!(
        "monte carlo {} trials, classes [{}] cycled, noise scale {:?}",
        study.trials,
        classes.join(", "),
        study.noise_scale
    );
    Ok(())
}
