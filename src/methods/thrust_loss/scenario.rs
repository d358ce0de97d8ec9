//! Trial scenarios of launch-vehicle studies (method 001): which engine loses how much thrust from when,
//! with what sensor noise and gusts. The scheme of [`crate::engine::scenario::draws`]: a function of (deck, seed, trial
//! index) only; listed factors form a grid cycled over the trial index (engine fastest, then loss,
//! onset, noise, gust scale); ranges are drawn by the deck's sampler; whether a trial is fault-free is
//! the first draw of its scenario stream.

use crate::engine::scenario::design::{Factors, Part, Slot};
use crate::engine::scenario::draws::{DIM_NOISE, DIM_ONSET, DIM_SIZE, FIRST_OWN_DIM, UnitSampler};
use crate::engine::scenario::streams::{Substream, trial_rng};
use crate::methods::thrust_loss::study::LaunchStudy;
use crate::methods::thrust_loss::vehicle::{Gust, LaunchVehicleConfig, ThrustFault};
use rand::RngExt;
use rand_distr::StandardNormal;

const DIM_GUST: usize = FIRST_OWN_DIM;
const DIMS: usize = DIM_GUST + 1;

/// One trial's scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchTrialSpec {
    pub trial: u64,
    /// `None`: fault-free.
    pub fault: Option<ThrustFault>,
    /// The loss (%) and its group label; NaN when fault-free.
    pub loss_percent: f64,
    pub loss_bin: f64,
    pub noise_scale: f64,
    pub noise_bin: f64,
    pub gust_scale: f64,
    pub gust_bin: f64,
}

/// Draws the trial scenarios of one launch study.
pub struct LaunchScenarioSampler<'a> {
    study: &'a LaunchStudy,
    units: UnitSampler,
}

impl<'a> LaunchScenarioSampler<'a> {
    pub fn new(study: &'a LaunchStudy) -> Self {
        let mc = &study.monte_carlo;
        LaunchScenarioSampler { study, units: UnitSampler::for_study(&mc.common, study.header.seed, DIMS) }
    }

    /// The scenario of trial `trial`.
    pub fn spec(&self, trial: u64) -> LaunchTrialSpec {
        let s = self.study;
        let mc = &s.monte_carlo;
        let mut t = self.units.trial(trial);
        let sampled = mc.loss_percent.as_ref().map(|f| {
            let engine = mc.engines[t.digit(mc.engines.len())];
            let (loss, bin) = t.factor(f, DIM_SIZE);
            (engine, loss, bin)
        });
        let (onset_s, noise_scale, noise_bin) = t.onset_and_noise(&mc.common);
        let (gust_scale, gust_bin) = t.factor(&mc.gust_scale, DIM_GUST);
        let (fault, loss_percent, loss_bin) = match (t.fault_free, sampled, s.fault) {
            (true, _, _) => (None, f64::NAN, f64::NAN),
            (false, Some((engine, loss, bin)), _) => {
                (Some(ThrustFault { engine, loss_fraction: loss / 100.0, onset_s }), loss, bin)
            }
            (false, None, Some(f)) => (
                Some(ThrustFault { engine: f.engine, loss_fraction: f.loss_percent / 100.0, onset_s: f.onset_s }),
                f.loss_percent,
                f.loss_percent,
            ),
            (false, None, None) => (None, f64::NAN, f64::NAN),
        };
        LaunchTrialSpec { trial, fault, loss_percent, loss_bin, noise_scale, noise_bin, gust_scale, gust_bin }
    }

    /// The trial whose noise streams trial `trial` uses (another in a sensitivity design).
    pub fn noise_trial(&self, trial: u64) -> u64 {
        self.units.noise_trial(trial)
    }

    /// What the trial's truth flies: the study's vehicle with the trial's noise and gusts.
    pub fn config(&self, spec: &LaunchTrialSpec) -> LaunchVehicleConfig {
        let s = self.study;
        let noise = s.config.noise.scaled(spec.noise_scale);
        // The gyro biases from the trial's own stream for draws of its sensors' errors (none drawn
        // without a bias stability, so decks without one keep their records).
        let rate_bias_rad_s = if noise.rate_bias_stability_rad_s > 0.0 {
            let mut rng = trial_rng(s.header.seed, self.noise_trial(spec.trial), Substream::Fault);
            std::array::from_fn(|_| noise.rate_bias_stability_rad_s * rng.sample::<f64, _>(StandardNormal))
        } else {
            [0.0; 3]
        };
        LaunchVehicleConfig {
            noise,
            gusts: s.gusts.iter().map(|g| Gust { amplitude_mps: g.amplitude_mps * spec.gust_scale, ..*g }).collect(),
            rate_bias_rad_s,
            ..s.config.clone()
        }
    }
}

