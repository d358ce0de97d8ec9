//! Channel faults as decks write them: a fixed scenario (`[[faults]]`) and sampled populations
//! (`[[monte_carlo.fault]]`), the same syntax in every deck with sensor faults (methods 000 and 002).
//! A kind whose model has inputs that can fail (detection-filter decks) also takes actuator faults:
//! `input = "..."` in `[[faults]]`, `inputs = [...]` in a population. Their records name the kind
//! `actuator_<kind>` (so a sensor bias and an actuator bias are different rows, with their own units).

use serde::Deserialize;

use super::{ChannelFault, FaultMode};
use crate::engine::results::schema::unit;
use crate::engine::scenario::deck::{DeckError, Factor, FactorSpec, Validator};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSection {
    /// The faulty sensor's output, or
    pub output: Option<String>,
    /// the faulty actuator's input (kinds with actuator faults).
    pub input: Option<String>,
    pub kind: String,
    pub onset_s: f64,
    pub size: Option<f64>,
    pub frequency_hz: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultKindSection {
    pub kind: String,
    pub size: Option<FactorSpec>,
    pub size_sigma: Option<FactorSpec>,
    pub frequency_hz: Option<f64>,
    /// Actuator faults on one of these inputs (drawn per trial) instead of a sensor fault.
    pub inputs: Option<Vec<String>>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// Held at the reading at onset.
    Stuck,
    Gain,
    Bias,
    TotalFailure,
    /// An actuator whose surface trails at its trim (inputs only).
    Float,
    Drift,
    Oscillation {
        frequency_hz: f64,
    },
}

impl FaultKind {
    pub fn name(&self) -> &'static str {
        match self {
            FaultKind::Stuck => "stuck",
            FaultKind::Gain => "gain",
            FaultKind::Bias => "bias",
            FaultKind::TotalFailure => "total_failure",
            FaultKind::Float => "float",
            FaultKind::Drift => "drift",
            FaultKind::Oscillation { .. } => "oscillation",
        }
    }

    /// The fault with a given size (channel units, or a factor for gain; a stuck fault with a NaN size
    /// holds the value at onset).
    pub fn mode(&self, size: f64) -> FaultMode {
        match *self {
            FaultKind::Stuck => FaultMode::Stuck { value: (!size.is_nan()).then_some(size) },
            FaultKind::Gain => FaultMode::Gain { factor: size },
            FaultKind::Bias => FaultMode::Bias { bias: size },
            FaultKind::TotalFailure => FaultMode::TotalFailure,
            FaultKind::Float => FaultMode::Float,
            FaultKind::Drift => FaultMode::Drift { rate_per_s: size },
            FaultKind::Oscillation { frequency_hz } => FaultMode::Oscillation { amplitude: size, frequency_hz },
        }
    }
}

/// How a fault kind's size is given.
#[derive(Debug, Clone, PartialEq)]
pub enum SizeSpec {
    /// The kind has no size (stuck at the held value, total failure).
    None,
    /// In the faulty output's units (a factor for gain).
    Output(Factor),
    /// In multiples of the faulty output's nominal sensor sigma (so one spec fits every output).
    SensorSigma(Factor),
}

impl SizeSpec {
    /// A trial's size and its group label, from dimension `dim` of its draws; NaN for a kind without one.
    pub fn draw(&self, t: &mut crate::engine::scenario::draws::TrialDraws, dim: usize) -> (f64, f64) {
        match self {
            SizeSpec::None => (f64::NAN, f64::NAN),
            SizeSpec::Output(f) | SizeSpec::SensorSigma(f) => t.factor(f, dim),
        }
    }

