//! Launch-vehicle thrust-loss decks (method 001): parse a TOML deck with a `[vehicle]` section, then
//! validate it into a [`LaunchStudy`] that cannot be invalid. Every rejection names the file, the field
//! and what is allowed.
//!
//! ```toml
//! [study]            name, seed, duration_s, dt_s (0.01 s: the seed's D)
//! [vehicle]          model = "medium_launcher" (src/methods/thrust_loss/vehicle.rs), optional the gyros'
//!                    grade: gyro_arw_deg_per_sqrt_h (angle random walk; default 0.1, tactical) and
//!                    gyro_bias_stability_deg_per_h (a constant bias per flight and axis; default 0)
//! [[gust]]           axis = "down_range" | "cross_range", amplitude_mps, start_s, duration_s: 1 - cosine
//!                    gusts in the truth (the filter knows no wind): residual jumps with no engine at fault
//! [[detector]]       name, kind = "ekf_mhe", optional: window_n (N), interval_samples (D), fault_intensity
//!                    (F, R = F^2), window_variance (v, V = v I), threshold_fhat, loss_fit_onsets_s,
//!                    loss_fit_losses_percent, loss_fit_horizon_s, loss_fit_noisy_flights (0: one
//!                    noise-free flight per loss; n >= 2: n noisy flights per loss and onset),
//!                    moment_bias_sigma_rad_s2_per_sqrt_s (the recovering residual: a filter with
//!                    angular-acceleration biases walking at this rate; absent: the plain filter)
//! [[faults]]         one thrust loss for every faulty trial: engine (1-4), loss_percent, onset_s
//! [monte_carlo]      trials, fault_free_fraction, sampler, target_pfa, engines (default 1-4),
//!                    detection_window_s (default 2 s), and the factors loss_percent, onset_s, noise_scale
//!                    (on every sensor sigma), gust_scale (on every gust's amplitude)
//! ```

use std::path::Path;

use serde::Deserialize;

use crate::engine::method::Opt;
use crate::engine::scenario::deck::{
    DeckError, Factor, FromDeck, MonteCarlo, MonteCarloRules, StudyHeader, Validator, open_deck,
};
use crate::engine::scenario::deck::{FactorSpec, StudySection};
use crate::methods::thrust_loss::ekf_mhe::{DetectorParams, EkfParams, MheParams};
use crate::methods::thrust_loss::vehicle::{ENGINES, Gust, GustAxis, LaunchVehicleConfig};

/// The options this kind takes beyond the common ones (its `Method::options`): said here, where its deck
/// rules read them (`monte_carlo.target_pfa` with [`Opt::Thresholds`]).
pub const OPTIONS: &[Opt] = &[Opt::Thresholds, Opt::Sensitivity];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LaunchDeck {
    study: StudySection,
    vehicle: VehicleSection,
    #[serde(default)]
    gust: Vec<GustSection>,
    detector: Vec<DetectorSection>,
    #[serde(default)]
    faults: Vec<FaultSection>,
    monte_carlo: Option<crate::engine::scenario::deck::MonteCarloSection>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct VehicleSection {
    model: String,
    gyro_arw_deg_per_sqrt_h: Option<f64>,
    gyro_bias_stability_deg_per_h: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GustSection {
    axis: String,
    amplitude_mps: f64,
    start_s: f64,
    duration_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DetectorSection {
    name: String,
    kind: String,
    window_n: Option<usize>,
    interval_samples: Option<usize>,
    fault_intensity: Option<f64>,
    window_variance: Option<f64>,
    threshold_fhat: Option<f64>,
    loss_fit_onsets_s: Option<Vec<f64>>,
    loss_fit_losses_percent: Option<Vec<f64>>,
    loss_fit_horizon_s: Option<f64>,
    loss_fit_noisy_flights: Option<usize>,
    moment_bias_sigma_rad_s2_per_sqrt_s: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FaultSection {
    engine: usize,
    loss_percent: f64,
    onset_s: f64,
}

/// `[monte_carlo]`'s own fields in launch-vehicle decks.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct MonteCarloOwn {
    engines: Option<Vec<usize>>,
    loss_percent: Option<FactorSpec>,
    gust_scale: Option<FactorSpec>,
}

/// The loss-percentage table of a detector: linear fits of the loss against the peak `|fhat|` at each
/// of `onsets_s` (the seed's table over onset time and loss), from flights with `losses_percent`, the
/// peak taken over `horizon_s`: one noise-free flight per loss, or `noisy_flights_per_loss` flights with
/// the sensor noise drawn from `noise_seed` (the study's seed + 1, never the trials' streams).
#[derive(Debug, Clone, PartialEq)]
pub struct LossTableSpec {
    pub onsets_s: Vec<f64>,
    pub losses_percent: Vec<f64>,
    pub horizon_s: f64,
    pub noisy_flights_per_loss: usize,
    pub noise_seed: u64,
}

impl Default for LossTableSpec {
    /// Onsets 10 to 110 s every 20 s, losses 10, 30, 50 %, peaks over 3 s, noise-free.
    fn default() -> Self {
        LossTableSpec {
            onsets_s: vec![10.0, 30.0, 50.0, 70.0, 90.0, 110.0],
            losses_percent: vec![10.0, 30.0, 50.0],
            horizon_s: 3.0,
            noisy_flights_per_loss: 0,
            noise_seed: 0,
        }
    }
}

/// One detector configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchDetector {
    pub name: String,
    pub params: DetectorParams,
    pub loss_table: LossTableSpec,
}

/// A thrust loss of the fixed scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaunchFault {
    /// Engine index 0..4 (the seed's engine `index + 1`).
    pub engine: usize,
    pub loss_percent: f64,
    pub onset_s: f64,
}

/// The Monte Carlo section.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchMonteCarlo {
    pub common: MonteCarlo,
    /// Engines a sampled loss may hit (indices).
    pub engines: Vec<usize>,
    /// `None`: every faulty trial flies the deck's `[[faults]]`.
    pub loss_percent: Option<Factor>,
    pub gust_scale: Factor,
}

