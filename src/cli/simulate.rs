use std::path::Path;

use super::{CliError, design_error};
use crate::output::{TableFormat, trace_frame, write_table};
use crate::sampling::MAX_TRIAL;
use crate::sim::{Engine, Trace};
use crate::study::Study;

pub fn exec(deck: &Path, trial: u64, detector: Option<&str>, out: &Path) -> Result<(), CliError> {
    // Check the output name before simulating, so a typo costs nothing.
    TableFormat::from_path(out)?;
    if trial > MAX_TRIAL {
        return Err(CliError::Invalid(format!("--trial {trial}: allowed 0 to {MAX_TRIAL}")));
    }
    let study = Study::load(deck)?;
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
