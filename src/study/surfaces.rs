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
//!                    likelihood = "gaussian" | "euclidean_norm", optional overrides of the seed's numbers
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::DeckError;
use crate::detector::stmmae::{BankParams, CovarianceForm};
use crate::estimation::LikelihoodForm;
use crate::plant::uav::{SURFACE_NAMES, Setpoints};

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
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StudySection {
    name: String,
    seed: u64,
    duration_s: f64,
    dt_s: f64,
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
}

/// What a surface fault does from its onset to its end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SurfaceFaultKind {
    Stuck { position_rad: f64 },
    Oscillation { low_rad: f64, high_rad: f64, period_s: f64 },
    LossOfEffectiveness { effectiveness: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceFault {
    pub surface: usize,
    pub kind: SurfaceFaultKind,
    pub onset_s: f64,
    pub end_s: Option<f64>,
}

/// Sensor noise of the truth simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorNoise {
    pub gyro_variance_rad2_s2: f64,
    pub flow_angle_variance_rad2: f64,
    pub airspeed_variance_m2_s2: f64,
    pub attitude_sigma_rad: f64,
}

/// A validated control-surface study.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceStudy {
    pub path: PathBuf,
    pub name: String,
    pub seed: u64,
    pub duration_s: f64,
    pub dt_s: f64,
    pub trim_airspeed_mps: f64,
    pub trim_altitude_m: f64,
    pub wind_ned_mps: [f64; 3],
    pub sensors: SensorNoise,
    pub setpoints: Vec<(f64, Setpoints)>,
    pub faults: Vec<SurfaceFault>,
    pub banks: Vec<(String, BankParams)>,
}

/// Whether a TOML text is a control-surface deck (it has an `[airframe]` table).
pub fn is_surface_deck(text: &str) -> bool {
    text.parse::<toml::Table>().is_ok_and(|t| t.contains_key("airframe"))
}

impl SurfaceStudy {
    pub fn load(path: &Path) -> Result<SurfaceStudy, DeckError> {
        let text = std::fs::read_to_string(path).map_err(|source| DeckError::Read { file: path.into(), source })?;
        Self::from_toml(&text, path)
    }

