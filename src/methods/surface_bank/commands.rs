//! What `fdimc validate` and `fdimc simulate` print and write for this kind of deck.

use std::path::Path;

use super::actuator::ActuatorFaultKind;
use super::scenario::SurfaceScenarioSampler;
use super::stmmae::{CovarianceForm, MODELS};
use super::study::{SurfaceFaultSpec, SurfaceStudy};
use super::trial::{SurfaceTrial, run_banks};
use crate::engine::method::keep_detector;
use crate::engine::run::output::Trace;
use crate::engine::run::runner::RunError;
use crate::engine::scenario::streams::{Substream, noise_rng};
use crate::estimation::bank::LikelihoodForm;
use crate::vehicles::aerosonde::{AerosondeParams, SURFACE_NAMES, trim};

/// The resolved control-surface study (method 004).
pub fn validate(study: &SurfaceStudy) -> Result<(), RunError> {
    study.header.print_valid();
    println!(
        "airframe    aerosonde trimmed at {} m/s, {} m; wind NED {:?} m/s",
        study.trim_airspeed_mps, study.trim_altitude_m, study.wind_ned_mps
    );
    // Stuck positions and square-wave centres are absolute: the trim says how far from it they are.
    let (_, surfaces, throttle) = trim(&AerosondeParams::default(), study.trim_airspeed_mps, study.trim_altitude_m)
        .map_err(|e| RunError::Invalid(format!("{}: airframe: {e}", study.header.path.display())))?;
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
        // As the deck spells them.
        let covariance = match p.covariance {
            CovarianceForm::Ekf => "ekf",
            CovarianceForm::StrongTracking => "strong_tracking",
            CovarianceForm::SymmetricStrongTracking => "symmetric_strong_tracking",
        };
        let likelihood = match p.likelihood {
            LikelihoodForm::Gaussian => "gaussian",
            LikelihoodForm::EuclideanNorm => "euclidean_norm",
            LikelihoodForm::EuclideanNormOneDimensional => "euclidean_norm_1d",
        };
        println!(
            "bank        {name}: covariance {covariance}, likelihood {likelihood}, R_W {:?}/s, R_V {:?}, rho {}, beta {}",
            p.process_variance_per_s, p.measurement_variance, p.rho, p.beta
        );
    }
    let mc = &study.monte_carlo;
    println!(
        "monte carlo {} trials, fault-free fraction {}, sampler {}, noise scale {}",
        mc.common.trials, mc.common.fault_free_fraction, mc.common.sampler, mc.common.noise_scale
    );
    if mc.faults.is_empty() {
        println!("            every faulty trial flies the faults above");
    } else {
        let surfaces: Vec<&str> = mc.surfaces.iter().map(|&j| SURFACE_NAMES[j]).collect();
        let lasting = mc.fault_duration_s.as_ref().map_or("to the end".to_string(), |d| format!("{d} s"));
        println!(
            "            one fault per faulty trial on [{}], onset {} s, lasting {lasting}",
            surfaces.join(", "),
            mc.common.onset_s
        );
        for f in &mc.faults {
            let what = match f {
                SurfaceFaultSpec::Stuck { position_deg } => format!("position {position_deg} deg"),
                SurfaceFaultSpec::Oscillation { amplitude_deg, center_deg, period_s } => {
                    format!("amplitude {amplitude_deg} deg about {center_deg} deg, period {period_s} s")
                }
                SurfaceFaultSpec::LossOfEffectiveness { effectiveness } => format!("effectiveness {effectiveness}"),
            };
            println!("            fault kind {}: {what}", f.name());
        }
    }
    for pe in &mc.parameter_errors {
        println!(
            "            parameter error {} on the {} airframe: [{}] scaled by 1 + {}",
            pe.name,
            pe.model,
            pe.what.0.join(", "),
            pe.value
        );
    }
    Ok(())
}

/// One flight of a control-surface deck: every bank (or `--detector`'s) on the same samples; the trace
/// holds the measurements, commands, true positions, and per bank the model probabilities and the
/// declared surface.
pub fn simulate(study: &SurfaceStudy, trial: u64, detector: Option<&str>, out: &Path) -> Result<(), RunError> {
    let mut banks = study.banks.clone();
    keep_detector(&study.header, &mut banks, |(name, _)| name, detector)?;
    let params: Vec<_> = banks.iter().map(|(_, p)| p.clone()).collect();
    // The trial `fdimc run` flies under this index: its scenario, airframes, noise stream.
    let sampler = SurfaceScenarioSampler::new(study);
    let spec = sampler.spec(trial);
    let setup = SurfaceTrial::new(&sampler, &spec);
    let mut rng = noise_rng(study.header.seed, trial, Substream::SensorNoise);
    let mut trace = Trace::default();
    let measured = ["p_rad_s", "q_rad_s", "r_rad_s", "alpha_rad", "beta_rad"];
    let outcomes = run_banks(study, &setup, &params, &mut rng, |s, rows| {
        let mut row = trace.row();
        row.float(|| "t_s".into(), s.t_s);
        for (j, m) in measured.iter().enumerate() {
            row.float(|| format!("{m}_measured"), s.y[j]).float(|| format!("{m}_true"), s.truth_y[j]);
        }
        row.float(|| "airspeed_measured_mps".into(), s.va_mps).float(|| "altitude_m".into(), s.altitude_m);
        for (j, name) in SURFACE_NAMES.iter().enumerate() {
            row.float(|| format!("{name}_commanded_rad"), s.commanded_rad[j])
                .float(|| format!("{name}_position_rad"), s.positions_rad[j]);
        }
        for ((bank, _), r) in banks.iter().zip(rows) {
            for m in 0..MODELS {
                let model = if m == 0 { "no_fault" } else { SURFACE_NAMES[m - 1] };
                row.float(|| format!("{bank}_p_{model}"), r.step.probabilities[m]);
            }
            for (j, name) in SURFACE_NAMES.iter().enumerate() {
                row.float(|| format!("{bank}_{name}_estimate_rad"), r.step.surface_estimates_rad[j]);
            }
        }
        for ((bank, _), r) in banks.iter().zip(rows) {
            for (j, name) in SURFACE_NAMES.iter().enumerate() {
                row.flag(|| format!("{bank}_declared_{name}"), r.declared == Some(j));
            }
        }
    });
    let samples = trace.write(out)?;
    let outcomes =
        outcomes.map_err(|e| RunError::Invalid(format!("{}: trial {trial}: {e}", study.header.path.display())))?;
    println!("{}: trial {trial}, {} bank(s), {samples} samples -> {}", study.header.name, banks.len(), out.display());
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
        "  {:<16} {:<15} {:>9} {:>8} {:>10} {:>9} {:>10} {:>12}",
        "bank", "fault", "onset_s", "delay_s", "isolated", "clear_s", "recover_s", "estimate_rms"
    );
    for ((bank, _), o) in banks.iter().zip(&outcomes) {
        for w in &o.windows {
            let isolated = w.first_declared.map_or("-", |j| SURFACE_NAMES[j]);
            println!(
                "  {bank:<16} {:<15} {:>9} {:>8} {isolated:>10} {:>9} {:>10} {:>9.2} deg",
                SURFACE_NAMES[w.surface],
                w.onset_s,
                secs(w.detection_delay_s),
                secs(w.clearing_delay_s),
                secs(w.recovery_delay_s),
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
