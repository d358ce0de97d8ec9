//! What an FMU's `modelDescription.xml` says that a deck needs: version, interfaces and their
//! capabilities, variables with causality, start, unit and declared range, the default experiment.
//!
//! Read with roxmltree, leniently: exporters write vendor attributes (Dymola's
//! `canHandleMultipleSetPerTimeInstant`) and elements a strict schema would refuse, and a deck's
//! checks need only what is read here.

use std::collections::HashMap;

/// The FMI major versions fdimc reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FmiVersion {
    V2,
    V3,
}

impl FmiVersion {
    pub fn label(self) -> &'static str {
        match self {
            FmiVersion::V2 => "2.0",
            FmiVersion::V3 => "3.0",
        }
    }
}

/// An FMI interface type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Interface {
    ModelExchange,
    CoSimulation,
}

impl Interface {
    /// The deck's spelling.
    pub fn name(self) -> &'static str {
        match self {
            Interface::ModelExchange => "model_exchange",
            Interface::CoSimulation => "co_simulation",
        }
    }
    pub const NAMES: &'static [&'static str] = &["model_exchange", "co_simulation"];
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "model_exchange" => Some(Interface::ModelExchange),
            "co_simulation" => Some(Interface::CoSimulation),
            _ => None,
        }
    }
}

/// One interface's element (`<ModelExchange>` or `<CoSimulation>`): its library and capabilities.
#[derive(Debug, Clone, PartialEq)]
pub struct InterfaceInfo {
    pub model_identifier: String,
    pub can_get_and_set_state: bool,
    pub provides_directional_derivatives: bool,
    pub only_one_instance_per_process: bool,
    pub needs_execution_tool: bool,
    /// Co-simulation: whether the communication step may differ from step to step.
    pub variable_step: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Causality {
    Parameter,
    CalculatedParameter,
    StructuralParameter,
    Input,
    Output,
    Local,
    Independent,
}

impl Causality {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "parameter" => Causality::Parameter,
            "calculatedParameter" => Causality::CalculatedParameter,
            "structuralParameter" => Causality::StructuralParameter,
            "input" => Causality::Input,
            "output" => Causality::Output,
            "local" => Causality::Local,
            "independent" => Causality::Independent,
            _ => return None,
        })
    }
    pub fn label(self) -> &'static str {
        match self {
            Causality::Parameter => "parameter",
            Causality::CalculatedParameter => "calculatedParameter",
            Causality::StructuralParameter => "structuralParameter",
            Causality::Input => "input",
            Causality::Output => "output",
            Causality::Local => "local",
            Causality::Independent => "independent",
        }
    }
}

/// A variable's value type, as far as fdimc exchanges it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueType {
    /// FMI 2.0 `Real`, FMI 3.0 `Float64`: what fdimc reads and writes.
    Real,
    /// FMI 2.0 `Integer`, FMI 3.0 `Int32`: readable as an isolated channel.
    Integer,
    Boolean,
    /// Anything else (strings, enumerations, other widths, clocks, binaries).
    Other,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    pub name: String,
    pub value_reference: u32,
    pub causality: Causality,
    pub variability: String,
    pub value_type: ValueType,
    /// The start value as written (a number for reals and integers).
    pub start: Option<String>,
    pub unit: Option<String>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// The declared `nominal` (its order of magnitude, FMI's scaling hint).
    pub nominal: Option<f64>,
    pub description: Option<String>,
    /// FMI 3.0 array variables: their dimensions' sizes where given as numbers (`start` sizes and
    /// `<Dimension start=...>`), empty for a scalar. fdimc exchanges scalars only.
    pub dimensions: Vec<Option<u64>>,
    /// The type's name as the description writes it (`Real`, `Float64`, `Int64`, `String`, ...).
    pub type_name: String,
}

impl Variable {
    /// How many values it holds: 1 for a scalar, the product of an array's sizes (`None`: a size
    /// the description does not give as a number).
    pub fn elements(&self) -> Option<usize> {
        self.dimensions.iter().try_fold(1usize, |n, d| Some(n * usize::try_from((*d)?).ok()?))
    }

