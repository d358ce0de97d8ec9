//! `fdimc fmu FILE`: what an FMU offers a deck (variables, units, ranges, capabilities), checked by
//! instantiating each interface fdimc can run.

use std::path::Path;

use crate::fmu::{Causality, Fmu, FmuError, Interface, Variable};

use super::CliError;

pub fn exec_fmu(file: &Path) -> Result<(), CliError> {
    let fmu = Fmu::open(file).map_err(|e| CliError::Invalid(e.to_string()))?;
    let d = &fmu.description;
    println!(
        "{}: FMI {} ({}), model {:?}",
        file.display(),
        d.fmi_version,
        d.generation_tool.as_deref().unwrap_or("tool not named"),
        d.model_name
    );
    println!("sha256 {}", fmu.sha256);
    println!("continuous states {}, event indicators {}", d.n_states, d.n_event_indicators);
    let e = &d.default_experiment;
    let show = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| v.to_string());
    println!(
        "default experiment: start {} s, stop {} s, step {} s, tolerance {}",
        show(e.start_time_s),
        show(e.stop_time_s),
        show(e.step_size_s),
        show(e.tolerance)
    );
    println!("\ninterfaces (deck `interface = ...`):");
    for interface in [Interface::ModelExchange, Interface::CoSimulation] {
        let Some(info) = d.interface(interface) else { continue };
        let runs = match fmu.supports(interface).and_then(|()| fmu.instantiate(interface, "fdimc-check").map(drop)) {
            Ok(()) => "runs here".to_string(),
            Err(FmuError::Invalid(why) | FmuError::Failed(why)) => format!("does not run here: {why}"),
        };
        println!(
            "  {:<15} library {:<20} get/set state {:<3} directional derivatives {:<3} instances per process {}{}: {runs}",
            interface.name(),
            info.model_identifier,
            yes(info.can_get_and_set_state),
            yes(info.provides_directional_derivatives),
            if info.only_one_instance_per_process { "one (runs on one thread)" } else { "many" },
            if interface == Interface::CoSimulation && !info.variable_step { ", fixed communication step" } else { "" },
        );
    }
    for (title, causality) in [
        ("inputs (commands, actuators, the model's own fault inputs)", &[Causality::Input][..]),
        ("outputs (sensors a deck may measure)", &[Causality::Output]),
        ("parameters (set before initialisation; a deck's parameter errors act on these)", &[Causality::Parameter]),
    ] {
        let vars: Vec<&Variable> = d.variables.iter().filter(|v| causality.contains(&v.causality)).collect();
        println!("\n{title}: {}", vars.len());
        if vars.is_empty() {
            continue;
        }
        println!(
            "  {:<28} {:>6} {:<9} {:>14} {:<10} {:>10} {:>10}  description",
            "name", "vr", "type", "start", "unit", "min", "max"
        );
        for v in vars {
            println!(
                "  {:<28} {:>6} {:<9} {:>14} {:<10} {:>10} {:>10}  {}",
                v.name,
                v.value_reference,
                format!("{:?}", v.value_type).to_lowercase(),
                v.start.as_deref().unwrap_or("-"),
                v.unit.as_deref().unwrap_or("-"),
                show(v.min),
                show(v.max),
                v.description.as_deref().unwrap_or("")
            );
        }
    }
    Ok(())
}

fn yes(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}