    /// Whether trials draw the size (a range or several values): a factor of a sensitivity design.
    pub fn is_sampled(&self) -> bool {
        matches!(self, SizeSpec::Output(f) | SizeSpec::SensorSigma(f) if f.is_sampled())
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct FaultKindSpec {
    pub kind: FaultKind,
    pub size: SizeSpec,
    /// The inputs an actuator fault of this population may hit (indices of the deck's failing inputs);
    /// empty: a sensor fault on one of `monte_carlo.outputs`.
    pub inputs: Vec<usize>,
}

impl FaultKindSpec {
    /// The `kind` of its records: the kind's name, `actuator_<kind>` for an actuator population.
    pub fn record_kind(&self) -> &'static str {
        let mode = self.kind.mode(f64::NAN);
        if self.inputs.is_empty() { mode.name() } else { mode.actuator_name() }
    }

    /// As `validate` prints it: `none`, `1 to 25 in 6 bins (multiples of the sensor sigma)`.
    pub fn size_text(&self) -> String {
        match &self.size {
            SizeSpec::None => unit::NONE.to_string(),
            SizeSpec::Output(x) | SizeSpec::SensorSigma(x) => format!("{x} ({})", self.size_unit()),
        }
    }

    /// The size bins of these populations, per fault kind (ranges only).
    pub fn size_bins(populations: &[FaultKindSpec]) -> crate::engine::scenario::deck::SizeBins {
        let mut bins = Default::default();
        for f in populations {
            if let SizeSpec::Output(x) | SizeSpec::SensorSigma(x) = &f.size {
                x.add_bins_to(f.record_kind(), &mut bins);
            }
        }
        bins
    }

    /// The unit the deck gives this population's sizes in.
    pub fn size_unit(&self) -> &'static str {
        match (&self.size, self.kind) {
            (SizeSpec::None, _) => unit::NONE,
            // A drift's size is its rate.
            (SizeSpec::SensorSigma(_), FaultKind::Drift) => unit::SENSOR_SIGMA_PER_S,
            (SizeSpec::SensorSigma(_), _) => unit::SENSOR_SIGMA,
            (SizeSpec::Output(_), FaultKind::Drift) => unit::OUTPUT_UNITS_PER_S,
            (SizeSpec::Output(_), FaultKind::Gain) => unit::GAIN_FACTOR,
            (SizeSpec::Output(_), _) if !self.inputs.is_empty() => unit::INPUT_UNITS,
            (SizeSpec::Output(_), _) => unit::OUTPUT_UNITS,
        }
    }

    /// A drawn size, given in [`FaultKindSpec::size_unit`], in the faulty output's units (`sigma`: its
    /// nominal sensor sigma).
    pub fn in_output_units(&self, given: f64, sigma: f64) -> f64 {
        match self.size {
            SizeSpec::SensorSigma(_) => given * sigma,
            _ => given,
        }
    }
}

/// One trial's faults and how the tables label them (the core columns `kind`, `target`, `size`,
/// `size_bin`, `size_unit`, `onset_s`), for kinds whose faults are [`ChannelFault`]s.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialFaults {
    /// The sensor faults (channels: outputs).
    pub faults: Vec<ChannelFault>,
    /// The actuator faults (channels: the deck's failing inputs).
    pub actuators: Vec<ChannelFault>,
    /// Kind of the (first) fault as records name it, "none" when fault-free.
    pub kind: &'static str,
    /// The size as the deck gives it, in `size_unit` (the faults themselves are in their outputs'
    /// units); NaN when fault-free or for a kind without a size.
    pub size: f64,
    /// Group label of the size, in `size_unit`.
    pub size_bin: f64,
    pub size_unit: &'static str,
    /// The earliest onset; NaN when fault-free.
    pub onset_s: f64,
}

impl TrialFaults {
    /// As `simulate` and the trace plots say it: `bias 0.5503 (multiples of the sensor sigma) from
    /// 4.21 s`; a kind without a size (stuck, total failure) without one, not `size NaN`.
    pub fn label(&self) -> String {
        let text = crate::engine::results::text::significant;
        let size =
            if self.size.is_nan() { String::new() } else { format!(" {} ({})", text(self.size), self.size_unit) };
        format!("{}{size} from {} s", self.kind, text(self.onset_s))
    }