    /// Its type as the description names it, lower case, with an array's sizes: `float64[3x3]`.
    pub fn type_label(&self) -> String {
        let name = self.type_name.to_lowercase();
        if self.dimensions.is_empty() {
            return name;
        }
        let sizes: Vec<String> = self.dimensions.iter().map(|d| d.map_or("?".to_string(), |n| n.to_string())).collect();
        format!("{name}[{}]", sizes.join("x"))
    }

    pub fn start_f64(&self) -> Option<f64> {
        self.start.as_deref().and_then(|s| s.trim().parse().ok())
    }
    /// `value` against the declared `[min, max]`: why it is outside, if it is.
    pub fn out_of_range(&self, value: f64) -> Option<String> {
        match (self.min, self.max) {
            (Some(lo), _) if value < lo => Some(format!("{value} is below its declared min {lo}")),
            (_, Some(hi)) if value > hi => Some(format!("{value} is above its declared max {hi}")),
            _ => None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DefaultExperiment {
    pub start_time_s: Option<f64>,
    pub stop_time_s: Option<f64>,
    pub tolerance: Option<f64>,
    pub step_size_s: Option<f64>,
}

/// The parts of `modelDescription.xml` fdimc uses.
#[derive(Debug, Clone, PartialEq)]
pub struct Description {
    pub version: FmiVersion,
    /// The `fmiVersion` attribute as written.
    pub fmi_version: String,
    pub model_name: String,
    /// FMI 2.0 `guid`, FMI 3.0 `instantiationToken`: checked by the FMU when it is instantiated.
    pub instantiation_token: String,
    pub generation_tool: Option<String>,
    pub model_exchange: Option<InterfaceInfo>,
    pub co_simulation: Option<InterfaceInfo>,
    pub variables: Vec<Variable>,
    pub default_experiment: DefaultExperiment,
    pub n_states: usize,
    /// FMI 2.0: each continuous state's value reference and its derivative's, in state order (the
    /// order of `<Derivatives>`); what directional derivatives are asked of. Empty when not declared.
    pub state_derivative_vrs: Vec<(u32, u32)>,
    pub n_event_indicators: usize,
    /// `<LogCategories>`' names: fdimc turns on the `logStatus*` ones, so the FMU logs its errors.
    pub log_categories: Vec<String>,
    /// `<ModelStructure>`'s declared dependencies of outputs and state derivatives, by the unknown's
    /// value reference: the value references it depends on. An unknown without a `dependencies`
    /// attribute is absent (it may depend on anything).
    pub dependencies: HashMap<u32, Vec<u32>>,
}

impl Description {
    /// Parses `modelDescription.xml`; the error says what is wrong in words (the caller names the file).
    pub fn parse(xml: &str) -> Result<Self, String> {
        let doc = roxmltree::Document::parse(xml).map_err(|e| format!("modelDescription.xml is not XML: {e}"))?;
        let root = doc.root_element();
        if root.tag_name().name() != "fmiModelDescription" {
            return Err(format!(
                "modelDescription.xml: root element is <{}>, not <fmiModelDescription>",
                root.tag_name().name()
            ));
        }
        let fmi_version = root.attribute("fmiVersion").ok_or("modelDescription.xml: no fmiVersion attribute")?;
        let version = if fmi_version.starts_with("2.") {
            FmiVersion::V2
        } else if fmi_version.starts_with("3.") {
            FmiVersion::V3
        } else {
            return Err(format!(
                "FMI version {fmi_version:?} is not supported: fdimc reads FMI 2.0 and 3.0 (an FMI 1.0 FMU can be \
                 re-exported as 2.0 by most tools)"
            ));
        };
        let child = |name: &str| root.children().find(|n| n.has_tag_name(name));
        let interface = |name: &str| {
            child(name).map(|n| {
                let flag = |a: &str| n.attribute(a).is_some_and(|v| v == "true");
                InterfaceInfo {
                    model_identifier: n.attribute("modelIdentifier").unwrap_or_default().to_string(),
                    can_get_and_set_state: flag("canGetAndSetFMUstate") || flag("canGetAndSetFMUState"),
                    provides_directional_derivatives: flag("providesDirectionalDerivative")
                        || flag("providesDirectionalDerivatives"),
                    only_one_instance_per_process: flag("canBeInstantiatedOnlyOncePerProcess"),
                    needs_execution_tool: flag("needsExecutionTool"),
                    variable_step: match version {
                        FmiVersion::V2 => flag("canHandleVariableCommunicationStepSize"),
                        // FMI 3.0 co-simulation always accepts any communication step.
                        FmiVersion::V3 => true,
                    },
                }
            })
        };
        let model_exchange = interface("ModelExchange");
        let co_simulation = interface("CoSimulation");
        for info in model_exchange.iter().chain(&co_simulation) {
            if info.model_identifier.is_empty() {
                return Err("modelDescription.xml: an interface element has no modelIdentifier".into());
            }
        }
        let number = |n: roxmltree::Node, a: &str| -> Result<Option<f64>, String> {
            n.attribute(a)
                .map(|v| {
                    v.trim().parse::<f64>().map_err(|_| format!("modelDescription.xml: {a}={v:?} is not a number"))
                })
                .transpose()
        };
        let default_experiment = match child("DefaultExperiment") {
            Some(n) => DefaultExperiment {
                start_time_s: number(n, "startTime")?,
                stop_time_s: number(n, "stopTime")?,
                tolerance: number(n, "tolerance")?,
                step_size_s: number(n, "stepSize")?,
            },
            None => DefaultExperiment::default(),
        };
        let types = type_definitions(child("TypeDefinitions"), version, &number)?;
        let variables = match child("ModelVariables") {
            Some(vars) => match version {
                FmiVersion::V2 => variables_v2(vars, &types, &number)?,
                FmiVersion::V3 => variables_v3(vars, &types, &number)?,
            },
            None => Vec::new(),
        };
        let structure = child("ModelStructure");
        let mut state_derivative_vrs = Vec::new();
        let (n_states, n_event_indicators) = match version {
            FmiVersion::V2 => {
                let unknowns: Vec<roxmltree::Node> = structure
                    .and_then(|s| s.children().find(|n| n.has_tag_name("Derivatives")))
                    .map_or_else(Vec::new, |d| d.children().filter(|n| n.has_tag_name("Unknown")).collect());
                // Unknown index -> the derivative's ScalarVariable (1-based), whose `derivative`
                // attribute is its state's index.
                let scalars: Vec<roxmltree::Node> = child("ModelVariables")
                    .map_or_else(Vec::new, |v| v.children().filter(|n| n.has_tag_name("ScalarVariable")).collect());
                let index = |n: roxmltree::Node, a: &str| {
                    n.attribute(a)
                        .and_then(|v| v.trim().parse::<usize>().ok())
                        .and_then(|i| scalars.get(i.checked_sub(1)?))
                };
                let vr = |n: &roxmltree::Node| n.attribute("valueReference").and_then(|v| v.trim().parse::<u32>().ok());
                for u in &unknowns {
                    let derivative = index(*u, "index");
                    let state = derivative
                        .and_then(|d| d.children().find(|n| n.has_tag_name("Real")))
                        .and_then(|real| index(real, "derivative"));
                    match (state.and_then(vr), derivative.and_then(vr)) {
                        (Some(s), Some(d)) => state_derivative_vrs.push((s, d)),
                        _ => {
                            state_derivative_vrs.clear();
                            break;
                        }
                    }
                }
                let z = root.attribute("numberOfEventIndicators").and_then(|v| v.trim().parse().ok()).unwrap_or(0);
                (unknowns.len(), z)
            }
            FmiVersion::V3 => {
                let count = |tag: &str| structure.map_or(0, |s| s.children().filter(|n| n.has_tag_name(tag)).count());
                // Each ContinuousStateDerivative's variable names its state in its `derivative` attribute.
                let by_vr: HashMap<u32, roxmltree::Node> = child("ModelVariables")
                    .map(|v| {
                        v.children()
                            .filter(|n| n.is_element())
                            .filter_map(|n| Some((n.attribute("valueReference")?.trim().parse().ok()?, n)))
                            .collect()
                    })
                    .unwrap_or_default();
                for d in
                    structure.iter().flat_map(|s| s.children()).filter(|n| n.has_tag_name("ContinuousStateDerivative"))
                {
                    let dvr = d.attribute("valueReference").and_then(|v| v.trim().parse::<u32>().ok());
                    let svr = dvr
                        .and_then(|d| by_vr.get(&d))
                        .and_then(|n| n.attribute("derivative"))
                        .and_then(|v| v.trim().parse::<u32>().ok());
                    match (svr, dvr) {
                        (Some(s), Some(d)) => state_derivative_vrs.push((s, d)),
                        _ => {
                            state_derivative_vrs.clear();
                            break;
                        }
                    }
                }
                // An array state is as many states as it has elements (where its sizes are known).
                let elements = state_derivative_vrs.iter().try_fold(0usize, |sum, &(state, _)| {
                    let v = variables.iter().find(|v| v.value_reference == state)?;
                    Some(sum + v.elements()?)
                });
                (elements.unwrap_or(count("ContinuousStateDerivative")), count("EventIndicator"))
            }
        };
        let dependencies = dependencies_of(structure, version, child("ModelVariables"));
        let log_categories = child("LogCategories")
            .map(|c| c.children().filter_map(|n| n.attribute("name").map(str::to_string)).collect())
            .unwrap_or_default();
        Ok(Description {
            dependencies,
            log_categories,
            version,
            fmi_version: fmi_version.to_string(),
            model_name: root.attribute("modelName").unwrap_or_default().to_string(),
            instantiation_token: root
                .attribute(if version == FmiVersion::V2 { "guid" } else { "instantiationToken" })
                .unwrap_or_default()
                .to_string(),
            generation_tool: root.attribute("generationTool").map(str::to_string),
            model_exchange,
            co_simulation,
            variables,
            default_experiment,
            n_states,
            state_derivative_vrs,
            n_event_indicators,
        })
    }

    pub fn interface(&self, interface: Interface) -> Option<&InterfaceInfo> {
        match interface {
            Interface::ModelExchange => self.model_exchange.as_ref(),
            Interface::CoSimulation => self.co_simulation.as_ref(),
        }
    }

    /// Why two instances on `interface` must not run on two threads of one process (`None`: they may):
    /// the description forbids a second instance (`canBeInstantiatedOnlyOncePerProcess`), or the
    /// exporter's runtime is known to share unlocked global state between instances. OpenModelica's
    /// does (its memory pool: a 2-thread run in process died in about 1 run of 10 with a heap corruption
    /// or a segmentation fault, tests/data/openmodelica/README.md), though its descriptions do not say
    /// so. In worker processes each process has its own, so only a run in process needs one thread.
    pub fn one_thread_per_process(&self, interface: Interface) -> Option<String> {
        if self.interface(interface).is_some_and(|i| i.only_one_instance_per_process) {
            return Some("it may be instantiated only once per process (canBeInstantiatedOnlyOncePerProcess)".into());
        }
        let tool = self.generation_tool.as_deref().unwrap_or_default();
        tool.contains("OpenModelica")
            .then(|| format!("its exporter's runtime ({tool}) shares unlocked global memory between instances"))
    }

    pub fn variable(&self, name: &str) -> Option<&Variable> {
        self.variables.iter().find(|v| v.name == name)
    }

    /// The real variable of value reference `vr` (value references are unique per type only).
    pub fn real(&self, vr: u32) -> Option<&Variable> {
        self.variables.iter().find(|v| v.value_reference == vr && v.value_type == ValueType::Real)
    }

    /// The real variable's name, or `vr N` where the description has none.
    pub fn real_name(&self, vr: u32) -> String {
        self.real(vr).map_or_else(|| format!("vr {vr}"), |v| v.name.clone())
    }

    /// The continuous states' names in state order, where `<ModelStructure>` declares them.
    pub fn state_names(&self) -> Vec<String> {
        self.state_derivative_vrs.iter().map(|s| self.real_name(s.0)).collect()
    }

    /// The names of the variables of `causality`, for messages that list what a deck may name.
    pub fn names_of(&self, causality: &[Causality]) -> Vec<&str> {
        self.variables.iter().filter(|v| causality.contains(&v.causality)).map(|v| v.name.as_str()).collect()
    }
}

/// A declared type's unit, range and nominal, by type name.
type Types = HashMap<String, (Option<String>, Option<f64>, Option<f64>, Option<f64>)>;

fn type_definitions(
    node: Option<roxmltree::Node>,
    version: FmiVersion,
    number: &dyn Fn(roxmltree::Node, &str) -> Result<Option<f64>, String>,
) -> Result<Types, String> {
    let mut types = Types::new();
    let Some(node) = node else { return Ok(types) };
    for t in node.children().filter(|n| n.is_element()) {
        // FMI 2.0: <SimpleType name><Real unit min max/></SimpleType>; FMI 3.0: <Float64Type name unit .../>.
        let (name, attrs) = match version {
            FmiVersion::V2 => match (t.attribute("name"), t.children().find(|n| n.is_element())) {
                (Some(name), Some(elem)) => (name, elem),
                _ => continue,
            },
            FmiVersion::V3 => match t.attribute("name") {
                Some(name) => (name, t),
                None => continue,
            },
        };
        types.insert(
            name.to_string(),
            (
                attrs.attribute("unit").map(str::to_string),
                number(attrs, "min")?,
                number(attrs, "max")?,
                number(attrs, "nominal")?,
            ),
        );
    }
    Ok(types)
}

fn causality_of(n: roxmltree::Node, name: &str) -> Result<Causality, String> {
    let c = n.attribute("causality").unwrap_or("local");
    Causality::parse(c).ok_or_else(|| format!("modelDescription.xml: variable {name:?} has an unknown causality {c:?}"))
}

fn variables_v2(
    vars: roxmltree::Node,
    types: &Types,
    number: &dyn Fn(roxmltree::Node, &str) -> Result<Option<f64>, String>,
) -> Result<Vec<Variable>, String> {
    let mut out = Vec::new();
    for v in vars.children().filter(|n| n.has_tag_name("ScalarVariable")) {
        let name = v.attribute("name").ok_or("modelDescription.xml: a ScalarVariable has no name")?;
        let vr = value_reference(v, name)?;
        let Some(elem) = v.children().find(|n| n.is_element() && !n.has_tag_name("Annotations")) else {
            return Err(format!("modelDescription.xml: variable {name:?} has no type element"));
        };
        let value_type = match elem.tag_name().name() {
            "Real" => ValueType::Real,
            "Integer" | "Enumeration" => ValueType::Integer,
            "Boolean" => ValueType::Boolean,
            _ => ValueType::Other,
        };
        let declared = elem.attribute("declaredType").and_then(|t| types.get(t));
        out.push(Variable {
            name: name.to_string(),
            value_reference: vr,
            causality: causality_of(v, name)?,
            variability: v.attribute("variability").unwrap_or("continuous").to_string(),
            value_type,
            start: elem.attribute("start").map(str::to_string),
            unit: elem.attribute("unit").map(str::to_string).or_else(|| declared.and_then(|d| d.0.clone())),
            min: number(elem, "min")?.or(declared.and_then(|d| d.1)),
            max: number(elem, "max")?.or(declared.and_then(|d| d.2)),
            nominal: number(elem, "nominal")?.or(declared.and_then(|d| d.3)),
            description: v.attribute("description").map(str::to_string),
            dimensions: Vec::new(),
            type_name: elem.tag_name().name().to_string(),
        });
    }
    Ok(out)
}

fn variables_v3(
    vars: roxmltree::Node,
    types: &Types,
    number: &dyn Fn(roxmltree::Node, &str) -> Result<Option<f64>, String>,
) -> Result<Vec<Variable>, String> {
    let mut out = Vec::new();
    for v in vars.children().filter(|n| n.is_element()) {
        let name = v.attribute("name").ok_or("modelDescription.xml: a variable has no name")?;
        let value_type = match v.tag_name().name() {
            "Float64" => ValueType::Real,
            "Int32" => ValueType::Integer,
            "Boolean" => ValueType::Boolean,
            _ => ValueType::Other,
        };
        let declared = v.attribute("declaredType").and_then(|t| types.get(t));
        out.push(Variable {
            name: name.to_string(),
            value_reference: value_reference(v, name)?,
            causality: causality_of(v, name)?,
            variability: v
                .attribute("variability")
                .unwrap_or(if value_type == ValueType::Real { "continuous" } else { "discrete" })
                .to_string(),
            value_type,
            start: v.attribute("start").map(str::to_string),
            unit: v.attribute("unit").map(str::to_string).or_else(|| declared.and_then(|d| d.0.clone())),
            min: number(v, "min")?.or(declared.and_then(|d| d.1)),
            max: number(v, "max")?.or(declared.and_then(|d| d.2)),
            nominal: number(v, "nominal")?.or(declared.and_then(|d| d.3)),
            description: v.attribute("description").map(str::to_string),
            dimensions: v
                .children()
                .filter(|n| n.has_tag_name("Dimension"))
                .map(|n| {
                    n.attribute("start").and_then(|s| s.trim().parse().ok()).or_else(|| {
                        // A structural parameter's size: its start value.
                        let vr: u32 = n.attribute("valueReference")?.trim().parse().ok()?;
                        let sizes = vars.children().filter(|m| m.is_element());
                        sizes
                            .filter(|m| m.attribute("valueReference").and_then(|r| r.trim().parse().ok()) == Some(vr))
                            .find_map(|m| m.attribute("start")?.trim().parse().ok())
                    })
                })
                .collect(),
            type_name: v.tag_name().name().to_string(),
        });
    }
    Ok(out)
}

/// The declared dependencies of the outputs and state derivatives (see [`Description::dependencies`]):
/// FMI 2.0 writes 1-based variable indices, FMI 3.0 value references.
fn dependencies_of(
    structure: Option<roxmltree::Node>,
    version: FmiVersion,
    variables: Option<roxmltree::Node>,
) -> HashMap<u32, Vec<u32>> {
    let mut out = HashMap::new();
    let Some(structure) = structure else { return out };
    let numbers = |s: &str| s.split_ascii_whitespace().map(|w| w.parse::<usize>().ok()).collect::<Option<Vec<_>>>();
    match version {
        FmiVersion::V2 => {
            let vrs: Vec<Option<u32>> = variables
                .map(|v| {
                    v.children()
                        .filter(|n| n.has_tag_name("ScalarVariable"))
                        .map(|n| n.attribute("valueReference").and_then(|r| r.trim().parse().ok()))
                        .collect()
                })
                .unwrap_or_default();
            let vr_of = |i: usize| vrs.get(i.checked_sub(1)?).copied().flatten();
            for group in structure.children().filter(|n| n.has_tag_name("Outputs") || n.has_tag_name("Derivatives")) {
                for u in group.children().filter(|n| n.has_tag_name("Unknown")) {
                    let unknown = u.attribute("index").and_then(|i| i.trim().parse().ok()).and_then(vr_of);
                    let deps = u
                        .attribute("dependencies")
                        .and_then(numbers)
                        .and_then(|d| d.into_iter().map(vr_of).collect::<Option<Vec<u32>>>());
                    if let (Some(unknown), Some(deps)) = (unknown, deps) {
                        out.insert(unknown, deps);
                    }
                }
            }
        }
        FmiVersion::V3 => {
            for u in
                structure.children().filter(|n| n.has_tag_name("Output") || n.has_tag_name("ContinuousStateDerivative"))
            {
                let unknown = u.attribute("valueReference").and_then(|i| i.trim().parse::<u32>().ok());
                let deps = u
                    .attribute("dependencies")
                    .and_then(numbers)
                    .map(|d| d.into_iter().map(|v| v as u32).collect::<Vec<u32>>());
                if let (Some(unknown), Some(deps)) = (unknown, deps) {
                    out.insert(unknown, deps);
                }
            }
        }
    }
    out
}

fn value_reference(v: roxmltree::Node, name: &str) -> Result<u32, String> {
    v.attribute("valueReference")
        .and_then(|s| s.trim().parse().ok())
        .ok_or_else(|| format!("modelDescription.xml: variable {name:?} has no valid valueReference"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const FMI2: &str = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{1}" numberOfEventIndicators="1">
  <ModelExchange modelIdentifier="m" canGetAndSetFMUstate="true"/>
  <CoSimulation modelIdentifier="m" canHandleVariableCommunicationStepSize="true"
                canBeInstantiatedOnlyOncePerProcess="true"/>
  <UnitDefinitions><Unit name="m/s"/></UnitDefinitions>
  <TypeDefinitions><SimpleType name="Speed"><Real unit="m/s" min="0"/></SimpleType></TypeDefinitions>
  <DefaultExperiment startTime="0" stopTime="3" stepSize="0.01"/>
  <ModelVariables>
    <ScalarVariable name="v" valueReference="1" causality="output" canHandleMultipleSetPerTimeInstant="false">
      <Real declaredType="Speed" start="2"/><Annotations/></ScalarVariable>
    <ScalarVariable name="der(v)" valueReference="2"><Real derivative="1"/></ScalarVariable>
    <ScalarVariable name="k" valueReference="3" causality="parameter" variability="fixed">
      <Real start="0.5" unit="1/s" min="0" max="1"/></ScalarVariable>
    <ScalarVariable name="n" valueReference="4" causality="output" variability="discrete"><Integer/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1"/></Outputs><Derivatives><Unknown index="2"/></Derivatives></ModelStructure>
</fmiModelDescription>"#;

    #[test]
    fn fmi2_units_ranges_and_capabilities_come_through_declared_types_and_exporter_attributes() {
        let d = Description::parse(FMI2).unwrap();
        assert_eq!(d.version, FmiVersion::V2);
        assert_eq!((d.n_states, d.n_event_indicators), (1, 1));
        // The state v (value reference 1) and its derivative der(v) (2), through the 1-based indices.
        assert_eq!(d.state_derivative_vrs, [(1, 2)]);
        let me = d.model_exchange.as_ref().unwrap();
        assert!(me.can_get_and_set_state && !me.only_one_instance_per_process);
        assert!(d.co_simulation.as_ref().unwrap().only_one_instance_per_process);
        let v = d.variable("v").unwrap();
        assert_eq!((v.unit.as_deref(), v.min, v.start_f64()), (Some("m/s"), Some(0.0), Some(2.0)));
        let k = d.variable("k").unwrap();
        assert_eq!(k.out_of_range(1.5).unwrap(), "1.5 is above its declared max 1");
        assert!(k.out_of_range(0.25).is_none());
        assert_eq!(d.variable("n").unwrap().value_type, ValueType::Integer);
        assert_eq!(d.default_experiment.step_size_s, Some(0.01));
        assert_eq!(d.names_of(&[Causality::Output]), ["v", "n"]);
    }

    #[test]
    fn fmi3_variables_and_structure_are_read_and_fmi1_is_refused() {
        let xml = r#"<fmiModelDescription fmiVersion="3.0" modelName="b" instantiationToken="t">
  <CoSimulation modelIdentifier="b" canGetAndSetFMUState="true" providesDirectionalDerivatives="true"/>
  <UnitDefinitions><Unit name="m"/></UnitDefinitions>
  <TypeDefinitions><Float64Type name="Height" unit="m" max="100"/></TypeDefinitions>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent"/>
    <Float64 name="h" valueReference="1" causality="output" declaredType="Height" start="1"/>
    <Float64 name="der(h)" valueReference="2" derivative="1"/>
    <Int32 name="c" valueReference="3" causality="output"/>
  </ModelVariables>
  <ModelStructure><Output valueReference="1"/><ContinuousStateDerivative valueReference="2"/>
    <EventIndicator valueReference="1"/></ModelStructure>
</fmiModelDescription>"#;
        let d = Description::parse(xml).unwrap();
        assert_eq!((d.version, d.n_states, d.n_event_indicators), (FmiVersion::V3, 1, 1));
        let cs = d.co_simulation.as_ref().unwrap();
        assert!(cs.can_get_and_set_state && cs.provides_directional_derivatives && cs.variable_step);
        assert!(d.model_exchange.is_none());
        let h = d.variable("h").unwrap();
        assert_eq!((h.unit.as_deref(), h.max, h.value_reference), (Some("m"), Some(100.0), 1));
        assert_eq!(d.variable("c").unwrap().value_type, ValueType::Integer);
        let old = Description::parse(r#"<fmiModelDescription fmiVersion="1.0"/>"#).unwrap_err();
        assert!(old.contains("\"1.0\" is not supported"), "{old}");
    }
}