    pub fn from_toml(text: &str, path: &Path) -> Result<SurfaceStudy, DeckError> {
        let deck: SurfaceDeck =
            toml::from_str(text).map_err(|e| DeckError::Parse { file: path.into(), message: e.to_string() })?;
        let bad = |field: String, message: String| DeckError::Invalid { file: path.into(), field, message };
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(bad(field.into(), format!("must be a positive number, got {v}")))
            }
        };
        let finite = |field: String, v: f64| {
            if v.is_finite() { Ok(v) } else { Err(bad(field, format!("must be a finite number, got {v}"))) }
        };

        let s = &deck.study;
        if s.name.is_empty() || !s.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
            return Err(bad(
                "study.name".into(),
                format!("must be letters, digits, '_' or '-' (a folder name), got {:?}", s.name),
            ));
        }
        let duration_s = positive("study.duration_s", s.duration_s)?;
        let dt_s = positive("study.dt_s", s.dt_s)?;
        if dt_s > 0.05 || dt_s * 10.0 > duration_s {
            return Err(bad(
                "study.dt_s".into(),
                format!("must be at most 0.05 s and a tenth of duration_s, got {dt_s}"),
            ));
        }

        let a = &deck.airframe;
        if a.model != "aerosonde" {
            return Err(bad(
                "airframe.model".into(),
                format!("must be \"aerosonde\" (the only airframe so far), got {:?}", a.model),
            ));
        }
        let trim_airspeed_mps = positive("airframe.trim_airspeed_mps", a.trim_airspeed_mps)?;
        if !(15.0..=45.0).contains(&trim_airspeed_mps) {
            return Err(bad(
                "airframe.trim_airspeed_mps".into(),
                format!("must be within 15..45 m/s, got {trim_airspeed_mps}"),
            ));
        }
        let trim_altitude_m = positive("airframe.trim_altitude_m", a.trim_altitude_m)?;
        let wind_ned_mps = a.wind_ned_mps.unwrap_or([0.0; 3]);
        for (i, w) in wind_ned_mps.iter().enumerate() {
            finite(format!("airframe.wind_ned_mps[{i}]"), *w)?;
        }

        let sensors = {
            let s = deck.sensors.as_ref();
            let non_negative = |field: &str, v: Option<f64>, default: f64| {
                let v = v.unwrap_or(default);
                if v.is_finite() && v >= 0.0 {
                    Ok(v)
                } else {
                    Err(bad(format!("sensors.{field}"), format!("must be >= 0, got {v}")))
                }
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
            let from_s = finite(field("from_s"), sp.from_s)?;
            if let Some(&(last, _)) = setpoints.last()
                && from_s <= last
            {
                return Err(bad(
                    field("from_s"),
                    format!("must be later than the previous setpoint's {last} s, got {from_s}"),
                ));
            }
            let va_mps = positive(&field("airspeed_mps"), sp.airspeed_mps)?;
            let altitude_m = positive(&field("altitude_m"), sp.altitude_m)?;
            let roll_deg = finite(field("roll_deg"), sp.roll_deg)?;
            if roll_deg.abs() > 45.0 {
                return Err(bad(
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
                bad(field("surface"), format!("must be one of {}, got {:?}", SURFACE_NAMES.join(", "), f.surface))
            })?;
            let onset_s = finite(field("onset_s"), f.onset_s)?;
            if !(0.0..duration_s).contains(&onset_s) {
                return Err(bad(
                    field("onset_s"),
                    format!("must be within 0..{duration_s} s (study.duration_s), got {onset_s}"),
                ));
            }
            if let Some(end) = f.end_s
                && !(end.is_finite() && end > onset_s)
            {
                return Err(bad(field("end_s"), format!("must be later than onset_s ({onset_s} s), got {end}")));
            }
            let need = |name: &str, v: Option<f64>| {
                v.filter(|v| v.is_finite())
                    .ok_or_else(|| bad(field(name), format!("a finite number is required for kind = {:?}", f.kind)))
            };
            let deflection = |name: &str, v: Option<f64>| {
                let v = need(name, v)?;
                if v.abs() <= 25.0 {
                    Ok(v.to_radians())
                } else {
                    Err(bad(field(name), format!("must be within -25..25 deg (the actuator's travel), got {v}")))
                }
            };
            let (kind, used): (_, &[&str]) = match f.kind.as_str() {
                "stuck" => (
                    SurfaceFaultKind::Stuck { position_rad: deflection("position_deg", f.position_deg)? },
                    &["position_deg"],
                ),
                "oscillation" => {
                    let low_rad = deflection("low_deg", f.low_deg)?;
                    let high_rad = deflection("high_deg", f.high_deg)?;
                    if high_rad <= low_rad {
                        return Err(bad(field("high_deg"), "must be above low_deg".into()));
                    }
                    let period_s = positive(&field("period_s"), need("period_s", f.period_s)?)?;
                    (
                        SurfaceFaultKind::Oscillation { low_rad, high_rad, period_s },
                        &["low_deg", "high_deg", "period_s"],
                    )
                }
                "loss_of_effectiveness" => {
                    let e = need("effectiveness", f.effectiveness)?;
                    if !(0.0..1.0).contains(&e) {
                        return Err(bad(
                            field("effectiveness"),
                            format!("must be within [0, 1) (1 is no fault), got {e}"),
                        ));
                    }
                    (SurfaceFaultKind::LossOfEffectiveness { effectiveness: e }, &["effectiveness"])
                }
                other => {
                    return Err(bad(
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
                return Err(bad(
                    field(name),
                    format!("does not apply to kind = {:?} (it takes {})", f.kind, used.join(", ")),
                ));
            }
            faults.push(SurfaceFault { surface, kind, onset_s, end_s: f.end_s });
        }
        let mut windows: Vec<_> = faults.iter().map(|f| (f.onset_s, f.end_s.unwrap_or(duration_s))).collect();
        windows.sort_by(|a, b| a.0.total_cmp(&b.0));
        if let Some(w) = windows.windows(2).find(|w| w[1].0 < w[0].1) {
            return Err(bad(
                "surface_fault".into(),
                format!("faults must not overlap: one from {} s to {} s, the next from {} s", w[0].0, w[0].1, w[1].0),
            ));
        }

        if deck.bank.is_empty() {
            return Err(bad("bank".into(), "at least one [[bank]] is required".into()));
        }
        let mut banks: Vec<(String, BankParams)> = Vec::new();
        for (i, b) in deck.bank.iter().enumerate() {
            let field = |f: &str| format!("bank[{i}].{f}");
            if banks.iter().any(|(n, _)| *n == b.name) || b.name.is_empty() {
                return Err(bad(field("name"), format!("must be non-empty and unique, got {:?}", b.name)));
            }
            let covariance = match b.covariance.as_str() {
                "ekf" => CovarianceForm::Ekf,
                "strong_tracking" => CovarianceForm::StrongTracking,
                "symmetric_strong_tracking" => CovarianceForm::SymmetricStrongTracking,
                other => {
                    return Err(bad(
                        field("covariance"),
                        format!("must be \"ekf\", \"strong_tracking\" or \"symmetric_strong_tracking\", got {other:?}"),
                    ));
                }
            };
            let likelihood = match b.likelihood.as_str() {
                "gaussian" => LikelihoodForm::Gaussian,
                "euclidean_norm" => LikelihoodForm::EuclideanNorm,
                other => {
                    return Err(bad(
                        field("likelihood"),
                        format!("must be \"gaussian\" or \"euclidean_norm\", got {other:?}"),
                    ));
                }
            };
            let mut p = BankParams::seed(covariance, likelihood);
            if let Some(v) = b.process_variance_per_s {
                for (j, x) in v.iter().enumerate() {
                    positive(&format!("bank[{i}].process_variance_per_s[{j}]"), *x)?;
                }
                p.process_variance_per_s = v;
            }
            if let Some(v) = b.measurement_variance {
                for (j, x) in v.iter().enumerate() {
                    positive(&format!("bank[{i}].measurement_variance[{j}]"), *x)?;
                }
                p.measurement_variance = v;
            }
            if let Some(v) = b.surface_process_variance_rad2_per_s {
                p.surface_process_variance_rad2_per_s = positive(&field("surface_process_variance_rad2_per_s"), v)?;
            }
            if let Some(rho) = b.rho {
                if !(rho > 0.0 && rho <= 1.0) {
                    return Err(bad(field("rho"), format!("must be within (0, 1], got {rho}")));
                }
                p.rho = rho;
            }
            if let Some(beta) = b.beta {
                if !(beta.is_finite() && beta >= 1.0) {
                    return Err(bad(field("beta"), format!("must be >= 1 (a weakening factor), got {beta}")));
                }
                p.beta = beta;
            }
            if let Some(a) = b.a {
                if let Some(j) = a.iter().position(|a| !(a.is_finite() && *a >= 1.0)) {
                    return Err(bad(
                        format!("bank[{i}].a[{j}]"),
                        format!("must be >= 1 (a prior weight), got {}", a[j]),
                    ));
                }
                p.a = a;
            }
            if let Some(a) = b.a_surface {
                if !(a.is_finite() && a >= 1.0) {
                    return Err(bad(field("a_surface"), format!("must be >= 1 (a prior weight), got {a}")));
                }
                p.a_surface = a;
            }
            if let Some(h) = b.declare_hold_s {
                if !(h.is_finite() && h >= 0.0) {
                    return Err(bad(field("declare_hold_s"), format!("must be >= 0, got {h}")));
                }
                p.declare_hold_s = h;
            }
            banks.push((b.name.clone(), p));
        }

        Ok(SurfaceStudy {
            path: path.into(),
            name: s.name.clone(),
            seed: s.seed,
            duration_s,
            dt_s,
            trim_airspeed_mps,
            trim_altitude_m,
            wind_ned_mps,
            sensors,
            setpoints,
            faults,
            banks,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seed_deck() -> String {
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/studies/seed004_surfaces.toml")).unwrap()
    }

    #[test]
    fn the_seed_deck_holds_the_seed_scenario_and_four_variants() {
        let study = SurfaceStudy::from_toml(&seed_deck(), Path::new("seed004_surfaces.toml")).unwrap();
        assert_eq!(study.duration_s, 300.0);
        let expected = [
            (0, 10.0, 40.0, SurfaceFaultKind::Stuck { position_rad: (-15f64).to_radians() }),
            (
                1,
                70.0,
                100.0,
                SurfaceFaultKind::Oscillation {
                    low_rad: (-15f64).to_radians(),
                    high_rad: 15f64.to_radians(),
                    period_s: 2.0,
                },
            ),
            (4, 130.0, 160.0, SurfaceFaultKind::Stuck { position_rad: (-1f64).to_radians() }),
            (2, 190.0, 220.0, SurfaceFaultKind::Stuck { position_rad: 10f64.to_radians() }),
            (
                3,
                250.0,
                280.0,
                SurfaceFaultKind::Oscillation {
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
        assert!(is_surface_deck(&seed_deck()));
    }

    #[test]
    fn bad_decks_name_the_field_and_what_is_allowed() {
        let cases: &[(&str, &str, &str)] = &[
            ("model = \"aerosonde\"", "model = \"cessna\"", "airframe.model: must be \"aerosonde\""),
            ("surface = \"rudder\"", "surface = \"flap\"", "surface_fault[2].surface: must be one of aileron_left"),
            (
                "position_deg = -15.0",
                "position_deg = -40.0",
                "surface_fault[0].position_deg: must be within -25..25 deg",
            ),
            (
                "position_deg = -15.0",
                "position_deg = -15.0\nperiod_s = 3.0",
                "surface_fault[0].period_s: does not apply to kind = \"stuck\"",
            ),
            ("onset_s = 70.0", "onset_s = 30.0", "faults must not overlap"),
            (
                "likelihood = \"gaussian\"",
                "likelihood = \"laplace\"",
                "bank[0].likelihood: must be \"gaussian\" or \"euclidean_norm\"",
            ),
            ("covariance = \"ekf\"", "covariance = \"ukf\"", "bank[0].covariance: must be \"ekf\""),
            ("duration_s = 300.0", "duration_s = nan", "study.duration_s: must be a positive number"),
            ("trim_airspeed_mps = 25.0", "trim_airspeed_mps = 25.0\nflaps = 1", "unknown field `flaps`"),
        ];
        for (from, to, want) in cases {
            let text = seed_deck();
            assert!(text.contains(from), "{from}");
            let broken = text.replacen(from, to, 1);
            let err = SurfaceStudy::from_toml(&broken, Path::new("x.toml")).unwrap_err().to_string();
            assert!(err.starts_with("x.toml: ") && err.contains(want), "{to}: {err}");
        }
    }
}
