//! What `fdimc validate` and `fdimc simulate` print and write for this kind of deck.

use std::path::Path;

use super::study::LaunchStudy;
use crate::engine::method::keep_detector;
use crate::engine::run::output::Trace;
use crate::engine::run::runner::RunError;

/// The resolved launch-vehicle study (method 001).
pub fn validate(study: &LaunchStudy) -> Result<(), RunError> {
    study.header.print_valid();
    let c = &study.config;
    let p = &c.params;
    println!(
        "vehicle     medium_launcher: {:.0} t at lift-off, 4 engines of {:.0} kN at sea level, thrust/weight {:.2}",
        p.liftoff_mass_kg / 1000.0,
        p.engine_thrust_n(0.0) / 1000.0,
        4.0 * p.engine_thrust_n(0.0) / (p.liftoff_mass_kg * p.gravity_mps2)
    );
    for g in &study.gusts {
        println!(
            "gust        {} {} m/s from {} s for {} s (1 - cosine; the filter knows no wind)",
            g.axis.name(),
            g.amplitude_mps,
            g.start_s,
            g.duration_s
        );
    }
    for d in &study.detectors {
        let m = &d.params.mhe;
        let filter = match d.params.ekf.moment_bias_sigma_rad_s2_per_sqrt_s {
            None => "plain filter".to_string(),
            Some(s) => format!("recovering filter (moment biases at {s} rad/s^2/sqrt(s))"),
        };
        let t = &d.loss_table;
        let flights = match t.noisy_flights_per_loss {
            0 => "noise-free flights".to_string(),
            n => format!("{n} noisy flights per loss"),
        };
        println!(
            "detector    {}: ekf_mhe, {filter}, N {}, D {} sample(s), F {} (R = F^2), V = {} I, threshold |fhat| {:e}; loss table at {:?} s from losses {:?} % ({flights}, peak over {} s)",
            d.name,
            m.window_n,
            m.interval_samples,
            m.fault_intensity,
            m.window_variance,
            d.params.threshold_fhat,
            t.onsets_s,
            t.losses_percent,
            t.horizon_s,
        );
    }
    if let Some(f) = &study.fault {
        println!("fault       engine {} loses {} % from {} s", f.engine + 1, f.loss_percent, f.onset_s);
    }
    let mc = &study.monte_carlo;
    println!(
        "monte carlo {} trials, fault-free fraction {}, sampler {}, target Pfa {}, engines {:?}",
        mc.common.trials,
        mc.common.fault_free_fraction,
        mc.common.sampler,
        mc.common.target_pfa,
        mc.engines.iter().map(|e| e + 1).collect::<Vec<_>>()
    );
    println!(
        "            loss {} %, onset {} s, noise scale {}, gust scale {}; detection within {} s of the onset",
        mc.loss_percent.as_ref().map_or("the deck's [[faults]]".to_string(), |l| l.to_string()),
        mc.common.onset_s,
        mc.common.noise_scale,
        mc.gust_scale,
        mc.common.detection_window_s
    );
    Ok(())
}

/// One flight of a launch deck: every detector (or `--detector`'s) on the same samples; the trace holds
/// the measured pitch rate and overloads, the true thrust, and per detector the residual, `fhat`, `|fhat|`
/// over the deck's threshold (one scale for detectors whose `fhat` differ by orders of magnitude) and the
/// alarm.
pub fn simulate(study: &LaunchStudy, trial: u64, detector: Option<&str>, out: &Path) -> Result<(), RunError> {
    let mut selected = study.clone();
    keep_detector(&study.header, &mut selected.detectors, |d| &d.name, detector)?;
    let trials = crate::methods::thrust_loss::LaunchTrials::new(&selected)
        .map_err(|e| RunError::Invalid(format!("{}: {e}", study.header.path.display())))?;
    let mut trace = Trace::default();
    let result = trials.run_trial_with(trial, |m, steps| {
        use crate::methods::thrust_loss::vehicle::idx;
        let mut row = trace.row();
        row.float(|| "t_s".into(), m.t_s)
            .float(|| "wz_measured_rad_s".into(), m.y[idx::WZ - 1])
            .float(|| "wz_true_rad_s".into(), m.truth[idx::WZ])
            .float(|| "n_y_measured_g".into(), m.n_y_g)
            .float(|| "n_z_measured_g".into(), m.n_z_g)
            .float(|| "thrust_true_n".into(), m.truth[idx::THRUST]);
        for (d, step) in selected.detectors.iter().zip(steps) {
            row.float(|| format!("{}_residual_rad_s", d.name), step.residual_rad_s)
                .float(|| format!("{}_fhat", d.name), step.fhat)
                .float(|| format!("{}_fhat_over_threshold", d.name), step.fhat.abs() / d.params.threshold_fhat)
                .flag(|| format!("{}_alarm", d.name), step.alarm);
        }
    });
    let samples = trace.write(out)?;
    let outcomes = result
        .outcome
        .map_err(|e| RunError::Invalid(format!("{}: trial {trial}: {e}", study.header.path.display())))?;
    let spec = &result.spec;
    println!(
        "{}: trial {trial}, {} detector(s), {} samples -> {}",
        study.header.name,
        outcomes.len(),
        samples,
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