/// A validated launch study.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchStudy {
    pub header: StudyHeader,
    /// The vehicle flown and designed on (no gusts, noise x1; trials add their own).
    pub config: LaunchVehicleConfig,
    pub gusts: Vec<Gust>,
    pub detectors: Vec<LaunchDetector>,
    pub fault: Option<LaunchFault>,
    pub monte_carlo: LaunchMonteCarlo,
}

impl FromDeck for LaunchStudy {
    fn from_toml(text: &str, path: &Path) -> Result<LaunchStudy, DeckError> {
        let (deck, v, header) = open_deck(text, path, |d: &LaunchDeck| &d.study)?;
        let (duration_s, dt_s) = (header.duration_s, header.dt_s);
        if !(0.001..=0.05).contains(&dt_s) {
            return Err(v.err("study.dt_s", format!("allowed 0.001 to 0.05 s (the seed's D is 0.01), got {dt_s}")));
        }
        if deck.vehicle.model != "medium_launcher" {
            let models = [("medium_launcher", "src/methods/thrust_loss/vehicle.rs")];
            return Err(v.not_allowed("vehicle.model", &deck.vehicle.model, &models));
        }
        let mut config = LaunchVehicleConfig { dt_s, ..LaunchVehicleConfig::default() };
        // The gyro's grade: white noise per sample from the angle random walk, a constant bias per flight
        // from the bias stability (both in the units data sheets give).
        if let Some(arw) = deck.vehicle.gyro_arw_deg_per_sqrt_h {
            let arw = v.positive("vehicle.gyro_arw_deg_per_sqrt_h", arw)?;
            config.noise.rate_rad_s = arw.to_radians() / 60.0 / dt_s.sqrt();
        }
        if let Some(stability) = deck.vehicle.gyro_bias_stability_deg_per_h {
            let stability = v.non_negative("vehicle.gyro_bias_stability_deg_per_h", stability)?;
            config.noise.rate_bias_stability_rad_s = stability.to_radians() / 3600.0;
        }
        // First-stage burnout ends a flight: a study past it would fail every trial.
        let burnout_s = config.params.liftoff_mass_kg - config.params.burnout_mass_kg();
        let burnout_s = burnout_s / (ENGINES as f64 * config.params.engine_flow_kg_s());
        if duration_s >= burnout_s {
            return Err(v.err(
                "study.duration_s",
                format!("{duration_s} s: the first stage burns out at {burnout_s:.1} s; allowed less"),
            ));
        }

        let mut gusts = Vec::with_capacity(deck.gust.len());
        for (i, g) in deck.gust.iter().enumerate() {
            let field = |f: &str| format!("gust[{i}].{f}");
            let axes = [("down_range", GustAxis::DownRange, ""), ("cross_range", GustAxis::CrossRange, "")];
            let axis = v.choice(&field("axis"), &g.axis, &axes)?;
            let amplitude_mps = v.finite(&field("amplitude_mps"), g.amplitude_mps)?;
            let start_s = v.finite(&field("start_s"), g.start_s)?;
            if !(0.0..duration_s).contains(&start_s) {
                return Err(v.err(field("start_s"), format!("allowed 0 <= start_s < duration_s = {duration_s}")));
            }
            let duration = v.positive(&field("duration_s"), g.duration_s)?;
            gusts.push(Gust { axis, amplitude_mps, start_s, duration_s: duration });
        }

        v.detector_names("detector", deck.detector.iter().map(|d| d.name.as_str()))?;
        let mut detectors: Vec<LaunchDetector> = Vec::new();
        for (i, d) in deck.detector.iter().enumerate() {
            let field = |f: &str| format!("detector[{i}].{f}");
            if d.kind != "ekf_mhe" {
                return Err(v.not_allowed(field("kind"), &d.kind, &[("ekf_mhe", "method 001")]));
            }
            let mut mhe = MheParams::seed();
            crate::take_given!(mhe, d, [window_n, interval_samples, fault_intensity, window_variance]);
            let mut params = DetectorParams { mhe, ekf: EkfParams::for_noise(&config.noise), ..DetectorParams::seed() };
            if let Some(t) = d.threshold_fhat {
                params.threshold_fhat = t;
            }
            // The detector checks its own numbers at design; checking here names the deck's field.
            for (name, ok, value, allowed) in [
                ("window_n", mhe.window_n >= 1, mhe.window_n as f64, ">= 1"),
                ("interval_samples", mhe.interval_samples >= 1, mhe.interval_samples as f64, ">= 1"),
                (
                    "fault_intensity",
                    mhe.fault_intensity.is_finite() && mhe.fault_intensity > 0.0,
                    mhe.fault_intensity,
                    "> 0",
                ),
                (
                    "window_variance",
                    mhe.window_variance.is_finite() && mhe.window_variance > 0.0,
                    mhe.window_variance,
                    "> 0",
                ),
                (
                    "threshold_fhat",
                    params.threshold_fhat.is_finite() && params.threshold_fhat > 0.0,
                    params.threshold_fhat,
                    "> 0",
                ),
            ] {
                if !ok {
                    return Err(v.err(field(name), format!("{value}: allowed {allowed}")));
                }
            }
            if let Some(sigma) = d.moment_bias_sigma_rad_s2_per_sqrt_s {
                v.positive(&field("moment_bias_sigma_rad_s2_per_sqrt_s"), sigma)?;
                params.ekf.moment_bias_sigma_rad_s2_per_sqrt_s = Some(sigma);
            }
            let defaults = LossTableSpec::default();
            let onsets_s = d.loss_fit_onsets_s.clone().unwrap_or(defaults.onsets_s);
            if onsets_s.is_empty() || onsets_s.windows(2).any(|w| !(w[0] < w[1])) {
                return Err(v.err(field("loss_fit_onsets_s"), "list increasing onsets (s), at least one"));
            }
            if let Some(t) = onsets_s.iter().find(|t| !(t.is_finite() && **t > 0.0 && **t < burnout_s - 5.0)) {
                return Err(
                    v.err(field("loss_fit_onsets_s"), format!("{t}: allowed 0 < onset < {:.0} s", burnout_s - 5.0))
                );
            }
            let losses_percent = d.loss_fit_losses_percent.clone().unwrap_or(defaults.losses_percent);
            if losses_percent.len() < 2 || losses_percent.iter().any(|l| !(*l > 0.0 && *l <= 100.0)) {
                return Err(v.err(field("loss_fit_losses_percent"), "list at least two losses in (0, 100] %"));
            }
            let horizon_s =
                v.positive(&field("loss_fit_horizon_s"), d.loss_fit_horizon_s.unwrap_or(defaults.horizon_s))?;
            let noisy_flights_per_loss = d.loss_fit_noisy_flights.unwrap_or(0);
            if noisy_flights_per_loss == 1 {
                return Err(v.err(
                    field("loss_fit_noisy_flights"),
                    "1: allowed 0 (noise-free flights) or at least 2 noisy flights per loss and onset",
                ));
            }
            let loss_table = LossTableSpec {
                onsets_s,
                losses_percent,
                horizon_s,
                noisy_flights_per_loss,
                noise_seed: header.seed.wrapping_add(1),
            };
            detectors.push(LaunchDetector { name: d.name.clone(), params, loss_table });
        }

        if deck.faults.len() > 1 {
            return Err(v.err("faults", "one thrust loss per trial (the plant models one faulty engine)"));
        }
        let fault = match deck.faults.first() {
            None => None,
            Some(f) => Some(LaunchFault {
                engine: engine_index(&v, "faults[0].engine", f.engine)?,
                loss_percent: loss(&v, "faults[0].loss_percent", f.loss_percent)?,
                onset_s: onset(&v, "faults[0].onset_s", f.onset_s, duration_s)?,
            }),
        };

        // An alarm is the loss's detection only 2 s after the onset by default: a 10 % loss takes up to
        // about 1.5 s to alarm, and an alarm seconds later says more of a gust or the noise than of the loss.
        let rules = MonteCarloRules {
            detection_window_s: 2.0,
            ..MonteCarloRules::sampled("launch-vehicle decks", duration_s, OPTIONS.contains(&Opt::Thresholds))
        };
        let (common, own, _) = v.monte_carlo(deck.monte_carlo, &rules, |_, _| Ok(()))?;
        // A loss at lift-off leaves no window before it to calibrate on.
        v.factor_within(
            "monte_carlo.onset_s",
            &common.onset_s,
            |t| t > 0.0,
            &format!("0 < onset_s < duration_s = {duration_s}"),
        )?;
        let section_given = own.is_some();
        let own: MonteCarloOwn = own.unwrap_or_default();
        let engines = match &own.engines {
            None => (0..ENGINES).collect(),
            Some(list) if list.is_empty() => return Err(v.err("monte_carlo.engines", "name at least one")),
            Some(list) => list
                .iter()
                .enumerate()
                .map(|(k, e)| engine_index(&v, &format!("monte_carlo.engines[{k}]"), *e))
                .collect::<Result<Vec<_>, _>>()?,
        };
        let loss_percent = match &own.loss_percent {
            None => None,
            Some(spec) => {
                let f = v.factor("monte_carlo.loss_percent", Some(spec), Factor::Fixed(0.0))?;
                v.factor_within("monte_carlo.loss_percent", &f, |x| x > 0.0 && x <= 100.0, "0 < loss <= 100 %")?;
                Some(f)
            }
        };
        if section_given && loss_percent.is_none() && fault.is_none() && common.fault_free_fraction < 1.0 {
            return Err(v.err(
                "monte_carlo.loss_percent",
                "faulty trials need a loss: give loss_percent, or [[faults]], or fault_free_fraction = 1",
            ));
        }
        let gust_scale = v.factor("monte_carlo.gust_scale", own.gust_scale.as_ref(), Factor::Fixed(1.0))?;
        // Negative would reverse every gust: refused rather than read as a sign convention.
        v.factor_within("monte_carlo.gust_scale", &gust_scale, |x| x >= 0.0, ">= 0 (0: no gusts)")?;
        v.one_fault_source("[[faults]]", "monte_carlo.loss_percent", loss_percent.is_some() && fault.is_some())?;
        let monte_carlo = LaunchMonteCarlo { common, engines, loss_percent, gust_scale };

        Ok(LaunchStudy { header, config, gusts, detectors, fault, monte_carlo })
    }
}

