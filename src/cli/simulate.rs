use std::path::Path;

use crate::cli::{CliError, design_error};
use crate::engine::deck::{StudyKind, deck_kind};
use crate::engine::output::Trace;
use crate::engine::output::{TableFormat, trace_frame, write_table};
use crate::engine::streams::MAX_TRIAL;
use crate::engine::streams::{Substream, noise_rng};
use crate::methods::accelerometer::study::AccelerometerStudy;
use crate::methods::air_data::study::AirDataStudy;
use crate::methods::detection_filter::study::Study;
use crate::methods::detection_filter::trials::Engine;
use crate::methods::surface_bank::scenario::SurfaceScenarioSampler;
use crate::methods::surface_bank::stmmae::MODELS;
use crate::methods::surface_bank::study::SurfaceStudy;
use crate::methods::surface_bank::trial::{SurfaceTrial, run_banks};
use crate::methods::surface_bank::uav::SURFACE_NAMES;
use crate::methods::thrust_loss::study::LaunchStudy;

pub fn exec(
    deck: &Path,
    trial: u64,
    detector: Option<&str>,
    out: &Path,
    classifiers: Option<&Path>,
) -> Result<(), CliError> {
    // Check the output name before simulating, so a typo costs nothing.
    TableFormat::from_path(out)?;
    if trial > MAX_TRIAL {
        return Err(CliError::Invalid(format!("--trial {trial}: allowed 0 to {MAX_TRIAL}")));
    }
    let text = crate::engine::deck::read_deck(deck)?;
    match deck_kind(&text) {
        StudyKind::SurfaceBank => return surfaces(&SurfaceStudy::from_toml(&text, deck)?, trial, detector, out),
        StudyKind::AirData => return air_data(&AirDataStudy::from_toml(&text, deck)?, trial, detector, out),
        StudyKind::ThrustLoss => return launch(&LaunchStudy::from_toml(&text, deck)?, trial, detector, out),
        StudyKind::Accelerometer => {
            return accelerometer(&AccelerometerStudy::from_toml(&text, deck)?, trial, out, classifiers);
        }
        StudyKind::DetectionFilter => {}
    }
    let study = Study::from_toml(&text, deck)?;
    let names: Vec<&str> = study.detectors.iter().map(|d| d.name.as_str()).collect();
    let index = match detector {
        None => 0,
        Some(name) => names.iter().position(|n| *n == name).ok_or_else(|| {
            CliError::Invalid(format!("--detector {name:?}: {} has detectors {}", deck.display(), names.join(", ")))
        })?,
    };
    let engine = Engine::new(&study);
    let mut trace = Trace::default();
    let (spec, outcome) = engine
        .simulate(trial, index, &mut trace)
        .map_err(|e| design_error(deck, &format!("trial {trial}, detector {}", names[index]), e))?;
    let mut df = trace_frame(&trace).map_err(|e| CliError::Internal(e.to_string()))?;
    write_table(&mut df, out)?;

    let outputs = &study.plant.output_names;
    println!("{}: trial {trial}, detector {}, {} samples -> {}", study.name, names[index], study.steps, out.display());
    match spec.output {
        Some(j) => {
            println!("  fault               {} {} size {} from {} s", outputs[j], spec.kind, spec.size, spec.onset_s)
        }
        None => println!("  fault-free trial"),
    }
    if spec.noise_scale != 1.0 {
        println!("  noise scale         {}", spec.noise_scale);
    }
    for (pe, v) in study.monte_carlo.parameter_errors.iter().zip(&spec.parameter_errors) {
        if pe.absolute {
            println!("  parameter error     {} {v:+}", pe.name);
        } else {
            println!("  parameter error     {} {:+.2} %", pe.name, 100.0 * v);
        }
    }
    match outcome.false_alarm {
        Some((t, j)) => println!("  false alarm         {t:.3} s on {}", outputs[j]),
        None => println!("  false alarm         none"),
    }
    match outcome.detection {
        Some((t, j)) => println!("  detected            {t:.3} s on {} (delay {:.3} s)", outputs[j], t - spec.onset_s),
        None => println!("  detected            no"),
    }
    let name =
        |j: Option<usize>| j.map_or("none (no alarm, or the trial ended first)".to_string(), |j| outputs[j].clone());
    println!("  isolated (largest)  {}", name(outcome.isolated_by_max));
    println!("  isolated (direction) {}", name(outcome.isolated_by_direction));
    if let Some(t) = outcome.diverged_at_s {
        println!("  DIVERGED            residual non-finite at {t:.3} s");
    }
    Ok(())
}