/// The factors a sensitivity design varies, where [`LaunchScenarioSampler::spec`] takes them. Faulty
/// trials: engine (the first grid digit), loss, onset, noise scale, gust scale; fault-free trials: the
/// last two. A deck's fixed `[[faults]]` has no factor of its own.
pub fn sensitivity_parts(study: &LaunchStudy) -> Vec<Part> {
    let mc = &study.monte_carlo;
    let mut shared = Factors::default();
    shared.add("noise_scale", Slot::Dim(DIM_NOISE), mc.common.noise_scale.is_sampled());
    shared.add("gust_scale", Slot::Dim(DIM_GUST), mc.gust_scale.is_sampled());
    let mut faulty = Factors::default();
    if let Some(loss) = &mc.loss_percent {
        faulty.add("engine", Slot::Digit(0), mc.engines.len() > 1);
        faulty.add("loss_percent", Slot::Dim(DIM_SIZE), loss.is_sampled());
        faulty.add("onset_s", Slot::Dim(DIM_ONSET), mc.common.onset_s.is_sampled());
    }
    let has_faults = mc.loss_percent.is_some() || study.fault.is_some();
    Factors::parts(has_faults.then_some(faulty), shared)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::deck::FromDeck;

    /// The bundled deck: engines (4) fastest, then the gust scale (2 values); losses in 10-60 % with the
    /// onsets a Latin hypercube over 15-75 s; gusts scaled per trial, the vehicle's noise untouched.
    #[test]
    fn engines_and_gusts_cycle_and_losses_stay_in_range() {
        let study = LaunchStudy::bundled("seed001_thrust.toml");
        let sampler = LaunchScenarioSampler::new(&study);
        let mut fault_free = 0;
        let mut strata = vec![0u32; 2000];
        for i in 0..2000u64 {
            let spec = sampler.spec(i);
            assert_eq!(spec.gust_scale, [0.0, 1.0][(i / 4 % 2) as usize], "trial {i}");
            let config = sampler.config(&spec);
            assert_eq!(config.gusts.len(), 2);
            assert_eq!(config.gusts[0].amplitude_mps, 15.0 * spec.gust_scale);
            assert_eq!(config.noise, study.config.noise);
            let Some(f) = spec.fault else {
                fault_free += 1;
                continue;
            };
            assert_eq!(f.engine, (i % 4) as usize, "trial {i}");
            assert!((10.0..60.0).contains(&spec.loss_percent) && f.loss_fraction == spec.loss_percent / 100.0);
            assert!((15.0..75.0).contains(&f.onset_s));
            strata[((f.onset_s - 15.0) / 60.0 * 2000.0) as usize] += 1;
        }
        // 20 % fault-free: 400 expected, binomial sd 17.9.
        assert!((330..470).contains(&fault_free), "{fault_free}");
        assert!(strata.iter().all(|&c| c <= 1), "one onset per stratum of the hypercube");
    }

    /// A navigation-grade gyro from the deck's data-sheet units: white noise per 100-Hz sample from the
    /// angle random walk (0.002 deg/sqrt(h) -> 0.002 / 60 * 10 deg/s), and per flight a constant bias on
    /// each axis of the bias stability's spread (0.01 deg/h -> 4.848e-8 rad/s), the same for the same
    /// trial and in the measurement; the bundled deck draws none.
    #[test]
    fn the_gyro_grade_sets_the_rate_noise_and_a_bias_per_flight() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/seed001_thrust.toml");
        let text = std::fs::read_to_string(&path).unwrap().replace(
            "model = \"medium_launcher\"",
            "model = \"medium_launcher\"\ngyro_arw_deg_per_sqrt_h = 0.002\ngyro_bias_stability_deg_per_h = 0.01",
        );
        let study = LaunchStudy::from_toml(&text, &path).unwrap();
        let white = 0.002f64.to_radians() / 60.0 * 10.0;
        assert!((study.config.noise.rate_rad_s - white).abs() < 1e-18, "{}", study.config.noise.rate_rad_s);
        // 0.01 deg/h = 0.01 / 3600 * pi / 180 rad/s, as the deck field is read.
        let stability = study.config.noise.rate_bias_stability_rad_s;
        assert!((stability - 4.8481e-8).abs() < 1e-12, "{stability}");
        let sampler = LaunchScenarioSampler::new(&study);
        let biases: Vec<[f64; 3]> = (0..400).map(|i| sampler.config(&sampler.spec(i)).rate_bias_rad_s).collect();
        assert_eq!(biases[7], sampler.config(&sampler.spec(7)).rate_bias_rad_s, "the same trial, the same biases");
        // 1,200 normal draws times the stability: their RMS within 10 % (a chi-square's 4 sd is 8 %).
        let rms = (biases.iter().flatten().map(|b| b * b).sum::<f64>() / 1200.0).sqrt();
        assert!((rms / stability - 1.0).abs() < 0.1, "{rms}");
        // The measured rates carry the bias: a noise-free step of the biased vehicle against the unbiased.
        let mut config = sampler.config(&sampler.spec(3));
        config.noise = crate::methods::thrust_loss::vehicle::SensorNoise::none();
        let biased = crate::methods::thrust_loss::vehicle::Vehicle::new(&config, None).unwrap().step_exact().unwrap();
        config.rate_bias_rad_s = [0.0; 3];
        let plain = crate::methods::thrust_loss::vehicle::Vehicle::new(&config, None).unwrap().step_exact().unwrap();
        for axis in 0..3 {
            let got = biased.y[3 + axis] - plain.y[3 + axis];
            assert!((got - biases[3][axis]).abs() < 1e-15, "axis {axis}: {got}");
        }
        let bundled = LaunchStudy::bundled("seed001_thrust.toml");
        let sampler = LaunchScenarioSampler::new(&bundled);
        assert_eq!(sampler.config(&sampler.spec(3)).rate_bias_rad_s, [0.0; 3]);
    }
}