/// The seed numbers engines 1 to 4; the code indexes them from 0.
fn engine_index(v: &Validator, field: &str, engine: usize) -> Result<usize, DeckError> {
    if (1..=ENGINES).contains(&engine) {
        Ok(engine - 1)
    } else {
        Err(v.err(field, format!("{engine}: allowed 1, 2, 3 or 4 (the seed's quadrant numbering)")))
    }
}

fn loss(v: &Validator, field: &str, percent: f64) -> Result<f64, DeckError> {
    if percent.is_finite() && percent > 0.0 && percent <= 100.0 {
        Ok(percent)
    } else {
        Err(v.err(field, format!("{percent}: allowed 0 < loss <= 100 %")))
    }
}

fn onset(v: &Validator, field: &str, t: f64, duration_s: f64) -> Result<f64, DeckError> {
    if t.is_finite() && t > 0.0 && t < duration_s {
        Ok(t)
    } else {
        Err(v.err(field, format!("{t}: allowed 0 < onset_s < duration_s = {duration_s}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_seed_deck_reads_as_documented() {
        let study = LaunchStudy::bundled("seed001_thrust.toml");
        assert_eq!(study.detectors.len(), 2);
        assert_eq!(study.detectors[0].params.mhe, MheParams::seed());
        assert_eq!(study.detectors[0].loss_table, LossTableSpec { noise_seed: 2, ..LossTableSpec::default() });
        // The second reads the loss from the seed's 5 % steps fitted on noisy flights, with the same filter.
        let noisy = &study.detectors[1];
        assert_eq!(
            (noisy.params.clone(), noisy.loss_table.noisy_flights_per_loss),
            (study.detectors[0].params.clone(), 4)
        );
        assert_eq!(noisy.loss_table.losses_percent.len(), 11);
        // The recovering deck: three filters (plain, 0.1 and 0.01 rad/s^2/sqrt(s)) under 15 detectors.
        let recovering = LaunchStudy::bundled("seed001_recovering_residual.toml");
        let mut filters: Vec<Option<f64>> = Vec::new();
        for d in &recovering.detectors {
            let sigma = d.params.ekf.moment_bias_sigma_rad_s2_per_sqrt_s;
            if !filters.contains(&sigma) {
                filters.push(sigma);
            }
        }
        assert_eq!((recovering.detectors.len(), filters), (15, vec![None, Some(0.1), Some(0.01)]));
        assert_eq!(study.gusts.len(), 2);
        assert_eq!(study.monte_carlo.engines, [0, 1, 2, 3]);
    }
}
