//! Control-surface study decks (method 004): parse a TOML deck with an `[airframe]` section, then
//! validate it into a [`SurfaceStudy`] that cannot be invalid. Every rejection names the file, the
//! field as a TOML path and what is allowed, like the LTI decks of [`super`].
//!
//! ```toml
//! [study]            name, seed, duration_s, dt_s
//! [airframe]         model = "aerosonde", trim_airspeed_mps, trim_altitude_m, optional wind_ned_mps
//! [sensors]          optional: gyro_variance_rad2_s2, flow_angle_variance_rad2, airspeed_variance_m2_s2,
//!                    attitude_sigma_rad (defaults: the seed's, attitude 0.01 rad)
//! [[setpoint]]       from_s, airspeed_mps, altitude_m, roll_deg (optional schedule; trim before the first)
//! [[surface_fault]]  surface (aileron_left, aileron_right, elevator_left, elevator_right, rudder),
//!                    kind = "stuck" (position_deg) | "oscillation" (low_deg, high_deg, period_s)
//!                    | "loss_of_effectiveness" (effectiveness in [0, 1)), onset_s, optional end_s
//! [[bank]]           name, covariance = "ekf" | "strong_tracking" | "symmetric_strong_tracking",
//!                    likelihood = "gaussian" | "euclidean_norm" | "euclidean_norm_1d", optional overrides of the seed's numbers
//! [monte_carlo]      trials, fault_free_fraction, sampler, surfaces (default all), onset_s,
//!                    fault_duration_s (default: to the end), noise_scale (factors, as the LTI decks')
//! [[monte_carlo.fault]]            kind = "stuck" (position_deg) | "oscillation" (amplitude_deg,
//!                    optional center_deg = 0, period_s = 2) | "loss_of_effectiveness" (effectiveness)
//! [[monte_carlo.parameter_error]]  name, model = "plant" | "design", coefficients (names of
//!                    `AerosondeParams` coefficients; a book coefficient scales the split surfaces'
//!                    terms derived from it too), relative (factor: each scaled by 1 + relative)
//! ```
//!
//! Without `[[monte_carlo.fault]]` every faulty trial flies the deck's `[[surface_fault]]` scenario and
//! trials differ in their noise (and parameter errors); with it, each faulty trial has one sampled fault
//! on one of `monte_carlo.surfaces` and the fixed scenario is not used. A stuck position and an
//! oscillation's centre are absolute deflections, as the seed gives them (its rudder stuck at -1 deg is 1
//! deg from trim); the actuator's +/-25 deg travel limits every command.

use std::path::Path;

use serde::Deserialize;

use crate::engine::method::Opt;
use crate::engine::scenario::deck::{
    DeckError, Factor, FromDeck, MonteCarlo, MonteCarloRules, StudyHeader, Validator, open_deck,
};
use crate::engine::scenario::deck::{FactorSpec, StudySection};
use crate::estimation::{FloorRule, LikelihoodForm};
use crate::methods::surface_bank::actuator::DEFAULT_SQUARE_WAVE_PERIOD_S;
use crate::methods::surface_bank::actuator::{ActuatorFault, ActuatorFaultKind};
use crate::methods::surface_bank::stmmae::{BankParams, CovarianceForm};
use crate::vehicles::aerosonde::{DERIVED_COEFFICIENTS, SCALABLE_COEFFICIENTS, SURFACE_NAMES, Setpoints};

/// The options this kind takes beyond the common ones (its `Method::options`): said here, where its deck
/// rules read them (`monte_carlo.target_pfa` with [`Opt::Thresholds`]).
pub const OPTIONS: &[Opt] = &[Opt::Thresholds];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SurfaceDeck {
    study: StudySection,
    airframe: AirframeSection,
    sensors: Option<SensorsSection>,
    #[serde(default)]
    setpoint: Vec<SetpointSection>,
    #[serde(default)]
    surface_fault: Vec<SurfaceFaultSection>,
    bank: Vec<BankSection>,
    monte_carlo: Option<crate::engine::scenario::deck::MonteCarloSection>,
}