/// One flight of a control-surface deck: every bank (or `--detector`'s) on the same samples; the trace
/// holds the measurements, commands, true positions, and per bank the model probabilities and the
/// declared surface.
fn surfaces(study: &SurfaceStudy, trial: u64, detector: Option<&str>, out: &Path) -> Result<(), CliError> {
    let banks: Vec<_> = match detector {
        None => study.banks.iter().collect(),
        Some(name) => vec![study.banks.iter().find(|(n, _)| n == name).ok_or_else(|| {
            let names: Vec<_> = study.banks.iter().map(|(n, _)| n.as_str()).collect();
            CliError::Invalid(format!("--detector {name:?}: {} has banks {}", study.path.display(), names.join(", ")))
        })?],
    };
    let params: Vec<_> = banks.iter().map(|(_, p)| p.clone()).collect();
    // The trial `fdimc run` flies under this index: its scenario, airframes, noise stream.
    let sampler = SurfaceScenarioSampler::new(study);
    let spec = sampler.spec(trial);
    let setup = SurfaceTrial::new(&sampler, &spec);
    let mut rng = noise_rng(study.seed, trial, Substream::SensorNoise);
    let mut floats: Vec<(String, Vec<f64>)> = Vec::new();
    let mut bools: Vec<(String, Vec<bool>)> = Vec::new();
    let mut push_f = |i: &mut usize, name: &dyn Fn() -> String, v: f64| {
        if floats.len() <= *i {
            floats.push((name(), Vec::new()));
        }
        floats[*i].1.push(v);
        *i += 1;
    };
    let measured = ["p_rad_s", "q_rad_s", "r_rad_s", "alpha_rad", "beta_rad"];
    let outcomes = run_banks(study, &setup, &params, &mut rng, |s, rows| {
        let mut i = 0;
        push_f(&mut i, &|| "t_s".into(), s.t_s);
        for (j, m) in measured.iter().enumerate() {
            push_f(&mut i, &|| format!("{m}_measured"), s.y[j]);
            push_f(&mut i, &|| format!("{m}_true"), s.truth_y[j]);
        }
        push_f(&mut i, &|| "airspeed_measured_mps".into(), s.va_mps);
        push_f(&mut i, &|| "altitude_m".into(), s.altitude_m);
        for (j, name) in SURFACE_NAMES.iter().enumerate() {
            push_f(&mut i, &|| format!("{name}_commanded_rad"), s.commanded_rad[j]);
            push_f(&mut i, &|| format!("{name}_position_rad"), s.positions_rad[j]);
        }
        for ((bank, _), row) in banks.iter().zip(rows) {
            for m in 0..MODELS {
                let model = if m == 0 { "no_fault" } else { SURFACE_NAMES[m - 1] };
                push_f(&mut i, &|| format!("{bank}_p_{model}"), row.probabilities[m]);
            }
            for (j, name) in SURFACE_NAMES.iter().enumerate() {
                push_f(&mut i, &|| format!("{bank}_{name}_estimate_rad"), row.surface_estimates_rad[j]);
            }
        }
        let mut b = 0;
        for ((bank, _), row) in banks.iter().zip(rows) {
            for (j, name) in SURFACE_NAMES.iter().enumerate() {
                if bools.len() <= b {
                    bools.push((format!("{bank}_declared_{name}"), Vec::new()));
                }
                bools[b].1.push(row.declared == Some(j));
                b += 1;
            }
        }
    });
    let trace = Trace { float_columns: floats, bool_columns: bools };
    let mut df = trace_frame(&trace).map_err(|e| CliError::Internal(e.to_string()))?;
    write_table(&mut df, out)?;
    let samples = df.height();
    let outcomes = outcomes.map_err(|e| CliError::Invalid(format!("{}: trial {trial}: {e}", study.path.display())))?;
    println!("{}: trial {trial}, {} bank(s), {samples} samples -> {}", study.name, banks.len(), out.display());
    if spec.faults.is_empty() {
        println!("  fault-free trial");
    }
    if spec.noise_scale != 1.0 {
        println!("  noise scale {}", spec.noise_scale);
    }
    for (pe, v) in study.monte_carlo.parameter_errors.iter().zip(&spec.parameter_errors) {
        println!("  parameter error {} {:+.2} % on the {:?} airframe", pe.name, 100.0 * v, pe.model);
    }
    let secs = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    println!(
        "  {:<16} {:<15} {:>9} {:>8} {:>10} {:>9} {:>12}",
        "bank", "fault", "onset_s", "delay_s", "isolated", "clear_s", "estimate_rms"
    );
    for ((bank, _), o) in banks.iter().zip(&outcomes) {
        for w in &o.windows {
            let isolated = w.first_declared.map_or("-", |j| SURFACE_NAMES[j]);
            println!(
                "  {bank:<16} {:<15} {:>9} {:>8} {isolated:>10} {:>9} {:>9.2} deg",
                SURFACE_NAMES[w.surface],
                w.onset_s,
                secs(w.detection_delay_s),
                secs(w.clearing_delay_s),
                w.surface_estimate_rms_rad.to_degrees()
            );
        }
        let h = o.health;
        println!(
            "  {bank:<16} false alarms {}, post-fault declarations {}, covariance asymmetric {} / not positive definite {} / non-finite {} steps",
            o.false_alarms, o.post_fault_declarations, h.asymmetric, h.not_positive_definite, h.non_finite
        );
    }
    Ok(())
}

