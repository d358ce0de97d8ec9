//! Sensor faults as decks write them: a fixed scenario (`[[faults]]`) and sampled populations
//! (`[[monte_carlo.fault]]`), the same syntax in every deck with sensor faults (methods 000 and 002).

use serde::Deserialize;

use super::{FaultMode, SensorFault};
use crate::engine::results::schema::unit;
use crate::engine::scenario::deck::{DeckError, Factor, FactorSpec, Validator};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSection {
    pub output: String,
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
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// Held at the reading at onset.
    Stuck,
    Gain,
    Bias,
    TotalFailure,
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
            FaultKind::Drift => "drift",
            FaultKind::Oscillation { .. } => "oscillation",
        }
    }

    /// The fault with a given size (output units, or a factor for gain).
    pub fn mode(&self, size: f64) -> FaultMode {
        match *self {
            FaultKind::Stuck => FaultMode::Stuck { value: None },
            FaultKind::Gain => FaultMode::Gain { factor: size },
            FaultKind::Bias => FaultMode::Bias { bias: size },
            FaultKind::TotalFailure => FaultMode::TotalFailure,
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
}

impl FaultKindSpec {
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
                x.add_bins_to(f.kind.name(), &mut bins);
            }
        }
        bins
    }

    /// The unit the deck gives this population's sizes in.
    pub fn size_unit(&self) -> &'static str {
        match (&self.size, self.kind) {
            (SizeSpec::None, _) => unit::NONE,
            (SizeSpec::SensorSigma(_), _) => unit::SENSOR_SIGMA,
            (SizeSpec::Output(_), FaultKind::Gain) => unit::GAIN_FACTOR,
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

/// One trial's sensor faults and how the tables label them (the core columns `kind`, `size`,
/// `size_bin`, `size_unit`, `onset_s`), for kinds whose faults are [`SensorFault`]s.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialFaults {
    /// The faults (empty: fault-free).
    pub faults: Vec<SensorFault>,
    /// Kind of the (first) fault, "none" when fault-free.
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
    pub fn none() -> Self {
        TrialFaults {
            faults: Vec::new(),
            kind: crate::engine::results::schema::col::NO_FAULT,
            size: f64::NAN,
            size_bin: f64::NAN,
            size_unit: unit::NONE,
            onset_s: f64::NAN,
        }
    }

    /// `population`'s fault on each of `channels` from `onset_s`, its size drawn as `(size, size_bin)`
    /// in the deck's unit; `sigma(j)`: channel `j`'s nominal sensor sigma.
    pub fn drawn(
        population: &FaultKindSpec,
        channels: &[usize],
        (size, size_bin): (f64, f64),
        onset_s: f64,
        sigma: impl Fn(usize) -> f64,
    ) -> Self {
        let fault = |channel| {
            let mode = population.kind.mode(population.in_output_units(size, sigma(channel)));
            SensorFault { channel, onset_s, mode }
        };
        TrialFaults {
            faults: channels.iter().map(|&j| fault(j)).collect(),
            kind: population.kind.name(),
            size,
            size_bin,
            size_unit: population.size_unit(),
            onset_s,
        }
    }

    /// The deck's fixed faults (`[[faults]]`), labelled by the first; none when there are none.
    pub fn fixed(faults: &[SensorFault]) -> Self {
        let Some(first) = faults.first() else { return TrialFaults::none() };
        TrialFaults {
            faults: faults.to_vec(),
            kind: first.mode.name(),
            size: first.mode.size(),
            size_bin: first.mode.size(),
            size_unit: fixed_size_unit(&first.mode),
            onset_s: faults.iter().map(|f| f.onset_s).fold(f64::INFINITY, f64::min),
        }
    }
}

/// The unit of a fixed (`[[faults]]`) fault's size: the output's own, a factor for gain.
pub fn fixed_size_unit(mode: &FaultMode) -> &'static str {
    match mode {
        FaultMode::Gain { .. } => unit::GAIN_FACTOR,
        m if m.size().is_nan() => unit::NONE,
        _ => unit::OUTPUT_UNITS,
    }
}

