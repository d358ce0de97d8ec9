//! The usual redundancy management of a triplex air-data system, the baseline the patent claims to beat
//! where voting fails (issue 20.7): three sensors per quantity, mid-value select, and a miscompare
//! monitor with a persistence time.
//!
//! Per quantity (airspeed, alpha, beta), over the lanes not yet failed:
//! - output: with three, the middle value; with two, their mean; with one, it;
//! - monitor: with three, a lane whose distance to the middle value exceeds the threshold for
//!   `persistence_s` in a row is failed (latched: redundancy management does not take a sensor back in
//!   flight); with two, a disagreement beyond the threshold for as long fails the quantity without
//!   naming a lane (which of two is wrong cannot be voted). The threshold is `miscompare_sigma` times
//!   the sensor noise sigma the deck states.
//!
//! A fault is declared at the first failure; the faulty set is every quantity with a failed lane. The
//! voter's decision statistic is how long (s) a lane has miscompared in a row as if no lane had failed
//! (the three lanes' middle value): the first failure comes when it reaches the persistence, and a
//! study records it ([`crate::estimation::bank::held_s`]) to apply any other persistence after the run.
//! A
//! common-mode fault (all lanes alike) never miscompares: that is the case voting cannot see. The
//! numbers (5 sigma, 0.2 s) are choices, not any standard's: on `studies/seed002_hifi_truth.toml`'s
//! coloured air-data noise, 400 fault-free flights never tripped them (4 sigma for 0.1 s tripped in 46,
//! 5 sigma for 0.1 s in 3).

use crate::estimation::bank::{Decision, held_s, hold_steps};
use crate::methods::air_data::dual_ukf::COMPONENTS;
use crate::methods::air_data::flight::{AirData, MAX_LANES};

/// The voter's parameters; [`TriplexParams::seed`] the defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriplexParams {
    /// Miscompare threshold in sensor noise sigmas.
    pub miscompare_sigma: f64,
    /// How long a miscompare must persist before the lane is failed (s).
    pub persistence_s: f64,
}

impl TriplexParams {
    /// 5 sigma, 0.2 s (module docs).
    pub fn seed() -> Self {
        TriplexParams { miscompare_sigma: 5.0, persistence_s: 0.2 }
    }
}

/// One step of the voter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoterStep {
    /// The voted air data.
    pub air_data: AirData,
    /// Per quantity, the largest distance of a working lane from the vote, in sigmas.
    pub miscompare_sigma: [f64; COMPONENTS],
    /// Per quantity, a lane miscompares at this step.
    pub miscompares: [bool; COMPONENTS],
    /// Per quantity, a lane has failed (or two lanes disagree): the faulty set.
    pub failed: [bool; COMPONENTS],
    /// A fault is declared (latched).
    pub fault_declared: bool,
    /// The decision statistic (module docs), s.
    pub held_s: f64,
    /// The declaration, at the step it is made.
    pub decision: Option<Decision>,
}

/// The triplex voter; see the module docs.
#[derive(Debug, Clone)]
pub struct TriplexVoter {
    sigma: [f64; COMPONENTS],
    miscompare_sigma: f64,
    dt_s: f64,
    pub persistence_steps: u32,
    /// Per quantity and lane: still voting.
    working: [[bool; MAX_LANES]; COMPONENTS],
    /// Per quantity and lane: consecutive steps miscomparing (with two lanes, index 0 counts their
    /// disagreement).
    counts: [[u32; MAX_LANES]; COMPONENTS],
    /// Per quantity: two lanes disagreed for the persistence time.
    disagreed: [bool; COMPONENTS],
    /// Per quantity and lane: consecutive steps miscomparing with all three lanes voting (the statistic).
    all_lanes_counts: [[u32; MAX_LANES]; COMPONENTS],
    declared: bool,
}

impl TriplexVoter {
    /// A voter for sensors of noise `sigma` (airspeed m/s, alpha and beta rad) sampled every `dt_s`.
    pub fn new(params: &TriplexParams, sigma: [f64; COMPONENTS], dt_s: f64) -> Self {
        TriplexVoter {
            sigma,
            miscompare_sigma: params.miscompare_sigma,
            dt_s,
            persistence_steps: hold_steps(params.persistence_s, dt_s),
            working: [[true; MAX_LANES]; COMPONENTS],
            counts: [[0; MAX_LANES]; COMPONENTS],
            disagreed: [false; COMPONENTS],
            all_lanes_counts: [[0; MAX_LANES]; COMPONENTS],
            declared: false,
        }
    }

