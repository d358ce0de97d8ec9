//! What `fdimc validate` and `fdimc simulate` print and write for this kind of deck.

use std::path::Path;

use super::study::{AirDataStudy, DetectorKind};
use crate::engine::method::keep_detector;
use crate::engine::run::output::Trace;
use crate::engine::run::runner::RunError;

/// The resolved air-data study (method 002).
pub fn validate(study: &AirDataStudy) -> Result<(), RunError> {
    study.header.print_valid();
    let p = &study.profile;
    match study.airframe {
        crate::methods::air_data::flight::Airframe::Kinematic => println!(
            "flight      profile {:?}: {} m/s, alpha {:.1} deg, pitch {:.1} deg, {} manoeuvre segments",
            study.profile_name,
            p.airspeed_mps,
            p.alpha_rad.to_degrees(),
            p.pitch_rad.to_degrees(),
            p.segments.len()
        ),
        crate::methods::air_data::flight::Airframe::Aerosonde { manoeuvre_scale } => println!(
            "flight      the Aerosonde 6-DoF (method 004's airframe and autopilot) from trim at {} m/s, {} m: climb, bank, speed step, sideslip doublet, scaled by {manoeuvre_scale}",
            crate::methods::air_data::airframe::TRIM_AIRSPEED_MPS,
            crate::methods::air_data::airframe::TRIM_ALTITUDE_M
        ),
    }
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
    let e = &study.sensor_errors;
    if study.lanes > 1 || *e != crate::methods::air_data::flight::SensorErrors::default() {
        println!(
            "sensor errors {} air-data lane(s); lag airspeed {} s, flow angles {} s; scale factor airspeed {}, flow angles {}; misalignment alpha {:.3} deg, beta {:.3} deg, IMU {:.3} deg; noise correlation {} s",
            study.lanes,
            e.airspeed_lag_s,
            e.flow_angle_lag_s,
            e.airspeed_scale_factor,
            e.flow_angle_scale_factor,
            e.alpha_misalignment_rad.to_degrees(),
            e.beta_misalignment_rad.to_degrees(),
            e.imu_misalignment_rad.to_degrees(),
            e.noise_correlation_s
        );
    }
    for d in &study.detectors {
        match &d.kind {
            DetectorKind::DualUkf(q) => println!(
                "detector    {}: dual_ukf on lane 0, isolation P_fa {} over {} sample(s) (threshold {:.3}), declare {} held {} s, clear {}, {}, isolated set read {} s after a declaration",
                d.name,
                q.false_alarm_probability,
                q.isolation_window,
                crate::methods::air_data::dual_ukf::chi_square_threshold(
                    q.isolation_window as u32,
                    q.false_alarm_probability
                ),
                q.levels.declare_probability,
                q.levels.declare_hold_s,
                q.levels.clear_probability,
                if q.keep_significant_biases {
                    "faulty set kept while its bias is significant (Wald test, not the patent's)"
                } else {
                    "faulty set from each step's isolation (the patent's)"
                },
                d.isolation_delay_s
            ),
            DetectorKind::TriplexVoting(q) => println!(
                "detector    {}: triplex_voting, mid-value select, miscompare beyond {} sigma for {} s fails a lane, isolated set read {} s after a declaration",
                d.name, q.miscompare_sigma, q.persistence_s, d.isolation_delay_s
            ),
        }
    }
    let names = study.output_names();
    for f in &study.faults {
        println!("fault       {} {} {} from {} s", names[f.channel], f.mode.name(), f.mode.size(), f.onset_s);
    }
    let mc = &study.monte_carlo;
    println!(
        "monte carlo {} trials, fault-free fraction {}, sampler {}, onset {} s, noise scale {}, gust {} m/s",
        mc.common.trials,
        mc.common.fault_free_fraction,
        mc.common.sampler,
        mc.common.onset_s,
        mc.common.noise_scale,
        mc.gust_std_mps
    );
    let sets: Vec<String> = mc.output_sets.iter().map(|s| crate::methods::air_data::records::sensor_set(s)).collect();
    println!("            sensor sets [{}]", sets.join(", "));
    if study.lanes > 1 {
        println!("            faulty lanes per faulty sensor {:?} (of {})", mc.faulty_lanes, study.lanes);
    }
    for f in &mc.faults {
        println!("            fault kind {}: size {}", f.kind.name(), f.size_text());
    }
    if mc.faults.is_empty() {
        println!("            every faulty trial flies the faults above");
    }
    Ok(())
}

/// One flight of an air-data deck: every detector (or `--detector`'s) on the same samples; the trace
/// holds the inertial and air-data measurements, the true air data, and per detector the fault
/// probability, the declaration, the isolation statistics and flags, the air-data and bias estimates.
pub fn simulate(study: &AirDataStudy, trial: u64, detector: Option<&str>, out: &Path) -> Result<(), RunError> {
    use crate::methods::air_data::flight::{AIR_DATA_CHANNEL_NAMES, INERTIAL_CHANNEL_NAMES};
    let mut selected = study.clone();
    keep_detector(&study.header, &mut selected.detectors, |d| &d.name, detector)?;
    let trials = crate::methods::air_data::AirDataTrials::new(&selected);
    let mut trace = Trace::default();
    let result = trials.run_trial_with(trial, |s, steps| {
        let mut row = trace.row();
        row.float(|| "t_s".into(), s.t_s);
        for (name, v) in INERTIAL_CHANNEL_NAMES.iter().zip(s.inertial.to_array()) {
            row.float(|| format!("{name}_measured"), v);
        }
        for ((name, v), truth) in
            AIR_DATA_CHANNEL_NAMES.iter().zip(s.air_data.to_array()).zip(s.truth.air_data.to_array())
        {
            row.float(|| format!("{name}_measured"), v).float(|| format!("{name}_true"), truth);
        }
        for (d, step) in selected.detectors.iter().zip(steps) {
            row.float(|| format!("{}_p_fault", d.name), step.p_fault);
            row.flag(|| format!("{}_declared", d.name), step.fault_declared);
            for (j, name) in AIR_DATA_CHANNEL_NAMES.iter().enumerate() {
                row.float(|| format!("{}_{name}_estimate", d.name), step.air_data.to_array()[j])
                    .float(|| format!("{}_{name}_bias", d.name), step.bias.map_or(f64::NAN, |b| b[j]))
                    .float(|| format!("{}_{name}_test_statistic", d.name), step.statistic[j])
                    .flag(|| format!("{}_{name}_isolated", d.name), step.flagged[j]);
            }
        }
    });
    let outcomes = result
        .outcome
        .map_err(|e| RunError::Invalid(format!("{}: trial {trial}: {e}", study.header.path.display())))?;
    let samples = trace.write(out)?;
    let spec = &result.spec;
    println!(
        "{}: trial {trial}, {} detector(s), {} samples -> {}",
        study.header.name,
        selected.detectors.len(),
        samples,
        out.display()
    );
    if spec.fault.faults.is_empty() {
        println!("  fault-free trial");
    } else {
        println!(
            "  fault               {} {}",
            crate::methods::air_data::records::sensor_set(&spec.outputs),
            spec.fault.label()
        );
    }
    println!("  noise scale {}, gust {:.2} m/s", spec.noise_scale, spec.gust_std_mps);
    let secs = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    for (d, o) in selected.detectors.iter().zip(&outcomes) {
        let delay = o.detection_s.map(|t| t - spec.fault.onset_s);
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
