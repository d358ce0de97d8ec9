//! Trial scenarios of control-surface studies (method 004): which surface fault, noise level and
//! airframe-coefficient errors trial i has. The same scheme as the LTI studies' [`crate::engine::scenario::draws`]:
//! a function of (deck, seed, trial index) only; listed factors form a grid cycled over the trial index
//! (fault kind fastest, then surface, size, onset, noise, fault duration, parameter errors); ranges are
//! drawn by the deck's sampler, one dimension per factor; whether a trial is fault-free is the first
//! draw of its scenario stream.

use crate::engine::scenario::deck::ModelTarget;
use crate::engine::scenario::draws::{DIM_SIZE, FIRST_OWN_DIM, UnitSampler};
use crate::methods::surface_bank::actuator::{ActuatorFault, ActuatorFaultKind};
use crate::methods::surface_bank::study::{SensorNoise, SurfaceFaultSpec, SurfaceStudy};
use crate::vehicles::aerosonde::AerosondeParams;

/// Continuous-factor dimensions, fixed so a trial's draws do not depend on which factors are present.
const DIM_DURATION: usize = FIRST_OWN_DIM;
const DIM_PARAMETERS: usize = DIM_DURATION + 1;

/// One fault of a trial with its size and the size's group label (see [`ActuatorFaultKind::size`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScenarioFault {
    pub fault: ActuatorFault,
    pub size: f64,
    pub size_bin: f64,
}

/// One trial's scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceTrialSpec {
    pub trial: u64,
    /// In onset order; empty: fault-free.
    pub faults: Vec<ScenarioFault>,
    pub noise_scale: f64,
    pub noise_bin: f64,
    /// Relative error of each `monte_carlo.parameter_error`, in deck order.
    pub parameter_errors: Vec<f64>,
    /// Largest |group label| of the parameter errors (0 without any).
    pub parameter_error_bin: f64,
}

impl SurfaceTrialSpec {
    pub fn actuator_faults(&self) -> Vec<ActuatorFault> {
        self.faults.iter().map(|f| f.fault).collect()
    }
}

/// Draws the trial scenarios of one surface study.
pub struct SurfaceScenarioSampler<'a> {
    study: &'a SurfaceStudy,
    units: UnitSampler,
}

impl<'a> SurfaceScenarioSampler<'a> {
    pub fn new(study: &'a SurfaceStudy) -> Self {
        let mc = &study.monte_carlo;
        let dims = DIM_PARAMETERS + mc.parameter_errors.len();
        SurfaceScenarioSampler { study, units: UnitSampler::for_study(&mc.common, study.header.seed, dims) }
    }

    /// The scenario of trial `trial`.
    pub fn spec(&self, trial: u64) -> SurfaceTrialSpec {
        let s = self.study;
        let mc = &s.monte_carlo;
        let mut t = self.units.trial(trial);

        let sampled = (!mc.faults.is_empty()).then(|| {
            let spec = &mc.faults[t.digit(mc.faults.len())];
            let surface = mc.surfaces[t.digit(mc.surfaces.len())];
            let (size, size_bin) = t.factor(spec.size(), DIM_SIZE);
            (spec, surface, size, size_bin)
        });
        let (onset_s, noise_scale, noise_bin) = t.onset_and_noise(&mc.common);
        let duration_s = mc.fault_duration_s.as_ref().map(|f| t.factor(f, DIM_DURATION).0);
        let (parameter_errors, parameter_error_bin) = t.parameter_errors(&mc.parameter_errors, DIM_PARAMETERS);

        let faults = match (t.fault_free, sampled) {
            (true, _) => Vec::new(),
            (false, Some((spec, surface, size, size_bin))) => {
                let kind = match *spec {
                    SurfaceFaultSpec::Stuck { .. } => ActuatorFaultKind::Stuck { position_rad: size.to_radians() },
                    SurfaceFaultSpec::Oscillation { center_deg, period_s, .. } => ActuatorFaultKind::Oscillation {
                        low_rad: (center_deg - size).to_radians(),
                        high_rad: (center_deg + size).to_radians(),
                        period_s,
                    },
                    SurfaceFaultSpec::LossOfEffectiveness { .. } => {
                        ActuatorFaultKind::LossOfEffectiveness { effectiveness: size }
                    }
                };
                let fault = ActuatorFault { surface, kind, onset_s, end_s: duration_s.map(|d| onset_s + d) };
                vec![ScenarioFault { fault, size, size_bin }]
            }
            (false, None) => {
                let mut faults: Vec<_> = s
                    .faults
                    .iter()
                    .map(|&fault| ScenarioFault { fault, size: fault.kind.size(), size_bin: fault.kind.size() })
                    .collect();
                faults.sort_by(|a, b| a.fault.onset_s.total_cmp(&b.fault.onset_s));
                faults
            }
        };
        SurfaceTrialSpec { trial, faults, noise_scale, noise_bin, parameter_errors, parameter_error_bin }
    }

