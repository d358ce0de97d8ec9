//! What `fdimc validate` and `fdimc simulate` print and write for this kind of deck.

use std::path::Path;

use super::ekf_svm::SvmKernel;
use super::study::AccelerometerStudy;
use super::trial::TrainedClassifiers;
use crate::engine::run::output::Trace;
use crate::engine::run::runner::RunError;
use std::path::PathBuf;

/// The resolved accelerometer study (method 003).
pub fn validate(study: &AccelerometerStudy) -> Result<(), RunError> {
    let d = &study.design;
    study.header.print_valid();
    let n = &d.scenario.noise;
    let simulated = format!(
        "gyro noise {:.3} deg/s (bias spread {:.3}), accelerometer noise {} m/s^2 (bias spread {})",
        n.gyro_noise_std_rad_s.to_degrees(),
        n.gyro_bias_std_rad_s.to_degrees(),
        n.accel_noise_std_mps2,
        n.accel_bias_std_mps2
    );
    match &study.log {
        None => println!("imu         {simulated}"),
        Some(log) => {
            println!("log         {}", log_line(log));
            let part = |p| {
                let [a, b] = log.seconds(p);
                format!("[{a:.2}, {b:.2}) s")
            };
            println!("            trials start in the evaluated part {}", part(log.evaluate));
            match log.train {
                Some(p) => println!("            classifiers and thresholds may learn from {}", part(p)),
                None => println!("            nothing learns from the log (no train_s)"),
            }
            for (name, mean) in &log.removed_means {
                println!("            {name} less its training-part mean, {mean:.6e}");
            }
            for line in study.replay.iter().flat_map(replay_lines) {
                println!("            {line}");
            }
            println!("            simulated training trials (trained_on = \"simulation\"): {simulated}");
        }
    }
    let r = &d.ranges;
    println!(
        "faults      bias |{:?}| m/s^2, gain |factor - 1| {:?}, stuck at the reading at onset; onset {:?} s; axis and sign drawn",
        r.bias_mps2, r.gain_deviation, r.onset_s
    );
    println!("features    {} samples from {} s after the onset", d.features.window_len, d.window_delay_s);
    let t = &study.training;
    println!(
        "training    {} trials per class from seed {} at noise scales {:?}; SVM kernel {}, C {}",
        t.trials_per_class,
        t.seed,
        t.noise_scales,
        match t.svm.kernel {
            SvmKernel::Linear => "linear".to_string(),
            SvmKernel::Gaussian { gamma } => format!("gaussian (gamma {gamma:.4})"),
        },
        t.svm.c
    );
    println!(
        "detection   T over {} samples, threshold {}{}, counted from {} s",
        study.detection.window,
        study.detection.threshold,
        study
            .log_threshold_margin
            .map(|m| format!(" ({m} x the largest T of the fault-free training part)"))
            .unwrap_or_default(),
        study.settle_s
    );
    for c in &study.classifiers {
        println!(
            "classifier  {}: {} on the {} window, trained on {}{}",
            c.name,
            c.scheme.name(),
            c.window.name(),
            c.trained_on.name(),
            if c.balanced { ", classes weighted by the inverse of their size" } else { "" }
        );
    }
    let classes: Vec<&str> = study.classes.iter().map(|c| c.name()).collect();
    println!(
        "monte carlo {} trials, classes [{}] cycled, noise scale {}",
        study.monte_carlo.trials,
        classes.join(", "),
        study.monte_carlo.noise_scale
    );
    Ok(())
}

/// What the fault-free log gives at the study's threshold, part by part, with where each part's largest
/// statistic occurred, then the replay's warnings (`validate` and `run` print them).
pub fn replay_lines(r: &super::replay::ReplayRecord) -> Vec<String> {
    let e = &r.evaluate;
    let from = match r.calibration_margin {
        Some(m) => format!("{m} x the training part's largest"),
        None => "the deck's".to_string(),
    };
    let mut lines = vec![format!(
        "fault-free log, evaluated part [{:.2}, {:.2}) s, {:.1} s watched: largest T {:.1} at {:.2} s against the threshold {:.1} ({from}), {} alarm(s) ({:.0} per flight hour, 95 % upper bound {:.0})",
        e.part_s[0],
        e.part_s[1],
        e.watched_s,
        e.largest_statistic,
        e.largest_at_s,
        e.threshold,
        e.alarms,
        e.alarms_per_flight_hour,
        e.alarms_per_flight_hour_upper95
    )];
    if let Some(t) = &r.train {
        lines.push(format!(
            "fault-free log, training part [{:.2}, {:.2}) s, {:.1} s watched: largest T {:.1} at {:.2} s",
            t.part_s[0], t.part_s[1], t.watched_s, t.largest_statistic, t.largest_at_s
        ));
    }
    lines.extend(r.warnings.iter().map(|w| format!("warning: {w}")));
    lines
}