impl Validator<'_> {
    /// The `[[monte_carlo.fault]]` populations (the same syntax in every deck with sensor faults).
    pub(crate) fn fault_kind_specs(&self, sections: &[FaultKindSection]) -> Result<Vec<FaultKindSpec>, DeckError> {
        (sections.iter().enumerate())
            .map(|(i, f)| self.fault_kind_spec(&format!("monte_carlo.fault[{i}]"), f))
            .collect()
    }

    fn fault_kind_spec(&self, prefix: &str, f: &FaultKindSection) -> Result<FaultKindSpec, DeckError> {
        let field = |name: &str| format!("{prefix}.{name}");
        if f.frequency_hz.is_some() && f.kind != "oscillation" {
            return Err(self.err(field("frequency_hz"), format!("only used by kind \"oscillation\", not {:?}", f.kind)));
        }
        let kind = match f.kind.as_str() {
            "stuck" => FaultKind::Stuck,
            "gain" => FaultKind::Gain,
            "bias" => FaultKind::Bias,
            "total_failure" => FaultKind::TotalFailure,
            "drift" => FaultKind::Drift,
            "oscillation" => match f.frequency_hz {
                Some(v) => FaultKind::Oscillation { frequency_hz: self.positive(&field("frequency_hz"), v)? },
                None => return Err(self.err(field("frequency_hz"), "required for kind \"oscillation\"")),
            },
            other => {
                let kinds = [
                    ("stuck", "held at onset"),
                    ("gain", ""),
                    ("bias", ""),
                    ("total_failure", ""),
                    ("drift", ""),
                    ("oscillation", ""),
                ];
                return Err(self.not_allowed(field("kind"), other, &kinds));
            }
        };
        let sized = !matches!(kind, FaultKind::Stuck | FaultKind::TotalFailure);
        let size =
            match (sized, &f.size, &f.size_sigma) {
                (false, None, None) => SizeSpec::None,
                (false, _, _) => {
                    return Err(
                        self.err(field("size"), format!("kind {:?} has no size: remove size and size_sigma", f.kind))
                    );
                }
                (true, Some(_), Some(_)) => {
                    return Err(self.err(field("size_sigma"), "give size or size_sigma, not both"));
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
                    SizeSpec::SensorSigma(self.factor(&field("size_sigma"), Some(v), Factor::Fixed(0.0))?)
                }
            };
        if kind == FaultKind::Gain
            && let SizeSpec::Output(factor) = &size
        {
            self.factor_within(&field("size"), factor, |v| v != 1.0, "gain factors != 1")?;
        }
        Ok(FaultKindSpec { kind, size })
    }

    /// `[[faults]][i]`: its output among `outputs` (named `list` in messages), an onset within the
    /// trial (a fault after the end would never happen), a size its kind accepts.
    pub(crate) fn fault(
        &self,
        i: usize,
        f: &FaultSection,
        outputs: &[String],
        list: &str,
        duration_s: f64,
    ) -> Result<SensorFault, DeckError> {
        let field = |name: &str| format!("faults[{i}].{name}");
        let channel = self.index_of(&field("output"), &f.output, outputs, list)?;
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
            "total_failure" => {
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
                let kinds = ["stuck", "gain", "bias", "total_failure", "drift", "oscillation"].map(|k| (k, ""));
                return Err(self.not_allowed(field("kind"), other, &kinds));
            }
        };
        Ok(SensorFault { channel, onset_s, mode })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trial_faults_label_drawn_and_fixed_faults() {
        // A bias of 3 sensor sigmas on channels 1 and 4, whose sigmas are 0.5 and 2.
        let population = FaultKindSpec { kind: FaultKind::Bias, size: SizeSpec::SensorSigma(Factor::Fixed(3.0)) };
        let drawn = TrialFaults::drawn(&population, &[1, 4], (3.0, 2.5), 12.0, |j| if j == 1 { 0.5 } else { 2.0 });
        let biases: Vec<(usize, FaultMode)> = drawn.faults.iter().map(|f| (f.channel, f.mode)).collect();
        assert_eq!(biases, [(1, FaultMode::Bias { bias: 1.5 }), (4, FaultMode::Bias { bias: 6.0 })]);
        assert!(drawn.faults.iter().all(|f| f.onset_s == 12.0));
        assert_eq!((drawn.kind, drawn.size, drawn.size_bin, drawn.size_unit), ("bias", 3.0, 2.5, unit::SENSOR_SIGMA));

        // The deck's fixed faults: labelled by the first, from the earliest onset.
        let fixed = TrialFaults::fixed(&[
            SensorFault { channel: 2, onset_s: 9.0, mode: FaultMode::Gain { factor: 1.2 } },
            SensorFault { channel: 0, onset_s: 4.0, mode: FaultMode::Bias { bias: 0.1 } },
        ]);
        assert_eq!((fixed.kind, fixed.size, fixed.size_bin, fixed.size_unit), ("gain", 1.2, 1.2, unit::GAIN_FACTOR));
        assert_eq!((fixed.faults.len(), fixed.onset_s), (2, 4.0));

        let none = TrialFaults::fixed(&[]);
        assert!(none.faults.is_empty() && none.onset_s.is_nan() && none.size.is_nan());
        assert_eq!((none.kind, none.size_unit), ("none", unit::NONE));
    }
}
