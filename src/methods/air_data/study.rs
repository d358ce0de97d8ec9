//! Air-data study decks (method 002): parse a TOML deck with a `[flight]` section, then validate it into an
//! [`AirDataStudy`] that cannot be invalid. Every rejection names the file, the field and what is allowed.
//!
//! ```toml
//! [study]            name, seed, duration_s, dt_s
//! [flight]           profile = "seed" (level flight at 70 m/s and four manoeuvres) | "steady" |
//!                    "aerosonde" (method 004's 6-DoF airframe flying manoeuvres: a truth the filters do
//!                    not share), optional manoeuvre_scale (every manoeuvre's amplitude times it)
//! [sensors]          optional standard deviations: gyro_std_deg_s, accelerometer_std_mps2,
//!                    attitude_std_deg, airspeed_std_mps, alpha_std_deg, beta_std_deg; air_data_lanes
//!                    (redundant air-data sensors per quantity, 1 or 3; default 1)
//! [sensor_errors]    optional, what the filters do not model (default none): airspeed_lag_s,
//!                    flow_angle_lag_s, airspeed_scale_factor, flow_angle_scale_factor,
//!                    alpha_misalignment_deg, beta_misalignment_deg, imu_misalignment_deg,
//!                    noise_correlation_s
//! [wind]             optional: steady_ned_mps, gust_std_mps, gust_time_constant_s
//! [[detector]]       name, kind = "dual_ukf" (optional: false_alarm_probability, isolation_window,
//!                    declare_probability, clear_probability, declare_hold_s, prior_fault_probability,
//!                    keep_significant_biases) | "triplex_voting" (three lanes; optional:
//!                    miscompare_sigma, persistence_s); isolation_delay_s (when the isolated set is read
//!                    after a declaration; default 1 s)
//! [[faults]]         a fixed scenario, as in the LTI decks: output (airspeed_mps, alpha_rad, beta_rad),
//!                    kind (stuck, gain, bias, total_failure, drift, oscillation), size (the output's
//!                    units), onset_s, frequency_hz
//! [monte_carlo]      trials, fault_free_fraction, sampler, onset_s, noise_scale, gust_std_mps (factors;
//!                    the gust defaults to [wind]'s),
//!                    output_sets: the sets of sensors a fault hits together (default: each alone),
//!                    faulty_lanes: how many lanes of each faulty sensor it hits, from lane 0 (a list
//!                    cycled over the trials; default [1]; all lanes: common mode across the lanes)
//! [[monte_carlo.fault]]  kind with size (the outputs' units; a factor for gain) or size_sigma (multiples
//!                    of each faulty sensor's noise standard deviation), as in the LTI decks
//! ```
//!
//! A fault of a Monte Carlo population hits every sensor of the trial's set with the same kind and size
//! (in sigmas, each sensor's own): a common-mode fault when the set has two or three sensors. Faults
//! last to the end of the flight.

use std::path::Path;

use serde::Deserialize;

use crate::engine::method::Opt;
use crate::engine::scenario::deck::{FactorSpec, FromDeck, StudyHeader, StudySection};
use crate::estimation::bank::hold_threshold_s;

use crate::engine::scenario::deck::{DeckError, Factor, MonteCarlo, MonteCarloRules, Validator, open_deck};
use crate::fault::ChannelFault;
use crate::fault::deck::FaultKindSpec;
use crate::fault::deck::{FaultKindSection, FaultSection};
use crate::methods::air_data::dual_ukf::DualUkfParams;
use crate::methods::air_data::flight::{
    AIR_DATA_CHANNEL_NAMES, AirDataScenario, Airframe, FlightProfile, MAX_LANES, ScenarioParams, SensorErrors,
    SensorNoise, WindParams,
};
use crate::methods::air_data::voting::TriplexParams;