    /// One sample of the three lanes.
    pub fn step(&mut self, lanes: &[AirData; MAX_LANES]) -> VoterStep {
        let values = lanes.map(|l| l.to_array());
        let mut voted = [0.0; COMPONENTS];
        let mut distance = [0.0f64; COMPONENTS];
        let mut miscompares = [false; COMPONENTS];
        let mut newly_failed = false;
        let mut held = 0;
        for j in 0..COMPONENTS {
            // The statistic's counts, as the first branch below counts while all three lanes vote.
            let middle = median3(values[0][j], values[1][j], values[2][j]);
            for (i, count) in self.all_lanes_counts[j].iter_mut().enumerate() {
                let d = (values[i][j] - middle).abs() / self.sigma[j];
                *count = if d > self.miscompare_sigma { *count + 1 } else { 0 };
                held = held.max(*count);
            }
            // The working lanes and their values, without allocating on every sample.
            let (mut working, mut y, mut n) = ([0usize; MAX_LANES], [0.0; MAX_LANES], 0);
            for i in (0..MAX_LANES).filter(|&i| self.working[j][i]) {
                (working[n], y[n]) = (i, values[i][j]);
                n += 1;
            }
            let (working, y) = (&working[..n], &y[..n]);
            // Compared in sigmas, as the statistic is, so the two agree to the bit.
            let threshold = self.miscompare_sigma;
            match n {
                3 => {
                    voted[j] = median3(y[0], y[1], y[2]);
                    for (k, &i) in working.iter().enumerate() {
                        let d = (y[k] - voted[j]).abs() / self.sigma[j];
                        distance[j] = distance[j].max(d);
                        let count = &mut self.counts[j][i];
                        *count = if d > threshold { *count + 1 } else { 0 };
                        miscompares[j] |= d > threshold;
                    }
                    // At most one lane fails per step: the one that has miscompared longest.
                    let worst = working.iter().copied().max_by_key(|&i| self.counts[j][i]);
                    if let Some(i) = worst.filter(|&i| self.counts[j][i] >= self.persistence_steps) {
                        self.working[j][i] = false;
                        self.counts[j] = [0; MAX_LANES];
                        newly_failed = true;
                    }
                }
                2 => {
                    voted[j] = 0.5 * (y[0] + y[1]);
                    let d = (y[0] - y[1]).abs() / self.sigma[j];
                    distance[j] = d;
                    miscompares[j] = d > threshold;
                    let count = &mut self.counts[j][0];
                    *count = if d > threshold { *count + 1 } else { 0 };
                    if *count >= self.persistence_steps && !self.disagreed[j] {
                        self.disagreed[j] = true;
                        newly_failed = true;
                    }
                }
                _ => voted[j] = y.first().copied().unwrap_or(values[0][j]),
            }
        }
        let failed: [bool; COMPONENTS] =
            std::array::from_fn(|j| self.disagreed[j] || self.working[j].iter().any(|w| !w));
        let decision = (newly_failed && !self.declared).then_some(Decision::Declared(1));
        self.declared |= newly_failed;
        VoterStep {
            air_data: AirData::from_array(voted),
            miscompare_sigma: distance,
            miscompares,
            failed,
            fault_declared: self.declared,
            decision,
            held_s: held_s(held, self.dt_s),
        }
    }
}

/// The middle of three values.
fn median3(a: f64, b: f64, c: f64) -> f64 {
    let mut sorted = [a, b, c];
    sorted.sort_by(f64::total_cmp);
    sorted[1]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lanes(v: [f64; MAX_LANES]) -> [AirData; MAX_LANES] {
        v.map(|a| AirData { airspeed_mps: a, alpha_rad: 0.0, beta_rad: 0.0 })
    }

    /// With 4 sigma for 0.1 s: a lane 5 sigma off fails after the persistence (10 samples at 100 Hz), not before; the vote
    /// stays the middle value, then the mean of the other two; a common offset on all three never
    /// miscompares; a lone glitch resets the count.
    #[test]
    fn a_lane_off_by_more_than_the_threshold_fails_after_the_persistence() {
        let sigma = [0.5, 0.01, 0.01];
        let mut voter = TriplexVoter::new(&TriplexParams { miscompare_sigma: 4.0, persistence_s: 0.1 }, sigma, 0.01);
        let step = voter.step(&lanes([70.0 + 2.5, 70.1, 69.9]));
        assert_eq!((step.miscompares[0], step.decision), (true, None));
        assert_eq!(step.air_data.airspeed_mps, 70.1, "middle value");
        assert!((step.miscompare_sigma[0] - 2.4 / 0.5).abs() < 1e-12, "{:?}", step.miscompare_sigma);
        let step = voter.step(&lanes([70.0, 70.1, 69.9]));
        assert!(!step.miscompares[0], "the glitch is over: the count restarts");
        let threshold_s = crate::estimation::bank::held_threshold_s(voter.persistence_steps, 0.01);
        for k in 1..=10 {
            let step = voter.step(&lanes([72.5, 70.1, 69.9]));
            assert_eq!(step.decision.is_some(), k == 10, "sample {k}");
            assert_eq!(step.failed[0], k == 10);
            assert_eq!(step.held_s > threshold_s, k == 10, "the statistic crosses at the failure");
        }
        let step = voter.step(&lanes([72.5, 70.1, 69.9]));
        assert_eq!((step.air_data.airspeed_mps, step.decision, step.fault_declared), (70.0, None, true));
        assert!((step.held_s - 0.11).abs() < 1e-12, "counted on as if lane 0 still voted: {}", step.held_s);
        assert_eq!(step.failed, [true, false, false]);

        let mut voter = TriplexVoter::new(&TriplexParams { miscompare_sigma: 4.0, persistence_s: 0.1 }, sigma, 0.01);
        for _ in 0..100 {
            let step = voter.step(&lanes([75.0, 75.1, 74.9]));
            assert!(!step.fault_declared && !step.miscompares[0]);
        }
    }
}