    pub fn none() -> Self {
        TrialFaults {
            faults: Vec::new(),
            actuators: Vec::new(),
            kind: crate::engine::results::schema::col::NO_FAULT,
            size: f64::NAN,
            size_bin: f64::NAN,
            size_unit: unit::NONE,
            onset_s: f64::NAN,
        }
    }

    /// No fault at all, sensor or actuator.
    pub fn is_fault_free(&self) -> bool {
        self.faults.is_empty() && self.actuators.is_empty()
    }

    /// The faulty channel the records name: the first sensor fault's output, else the first actuator
    /// fault's input; `None` when fault-free.
    pub fn target(&self) -> Option<FaultTarget> {
        match (self.faults.first(), self.actuators.first()) {
            (Some(f), _) => Some(FaultTarget::Output(f.channel)),
            (None, Some(f)) => Some(FaultTarget::Input(f.channel)),
            (None, None) => None,
        }
    }

    /// `population`'s fault on each of `channels` (outputs, or inputs for an actuator population) from
    /// `onset_s`, its size drawn as `(size, size_bin)` in the deck's unit; `sigma(j)`: output `j`'s
    /// nominal sensor sigma.
    pub fn drawn(
        population: &FaultKindSpec,
        channels: &[usize],
        (size, size_bin): (f64, f64),
        onset_s: f64,
        sigma: impl Fn(usize) -> f64,
    ) -> Self {
        let fault = |channel| {
            let mode = population.kind.mode(population.in_output_units(size, sigma(channel)));
            ChannelFault { channel, onset_s, mode }
        };
        let faults: Vec<ChannelFault> = channels.iter().map(|&j| fault(j)).collect();
        let (faults, actuators) =
            if population.inputs.is_empty() { (faults, Vec::new()) } else { (Vec::new(), faults) };
        TrialFaults {
            faults,
            actuators,
            kind: population.record_kind(),
            size,
            size_bin,
            size_unit: population.size_unit(),
            onset_s,
        }
    }

    /// The deck's fixed faults (`[[faults]]`) on sensors and actuators, labelled by the first sensor
    /// fault (the first actuator fault without one); none when there are none.
    pub fn fixed(sensors: &[ChannelFault], actuators: &[ChannelFault]) -> Self {
        let (first, actuator) = match (sensors.first(), actuators.first()) {
            (Some(f), _) => (f, false),
            (None, Some(f)) => (f, true),
            (None, None) => return TrialFaults::none(),
        };
        TrialFaults {
            faults: sensors.to_vec(),
            actuators: actuators.to_vec(),
            kind: if actuator { first.mode.actuator_name() } else { first.mode.name() },
            size: first.mode.size(),
            size_bin: first.mode.size(),
            size_unit: fixed_size_unit(&first.mode, actuator),
            onset_s: sensors.iter().chain(actuators).map(|f| f.onset_s).fold(f64::INFINITY, f64::min),
        }
    }
}

/// Which channel a trial's labelled fault is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultTarget {
    Output(usize),
    /// Among the deck's failing inputs.
    Input(usize),
}

/// The unit of a fixed (`[[faults]]`) fault's size: the channel's own, a factor for gain.
pub fn fixed_size_unit(mode: &FaultMode, actuator: bool) -> &'static str {
    match mode {
        FaultMode::Gain { .. } => unit::GAIN_FACTOR,
        m if m.size().is_nan() => unit::NONE,
        FaultMode::Drift { .. } => unit::OUTPUT_UNITS_PER_S,
        _ if actuator => unit::INPUT_UNITS,
        _ => unit::OUTPUT_UNITS,
    }
}

/// Whether a `[[faults]]` entry is on a sensor or an actuator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultSide {
    Sensor,
    Actuator,
}