/// What was read of a replayed log and how it was repaired (the run reports it too).
pub fn log_line(log: &crate::engine::logs::log_source::ReplayLog) -> String {
    format!(
        "{} {} (SHA-256 {}): {} samples at {:.2} Hz from {:.3} s on the log's clock, counted as 0 (largest gap {:.3} s, bridged), resampled to {} samples every {} s (means over each step, interpolated across gaps){}",
        log.file.display(),
        log.origin,
        log.sha256,
        log.log_samples,
        log.log_rate_hz,
        log.first_sample_s,
        log.largest_gap_s,
        log.samples(),
        log.dt_s,
        log.ending.as_deref().map(|e| format!("; {e}")).unwrap_or_default()
    )
}

/// One trial of an accelerometer deck: the residual and its detection statistic per sample, and what
/// both classifiers make of the window after the onset (from `classifiers`, or trained now).
pub fn simulate(
    study: &AccelerometerStudy,
    trial: u64,
    out: &Path,
    classifiers: Option<&Path>,
) -> Result<(), RunError> {
    use crate::methods::accelerometer::AccelerometerTrials;
    use crate::methods::accelerometer::trial::TrainedClassifiers;
    let trained = match classifiers {
        Some(file) => TrainedClassifiers::load(file, study)?,
        None => TrainedClassifiers::train(study)
            .map_err(|e| RunError::Invalid(format!("{}: {e}", study.header.path.display())))?,
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
    let outcome = result
        .outcome
        .map_err(|e| RunError::Invalid(format!("{}: trial {trial}: {e}", study.header.path.display())))?;
    let threshold = study.detection.threshold;
    let alarm = floats.last().map(|(_, t)| t.iter().map(|&v| v >= threshold).collect()).unwrap_or_default();
    let samples = Trace { float_columns: floats, bool_columns: vec![("alarm".into(), alarm)] }.write(out)?;
    let s = &result.spec;
    println!("{}: trial {trial}, {} samples -> {}", study.header.name, samples, out.display());
    let axis = s.axis.map_or("-", |a| ["x", "y", "z"][a]);
    println!(
        "  class {} on axis {axis}, size {}, onset {:.3} s, noise scale {}",
        s.class.name(),
        s.size,
        s.onset_s,
        s.noise_scale
    );
    for (c, predicted) in trained.classifiers.iter().zip(&outcome.predicted) {
        println!("  {:<12} ({} window) predicts {}", c.name, c.window.name(), predicted.name());
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

/// `fdimc train`: trains an accelerometer deck's classifiers and writes them.
pub fn train(study: &AccelerometerStudy, out: Option<&Path>) -> Result<(), RunError> {
    let deck = &study.header.path;
    let out = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("results").join(&study.header.name).join("classifiers.json"));
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        // The folder is the user's choice (--out): one that cannot be made is their input to fix.
        std::fs::create_dir_all(parent).map_err(|e| {
            RunError::Invalid(format!("--out {}: cannot create the folder {} ({e})", out.display(), parent.display()))
        })?;
    }
    let started = std::time::Instant::now();
    let trained =
        TrainedClassifiers::train(study).map_err(|e| RunError::Invalid(format!("{}: {e}", deck.display())))?;
    trained.save(&out)?;
    println!(
        "{}: trained {} on {} trials per class (seed {}) in {:.1} s -> {}",
        study.header.name,
        trained
            .classifiers
            .iter()
            .map(|c| format!("{} ({} window)", c.name, c.window.name()))
            .collect::<Vec<_>>()
            .join(", "),
        study.training.trials_per_class,
        study.training.seed,
        started.elapsed().as_secs_f64(),
        out.display()
    );
    for (c, tree) in trained.classifiers.iter().filter_map(|c| c.classifier.tree().map(|t| (c, t))) {
        println!("  {}:", c.name);
        for (k, m) in tree.merges.iter().enumerate() {
            let names = |c: &[crate::methods::accelerometer::ekf_svm::FaultClass]| {
                c.iter().map(|c| c.name()).collect::<Vec<_>>().join("+")
            };
            println!(
                "    merge {}: {} | {} (separability {:.3}, of {} candidate pairs)",
                k + 1,
                names(&m.positive),
                names(&m.negative),
                m.separability,
                m.candidates.len()
            );
        }
    }
    Ok(())
}