/// `[monte_carlo]`'s own fields in control-surface decks.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct MonteCarloOwn {
    surfaces: Option<Vec<String>>,
    fault_duration_s: Option<FactorSpec>,
    #[serde(default)]
    fault: Vec<MonteCarloFaultSection>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MonteCarloFaultSection {
    kind: String,
    position_deg: Option<FactorSpec>,
    amplitude_deg: Option<FactorSpec>,
    center_deg: Option<f64>,
    period_s: Option<f64>,
    effectiveness: Option<FactorSpec>,
}

/// What a parameter error scales, as decks write it.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CoefficientsSection {
    coefficients: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AirframeSection {
    model: String,
    trim_airspeed_mps: f64,
    trim_altitude_m: f64,
    wind_ned_mps: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorsSection {
    gyro_variance_rad2_s2: Option<f64>,
    flow_angle_variance_rad2: Option<f64>,
    airspeed_variance_m2_s2: Option<f64>,
    attitude_sigma_rad: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SetpointSection {
    from_s: f64,
    airspeed_mps: f64,
    altitude_m: f64,
    roll_deg: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SurfaceFaultSection {
    surface: String,
    kind: String,
    onset_s: f64,
    end_s: Option<f64>,
    position_deg: Option<f64>,
    low_deg: Option<f64>,
    high_deg: Option<f64>,
    period_s: Option<f64>,
    effectiveness: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BankSection {
    name: String,
    covariance: String,
    likelihood: String,
    process_variance_per_s: Option<[f64; 5]>,
    measurement_variance: Option<[f64; 5]>,
    surface_process_variance_rad2_per_s: Option<f64>,
    rho: Option<f64>,
    beta: Option<f64>,
    a: Option<[f64; 5]>,
    a_surface: Option<f64>,
    declare_hold_s: Option<f64>,
    clear_hold_s: Option<f64>,
    probability_floor_rule: Option<String>,
}

/// Sensor noise of the truth simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorNoise {
    pub gyro_variance_rad2_s2: f64,
    pub flow_angle_variance_rad2: f64,
    pub airspeed_variance_m2_s2: f64,
    pub attitude_sigma_rad: f64,
}

impl SensorNoise {
    /// Every standard deviation times `factor` (variances times `factor^2`).
    pub fn scaled(&self, factor: f64) -> SensorNoise {
        let f2 = factor * factor;
        SensorNoise {
            gyro_variance_rad2_s2: self.gyro_variance_rad2_s2 * f2,
            flow_angle_variance_rad2: self.flow_angle_variance_rad2 * f2,
            airspeed_variance_m2_s2: self.airspeed_variance_m2_s2 * f2,
            attitude_sigma_rad: self.attitude_sigma_rad * factor,
        }
    }
}

/// A sampled fault population of a surface Monte Carlo study; sizes in degrees (effectiveness: a
/// fraction).
#[derive(Debug, Clone, PartialEq)]
pub enum SurfaceFaultSpec {
    /// The surface driven to and held at `position_deg`.
    Stuck { position_deg: Factor },
    /// Square wave between `center_deg - amplitude_deg` and `center_deg + amplitude_deg`.
    Oscillation { amplitude_deg: Factor, center_deg: f64, period_s: f64 },
    /// Only `effectiveness` of the surface's deflection acts on the airframe.
    LossOfEffectiveness { effectiveness: Factor },
}

impl SurfaceFaultSpec {
    pub fn name(&self) -> &'static str {
        match self {
            SurfaceFaultSpec::Stuck { .. } => "stuck",
            SurfaceFaultSpec::Oscillation { .. } => "oscillation",
            SurfaceFaultSpec::LossOfEffectiveness { .. } => "loss_of_effectiveness",
        }
    }

    /// The factor whose value is the fault's size.
    pub fn size(&self) -> &Factor {
        match self {
            SurfaceFaultSpec::Stuck { position_deg } => position_deg,
            SurfaceFaultSpec::Oscillation { amplitude_deg, .. } => amplitude_deg,
            SurfaceFaultSpec::LossOfEffectiveness { effectiveness } => effectiveness,
        }
    }
}

/// Airframe coefficients a parameter error scales (names from [`SCALABLE_COEFFICIENTS`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CoefficientNames(pub Vec<String>);

/// Relative errors of airframe coefficients, on the truth or on the banks' model.
pub type CoefficientError = crate::engine::scenario::deck::ParameterError<CoefficientNames>;

/// The Monte Carlo section of a surface study.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceMonteCarlo {
    pub common: MonteCarlo,
    /// Surfaces a sampled fault may hit (indices into [`SURFACE_NAMES`]).
    pub surfaces: Vec<usize>,
    /// How long a sampled fault lasts; `None`: to the end of the trial.
    pub fault_duration_s: Option<Factor>,
    /// Sampled faults; empty: every faulty trial flies the deck's `[[surface_fault]]` scenario.
    pub faults: Vec<SurfaceFaultSpec>,
    pub parameter_errors: Vec<CoefficientError>,
}

/// A validated control-surface study.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceStudy {
    pub header: StudyHeader,
    pub trim_airspeed_mps: f64,
    pub trim_altitude_m: f64,
    pub wind_ned_mps: [f64; 3],
    pub sensors: SensorNoise,
    pub setpoints: Vec<(f64, Setpoints)>,
    pub faults: Vec<ActuatorFault>,
    pub banks: Vec<(String, BankParams)>,
    pub monte_carlo: SurfaceMonteCarlo,
}