/// One flight of an air-data deck: every detector (or `--detector`'s) on the same samples; the trace
/// holds the inertial and air-data measurements, the true air data, and per detector the fault
/// probability, the declaration, the isolation statistics and flags, the air-data and bias estimates.
fn air_data(study: &AirDataStudy, trial: u64, detector: Option<&str>, out: &Path) -> Result<(), CliError> {
    use crate::methods::air_data::flight::{AIR_DATA_CHANNEL_NAMES, INERTIAL_CHANNEL_NAMES};
    let names: Vec<&str> = study.detectors.iter().map(|d| d.name.as_str()).collect();
    let mut selected = study.clone();
    if let Some(name) = detector {
        let d = study.detectors.iter().find(|d| d.name == name).ok_or_else(|| {
            CliError::Invalid(format!(
                "--detector {name:?}: {} has detectors {}",
                study.path.display(),
                names.join(", ")
            ))
        })?;
        selected.detectors = vec![d.clone()];
    }
    let trials = crate::methods::air_data::AirDataTrials::new(&selected);
    let mut floats: Vec<(String, Vec<f64>)> = Vec::new();
    let mut bools: Vec<(String, Vec<bool>)> = Vec::new();
    let result = trials.run_trial_with(trial, |s, steps| {
        let mut f = Vec::new();
        let mut b = Vec::new();
        f.push(("t_s".to_string(), s.t_s));
        for (name, v) in INERTIAL_CHANNEL_NAMES.iter().zip(s.inertial.to_array()) {
            f.push((format!("{name}_measured"), v));
        }
        for ((name, v), truth) in
            AIR_DATA_CHANNEL_NAMES.iter().zip(s.air_data.to_array()).zip(s.truth.air_data.to_array())
        {
            f.push((format!("{name}_measured"), v));
            f.push((format!("{name}_true"), truth));
        }
        for (d, step) in selected.detectors.iter().zip(steps) {
            f.push((format!("{}_p_fault", d.name), step.probabilities[1]));
            b.push((format!("{}_declared", d.name), step.fault_declared));
            for (j, name) in AIR_DATA_CHANNEL_NAMES.iter().enumerate() {
                f.push((format!("{}_{name}_estimate", d.name), step.air_data.to_array()[j]));
                f.push((format!("{}_{name}_bias", d.name), step.bias[j]));
                f.push((format!("{}_{name}_chi_square", d.name), step.chi_square[j]));
                b.push((format!("{}_{name}_isolated", d.name), step.isolated[j]));
            }
        }
        if floats.is_empty() {
            floats = f.iter().map(|(n, _)| (n.clone(), Vec::new())).collect();
            bools = b.iter().map(|(n, _)| (n.clone(), Vec::new())).collect();
        }
        for (col, (_, v)) in floats.iter_mut().zip(f) {
            col.1.push(v);
        }
        for (col, (_, v)) in bools.iter_mut().zip(b) {
            col.1.push(v);
        }
    });
    let outcomes =
        result.outcome.map_err(|e| CliError::Invalid(format!("{}: trial {trial}: {e}", study.path.display())))?;
    let trace = Trace { float_columns: floats, bool_columns: bools };
    let mut df = trace_frame(&trace).map_err(|e| CliError::Internal(e.to_string()))?;
    write_table(&mut df, out)?;
    let spec = &result.spec;
    println!(
        "{}: trial {trial}, {} detector(s), {} samples -> {}",
        study.name,
        selected.detectors.len(),
        df.height(),
        out.display()
    );
    if spec.faults.is_empty() {
        println!("  fault-free trial");
    } else {
        println!(
            "  fault               {} {} size {} from {:.3} s",
            crate::methods::air_data::records::sensor_set(&spec.outputs),
            spec.kind,
            spec.size,
            spec.onset_s
        );
    }
    println!("  noise scale {}, gust {:.2} m/s", spec.noise_scale, spec.gust_std_mps);
    let secs = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    for (d, o) in selected.detectors.iter().zip(&outcomes) {
        let delay = o.detection_s.map(|t| t - spec.onset_s);
        let isolated = o.isolated.as_deref().map_or("-".to_string(), crate::methods::air_data::records::sensor_set);
        println!(
            "  {:<12} false alarm {}, delay {} s, isolated {isolated}, bias error {} sigma, air data {} / raw {} sigma",
            d.name,
            secs(o.false_alarm_s),
            secs(delay),
            secs(o.bias_error_rms_sigma),
            secs(o.estimate_rms_sigma),
            secs(o.raw_rms_sigma)
        );
    }
    Ok(())
}

