//! `fdimc fmu FILE`: what an FMU offers a deck (variables, units, ranges, capabilities), checked by
//! instantiating each interface fdimc can run.

use std::path::Path;

use crate::fmu::{Causality, Fmu, FmuError, Interface, Variable};

use super::CliError;

pub fn exec_fmu(file: &Path, locals: bool) -> Result<(), CliError> {
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
            match d.one_thread_per_process(interface) {
                Some(why) => format!("one thread in process ({why})"),
                None => "many".into(),
            },
            if interface == Interface::CoSimulation && !info.variable_step { ", fixed communication step" } else { "" },
        );
    }
    let inputs = d.variables.iter().filter(|v| v.causality == Causality::Input).collect::<Vec<_>>();
    table("inputs (commands, actuators, the model's own fault inputs)", &inputs, None);
    let outputs = d.variables.iter().filter(|v| v.causality == Causality::Output).collect::<Vec<_>>();
    table("outputs (sensors a deck may measure)", &outputs, None);
    // The states in state order, each with its derivative: a deck's [plant] states follow this order.
    // Each state with its own derivative (a state the description does not list is left out, with its).
    let (states, derivatives): (Vec<&Variable>, Vec<String>) = d
        .state_derivative_vrs
        .iter()
        .filter_map(|&(s, der)| Some((d.variables.iter().find(|v| v.value_reference == s)?, d.real_name(der))))
        .unzip();
    let declared: usize = states.iter().map(|v| v.elements().unwrap_or(1)).sum();
    let title = if declared == d.n_states {
        "continuous states (in the FMU's state order, which a deck's [plant] states follow; an array holds as many \
         as it has elements)"
            .to_string()
    } else {
        format!("continuous states (<ModelStructure> declares {declared} of the {} here)", d.n_states)
    };
    table(&title, &states, Some(&derivatives));
    let parameters = d.variables.iter().filter(|v| v.causality == Causality::Parameter).collect::<Vec<_>>();
    table("parameters (set before initialisation; a deck's parameter errors act on these)", &parameters, None);
    let local: Vec<&Variable> = d
        .variables
        .iter()
        .filter(|v| {
            v.causality == Causality::Local
                && !d.state_derivative_vrs.iter().any(|&(s, der)| v.value_reference == s || v.value_reference == der)
        })
        .collect();
    if locals {
        table("locals (the model's internal variables)", &local, None);
    } else {
        println!("\nlocals: {} (fdimc fmu --locals lists them)", local.len());
    }
    Ok(())
}

/// A titled table of variables: name, value reference, type (with array sizes), start, unit, range,
/// where given each one's derivative, and its description.
fn table(title: &str, vars: &[&Variable], derivatives: Option<&[String]>) {
    println!("\n{title}: {}", vars.len());
    if vars.is_empty() {
        return;
    }
    let show = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| v.to_string());
    let der = |i: usize| derivatives.map(|d| format!(" {:<16}", d[i])).unwrap_or_default();
    println!(
        "  {:<28} {:>6} {:<12} {:>14} {:<10} {:>10} {:>10}{}  description",
        "name",
        "vr",
        "type",
        "start",
        "unit",
        "min",
        "max",
        if derivatives.is_some() { format!(" {:<16}", "derivative") } else { String::new() }
    );
    for (i, v) in vars.iter().enumerate() {
        println!(
            "  {:<28} {:>6} {:<12} {:>14} {:<10} {:>10} {:>10}{}  {}",
            v.name,
            v.value_reference,
            v.type_label(),
            v.start.as_deref().unwrap_or("-"),
            v.unit.as_deref().unwrap_or("-"),
            show(v.min),
            show(v.max),
            der(i),
            v.description.as_deref().unwrap_or("")
        );
    }
}

fn yes(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}