    /// The sensor noise of a trial.
    pub fn noise(&self, spec: &SurfaceTrialSpec) -> SensorNoise {
        self.study.sensors.scaled(spec.noise_scale)
    }

    /// The true airframe and the banks' model of a trial: the default Aerosonde with the trial's
    /// coefficient errors applied to the one each error names.
    pub fn airframes(&self, spec: &SurfaceTrialSpec) -> (AerosondeParams, AerosondeParams) {
        let mut truth = AerosondeParams::default();
        let mut design = AerosondeParams::default();
        for (pe, relative) in self.study.monte_carlo.parameter_errors.iter().zip(&spec.parameter_errors) {
            let target = match pe.model {
                ModelTarget::Plant => &mut truth,
                ModelTarget::Design => &mut design,
            };
            for name in &pe.what.0 {
                // The deck validated every name and range, so scaling cannot fail.
                *target = target.scaled(name, 1.0 + relative).expect("validated coefficient");
            }
        }
        (truth, design)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::deck::FromDeck;

    fn mc_study() -> SurfaceStudy {
        SurfaceStudy::bundled("seed004_monte_carlo.toml")
    }

    /// The bundled Monte Carlo deck: kinds (2) fastest, then surfaces (5), noise (2 values), parameter
    /// errors (3 values) cycle over the trial index; onsets form a Latin hypercube over [5, 15) s.
    #[test]
    fn the_grid_cycles_and_the_ranges_are_stratified() {
        let study = mc_study();
        let sampler = SurfaceScenarioSampler::new(&study);
        let n = study.monte_carlo.common.trials;
        assert_eq!(n, 1200);
        let mut onset_strata = vec![0u32; n as usize];
        let mut fault_free = 0;
        for i in 0..n {
            let spec = sampler.spec(i);
            assert_eq!(spec, sampler.spec(i), "a function of the trial index");
            assert_eq!(spec.noise_scale, [1.0, 2.0][(i / 10 % 2) as usize], "trial {i}");
            assert_eq!(spec.parameter_errors, [[-0.2], [0.0], [0.2]][(i / 20 % 3) as usize], "trial {i}");
            assert_eq!(spec.parameter_error_bin, [0.2, 0.0, 0.2][(i / 20 % 3) as usize]);
            let Some(f) = spec.faults.first() else {
                fault_free += 1;
                continue;
            };
            assert_eq!(spec.faults.len(), 1);
            assert_eq!(f.fault.surface, (i / 2 % 5) as usize, "trial {i}");
            let onset = f.fault.onset_s;
            assert!((5.0..15.0).contains(&onset) && f.fault.end_s == Some(onset + 15.0), "{f:?}");
            onset_strata[((onset - 5.0) / 10.0 * n as f64) as usize] += 1;
            match (i % 2, f.fault.kind) {
                (0, ActuatorFaultKind::Stuck { position_rad }) => {
                    assert!((-20.0..20.0).contains(&f.size) && (position_rad.to_degrees() - f.size).abs() < 1e-12);
                    assert!([-15.0, -5.0, 5.0, 15.0].contains(&f.size_bin) && (f.size - f.size_bin).abs() <= 5.0);
                }
                (1, ActuatorFaultKind::Oscillation { low_rad, high_rad, period_s }) => {
                    assert!((2.0..15.0).contains(&f.size) && period_s == 2.0);
                    assert!((high_rad.to_degrees() - f.size).abs() < 1e-12 && low_rad == -high_rad);
                }
                other => panic!("trial {i}: {other:?}"),
            }
        }
        // 10 % fault-free: 120 expected, binomial sd 10.4.
        assert!((90..150).contains(&fault_free), "{fault_free}");
        // Every faulty trial's onset in its own stratum of 1200: at most one per stratum.
        assert!(onset_strata.iter().all(|&c| c <= 1));
        assert_eq!(onset_strata.iter().sum::<u32>(), 1200 - fault_free);
    }

    #[test]
    fn coefficient_errors_scale_only_the_named_airframe() {
        let study = mc_study();
        let sampler = SurfaceScenarioSampler::new(&study);
        let spec = sampler.spec(5); // parameter error -0.2 (grid digit 0)
        assert_eq!(spec.parameter_errors, [-0.2]);
        let (truth, design) = sampler.airframes(&spec);
        let nominal = AerosondeParams::default();
        assert_eq!(truth, nominal);
        assert_eq!(design.C_l_delta_a, 0.8 * nominal.C_l_delta_a);
        assert_eq!(design.C_m_delta_e, 0.8 * nominal.C_m_delta_e);
        assert_eq!(design.C_n_delta_r, 0.8 * nominal.C_n_delta_r);
        assert_eq!(design.C_m_alpha, nominal.C_m_alpha);
        let noisy = sampler.spec(10);
        assert_eq!(noisy.noise_scale, 2.0);
        assert_eq!(sampler.noise(&noisy).gyro_variance_rad2_s2, 4.0 * 0.0076);
        assert_eq!(sampler.noise(&noisy).attitude_sigma_rad, 0.02);
    }
}