/// One flight of a launch deck: every detector (or `--detector`'s) on the same samples; the trace holds
/// the measured pitch rate and overloads, the true thrust, and per detector the residual, `fhat` and the
/// alarm.
fn launch(study: &LaunchStudy, trial: u64, detector: Option<&str>, out: &Path) -> Result<(), CliError> {
    let names: Vec<&str> = study.detectors.iter().map(|d| d.name.as_str()).collect();
    let mut selected = study.clone();
    if let Some(name) = detector {
        let d = study.detectors.iter().find(|d| d.name == name).ok_or_else(|| {
            CliError::Invalid(format!(
                "--detector {name:?}: {} has detectors {}",
                study.path.display(),
                names.join(", ")
            ))
        })?;
        selected.detectors = vec![d.clone()];
    }
    let trials = crate::methods::thrust_loss::LaunchTrials::new(&selected)
        .map_err(|e| CliError::Invalid(format!("{}: {e}", study.path.display())))?;
    let mut floats: Vec<(String, Vec<f64>)> = Vec::new();
    let mut bools: Vec<(String, Vec<bool>)> = Vec::new();
    let result = trials.run_trial_with(trial, |m, steps| {
        use crate::methods::thrust_loss::vehicle::idx;
        let mut f = vec![
            ("t_s".to_string(), m.t_s),
            ("wz_measured_rad_s".to_string(), m.y[idx::WZ - 1]),
            ("wz_true_rad_s".to_string(), m.truth[idx::WZ]),
            ("n_y_measured_g".to_string(), m.n_y_g),
            ("n_z_measured_g".to_string(), m.n_z_g),
            ("thrust_true_n".to_string(), m.truth[idx::THRUST]),
        ];
        let mut b = Vec::new();
        for (d, step) in selected.detectors.iter().zip(steps) {
            f.push((format!("{}_residual_rad_s", d.name), step.residual_rad_s));
            f.push((format!("{}_fhat", d.name), step.fhat));
            b.push((format!("{}_alarm", d.name), step.alarm));
        }
        if floats.is_empty() {
            floats = f.iter().map(|(n, _)| (n.clone(), Vec::new())).collect();
            bools = b.iter().map(|(n, _)| (n.clone(), Vec::new())).collect();
        }
        for (col, (_, v)) in floats.iter_mut().zip(f) {
            col.1.push(v);
        }
        for (col, (_, v)) in bools.iter_mut().zip(b) {
            col.1.push(v);
        }
    });
    let trace = Trace { float_columns: floats, bool_columns: bools };
    let mut df = trace_frame(&trace).map_err(|e| CliError::Internal(e.to_string()))?;
    write_table(&mut df, out)?;
    let outcomes =
        result.outcome.map_err(|e| CliError::Invalid(format!("{}: trial {trial}: {e}", study.path.display())))?;
    let spec = &result.spec;
    println!(
        "{}: trial {trial}, {} detector(s), {} samples -> {}",
        study.name,
        outcomes.len(),
        df.height(),
        out.display()
    );
    match spec.fault {
        Some(f) => println!(
            "  fault               engine {} loses {:.1} % from {:.3} s",
            f.engine + 1,
            spec.loss_percent,
            f.onset_s
        ),
        None => println!("  fault-free trial"),
    }
    println!("  noise scale {}, gust scale {}", spec.noise_scale, spec.gust_scale);
    let secs = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    for (d, o) in selected.detectors.iter().zip(&outcomes) {
        let delay = o.alarm_s.zip(spec.fault).map(|(a, f)| a - f.onset_s);
        let engine =
            o.localised.map_or("-".to_string(), |e| e.map_or("none".to_string(), |e| format!("engine {}", e + 1)));
        println!(
            "  {:<12} max |fhat| before onset {:.3e}, false alarm {}, delay {} s, localised {engine}, loss estimate {} %",
            d.name,
            o.pre_max_fhat,
            secs(o.false_alarm_s),
            secs(delay),
            o.loss_estimate_percent.map_or("-".to_string(), |l| format!("{l:.1}"))
        );
    }
    Ok(())
}