/// The options this kind takes beyond the common ones (its `Method::options`): said here, where its deck
/// rules read them (`monte_carlo.target_pfa` with [`Opt::Thresholds`]).
pub const OPTIONS: &[Opt] = &[Opt::Thresholds, Opt::Sensitivity];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AirDataDeck {
    study: StudySection,
    flight: FlightSection,
    sensors: Option<SensorsSection>,
    sensor_errors: Option<SensorErrorsSection>,
    wind: Option<WindSection>,
    detector: Vec<DetectorSection>,
    #[serde(default)]
    faults: Vec<FaultSection>,
    monte_carlo: Option<crate::engine::scenario::deck::MonteCarloSection>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FlightSection {
    profile: String,
    manoeuvre_scale: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorsSection {
    gyro_std_deg_s: Option<f64>,
    accelerometer_std_mps2: Option<f64>,
    attitude_std_deg: Option<f64>,
    airspeed_std_mps: Option<f64>,
    alpha_std_deg: Option<f64>,
    beta_std_deg: Option<f64>,
    air_data_lanes: Option<usize>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorErrorsSection {
    airspeed_lag_s: Option<f64>,
    flow_angle_lag_s: Option<f64>,
    airspeed_scale_factor: Option<f64>,
    flow_angle_scale_factor: Option<f64>,
    alpha_misalignment_deg: Option<f64>,
    beta_misalignment_deg: Option<f64>,
    imu_misalignment_deg: Option<f64>,
    noise_correlation_s: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WindSection {
    steady_ned_mps: Option<[f64; 3]>,
    gust_std_mps: Option<f64>,
    gust_time_constant_s: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DetectorSection {
    name: String,
    kind: String,
    false_alarm_probability: Option<f64>,
    isolation_window: Option<usize>,
    declare_probability: Option<f64>,
    clear_probability: Option<f64>,
    declare_hold_s: Option<f64>,
    prior_fault_probability: Option<f64>,
    isolation_delay_s: Option<f64>,
    keep_significant_biases: Option<bool>,
    miscompare_sigma: Option<f64>,
    persistence_s: Option<f64>,
}

/// `[monte_carlo]`'s own fields in air-data decks.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct MonteCarloOwn {
    gust_std_mps: Option<FactorSpec>,
    output_sets: Option<Vec<Vec<String>>>,
    faulty_lanes: Option<Vec<usize>>,
    #[serde(default)]
    fault: Vec<FaultKindSection>,
}

/// What a detector of an air-data study is.
#[derive(Debug, Clone, PartialEq)]
pub enum DetectorKind {
    /// The patent's dual-model UKF, on air-data lane 0.
    DualUkf(DualUkfParams),
    /// Mid-value select and miscompare monitoring of three lanes.
    TriplexVoting(TriplexParams),
}

/// One detector configuration of an air-data study.
#[derive(Debug, Clone, PartialEq)]
pub struct AirDataDetector {
    pub name: String,
    pub kind: DetectorKind,
    /// The isolated set is the detector's faulty set this long after its declaration (s).
    pub isolation_delay_s: f64,
}

impl AirDataDetector {
    /// The threshold on the detector's decision statistic (`held_s`, [`crate::estimation::bank::held_s`])
    /// that its deck sets at the sample period `dt_s`: the dual UKF's declaration hold, the voter's
    /// persistence.
    pub fn alarm_threshold_s(&self, dt_s: f64) -> f64 {
        match &self.kind {
            DetectorKind::DualUkf(p) => p.levels.alarm_threshold_s(dt_s),
            DetectorKind::TriplexVoting(p) => hold_threshold_s(p.persistence_s, dt_s),
        }
    }
}

/// The Monte Carlo section of an air-data study.
#[derive(Debug, Clone, PartialEq)]
pub struct AirDataMonteCarlo {
    pub common: MonteCarlo,
    /// Stationary standard deviation of the gust (m/s).
    pub gust_std_mps: Factor,
    /// Sensor sets a fault hits together (indices into [`AIR_DATA_CHANNEL_NAMES`], ascending).
    pub output_sets: Vec<Vec<usize>>,
    /// Sampled fault populations; empty: every faulty trial flies the deck's `[[faults]]`.
    pub faults: Vec<FaultKindSpec>,
    /// How many lanes a fault hits (cycled over the trials).
    pub faulty_lanes: Vec<usize>,
}

/// A validated air-data study.
#[derive(Debug, Clone, PartialEq)]
pub struct AirDataStudy {
    pub header: StudyHeader,
    pub profile_name: String,
    pub profile: FlightProfile,
    pub noise: SensorNoise,
    pub wind: WindParams,
    pub airframe: Airframe,
    pub sensor_errors: SensorErrors,
    /// Air-data lanes per quantity (1 or 3).
    pub lanes: usize,
    pub detectors: Vec<AirDataDetector>,
    pub faults: Vec<ChannelFault>,
    pub monte_carlo: AirDataMonteCarlo,
}

impl FromDeck for AirDataStudy {
    fn from_toml(text: &str, path: &Path) -> Result<AirDataStudy, DeckError> {
        let (deck, v, header) = open_deck(text, path, |d: &AirDataDeck| &d.study)?;
        let (duration_s, dt_s) = (header.duration_s, header.dt_s);

        let f = &deck.flight;
        let scale = v.finite("flight.manoeuvre_scale", f.manoeuvre_scale.unwrap_or(1.0))?;
        // Far below this the profile check (airspeed, angles) already refuses; above it the amplitudes
        // could overflow to infinity before that check reads them.
        if scale.abs() > 100.0 {
            let got = if scale.abs() < 1e6 { format!("{scale}") } else { format!("{scale:e}") };
            return Err(v.err("flight.manoeuvre_scale", format!("allowed -100 to 100, got {got}")));
        }
        let (profile, airframe) = match f.profile.as_str() {
            "seed" => (FlightProfile::seed().scaled(scale), Airframe::Kinematic),
            "steady" => {
                if f.manoeuvre_scale.is_some() {
                    return Err(v.err("flight.manoeuvre_scale", "a steady flight has no manoeuvres: remove it"));
                }
                (FlightProfile::seed().scaled(0.0), Airframe::Kinematic)
            }
            // The kinematic profile is not flown; it stays for what prints it.
            "aerosonde" => (FlightProfile::seed(), Airframe::Aerosonde { manoeuvre_scale: scale }),
            other => {
                let profiles = [
                    ("seed", "70 m/s and four manoeuvres"),
                    ("steady", ""),
                    ("aerosonde", "method 004's 6-DoF airframe flying manoeuvres"),
                ];
                return Err(v.not_allowed("flight.profile", other, &profiles));
            }
        };

        let mut noise = SensorNoise::seed();
        if let Some(s) = &deck.sensors {
            let deg = |d: f64| d.to_radians();
            for (field, given, target, convert) in [
                ("gyro_std_deg_s", s.gyro_std_deg_s, &mut noise.gyro_std_rad_s, deg as fn(f64) -> f64),
                ("accelerometer_std_mps2", s.accelerometer_std_mps2, &mut noise.accelerometer_std_mps2, |x| x),
                ("attitude_std_deg", s.attitude_std_deg, &mut noise.attitude_std_rad, deg),
                ("airspeed_std_mps", s.airspeed_std_mps, &mut noise.airspeed_std_mps, |x| x),
                ("alpha_std_deg", s.alpha_std_deg, &mut noise.alpha_std_rad, deg),
                ("beta_std_deg", s.beta_std_deg, &mut noise.beta_std_rad, deg),
            ] {
                if let Some(x) = given {
                    *target = convert(v.positive(&format!("sensors.{field}"), x)?);
                }
            }
        }
        let lanes = deck.sensors.as_ref().and_then(|s| s.air_data_lanes).unwrap_or(1);
        if lanes != 1 && lanes != MAX_LANES {
            return Err(v.err("sensors.air_data_lanes", format!("{lanes}: allowed 1 or {MAX_LANES} (triplex)")));
        }

        let mut sensor_errors = SensorErrors::default();
        if let Some(e) = &deck.sensor_errors {
            let deg = |d: f64| d.to_radians();
            let same = |x: f64| x;
            for (field, given, target, convert, non_negative) in [
                ("airspeed_lag_s", e.airspeed_lag_s, &mut sensor_errors.airspeed_lag_s, same as fn(f64) -> f64, true),
                ("flow_angle_lag_s", e.flow_angle_lag_s, &mut sensor_errors.flow_angle_lag_s, same, true),
                (
                    "airspeed_scale_factor",
                    e.airspeed_scale_factor,
                    &mut sensor_errors.airspeed_scale_factor,
                    same,
                    false,
                ),
                (
                    "flow_angle_scale_factor",
                    e.flow_angle_scale_factor,
                    &mut sensor_errors.flow_angle_scale_factor,
                    same,
                    false,
                ),
                (
                    "alpha_misalignment_deg",
                    e.alpha_misalignment_deg,
                    &mut sensor_errors.alpha_misalignment_rad,
                    deg,
                    false,
                ),
                (
                    "beta_misalignment_deg",
                    e.beta_misalignment_deg,
                    &mut sensor_errors.beta_misalignment_rad,
                    deg,
                    false,
                ),
                ("imu_misalignment_deg", e.imu_misalignment_deg, &mut sensor_errors.imu_misalignment_rad, deg, false),
                ("noise_correlation_s", e.noise_correlation_s, &mut sensor_errors.noise_correlation_s, same, true),
            ] {
                if let Some(x) = given {
                    let name = format!("sensor_errors.{field}");
                    *target = convert(if non_negative { v.non_negative(&name, x)? } else { v.finite(&name, x)? });
                }
            }
        }

        let mut wind = WindParams::seed();
        if let Some(w) = &deck.wind {
            if let Some(steady) = w.steady_ned_mps {
                for (i, x) in steady.iter().enumerate() {
                    v.finite(&format!("wind.steady_ned_mps[{i}]"), *x)?;
                }
                wind.steady_ned_mps = steady;
            }
            if let Some(g) = w.gust_std_mps {
                wind.gust_std_mps = v.finite("wind.gust_std_mps", g)?;
                if g < 0.0 {
                    return Err(v.err("wind.gust_std_mps", format!("must be >= 0 (0: calm air), got {g}")));
                }
            }
            if let Some(t) = w.gust_time_constant_s {
                wind.gust_time_constant_s = v.positive("wind.gust_time_constant_s", t)?;
            }
        }

        v.detector_names("detector", deck.detector.iter().map(|d| d.name.as_str()))?;
        let mut detectors: Vec<AirDataDetector> = Vec::new();
        for (i, d) in deck.detector.iter().enumerate() {
            let field = |f: &str| format!("detector[{i}].{f}");
            let dual_fields = [
                ("false_alarm_probability", d.false_alarm_probability.is_some()),
                ("isolation_window", d.isolation_window.is_some()),
                ("declare_probability", d.declare_probability.is_some()),
                ("clear_probability", d.clear_probability.is_some()),
                ("declare_hold_s", d.declare_hold_s.is_some()),
                ("prior_fault_probability", d.prior_fault_probability.is_some()),
                ("keep_significant_biases", d.keep_significant_biases.is_some()),
            ];
            let voting_fields =
                [("miscompare_sigma", d.miscompare_sigma.is_some()), ("persistence_s", d.persistence_s.is_some())];
            let refuse = |given: &[(&str, bool)], kind: &str| match given.iter().find(|(_, g)| *g) {
                Some((name, _)) => Err(v.err(field(name), format!("does not apply to kind = {kind:?}"))),
                None => Ok(()),
            };
            let kind = match d.kind.as_str() {
                "dual_ukf" => {
                    refuse(&voting_fields, "dual_ukf")?;
                    let mut p = DualUkfParams { noise, ..DualUkfParams::seed() };
                    crate::take_given!(
                        p,
                        d,
                        [false_alarm_probability, isolation_window, prior_fault_probability, keep_significant_biases]
                    );
                    crate::take_given!(p.levels, d, [declare_probability, clear_probability, declare_hold_s]);
                    // The building blocks name the offending parameter; the deck adds the file and the table.
                    p.validate().map_err(|e| v.err(format!("detector[{i}]"), e.to_string()))?;
                    DetectorKind::DualUkf(p)
                }
                "triplex_voting" => {
                    refuse(&dual_fields, "triplex_voting")?;
                    if lanes != MAX_LANES {
                        return Err(v.err(
                            field("kind"),
                            format!("\"triplex_voting\" needs sensors.air_data_lanes = {MAX_LANES}, got {lanes}"),
                        ));
                    }
                    let mut p = TriplexParams::seed();
                    if let Some(x) = d.miscompare_sigma {
                        p.miscompare_sigma = v.positive(&field("miscompare_sigma"), x)?;
                    }
                    if let Some(x) = d.persistence_s {
                        p.persistence_s = v.non_negative(&field("persistence_s"), x)?;
                    }
                    DetectorKind::TriplexVoting(p)
                }
                other => {
                    let kinds = [("dual_ukf", "method 002"), ("triplex_voting", "the voting baseline")];
                    return Err(v.not_allowed(field("kind"), other, &kinds));
                }
            };
            let isolation_delay_s = d.isolation_delay_s.unwrap_or(1.0);
            if !(isolation_delay_s.is_finite() && isolation_delay_s >= 0.0) {
                return Err(v.err(field("isolation_delay_s"), format!("must be >= 0 s, got {isolation_delay_s}")));
            }
            detectors.push(AirDataDetector { name: d.name.clone(), kind, isolation_delay_s });
        }

        let outputs: Vec<String> = AIR_DATA_CHANNEL_NAMES.iter().map(|s| s.to_string()).collect();
        let faults = deck
            .faults
            .iter()
            .enumerate()
            .map(|(i, f)| v.fault(i, f, (&outputs, "the air-data outputs"), (&[], ""), duration_s).map(|(_, f)| f))
            .collect::<Result<Vec<_>, _>>()?;

        let monte_carlo =
            monte_carlo(&v, deck.monte_carlo, duration_s, &outputs, !faults.is_empty(), wind.gust_std_mps, lanes)?;

        // The scenario checks what the deck cannot see field by field (the profile's envelope).
        let worst_noise = [&monte_carlo.common.noise_scale, &monte_carlo.gust_std_mps].map(factor_max);
        let params = ScenarioParams {
            dt_s,
            duration_s,
            profile: profile.clone(),
            noise,
            noise_scale: worst_noise[0],
            wind: WindParams { gust_std_mps: wind.gust_std_mps.max(worst_noise[1]), ..wind },
            faults: faults.clone(),
            airframe,
            sensor_errors,
            lanes,
            faulty_lanes: 1,
        };
        AirDataScenario::new(params).map_err(|e| v.err("flight", e.to_string()))?;

        v.one_fault_source(
            "[[faults]]",
            "[[monte_carlo.fault]]",
            !monte_carlo.faults.is_empty() && !faults.is_empty(),
        )?;
        Ok(AirDataStudy {
            header,
            profile_name: f.profile.clone(),
            profile,
            noise,
            wind,
            airframe,
            sensor_errors,
            lanes,
            detectors,
            faults,
            monte_carlo,
        })
    }
}

impl AirDataStudy {
    /// The output names (channels a fault may hit).
    pub fn output_names(&self) -> Vec<String> {
        AIR_DATA_CHANNEL_NAMES.iter().map(|s| s.to_string()).collect()
    }
}

/// The largest value a factor takes.
fn factor_max(f: &Factor) -> f64 {
    match f {
        Factor::Fixed(v) => *v,
        Factor::Range { hi, .. } => *hi,
        Factor::Values(v) => v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    }
}

/// Validates `[monte_carlo]`; without one, 1000 trials of the deck's `[[faults]]`.
fn monte_carlo(
    v: &Validator,
    mc: Option<crate::engine::scenario::deck::MonteCarloSection>,
    duration_s: f64,
    outputs: &[String],
    fixed_faults: bool,
    deck_gust_std_mps: f64,
    lanes: usize,
) -> Result<AirDataMonteCarlo, DeckError> {
    let rules = MonteCarloRules::sampled("air-data decks", duration_s, OPTIONS.contains(&Opt::Thresholds));
    let (common, own, _) = v.monte_carlo(mc, &rules, |_, _| Ok(()))?;
    // Without [monte_carlo], every faulty trial flies the deck's [[faults]] (or none, if it has none).
    let section_given = own.is_some();
    let own: MonteCarloOwn = own.unwrap_or_default();
    let gust_std_mps =
        v.factor("monte_carlo.gust_std_mps", own.gust_std_mps.as_ref(), Factor::Fixed(deck_gust_std_mps))?;
    v.factor_within("monte_carlo.gust_std_mps", &gust_std_mps, |x| x >= 0.0, ">= 0 m/s (0: calm air)")?;
    let output_sets = match &own.output_sets {
        None => (0..outputs.len()).map(|j| vec![j]).collect(),
        Some(sets) if sets.is_empty() => return Err(v.err("monte_carlo.output_sets", "list at least one set")),
        Some(sets) => {
            let mut out = Vec::with_capacity(sets.len());
            for (k, set) in sets.iter().enumerate() {
                let field = format!("monte_carlo.output_sets[{k}]");
                if set.is_empty() {
                    return Err(v.err(field, "a set names one to three of airspeed_mps, alpha_rad, beta_rad"));
                }
                let mut idx = set
                    .iter()
                    .enumerate()
                    .map(|(m, n)| v.index_of(&format!("{field}[{m}]"), n, outputs, "the air-data outputs"))
                    .collect::<Result<Vec<_>, _>>()?;
                idx.sort_unstable();
                if idx.windows(2).any(|w| w[0] == w[1]) {
                    return Err(v.err(field, "names a sensor twice"));
                }
                out.push(idx);
            }
            out
        }
    };
    let faults = v.fault_kind_specs(&own.fault, (&[], ""))?;
    if section_given && faults.is_empty() && !fixed_faults && common.fault_free_fraction < 1.0 {
        return Err(v.err(
            "monte_carlo.fault",
            "faulty trials need a fault: add [[monte_carlo.fault]] or [[faults]], or set fault_free_fraction = 1",
        ));
    }
    let faulty_lanes = own.faulty_lanes.clone().unwrap_or_else(|| vec![1]);
    if faulty_lanes.is_empty() {
        return Err(v.err("monte_carlo.faulty_lanes", "list at least one count"));
    }
    if let Some(n) = faulty_lanes.iter().find(|n| !(1..=lanes).contains(*n)) {
        return Err(v.err("monte_carlo.faulty_lanes", format!("{n}: allowed 1 to sensors.air_data_lanes = {lanes}")));
    }
    Ok(AirDataMonteCarlo { common, gust_std_mps, output_sets, faults, faulty_lanes })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_seed_deck_reads_as_documented() {
        let study = AirDataStudy::bundled("seed002_air_data.toml");
        assert_eq!((study.header.duration_s, study.header.dt_s), (60.0, 0.01));
        assert_eq!(study.profile, FlightProfile::seed());
        assert_eq!(study.noise, SensorNoise::seed());
        let mc = &study.monte_carlo;
        assert_eq!(mc.output_sets, [vec![0], vec![1], vec![2], vec![0, 1], vec![0, 1, 2]]);
        assert_eq!(study.detectors.len(), 3);
        let DetectorKind::DualUkf(patent) = &study.detectors[0].kind else { panic!("{:?}", study.detectors[0]) };
        assert_eq!((patent.isolation_window, patent.keep_significant_biases), (1, false));
        assert!(matches!(&study.detectors[1].kind, DetectorKind::DualUkf(p) if p.keep_significant_biases));
        assert_eq!(
            (study.airframe, study.lanes, study.sensor_errors),
            (Airframe::Kinematic, 1, SensorErrors::default())
        );
        assert_eq!(mc.faulty_lanes, [1]);
    }

    #[test]
    fn the_hifi_deck_flies_the_aerosonde_on_imperfect_triplex_sensors() {
        let study = AirDataStudy::bundled("seed002_hifi_truth.toml");
        assert_eq!((study.airframe, study.lanes), (Airframe::Aerosonde { manoeuvre_scale: 1.0 }, 3));
        let e = study.sensor_errors;
        assert_eq!((e.airspeed_lag_s, e.flow_angle_scale_factor, e.noise_correlation_s), (0.05, 0.05, 0.2));
        assert!((e.alpha_misalignment_rad - 0.3f64.to_radians()).abs() < 1e-15);
        assert_eq!(study.monte_carlo.faulty_lanes, [1, 3]);
        let kinds: Vec<_> = study.detectors.iter().map(|d| std::mem::discriminant(&d.kind)).collect();
        assert_eq!(kinds[2], std::mem::discriminant(&DetectorKind::TriplexVoting(TriplexParams::seed())));
        assert_ne!(kinds[0], kinds[2]);
    }
}