impl FromDeck for SurfaceStudy {
    fn from_toml(text: &str, path: &Path) -> Result<SurfaceStudy, DeckError> {
        let (deck, v, header) = open_deck(text, path, |d: &SurfaceDeck| &d.study)?;
        let (duration_s, dt_s) = (header.duration_s, header.dt_s);
        if dt_s > 0.05 || dt_s * 10.0 > duration_s {
            return Err(v.err("study.dt_s", format!("must be at most 0.05 s and a tenth of duration_s, got {dt_s}")));
        }

        let a = &deck.airframe;
        if a.model != "aerosonde" {
            return Err(v.err(
                "airframe.model",
                format!("must be \"aerosonde\" (the only airframe so far), got {:?}", a.model),
            ));
        }
        let trim_airspeed_mps = v.positive("airframe.trim_airspeed_mps", a.trim_airspeed_mps)?;
        if !(15.0..=45.0).contains(&trim_airspeed_mps) {
            return Err(
                v.err("airframe.trim_airspeed_mps", format!("must be within 15..45 m/s, got {trim_airspeed_mps}"))
            );
        }
        let trim_altitude_m = v.positive("airframe.trim_altitude_m", a.trim_altitude_m)?;
        let wind_ned_mps = a.wind_ned_mps.unwrap_or([0.0; 3]);
        for (i, w) in wind_ned_mps.iter().enumerate() {
            v.finite(&format!("airframe.wind_ned_mps[{i}]"), *w)?;
        }

        let sensors = {
            let s = deck.sensors.as_ref();
            let non_negative = |field: &str, x: Option<f64>, default: f64| {
                v.non_negative(&format!("sensors.{field}"), x.unwrap_or(default))
            };
            SensorNoise {
                gyro_variance_rad2_s2: non_negative(
                    "gyro_variance_rad2_s2",
                    s.and_then(|s| s.gyro_variance_rad2_s2),
                    0.0076,
                )?,
                flow_angle_variance_rad2: non_negative(
                    "flow_angle_variance_rad2",
                    s.and_then(|s| s.flow_angle_variance_rad2),
                    0.0012,
                )?,
                airspeed_variance_m2_s2: non_negative(
                    "airspeed_variance_m2_s2",
                    s.and_then(|s| s.airspeed_variance_m2_s2),
                    1.0,
                )?,
                attitude_sigma_rad: non_negative("attitude_sigma_rad", s.and_then(|s| s.attitude_sigma_rad), 0.01)?,
            }
        };

        let mut setpoints = Vec::new();
        for (i, sp) in deck.setpoint.iter().enumerate() {
            let field = |f: &str| format!("setpoint[{i}].{f}");
            let from_s = v.finite(&field("from_s"), sp.from_s)?;
            if let Some(&(last, _)) = setpoints.last()
                && from_s <= last
            {
                return Err(v.err(
                    field("from_s"),
                    format!("must be later than the previous setpoint's {last} s, got {from_s}"),
                ));
            }
            let va_mps = v.positive(&field("airspeed_mps"), sp.airspeed_mps)?;
            let altitude_m = v.positive(&field("altitude_m"), sp.altitude_m)?;
            let roll_deg = v.finite(&field("roll_deg"), sp.roll_deg)?;
            if roll_deg.abs() > 45.0 {
                return Err(v.err(
                    field("roll_deg"),
                    format!("must be within -45..45 deg (the autopilot's limit), got {roll_deg}"),
                ));
            }
            setpoints.push((from_s, Setpoints { va_mps, altitude_m, roll_rad: roll_deg.to_radians() }));
        }

        let mut faults = Vec::new();
        for (i, f) in deck.surface_fault.iter().enumerate() {
            let field = |f: &str| format!("surface_fault[{i}].{f}");
            let surface = SURFACE_NAMES.iter().position(|n| *n == f.surface).ok_or_else(|| {
                v.err(field("surface"), format!("must be one of {}, got {:?}", SURFACE_NAMES.join(", "), f.surface))
            })?;
            let onset_s = v.finite(&field("onset_s"), f.onset_s)?;
            if !(0.0..duration_s).contains(&onset_s) {
                return Err(v.err(
                    field("onset_s"),
                    format!("must be within 0..{duration_s} s (study.duration_s), got {onset_s}"),
                ));
            }
            if let Some(end) = f.end_s
                && !(end.is_finite() && end > onset_s)
            {
                return Err(v.err(field("end_s"), format!("must be later than onset_s ({onset_s} s), got {end}")));
            }
            let need = |name: &str, x: Option<f64>| {
                x.filter(|x| x.is_finite())
                    .ok_or_else(|| v.err(field(name), format!("a finite number is required for kind = {:?}", f.kind)))
            };
            let deflection = |name: &str, x: Option<f64>| {
                let x = need(name, x)?;
                if x.abs() <= 25.0 {
                    Ok(x.to_radians())
                } else {
                    Err(v.err(field(name), format!("must be within -25..25 deg (the actuator's travel), got {x}")))
                }
            };
            let (kind, used): (_, &[&str]) = match f.kind.as_str() {
                "stuck" => (
                    ActuatorFaultKind::Stuck { position_rad: deflection("position_deg", f.position_deg)? },
                    &["position_deg"],
                ),
                "oscillation" => {
                    let low_rad = deflection("low_deg", f.low_deg)?;
                    let high_rad = deflection("high_deg", f.high_deg)?;
                    if high_rad <= low_rad {
                        return Err(v.err(field("high_deg"), "must be above low_deg"));
                    }
                    let period_s = v.positive(&field("period_s"), need("period_s", f.period_s)?)?;
                    (
                        ActuatorFaultKind::Oscillation { low_rad, high_rad, period_s },
                        &["low_deg", "high_deg", "period_s"],
                    )
                }
                "loss_of_effectiveness" => {
                    let e = need("effectiveness", f.effectiveness)?;
                    if !(0.0..1.0).contains(&e) {
                        return Err(
                            v.err(field("effectiveness"), format!("must be within [0, 1) (1 is no fault), got {e}"))
                        );
                    }
                    (ActuatorFaultKind::LossOfEffectiveness { effectiveness: e }, &["effectiveness"])
                }
                other => {
                    return Err(v.err(
                        field("kind"),
                        format!("must be \"stuck\", \"oscillation\" or \"loss_of_effectiveness\", got {other:?}"),
                    ));
                }
            };
            let given = [
                ("position_deg", f.position_deg),
                ("low_deg", f.low_deg),
                ("high_deg", f.high_deg),
                ("period_s", f.period_s),
                ("effectiveness", f.effectiveness),
            ];
            if let Some((name, _)) = given.iter().find(|(n, v)| v.is_some() && !used.contains(n)) {
                return Err(v.err(
                    field(name),
                    format!("does not apply to kind = {:?} (it takes {})", f.kind, used.join(", ")),
                ));
            }
            faults.push(ActuatorFault { surface, kind, onset_s, end_s: f.end_s });
        }
        let mut windows: Vec<_> = faults.iter().map(|f| (f.onset_s, f.end_s.unwrap_or(duration_s))).collect();
        windows.sort_by(|a, b| a.0.total_cmp(&b.0));
        if let Some(w) = windows.windows(2).find(|w| w[1].0 < w[0].1) {
            return Err(v.err(
                "surface_fault",
                format!("faults must not overlap: one from {} s to {} s, the next from {} s", w[0].0, w[0].1, w[1].0),
            ));
        }

        v.detector_names("bank", deck.bank.iter().map(|b| b.name.as_str()))?;
        let mut banks: Vec<(String, BankParams)> = Vec::new();
        for (i, b) in deck.bank.iter().enumerate() {
            let field = |f: &str| format!("bank[{i}].{f}");
            let covariance = v.choice(
                &field("covariance"),
                &b.covariance,
                &[
                    ("ekf", CovarianceForm::Ekf, ""),
                    ("strong_tracking", CovarianceForm::StrongTracking, ""),
                    ("symmetric_strong_tracking", CovarianceForm::SymmetricStrongTracking, ""),
                ],
            )?;
            let likelihood = v.choice(
                &field("likelihood"),
                &b.likelihood,
                &[
                    ("gaussian", LikelihoodForm::Gaussian, ""),
                    ("euclidean_norm", LikelihoodForm::EuclideanNorm, ""),
                    ("euclidean_norm_1d", LikelihoodForm::EuclideanNormOneDimensional, ""),
                ],
            )?;
            let mut p = BankParams::seed(covariance, likelihood);
            if let Some(given) = b.process_variance_per_s {
                for (j, x) in given.iter().enumerate() {
                    v.positive(&format!("bank[{i}].process_variance_per_s[{j}]"), *x)?;
                }
                p.process_variance_per_s = given;
            }
            if let Some(given) = b.measurement_variance {
                for (j, x) in given.iter().enumerate() {
                    v.positive(&format!("bank[{i}].measurement_variance[{j}]"), *x)?;
                }
                p.measurement_variance = given;
            }
            if let Some(x) = b.surface_process_variance_rad2_per_s {
                // 0 is the seed's own reading (its R_W has no surface entry): no random walk at all.
                p.surface_process_variance_rad2_per_s =
                    v.non_negative(&field("surface_process_variance_rad2_per_s"), x)?;
            }
            if let Some(rho) = b.rho {
                if !(rho > 0.0 && rho <= 1.0) {
                    return Err(v.err(field("rho"), format!("must be within (0, 1], got {rho}")));
                }
                p.rho = rho;
            }
            if let Some(beta) = b.beta {
                p.beta = v.at_least(&field("beta"), beta, 1.0, "a weakening factor")?;
            }
            if let Some(a) = b.a {
                for (j, a) in a.iter().enumerate() {
                    v.at_least(&format!("bank[{i}].a[{j}]"), *a, 1.0, "a prior weight")?;
                }
                p.a = a;
            }
            if let Some(a) = b.a_surface {
                p.a_surface = v.at_least(&field("a_surface"), a, 1.0, "a prior weight")?;
            }
            if let Some(h) = b.declare_hold_s {
                p.levels.declare_hold_s = v.non_negative(&field("declare_hold_s"), h)?;
            }
            if let Some(h) = b.clear_hold_s {
                p.clear_hold_s = v.non_negative(&field("clear_hold_s"), h)?;
            }
            if let Some(rule) = &b.probability_floor_rule {
                let rules =
                    [("every_step", FloorRule::EveryStep, "default"), ("reset_at_zero", FloorRule::ResetAtZero, "")];
                p.floor_rule = v.choice(&field("probability_floor_rule"), rule, &rules)?;
            }
            banks.push((b.name.clone(), p));
        }

        let monte_carlo = monte_carlo(&v, deck.monte_carlo, duration_s, &faults)?;
        v.one_fault_source(
            "[[surface_fault]]",
            "[[monte_carlo.fault]]",
            !monte_carlo.faults.is_empty() && !faults.is_empty(),
        )?;

        Ok(SurfaceStudy {
            header,
            trim_airspeed_mps,
            trim_altitude_m,
            wind_ned_mps,
            sensors,
            setpoints,
            faults,
            banks,
            monte_carlo,
        })
    }
}

