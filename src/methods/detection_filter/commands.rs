//! What `fdimc validate`, `design` and `simulate` print and write for detection-filter decks.

use std::path::Path;

use nalgebra::DMatrix;
use serde_json::json;

use super::false_alarms::{CONDITIONAL_SEED, for_detector};
use super::filter::{DetectionFilterParams, Gain, Isolation};
use super::study::{LtiStudy, Shape};
use super::trials::Engine;
use crate::design::Assignment;
use crate::engine::method::select_detector;
use crate::engine::run::output::Trace;
use crate::engine::run::runner::RunError;

/// A deck whose detector cannot be designed is invalid input.
fn design_error(deck: &Path, what: &str, e: impl std::fmt::Display) -> RunError {
    RunError::Invalid(format!("{}: detector: {what}: {e}", deck.display()))
}

/// The FMU truth, if the deck has one: file, interface, trim, and where `[plant]` came from.
fn print_truth(study: &LtiStudy) {
    let Some(t) = &study.truth else { return };
    let nums = |v: &[f64]| v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(", ");
    println!(
        "truth       FMU {} ({}, FMI {}, sha256 {}), {}",
        t.fmu.file_name(),
        t.fmu.description.model_name,
        t.fmu.description.fmi_version,
        &t.fmu.sha256[..16],
        t.interface.name()
    );
    if let Some(s) = &study.trim {
        let pairs = |names: &[String], v: &[f64]| {
            names.iter().zip(v).map(|(n, x)| format!("{n} {x}")).collect::<Vec<_>>().join(", ")
        };
        println!(
            "            trim solved in {} Newton steps: {}; residual {}",
            s.trim.steps,
            pairs(&s.free, &s.trim.values),
            s.zero.iter().zip(&s.trim.residual).map(|(n, x)| format!("{n} {x:.3e}")).collect::<Vec<_>>().join(", ")
        );
    }
    println!("            trim inputs [{}], outputs at the trim [{}]", nums(&t.input_trim), nums(&t.output_trim));
    println!(
        "            [plant] is {}",
        match &study.linearisation {
            Some(l) if l.x_trim.is_empty() =>
                "identified from the FMU's responses at the trim (fdimc design prints it)",
            Some(_) => "the FMU's linearisation at the trim (fdimc design prints it)",
            None => "the deck's matrices, in deviations from the trim",
        }
    );
    if let Some(a) = &t.at_start {
        let h = study.header.dt_s / t.substeps as f64;
        println!(
            "            model exchange: RK4, {} step{} of {h} s per study step; fastest mode at the trim {:.4} rad/s (|lambda| h = {:.3})",
            t.substeps,
            if t.substeps == 1 { "" } else { "s" },
            a.fastest_mode_per_s,
            a.fastest_mode_per_s * h
        );
        println!(
            "            states at the start: {}",
            (a.state_names.iter().zip(&a.states).zip(&a.derivatives))
                .map(|((n, x), dx)| format!("{n} {x} (d/dt {dx:.3e})"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    for w in study.truth_warnings() {
        eprintln!("warning: {}: {w}", study.header.path.display());
    }
}

/// `fdimc design`: gains, closed-loop eigenvalues, conditioning and bias signatures per detector.
pub fn design(study: &LtiStudy, as_json: bool) -> Result<(), RunError> {
    let deck = &study.header.path;
    let ranks = study.design_plant.structural_ranks().ok_or_else(|| {
        RunError::Internal("staircase reduction of the design plant failed (non-finite matrices?)".into())
    })?;
    let p = &study.design_plant;
    let mut filters = Vec::with_capacity(study.detectors.len());
    for d in &study.detectors {
        let f = d.params.design(&study.design_plant, study.header.dt_s).map_err(|e| design_error(deck, &d.name, e))?;
        filters.push(f);
    }

    if as_json {
        let rows =
            |m: &DMatrix<f64>| (0..m.nrows()).map(|i| m.row(i).iter().copied().collect::<Vec<_>>()).collect::<Vec<_>>();
        let assignment = |a: &Assignment| {
            json!({
                "K": rows(&a.K),
                "closed_loop_eigenvalues": a.closed_loop_eigenvalues,
                "eigenvector_condition": a.eigenvector_condition,
                "relative_residual": a.relative_residual,
            })
        };
        let detectors: Vec<_> = study
            .detectors
            .iter()
            .zip(&filters)
            .map(|(d, f)| {
                let (eigenvalues, directions) = match &d.params.gain {
                    Gain::Eigenstructure { eigenvalues_per_s, fault_directions } => {
                        (json!(eigenvalues_per_s), json!(rows(&fault_directions.transpose())))
                    }
                    Gain::Own(_) => (json!(null), json!(null)),
                };
                let false_alarms = match for_detector(study, f, f.thresholds.as_slice(), CONDITIONAL_SEED) {
                    Ok(a) => json!({
                        "residual_sd_end": a.residual_sd_end,
                        "lower": a.lower,
                        "upper": a.upper(),
                        "sidak_upper": a.sidak_upper,
                        "hunter_upper": a.hunter_upper,
                        "union_bound": a.sum,
                        "largest_sample": a.largest_sample,
                        "lower_from": a.lower_from(),
                        "samples": a.samples,
                        "conditional_monte_carlo": a.conditional,
                        "conditional_monte_carlo_lo": a.conditional_lo,
                        "conditional_monte_carlo_hi": a.conditional_hi,
                        "conditional_monte_carlo_draws": a.conditional_draws,
                        "hour_over_conversion": a.hour.map(|h| h.ratio),
                        "slowest_time_constant_s": a.hour.map(|h| h.slowest_time_constant_s),
                        "conversion_undercounts": a.hour.map(|h| h.undercounts()),
                    }),
                    Err(why) => json!({ "not_computed": why }),
                };
                json!({
                    "name": d.name,
                    "kind": d.params.kind(),
                    "false_alarms_at_deck_thresholds": false_alarms,
                    "eigenvalues_per_s": eigenvalues,
                    "fault_directions": directions,
                    "continuous": f.continuous.as_ref().map(assignment),
                    "discrete": assignment(&f.discrete),
                    "bias_signatures": rows(&f.signatures.transpose()),
                })
            })
            .collect();
        let doc = json!({
            "deck": deck.display().to_string(),
            "study": study.header.name,
            "dt_s": study.header.dt_s,
            "states": p.state_names,
            "outputs": p.output_names,
            "ranks": ranks,
            "linear_model": study.linearisation.as_ref().map(|l| json!({
                "method": l.method,
                "a": rows(&l.a), "b": rows(&l.b), "c": rows(&l.c), "d": rows(&l.d),
                "x_trim": l.x_trim,
                "derivative_at_trim": l.derivative_at_trim,
            })),
            "detectors": detectors,
        });
        println!("{}", serde_json::to_string_pretty(&doc).map_err(|e| RunError::Internal(e.to_string()))?);
        return Ok(());
    }

    println!("{}: {}", deck.display(), study.header.name);
    print_truth(study);
    if let Some(l) = &study.linearisation {
        println!("linear model (deviations from the trim), from {}:", l.method);
        for (name, m) in [("A", &l.a), ("B", &l.b), ("C", &l.c), ("D", &l.d)] {
            println!("  {name} =");
            print!("{}", indent(&format!("{m:.6}")));
        }
        // An identified model has no FMU states, so no derivatives at the trim to show.
        if !l.derivative_at_trim.is_empty() {
            let worst = l.derivative_at_trim.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            println!(
                "  the trim's state derivatives (zero at an equilibrium): [{}], largest {worst:.3e}",
                l.derivative_at_trim.iter().map(|v| format!("{v:.3e}")).collect::<Vec<_>>().join(", ")
            );
        }
    }
    println!(
        "rank ctrb(A, B) = {} of {}, rank obsv(A, C) = {} of {}",
        ranks.controllability_rank, ranks.states, ranks.observability_rank, ranks.states
    );
    for (d, filter) in study.detectors.iter().zip(&filters) {
        let discrete_label = format!("discrete time, dt = {} s", study.header.dt_s);
        println!("\ndetector {:?} ({}): {}", d.name, d.params.kind(), gain_summary(&d.params));
        let mut designs = vec![(discrete_label.as_str(), &filter.discrete)];
        if let Some(c) = &filter.continuous {
            designs.insert(0, ("continuous time", c));
        }
        for (label, a) in designs {
            println!(
                "{label}: K (rows: states {}; columns: outputs {})",
                p.state_names.join(", "),
                p.output_names.join(", ")
            );
            print!("{}", indent(&format!("{:.6}", a.K)));
            let evs: Vec<String> = a.closed_loop_eigenvalues.iter().map(|e| format!("{e:.9}")).collect();
            println!("  eigenvalues of A - K C: [{}]", evs.join(", "));
            println!("  eigenvector condition number: {:.6}", a.eigenvector_condition);
            if let Some(w) = a.conditioning_warning() {
                eprintln!("warning: detector {:?} ({label}): {w}", d.name);
            }
            if !a.relative_residual.is_nan() {
                println!("  assignment residual |(A - K C) F - F Lambda| / |A F|: {:.3e}", a.relative_residual);
            }
        }
        println!("steady residual per unit bias on each output (columns: faulty output; rows: residual)");
        print!("{}", indent(&format!("{:.4}", filter.signatures)));
        match for_detector(study, filter, filter.thresholds.as_slice(), CONDITIONAL_SEED) {
            Ok(f) => {
                let hour = |p: f64| crate::engine::results::thresholds::per_flight_hour(p, study.header.duration_s);
                println!(
                    "fault-free residual standard deviation per output at the trial's end (model exact, white Gaussian noise): {}",
                    p.output_names
                        .iter()
                        .zip(&f.residual_sd_end)
                        .map(|(n, s)| format!("{n} {s:.4e}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                println!(
                    "  thresholds at the deck: {}",
                    p.output_names
                        .iter()
                        .zip(filter.thresholds.iter())
                        .zip(&f.residual_sd_end)
                        .map(|((n, t), s)| format!("{n} {t} ({:.1} sd)", t / s))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                println!(
                    "false alarms at the deck's thresholds, analytic (fault-free, model exact, white Gaussian noise, {} samples):",
                    f.samples
                );
                println!(
                    "  per trial in [{:.4e}, {:.4e}] (lower: {}; upper: the smaller of Sidak {:.4e} and Hunter {:.4e}); per flight hour [{:.4e}, {:.4e}]",
                    f.lower,
                    f.upper(),
                    f.lower_from(),
                    f.sidak_upper,
                    f.hunter_upper,
                    hour(f.lower),
                    hour(f.upper())
                );
                println!(
                    "  conditional Monte Carlo on the same law ({} draws): {:.4e} [{:.4e}, {:.4e}] per trial, {:.4e} per flight hour",
                    f.conditional_draws,
                    f.conditional,
                    f.conditional_lo,
                    f.conditional_hi,
                    hour(f.conditional)
                );
                println!(
                    "  largest single sample (Sidak over its outputs) {:.3e}; sum over samples (union bound) {:.3e}",
                    f.largest_sample, f.sum
                );
                if let Some(h) = f.hour.filter(|h| h.ratio.is_finite()) {
                    // The per-hour figures above take the hour's trials as independent, each begun
                    // with the filter on the truth: a slow mode leaves a trial's residual unsettled.
                    println!(
                        "  per flight hour by that conversion: extremal index {:.3} against it over a whole hour flown from the same start (-ln P(no alarm) by Sidak's bounds, the hour's over its trials'; slowest mode of A - K C: time constant {:.3} s, against {} s trials)",
                        h.ratio, h.slowest_time_constant_s, study.header.duration_s
                    );
                    if h.undercounts() {
                        eprintln!(
                            "warning: detector {:?}: the per-flight-hour figures converted from a trial under-count false alarms about {:.2} times (the residual has not settled within a {} s trial: a mode of time constant {:.3} s): they are lower bounds, not figures to quote; estimate a whole flight with `fdimc rare-event DECK --flight-s 3600`",
                            d.name, h.ratio, study.header.duration_s, h.slowest_time_constant_s
                        );
                    }
                }
            }
            Err(why) => println!("false alarms, analytic: not computed: {why}"),
        }
    }
    Ok(())
}

/// How a detector's gain is designed, in a few words.
fn gain_summary(params: &DetectionFilterParams) -> String {
    match &params.gain {
        Gain::Eigenstructure { eigenvalues_per_s, fault_directions } => format!(
            "eigenvalues [{}] 1/s on {} fault directions",
            eigenvalues_per_s.iter().map(|l| format!("{l}")).collect::<Vec<_>>().join(", "),
            fault_directions.ncols()
        ),
        Gain::Own(g) => g.describe(),
    }
}

/// `fdimc validate`: the plant, its ranks, the detectors' designs and the Monte Carlo study.
pub fn validate(study: &LtiStudy) -> Result<(), RunError> {
    let deck = &study.header.path;
    let mut filters = Vec::with_capacity(study.detectors.len());
    for d in &study.detectors {
        filters
            .push(d.params.design(&study.design_plant, study.header.dt_s).map_err(|e| design_error(deck, &d.name, e))?);
    }
    let p = &study.plant;
    let ranks = p.structural_ranks().ok_or_else(|| {
        RunError::Internal("staircase reduction of the design plant failed (non-finite matrices?)".into())
    })?;
    let list = |v: &[String]| v.join(", ");
    let nums = |v: &[f64]| v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(", ");

    study.header.print_valid();
    println!("plant       {} states [{}]", p.n_states(), list(&p.state_names));
    println!("            {} inputs [{}]", p.n_inputs(), list(&p.input_names));
    println!("            {} outputs [{}]", p.n_outputs(), list(&p.output_names));
    println!(
        "            rank ctrb(A, B) = {} of {}, rank obsv(A, C) = {} of {}",
        ranks.controllability_rank, ranks.states, ranks.observability_rank, ranks.states
    );
    let same = study.design_plant.A == p.A && study.design_plant.B == p.B;
    let model = if study.truth.is_some() { "plant" } else { "true plant" };
    println!(
        "design      {}",
        if same { format!("on the {model}") } else { format!("on a design model that differs from the {model}") }
    );
    print_truth(study);
    if let Some(c) = &study.controller_fmu {
        let names = |idx: &[usize], of: &[String]| idx.iter().map(|&j| of[j].as_str()).collect::<Vec<_>>().join(", ");
        println!(
            "controller  FMU {} (co-simulation, sha256 {}): sees the measured [{}] and the commands on [{}], drives [{}]",
            c.fmu.fmu.file_name(),
            &c.fmu.fmu.sha256[..16],
            names(&c.measured, &p.output_names),
            names(&c.commands, &p.input_names),
            names(&c.drives, &p.input_names)
        );
    } else if study.output_feedback.amax() > 0.0 {
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
    if study.sensor_law.iter().any(|l| *l != crate::engine::scenario::noise::SensorLaw::Gaussian) {
        let laws: Vec<String> = study.sensor_law.iter().map(|l| l.describe()).collect();
        println!("            sensor law [{}] (each scaled to its sigma)", laws.join(", "));
    }
    if study.process_sigma_per_step.amax() > 0.0 {
        println!("            process sigma per step [{}]", nums(study.process_sigma_per_step.as_slice()));
    }
    for (d, filter) in study.detectors.iter().zip(&filters) {
        let params = &d.params;
        println!("detector    {}: {}, {}", d.name, params.kind(), gain_summary(params));
        println!(
            "            alarm when {} exceeds [{}]",
            filter.decision.describe(),
            nums(params.thresholds.as_slice())
        );
        let rule = match params.isolation {
            Isolation::Signature => "the bias signature nearest the mean residual",
            Isolation::LargestNormalised => "the largest normalised mean residual",
            Isolation::Named => "the channel the detector names by the end of the window,",
        };
        println!(
            "            isolation: {rule} {} s to {} s after the alarm",
            params.isolation_delay_s,
            params.isolation_delay_s + params.isolation_window_s
        );
        if filter.decision.fmu().is_some() {
            continue; // no filter runs for a detector FMU: no eigenvalues to show
        }
        // The continuous design's eigenvalues (1/s) where there is one, else the discrete ones.
        let (a, unit) = match &filter.continuous {
            Some(c) => (c, "1/s"),
            None => (&filter.discrete, "discrete"),
        };
        println!(
            "            closed-loop eigenvalues [{}] ({unit}), eigenvector condition {:.3}",
            a.closed_loop_eigenvalues.iter().map(|e| format!("{:.6}", e.re)).collect::<Vec<_>>().join(", "),
            a.eigenvector_condition
        );
        if let Some(w) = a.conditioning_warning() {
            eprintln!("warning: {}: detector {:?}: {w}", deck.display(), d.name);
        }
    }
    let mc = &study.monte_carlo;
    println!(
        "monte carlo {} trials, fault-free fraction {}, sampler {}, target Pfa {}",
        mc.common.trials, mc.common.fault_free_fraction, mc.common.sampler, mc.common.target_pfa
    );
    if !mc.faults.is_empty() {
        let outs: Vec<&str> = mc.outputs.iter().map(|&j| p.output_names[j].as_str()).collect();
        println!(
            "            faults on [{}], onset {} s, noise scale {}",
            outs.join(", "),
            mc.common.onset_s,
            mc.common.noise_scale
        );
        for f in &mc.faults {
            let on = if f.inputs.is_empty() {
                String::new()
            } else {
                let names: Vec<&str> = f.inputs.iter().map(|&k| study.failing_inputs[k].as_str()).collect();
                format!(" on inputs [{}]", names.join(", "))
            };
            println!("            fault kind {}{on}: size {}", f.record_kind(), f.size_text());
        }
    }
    for pe in &mc.parameter_errors {
        let how = if pe.absolute { "absolute" } else { "relative" };
        println!("            parameter error {} on the {} model: {how} {}", pe.name, pe.model, pe.value);
    }
    if study.faults.is_empty() && study.actuator_faults.is_empty() && mc.faults.is_empty() {
        println!("faults      none");
    }
    let sensors = study.faults.iter().map(|f| (&p.output_names[f.channel], f.mode.name(), f));
    let actuators = study.actuator_faults.iter().map(|f| (&study.failing_inputs[f.channel], f.mode.actuator_name(), f));
    for (target, kind, f) in sensors.chain(actuators) {
        let size = f.mode.size();
        let size = if size.is_nan() { String::new() } else { format!(" {size}") };
        println!("fault       {target} {kind}{size} from {} s", f.onset_s);
    }
    Ok(())
}

/// `fdimc simulate`: one trial of one detector configuration, every sample.
pub fn simulate(study: &LtiStudy, trial: u64, detector: Option<&str>, out: &Path) -> Result<(), RunError> {
    let deck = &study.header.path;
    let names: Vec<&str> = study.detectors.iter().map(|d| d.name.as_str()).collect();
    let index = select_detector(&study.header, &names, detector)?.unwrap_or(0);
    let engine = Engine::new(study);
    let mut trace = Trace::default();
    let (spec, outcome) = match engine.simulate(trial, index, &mut trace) {
        Ok(flown) => flown,
        Err(e) => {
            // What the trial flew before it failed is what shows why.
            if !trace.float_columns.is_empty() {
                trace.write(out)?;
                eprintln!("trial {trial}: its samples up to the failure -> {}", out.display());
            }
            return Err(design_error(deck, &format!("trial {trial}, detector {}", names[index]), e));
        }
    };
    trace.write(out)?;

    println!(
        "{}: trial {trial}, detector {}, {} samples -> {}",
        study.header.name,
        names[index],
        study.header.steps,
        out.display()
    );
    let outputs = &study.plant.output_names;
    match spec.target_name(study) {
        Some(target) => {
            println!("  fault               {target} {}", spec.fault.label())
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
        Some((t, j)) => {
            println!("  detected            {t:.3} s on {} (delay {:.3} s)", outputs[j], t - spec.fault.onset_s)
        }
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

pub(super) fn indent(s: &str) -> String {
    s.lines().filter(|l| !l.trim().is_empty()).map(|l| format!("            {l}\n")).collect()
}