/// One trial of an accelerometer deck: the residual and its detection statistic per sample, and what
/// both classifiers make of the window after the onset (from `classifiers`, or trained now).
fn accelerometer(
    study: &AccelerometerStudy,
    trial: u64,
    out: &Path,
    classifiers: Option<&Path>,
) -> Result<(), CliError> {
    use crate::methods::accelerometer::AccelerometerTrials;
    use crate::methods::accelerometer::trial::{DETECTORS, TrainedClassifiers};
    let trained = match classifiers {
        Some(file) => TrainedClassifiers::load(file)?,
        None => {
            TrainedClassifiers::train(study).map_err(|e| CliError::Invalid(format!("{}: {e}", study.path.display())))?
        }
    };
    let trials = AccelerometerTrials::new(study, &trained);
    let mut floats: Vec<(String, Vec<f64>)> = Vec::new();
    let result = trials.run_trial_with(trial, |samples, statistics| {
        let dt_s = study.design.scenario.dt_s;
        floats.push(("t_s".into(), (0..samples.len()).map(|k| k as f64 * dt_s).collect()));
        for (j, axis) in ["x", "y", "z"].iter().enumerate() {
            floats.push((format!("residual_{axis}"), samples.iter().map(|s| s.residual[j]).collect()));
        }
        floats.push(("detection_statistic".into(), statistics.to_vec()));
    });
    let outcome =
        result.outcome.map_err(|e| CliError::Invalid(format!("{}: trial {trial}: {e}", study.path.display())))?;
    let threshold = study.detection.threshold;
    let alarm = floats.last().map(|(_, t)| t.iter().map(|&v| v >= threshold).collect()).unwrap_or_default();
    let trace = Trace { float_columns: floats, bool_columns: vec![("alarm".into(), alarm)] };
    let mut df = trace_frame(&trace).map_err(|e| CliError::Internal(e.to_string()))?;
    write_table(&mut df, out)?;
    let s = &result.spec;
    println!("{}: trial {trial}, {} samples -> {}", study.name, df.height(), out.display());
    let axis = s.axis.map_or("-", |a| ["x", "y", "z"][a]);
    println!(
        "  class {} on axis {axis}, size {}, onset {:.3} s, noise scale {}",
        s.class.name(),
        s.size,
        s.onset_s,
        s.noise_scale
    );
    for (d, name) in DETECTORS.iter().enumerate() {
        println!("  {name:<6} predicts {}", outcome.predicted[d].name());
    }
    let secs = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    println!(
        "  residual detector: false alarm {} s, alarm {} s (delay {} s)",
        secs(outcome.false_alarm_s),
        secs(outcome.alarm_s),
        secs(outcome.alarm_s.map(|a| a - s.onset_s))
    );
    Ok(())
}