/// Validates the `[monte_carlo]` section; without one, 1000 trials of the deck's scenario.
fn monte_carlo(
    v: &Validator,
    mc: Option<crate::engine::scenario::deck::MonteCarloSection>,
    duration_s: f64,
    scenario: &[ActuatorFault],
) -> Result<SurfaceMonteCarlo, DeckError> {
    let rules = MonteCarloRules {
        parameter_errors: Some(false),
        ..MonteCarloRules::sampled("control-surface decks", duration_s, OPTIONS.contains(&Opt::Thresholds))
    };
    let (common, own, parameter_errors) = v.monte_carlo(mc, &rules, |prefix, table| {
        let field = |name: &str| format!("{prefix}.{name}");
        let pe: CoefficientsSection =
            toml::Value::Table(table).try_into().map_err(|e| v.err(prefix, e.to_string().trim_end().to_string()))?;
        if pe.coefficients.is_empty() {
            return Err(v.err(field("coefficients"), "name at least one coefficient"));
        }
        for (k, c) in pe.coefficients.iter().enumerate() {
            if !SCALABLE_COEFFICIENTS.contains(&c.as_str()) {
                return Err(v.err(
                    field(&format!("coefficients[{k}]")),
                    format!("{c:?}: allowed {}", SCALABLE_COEFFICIENTS.join(", ")),
                ));
            }
            if let Some((parent, _)) =
                DERIVED_COEFFICIENTS.iter().find(|(p, d)| d == c && pe.coefficients.iter().any(|n| n == p))
            {
                return Err(v.err(
                    field(&format!("coefficients[{k}]")),
                    format!("{c} is derived from {parent} and scales with it; name one of the two"),
                ));
            }
        }
        Ok(CoefficientNames(pe.coefficients))
    })?;
    let section_given = own.is_some();
    let mc: MonteCarloOwn = own.unwrap_or_default();
    let surfaces = match &mc.surfaces {
        None => (0..SURFACE_NAMES.len()).collect(),
        Some(names) if names.is_empty() => return Err(v.err("monte_carlo.surfaces", "name at least one surface")),
        Some(names) => names
            .iter()
            .enumerate()
            .map(|(k, n)| {
                SURFACE_NAMES.iter().position(|s| s == n).ok_or_else(|| {
                    v.err(format!("monte_carlo.surfaces[{k}]"), format!("{n:?}: allowed {}", SURFACE_NAMES.join(", ")))
                })
            })
            .collect::<Result<Vec<_>, _>>()?,
    };
    let fault_duration_s = match &mc.fault_duration_s {
        None => None,
        Some(spec) => {
            let f = v.factor("monte_carlo.fault_duration_s", Some(spec), Factor::Fixed(0.0))?;
            v.factor_within("monte_carlo.fault_duration_s", &f, |t| t > 0.0, "> 0 s")?;
            Some(f)
        }
    };

    let mut faults = Vec::with_capacity(mc.fault.len());
    for (i, f) in mc.fault.iter().enumerate() {
        let field = |name: &str| format!("monte_carlo.fault[{i}].{name}");
        let given = [
            ("position_deg", f.position_deg.is_some()),
            ("amplitude_deg", f.amplitude_deg.is_some()),
            ("center_deg", f.center_deg.is_some()),
            ("period_s", f.period_s.is_some()),
            ("effectiveness", f.effectiveness.is_some()),
        ];
        let required = |name: &str, spec: Option<&FactorSpec>| match spec {
            Some(spec) => v.factor(&field(name), Some(spec), Factor::Fixed(f64::NAN)),
            None => Err(v.err(field(name), format!("required for kind {:?}", f.kind))),
        };
        let (spec, used): (_, &[&str]) = match f.kind.as_str() {
            "stuck" => {
                let position_deg = required("position_deg", f.position_deg.as_ref())?;
                v.factor_within(
                    &field("position_deg"),
                    &position_deg,
                    |x| x.abs() <= 25.0,
                    "-25..25 deg (the actuator's travel)",
                )?;
                (SurfaceFaultSpec::Stuck { position_deg }, &["position_deg"])
            }
            "oscillation" => {
                let amplitude_deg = required("amplitude_deg", f.amplitude_deg.as_ref())?;
                v.factor_within(
                    &field("amplitude_deg"),
                    &amplitude_deg,
                    |x| x > 0.0 && x <= 25.0,
                    "0 < amplitude <= 25 deg",
                )?;
                let center_deg = v.finite(&field("center_deg"), f.center_deg.unwrap_or(0.0))?;
                if center_deg.abs() > 25.0 {
                    return Err(v.err(
                        field("center_deg"),
                        format!("allowed -25..25 deg (the actuator's travel), got {center_deg}"),
                    ));
                }
                let period_s = v.positive(&field("period_s"), f.period_s.unwrap_or(DEFAULT_SQUARE_WAVE_PERIOD_S))?;
                (
                    SurfaceFaultSpec::Oscillation { amplitude_deg, center_deg, period_s },
                    &["amplitude_deg", "center_deg", "period_s"],
                )
            }
            "loss_of_effectiveness" => {
                let effectiveness = required("effectiveness", f.effectiveness.as_ref())?;
                v.factor_within(
                    &field("effectiveness"),
                    &effectiveness,
                    |x| (0.0..1.0).contains(&x),
                    "0 <= effectiveness < 1 (1 is no fault)",
                )?;
                (SurfaceFaultSpec::LossOfEffectiveness { effectiveness }, &["effectiveness"])
            }
            other => {
                let kinds = [("stuck", ""), ("oscillation", ""), ("loss_of_effectiveness", "")];
                return Err(v.not_allowed(field("kind"), other, &kinds));
            }
        };
        if let Some((name, _)) = given.iter().find(|(n, g)| *g && !used.contains(n)) {
            return Err(
                v.err(field(name), format!("does not apply to kind = {:?} (it takes {})", f.kind, used.join(", ")))
            );
        }
        faults.push(spec);
    }
    if section_given && faults.is_empty() && scenario.is_empty() && common.fault_free_fraction < 1.0 {
        return Err(v.err(
            "monte_carlo.fault",
            "faulty trials need a fault: add [[monte_carlo.fault]] or [[surface_fault]], or set fault_free_fraction = 1",
        ));
    }
    Ok(SurfaceMonteCarlo { common, surfaces, fault_duration_s, faults, parameter_errors })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_seed_deck_holds_the_seed_scenario_and_four_variants() {
        let study = SurfaceStudy::bundled("seed004_surfaces.toml");
        assert_eq!(study.header.duration_s, 300.0);
        let expected = [
            (0, 10.0, 40.0, ActuatorFaultKind::Stuck { position_rad: (-15f64).to_radians() }),
            (
                1,
                70.0,
                100.0,
                ActuatorFaultKind::Oscillation {
                    low_rad: (-15f64).to_radians(),
                    high_rad: 15f64.to_radians(),
                    period_s: 2.0,
                },
            ),
            (4, 130.0, 160.0, ActuatorFaultKind::Stuck { position_rad: (-1f64).to_radians() }),
            (2, 190.0, 220.0, ActuatorFaultKind::Stuck { position_rad: 10f64.to_radians() }),
            (
                3,
                250.0,
                280.0,
                ActuatorFaultKind::Oscillation {
                    low_rad: 2f64.to_radians(),
                    high_rad: 6f64.to_radians(),
                    period_s: 2.0,
                },
            ),
        ];
        assert_eq!(study.faults.len(), 5);
        for (f, (surface, onset, end, kind)) in study.faults.iter().zip(expected) {
            assert_eq!((f.surface, f.onset_s, f.end_s, f.kind), (surface, onset, Some(end), kind));
        }
        let variants: Vec<_> = study.banks.iter().map(|(n, p)| (n.as_str(), p.covariance, p.likelihood)).collect();
        assert_eq!(
            variants,
            [
                ("emmae", CovarianceForm::Ekf, LikelihoodForm::Gaussian),
                ("ekf_fast", CovarianceForm::Ekf, LikelihoodForm::EuclideanNorm),
                ("stmmae", CovarianceForm::StrongTracking, LikelihoodForm::EuclideanNorm),
                ("improved_stmmae", CovarianceForm::SymmetricStrongTracking, LikelihoodForm::EuclideanNorm),
            ]
        );
        assert_eq!(study.sensors.gyro_variance_rad2_s2, 0.0076);
    }
}