impl Validator<'_> {
    /// The `[[monte_carlo.fault]]` populations (the same syntax in every deck with sensor faults);
    /// `inputs` names the inputs an actuator population may list (`[]`: the kind has no actuator
    /// faults), `list` what they are in messages.
    pub(crate) fn fault_kind_specs(
        &self,
        sections: &[FaultKindSection],
        (inputs, list): (&[String], &str),
    ) -> Result<Vec<FaultKindSpec>, DeckError> {
        (sections.iter().enumerate())
            .map(|(i, f)| self.fault_kind_spec(&format!("monte_carlo.fault[{i}]"), f, (inputs, list)))
            .collect()
    }

    fn fault_kind_spec(
        &self,
        prefix: &str,
        f: &FaultKindSection,
        (names, list): (&[String], &str),
    ) -> Result<FaultKindSpec, DeckError> {
        let field = |name: &str| format!("{prefix}.{name}");
        if f.frequency_hz.is_some() && f.kind != "oscillation" {
            return Err(self.err(field("frequency_hz"), format!("only used by kind \"oscillation\", not {:?}", f.kind)));
        }
        let inputs = match &f.inputs {
            None => Vec::new(),
            Some(_) if names.is_empty() => {
                return Err(self.err(field("inputs"), "this kind of study has no actuator faults: remove it"));
            }
            Some(given) if given.is_empty() => {
                return Err(self.err(field("inputs"), format!("name at least one of {list}")));
            }
            Some(given) => (given.iter().enumerate())
                .map(|(k, n)| self.index_of(&format!("{prefix}.inputs[{k}]"), n, names, list))
                .collect::<Result<_, _>>()?,
        };
        let actuator = !inputs.is_empty();
        let kind = match f.kind.as_str() {
            "stuck" => FaultKind::Stuck,
            "gain" => FaultKind::Gain,
            "bias" => FaultKind::Bias,
            "total_failure" if !actuator => FaultKind::TotalFailure,
            "float" if actuator => FaultKind::Float,
            "drift" => FaultKind::Drift,
            "oscillation" => match f.frequency_hz {
                Some(v) => FaultKind::Oscillation { frequency_hz: self.positive(&field("frequency_hz"), v)? },
                None => return Err(self.err(field("frequency_hz"), "required for kind \"oscillation\"")),
            },
            other => {
                let last = if actuator { ("float", "the surface trails at its trim") } else { ("total_failure", "") };
                let kinds = [
                    ("stuck", "held at onset, or at size"),
                    ("gain", ""),
                    ("bias", ""),
                    last,
                    ("drift", ""),
                    ("oscillation", ""),
                ];
                return Err(self.not_allowed(field("kind"), other, &kinds));
            }
        };
        let sized = !matches!(kind, FaultKind::Stuck | FaultKind::TotalFailure | FaultKind::Float);
        let size =
            match (sized, &f.size, &f.size_sigma) {
                (false, None, None) => SizeSpec::None,
                // Stuck at a value: the value is its size (in the channel's units).
                (false, Some(v), None) if kind == FaultKind::Stuck => {
                    SizeSpec::Output(self.factor(&field("size"), Some(v), Factor::Fixed(0.0))?)
                }
                (false, _, _) => {
                    let what = if kind == FaultKind::Stuck { "size (the value it is stuck at)" } else { "no size" };
                    return Err(self.err(field("size"), format!("kind {:?} takes {what}: remove size_sigma", f.kind)));
                }
                (true, Some(_), Some(_)) => {
                    return Err(self.err(field("size_sigma"), "give size or size_sigma, not both"));
                }
                (true, None, None) if actuator => {
                    return Err(self.err(field("size"), format!("kind {:?} needs size (input units)", f.kind)));
                }
                (true, None, None) => return Err(self.err(
                    field("size"),
                    format!(
                        "kind {:?} needs size (output units) or size_sigma (multiples of the output's sensor sigma)",
                        f.kind
                    ),
                )),
                (true, Some(v), None) => SizeSpec::Output(self.factor(&field("size"), Some(v), Factor::Fixed(0.0))?),
                (true, None, Some(v)) => {
                    if kind == FaultKind::Gain {
                        return Err(self.err(field("size_sigma"), "a gain is a factor: use size"));
                    }
                    if actuator {
                        return Err(self.err(field("size_sigma"), "an actuator has no sensor sigma: use size"));
                    }
                    SizeSpec::SensorSigma(self.factor(&field("size_sigma"), Some(v), Factor::Fixed(0.0))?)
                }
            };
        if kind == FaultKind::Gain
            && let SizeSpec::Output(factor) = &size
        {
            self.factor_within(&field("size"), factor, |v| v != 1.0, "gain factors != 1")?;
        }
        Ok(FaultKindSpec { kind, size, inputs })
    }

    /// `[[faults]][i]`: its output among `outputs` or its input among `inputs` (each `(names, what
    /// they are in messages)`; no inputs: the kind has no actuator faults), an onset within the trial
    /// (a fault after the end would never happen), a size its kind accepts.
    pub(crate) fn fault(
        &self,
        i: usize,
        f: &FaultSection,
        (outputs, list): (&[String], &str),
        (inputs, input_list): (&[String], &str),
        duration_s: f64,
    ) -> Result<(FaultSide, ChannelFault), DeckError> {
        let field = |name: &str| format!("faults[{i}].{name}");
        let (side, channel) = match (&f.output, &f.input) {
            (Some(o), None) => (FaultSide::Sensor, self.index_of(&field("output"), o, outputs, list)?),
            (None, Some(_)) if inputs.is_empty() => {
                return Err(self.err(field("input"), "this kind of study has no actuator faults: name an output"));
            }
            (None, Some(n)) => (FaultSide::Actuator, self.index_of(&field("input"), n, inputs, input_list)?),
            (Some(_), Some(_)) => {
                return Err(self.err(field("input"), "give output (a sensor) or input (an actuator), not both"));
            }
            (None, None) if inputs.is_empty() => {
                return Err(self.err(field("output"), format!("required: one of {list}")));
            }
            (None, None) => {
                return Err(self.err(
                    field("output"),
                    format!("required: output (a sensor, one of {list}) or input (an actuator, one of {input_list})"),
                ));
            }
        };
        let actuator = side == FaultSide::Actuator;
        let onset_s = self.finite(&field("onset_s"), f.onset_s)?;
        if !(0.0..duration_s).contains(&onset_s) {
            return Err(self.err(
                field("onset_s"),
                format!("{onset_s} s: allowed 0 <= onset_s < duration_s = {duration_s} (within the trial)"),
            ));
        }
        let size = match f.size {
            Some(v) => Some(self.finite(&field("size"), v)?),
            None => None,
        };
        let need_size = || size.ok_or_else(|| self.err(field("size"), format!("required for kind {:?}", f.kind)));
        if f.frequency_hz.is_some() && f.kind != "oscillation" {
            return Err(self.err(field("frequency_hz"), format!("only used by kind \"oscillation\", not {:?}", f.kind)));
        }
        let mode = match f.kind.as_str() {
            "stuck" => FaultMode::Stuck { value: size },
            "gain" => {
                let factor = need_size()?;
                if factor == 1.0 {
                    return Err(self.err(field("size"), "a gain fault needs a factor != 1"));
                }
                FaultMode::Gain { factor }
            }
            "bias" => {
                let bias = need_size()?;
                if bias == 0.0 {
                    return Err(self.err(field("size"), "a bias fault needs a bias != 0"));
                }
                FaultMode::Bias { bias }
            }
            "float" if actuator => {
                if size.is_some() {
                    return Err(
                        self.err(field("size"), "not used by kind \"float\" (the input trails at its trim): remove it")
                    );
                }
                FaultMode::Float
            }
            "total_failure" if !actuator => {
                if size.is_some() {
                    return Err(
                        self.err(field("size"), "not used by kind \"total_failure\" (the output is 0): remove it")
                    );
                }
                FaultMode::TotalFailure
            }
            "drift" => FaultMode::Drift { rate_per_s: need_size()? },
            "oscillation" => {
                let frequency_hz = match f.frequency_hz {
                    Some(v) => self.positive(&field("frequency_hz"), v)?,
                    None => return Err(self.err(field("frequency_hz"), "required for kind \"oscillation\"")),
                };
                FaultMode::Oscillation { amplitude: need_size()?, frequency_hz }
            }
            other => {
                let last = if actuator { "float" } else { "total_failure" };
                let kinds = ["stuck", "gain", "bias", last, "drift", "oscillation"].map(|k| (k, ""));
                return Err(self.not_allowed(field("kind"), other, &kinds));
            }
        };
        Ok((side, ChannelFault { channel, onset_s, mode }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trial_faults_label_drawn_and_fixed_faults() {
        // A bias of 3 sensor sigmas on channels 1 and 4, whose sigmas are 0.5 and 2.
        let population =
            FaultKindSpec { kind: FaultKind::Bias, size: SizeSpec::SensorSigma(Factor::Fixed(3.0)), inputs: vec![] };
        let drawn = TrialFaults::drawn(&population, &[1, 4], (3.0, 2.5), 12.0, |j| if j == 1 { 0.5 } else { 2.0 });
        let biases: Vec<(usize, FaultMode)> = drawn.faults.iter().map(|f| (f.channel, f.mode)).collect();
        assert_eq!(biases, [(1, FaultMode::Bias { bias: 1.5 }), (4, FaultMode::Bias { bias: 6.0 })]);
        assert!(drawn.faults.iter().all(|f| f.onset_s == 12.0));
        assert_eq!((drawn.kind, drawn.size, drawn.size_bin, drawn.size_unit), ("bias", 3.0, 2.5, unit::SENSOR_SIGMA));

        // The deck's fixed faults: labelled by the first, from the earliest onset.
        let fixed = TrialFaults::fixed(
            &[
                ChannelFault { channel: 2, onset_s: 9.0, mode: FaultMode::Gain { factor: 1.2 } },
                ChannelFault { channel: 0, onset_s: 4.0, mode: FaultMode::Bias { bias: 0.1 } },
            ],
            &[],
        );
        assert_eq!((fixed.kind, fixed.size, fixed.size_bin, fixed.size_unit), ("gain", 1.2, 1.2, unit::GAIN_FACTOR));
        assert_eq!((fixed.faults.len(), fixed.onset_s), (2, 4.0));

        // A drift's size is a rate: sigma (or output units) per second, in validate, tables and plots.
        let drift = |size| FaultKindSpec { kind: FaultKind::Drift, size, inputs: vec![] };
        assert_eq!(drift(SizeSpec::SensorSigma(Factor::Fixed(0.5))).size_unit(), unit::SENSOR_SIGMA_PER_S);
        assert_eq!(drift(SizeSpec::Output(Factor::Fixed(0.5))).size_unit(), unit::OUTPUT_UNITS_PER_S);
        assert_eq!(fixed_size_unit(&FaultMode::Drift { rate_per_s: 0.1 }, false), unit::OUTPUT_UNITS_PER_S);

        assert_eq!(drawn.label(), "bias 3 (multiples of the sensor sigma) from 12 s");
        let stuck = TrialFaults::fixed(
            &[ChannelFault { channel: 1, onset_s: 4.2137, mode: FaultMode::Stuck { value: None } }],
            &[],
        );
        assert_eq!(stuck.label(), "stuck from 4.214 s");

        let none = TrialFaults::fixed(&[], &[]);
        assert!(none.faults.is_empty() && none.onset_s.is_nan() && none.size.is_nan());
        assert_eq!((none.kind, none.size_unit), ("none", unit::NONE));
    }
}
