//! Trial scenarios of air-data studies (method 002): which sensors fail together, how, from when, with
//! what noise level and turbulence. The scheme of [`crate::engine::scenario::draws`]: a function of (deck, seed, trial
//! index) only; listed factors form a grid cycled over the trial index (fault kind fastest, then the
//! sensor set, size, onset, noise, gust); ranges are drawn by the deck's sampler; whether a trial is
//! fault-free is the first draw of its scenario stream.

use crate::engine::scenario::design::{Factors, Part, Slot};
use crate::engine::scenario::draws::{DIM_NOISE, DIM_ONSET, DIM_SIZE, FIRST_OWN_DIM, UnitSampler};
use crate::fault::deck::TrialFaults;
use crate::methods::air_data::flight::ScenarioParams;
use crate::methods::air_data::study::AirDataStudy;

const DIM_GUST: usize = FIRST_OWN_DIM;
const DIMS: usize = DIM_GUST + 1;

/// One trial's scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct AirDataTrialSpec {
    pub trial: u64,
    /// The faults (one per faulty sensor) and their labels.
    pub fault: TrialFaults,
    /// Faulty sensors, ascending channel indices.
    pub outputs: Vec<usize>,
    pub noise_scale: f64,
    pub noise_bin: f64,
    pub gust_std_mps: f64,
    pub gust_bin: f64,
    /// How many air-data lanes the faults hit, from lane 0 (0 in a fault-free trial).
    pub faulty_lanes: usize,
}

/// Draws the trial scenarios of one air-data study.
pub struct AirDataScenarioSampler<'a> {
    study: &'a AirDataStudy,
    units: UnitSampler,
}

impl<'a> AirDataScenarioSampler<'a> {
    pub fn new(study: &'a AirDataStudy) -> Self {
        let mc = &study.monte_carlo;
        AirDataScenarioSampler { study, units: UnitSampler::for_study(&mc.common, study.header.seed, DIMS) }
    }

    /// The trial whose noise streams trial `trial` uses (another in a sensitivity design).
    pub fn noise_trial(&self, trial: u64) -> u64 {
        self.units.noise_trial(trial)
    }

    /// The scenario of trial `trial`.
    pub fn spec(&self, trial: u64) -> AirDataTrialSpec {
        let s = self.study;
        let mc = &s.monte_carlo;
        let mut t = self.units.trial(trial);

        let sampled = (!mc.faults.is_empty()).then(|| {
            let spec = &mc.faults[t.digit(mc.faults.len())];
            let set = &mc.output_sets[t.digit(mc.output_sets.len())];
            let size = spec.size.draw(&mut t, DIM_SIZE);
            (spec, set, size)
        });
        let (onset_s, noise_scale, noise_bin) = t.onset_and_noise(&mc.common);
        let (gust_std_mps, gust_bin) = t.factor(&mc.gust_std_mps, DIM_GUST);
        // The last grid digit: a deck without redundancy lists one count, which leaves the others as they were.
        let faulty_lanes = mc.faulty_lanes[t.digit(mc.faulty_lanes.len())];
        let mut spec = AirDataTrialSpec {
            trial,
            fault: TrialFaults::none(),
            outputs: Vec::new(),
            noise_scale,
            noise_bin,
            gust_std_mps,
            gust_bin,
            faulty_lanes,
        };
        if t.fault_free {
            spec.faulty_lanes = 0;
            return spec;
        }
        match sampled {
            Some((kind_spec, set, size)) => {
                let sigma = s.noise.air_data_std();
                spec.fault = TrialFaults::drawn(kind_spec, set, size, onset_s, |j| sigma[j]);
                spec.outputs = set.to_vec();
            }
            None => {
                spec.fault = TrialFaults::fixed(&s.faults, &[]);
                let mut outputs: Vec<usize> = s.faults.iter().map(|f| f.channel).collect();
                outputs.sort_unstable();
                outputs.dedup();
                spec.outputs = outputs;
            }
        }
        spec
    }

    /// The flight of a trial, as the scenario generator takes it.
    pub fn scenario(&self, spec: &AirDataTrialSpec) -> ScenarioParams {
        let s = self.study;
        ScenarioParams {
            dt_s: s.header.dt_s,
            duration_s: s.header.duration_s,
            profile: s.profile.clone(),
            noise: s.noise,
            noise_scale: spec.noise_scale,
            wind: crate::methods::air_data::flight::WindParams { gust_std_mps: spec.gust_std_mps, ..s.wind },
            faults: spec.fault.faults.clone(),
            airframe: s.airframe,
            sensor_errors: s.sensor_errors,
            lanes: s.lanes,
            faulty_lanes: spec.faulty_lanes.max(1), // 0 in a fault-free trial: nothing to hit
        }
    }
}

/// The factors a sensitivity design varies, where [`AirDataScenarioSampler::spec`] takes them. Faulty
/// trials: fault kind and output set (the first two grid digits, with sampled faults), size, onset,
/// noise scale, gust level, faulty lanes (the last digit); fault-free trials: noise scale and gusts.
pub fn sensitivity_parts(study: &AirDataStudy) -> Vec<Part> {
    let mc = &study.monte_carlo;
    let mut shared = Factors::default();
    shared.add("noise_scale", Slot::Dim(DIM_NOISE), mc.common.noise_scale.is_sampled());
    shared.add("gust_std_mps", Slot::Dim(DIM_GUST), mc.gust_std_mps.is_sampled());
    let sampled = !mc.faults.is_empty();
    let mut faulty = Factors::default();
    if sampled {
        faulty.add("fault_kind", Slot::Digit(0), mc.faults.len() > 1);
        faulty.add("output_set", Slot::Digit(1), mc.output_sets.len() > 1);
        faulty.add("size", Slot::Dim(DIM_SIZE), mc.faults.iter().any(|f| f.size.is_sampled()));
        faulty.add("onset_s", Slot::Dim(DIM_ONSET), mc.common.onset_s.is_sampled());
    }
    // The digit after the kind's and the set's, which only sampled faults take.
    faulty.add("faulty_lanes", Slot::Digit(if sampled { 2 } else { 0 }), mc.faulty_lanes.len() > 1);
    Factors::parts((sampled || !study.faults.is_empty()).then_some(faulty), shared)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::deck::FromDeck;
    use crate::fault::FaultMode;

    /// The bundled deck: kind (1) and sensor sets (5) cycle over the trial index, then noise (2 values)
    /// and gust (2 values); bias sizes in each faulty sensor's own sigmas, one onset for all of them.
    #[test]
    fn sets_cycle_and_common_mode_biases_are_sized_per_sensor() {
        let study = AirDataStudy::bundled("seed002_air_data.toml");
        let sampler = AirDataScenarioSampler::new(&study);
        let sigma = study.noise.air_data_std();
        let mut fault_free = 0;
        for i in 0..3000u64 {
            let spec = sampler.spec(i);
            assert_eq!(spec.noise_scale, [1.0, 2.0][(i / 5 % 2) as usize], "trial {i}");
            assert_eq!(spec.gust_std_mps, [0.0, 0.5][(i / 10 % 2) as usize], "trial {i}");
            if spec.fault.faults.is_empty() {
                fault_free += 1;
                assert_eq!(spec.fault.kind, "none");
                continue;
            }
            let set = &study.monte_carlo.output_sets[(i % 5) as usize];
            assert_eq!(&spec.outputs, set, "trial {i}");
            assert_eq!(spec.fault.faults.len(), set.len());
            assert!((2.0..20.0).contains(&spec.fault.size) && (10.0..40.0).contains(&spec.fault.onset_s), "{spec:?}");
            for f in &spec.fault.faults {
                assert_eq!(f.onset_s, spec.fault.onset_s);
                assert_eq!(f.mode, FaultMode::Bias { bias: spec.fault.size * sigma[f.channel] }, "trial {i}");
            }
            let params = sampler.scenario(&spec);
            assert_eq!((params.noise_scale, params.wind.gust_std_mps), (spec.noise_scale, spec.gust_std_mps));
            assert_eq!(params.faults, spec.fault.faults);
        }
        // 10 % fault-free: 300 expected, binomial sd 16.4.
        assert!((250..350).contains(&fault_free), "{fault_free}");
    }
}
