//! The Bayesian probability recursion of a multiple-model bank and its declare/clear rule
//! (method 004; also usable by any bank of filters that report innovations).
//!
//! `p_i(k) = L_i(k) p_i(k-1) / sum_j L_j(k) p_j(k-1)`, with the likelihood `L_i` of filter i's
//! innovation `gamma_i` (covariance `S_i`) in one of two forms:
//! - [`LikelihoodForm::Gaussian`]: the m-variate normal density,
//!   `exp(-gamma' S^-1 gamma / 2) / sqrt((2 pi)^m det S)`;
//! - [`LikelihoodForm::EuclideanNorm`], the seed's fast form, which the seed names but does not write
//!   out: the normal density with `S` replaced by the isotropic `s I`, `s = tr S / m` (the mean
//!   variance per component), `exp(-|gamma|^2 / (2 s)) / (2 pi s)^(m/2)`. It depends on the innovation
//!   only through its Euclidean norm and needs no inverse and no determinant: O(m) per filter;
//! - [`LikelihoodForm::EuclideanNormOneDimensional`], the seed's section 2.6 read literally: a 1-D
//!   normal density of the innovation's Euclidean norm, variance `tr S` (the norm's mean square),
//!   `exp(-|gamma|^2 / (2 tr S)) / sqrt(2 pi tr S)`. Against the isotropic form its exponent is m times
//!   smaller: a mismatch is weighed m times less (docs/findings-seed004.md measures what that costs).
//!
//! Computed in logarithms (the Gaussian exponent of a wrong model easily underflows), normalised, then
//! floored by a [`FloorRule`]: by default every probability below the floor (0.001 in the seed) is set
//! to the floor at every step; [`FloorRule::ResetAtZero`] is the seed's literal rule, resetting only a
//! probability that has reached 0 (underflowed past the smallest double). Either way the others are
//! scaled down so the sum stays exactly 1. A filter whose innovation covariance is singular gets
//! likelihood 0 that step.
#![allow(non_snake_case)]

use nalgebra::{Const, DimMin, SMatrix};

use crate::estimation::stekf::Innovation;

/// Which likelihood turns innovations into probabilities; see the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LikelihoodForm {
    Gaussian,
    EuclideanNorm,
    EuclideanNormOneDimensional,
}

impl LikelihoodForm {
    /// `ln L` of one innovation; `-inf` when `S` is singular or not positive.
    pub fn log_likelihood<const M: usize>(self, innovation: &Innovation<M>) -> f64
    where
        Const<M>: DimMin<Const<M>, Output = Const<M>>,
    {
        let gamma = &innovation.gamma;
        let ln_2pi = (2.0 * std::f64::consts::PI).ln();
        match self {
            LikelihoodForm::Gaussian => {
                let (Some(S_inv), det) = (
                    innovation.S_inverse.as_ref(),
                    innovation.S_determinant.unwrap_or_else(|| innovation.S.determinant()),
                ) else {
                    return f64::NEG_INFINITY;
                };
                if !(det > 0.0) {
                    return f64::NEG_INFINITY;
                }
                let quadratic = (gamma.transpose() * S_inv * gamma)[(0, 0)];
                -0.5 * (quadratic + det.ln() + M as f64 * ln_2pi)
            }
            LikelihoodForm::EuclideanNorm => {
                let s = innovation.S.trace() / M as f64;
                if !(s > 0.0) {
                    return f64::NEG_INFINITY;
                }
                -0.5 * M as f64 * (gamma.norm_squared() / (M as f64 * s) + s.ln() + ln_2pi)
            }
            LikelihoodForm::EuclideanNormOneDimensional => {
                let trace = innovation.S.trace();
                if !(trace > 0.0) {
                    return f64::NEG_INFINITY;
                }
                -0.5 * (gamma.norm_squared() / trace + trace.ln() + ln_2pi)
            }
        }
    }
}

/// When the floor applies; see the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FloorRule {
    /// Every probability below the floor is raised to it at every step (a lower bound).
    #[default]
    EveryStep,
    /// The seed's words: a probability that reaches 0 is reset to the floor; others may sink below it.
    ResetAtZero,
}

/// The probabilities of K models (model 0: no fault) with the floor; see the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelProbabilities<const K: usize> {
    p: [f64; K],
    floor: f64,
    floor_rule: FloorRule,
    /// Steps on which at least one probability was raised to the floor.
    pub floor_steps: u32,
    /// Steps on which no model had a usable likelihood (probabilities kept).
    pub skipped_steps: u32,
}

impl<const K: usize> ModelProbabilities<K> {
    /// Starts from `prior` (must sum to 1, each at least `floor`).
    pub fn new(prior: [f64; K], floor: f64) -> Self {
        assert!((prior.iter().sum::<f64>() - 1.0).abs() < 1e-12 && prior.iter().all(|&p| p >= floor));
        assert!(floor >= 0.0 && floor * K as f64 <= 1.0);
        ModelProbabilities { p: prior, floor, floor_rule: FloorRule::EveryStep, floor_steps: 0, skipped_steps: 0 }
    }

    /// The same probabilities floored by `rule`.
    pub fn with_floor_rule(self, floor_rule: FloorRule) -> Self {
        ModelProbabilities { floor_rule, ..self }
    }

    pub fn probabilities(&self) -> &[f64; K] {
        &self.p
    }

    /// One Bayes step from the models' log-likelihoods.
    pub fn update(&mut self, log_likelihood: &[f64; K]) {
        let log_post: [f64; K] = std::array::from_fn(|i| self.p[i].ln() + log_likelihood[i]);
        let max = log_post.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if !max.is_finite() {
            self.skipped_steps += 1;
            return;
        }
        let unnormalised: [f64; K] = std::array::from_fn(|i| (log_post[i] - max).exp());
        let total: f64 = unnormalised.iter().sum();
        self.p = unnormalised.map(|u| u / total);
        self.apply_floor();
    }

    /// Raises probabilities below the floor (or, reset at zero, those at 0) to it and scales the rest so
    /// the sum is 1.
    fn apply_floor(&mut self) {
        let low = match self.floor_rule {
            FloorRule::EveryStep => self.p.map(|p| p < self.floor),
            FloorRule::ResetAtZero => self.p.map(|p| p == 0.0),
        };
        if !low.contains(&true) {
            return;
        }
        self.floor_steps += 1;
        let floored_mass = self.floor * low.iter().filter(|&&l| l).count() as f64;
        let rest: f64 = self.p.iter().zip(&low).filter(|(_, l)| !**l).map(|(p, _)| p).sum();
        let scale = (1.0 - floored_mass) / rest;
        for (p, l) in self.p.iter_mut().zip(&low) {
            *p = if *l { self.floor } else { *p * scale };
        }
    }

    /// The probability-weighted estimate `sum_i p_i x_i` of the states the models share.
    pub fn blend<const N: usize>(&self, estimates: &[SMatrix<f64, N, 1>; K]) -> SMatrix<f64, N, 1> {
        estimates.iter().zip(&self.p).map(|(x, p)| x * *p).sum()
    }
}

/// The seed's decision: model i (i >= 1) is declared faulty when its probability has stayed above
/// `declare` (0.9) for `hold_steps` consecutive samples; the declaration is cleared when it has stayed
/// below `clear` (0.05) for `clear_hold_steps` (the seed says "within a certain time" for both; 1 step
/// clears at the first sample below). Another model above `declare` for `hold_steps` replaces the
/// declared one.
///
/// Its decision statistic ([`DeclareClear::held_samples`]) is how many samples in a row some fault
/// model's probability has stayed above `declare`: the rule declares when it reaches `hold_steps`, so a
/// study records it ([`held_s`]) and applies any other hold after the run. The declared state does not
/// enter it (a declaration standing from before is no reason not to alarm again), and the probability
/// itself is not the statistic: it saturates at 1 minus the floors, so flights above the declare level
/// tie and no threshold between them exists.
#[derive(Debug, Clone, PartialEq)]
pub struct DeclareClear {
    pub declare: f64,
    pub clear: f64,
    pub hold_steps: u32,
    pub clear_hold_steps: u32,
    declared: Option<usize>,
    candidate: Option<(usize, u32)>,
    below_clear: u32,
    /// Per model (index 0 unused): samples in a row above `declare`.
    above: Vec<u32>,
}

/// Samples a hold of `hold_s` takes at the sample period `dt_s` (at least one).
pub fn hold_steps(hold_s: f64, dt_s: f64) -> u32 {
    (hold_s / dt_s).round().max(1.0) as u32
}

/// The threshold on [`held_s`] that a hold of `hold_s` sets at the sample period `dt_s`.
pub fn hold_threshold_s(hold_s: f64, dt_s: f64) -> f64 {
    held_threshold_s(hold_steps(hold_s, dt_s), dt_s)
}

/// A hold detector's decision statistic in seconds: `samples` in a row with its condition met, each
/// counting its period `dt_s`. The detector alarms when it exceeds [`held_threshold_s`].
pub fn held_s(samples: u32, dt_s: f64) -> f64 {
    samples as f64 * dt_s
}

/// The threshold on [`held_s`] of a hold of `hold_steps` samples: `(hold_steps - 1) dt_s`, exceeded at
/// the `hold_steps`-th sample in a row (the same product as the statistic's, so the comparison is exact).
pub fn held_threshold_s(hold_steps: u32, dt_s: f64) -> f64 {
    held_s(hold_steps.max(1) - 1, dt_s)
}

/// What changed at a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Model `i >= 1` declared (a fault of the thing model i stands for).
    Declared(usize),
    /// The declared model `i` cleared.
    Cleared(usize),
}

/// The decision numbers of a bank of model probabilities: the floor every probability keeps, the level
/// a fault model's probability must stay above for `declare_hold_s` to be declared, the level below
/// which a declaration clears. The surface banks (seed 004) and the air-data dual UKF (which borrows
/// seed 004's numbers) share them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecisionLevels {
    pub probability_floor: f64,
    pub declare_probability: f64,
    pub clear_probability: f64,
    /// A fault model's probability must stay above `declare_probability` this long (s).
    pub declare_hold_s: f64,
}

impl DecisionLevels {
    /// Seed 004's: floor 0.001, declare at 0.9 held 0.1 s, clear below 0.05.
    pub fn seed() -> Self {
        DecisionLevels {
            probability_floor: 0.001,
            declare_probability: 0.9,
            clear_probability: 0.05,
            declare_hold_s: 0.1,
        }
    }

    /// Checks the numbers for a bank of `models` probabilities: the offending field, its value and what
    /// is allowed.
    pub fn check(&self, models: usize) -> Result<(), (&'static str, f64, &'static str)> {
        if !(self.declare_hold_s >= 0.0 && self.declare_hold_s.is_finite()) {
            return Err(("declare_hold_s", self.declare_hold_s, "non-negative and finite"));
        }
        let floor = self.probability_floor;
        if !(floor > 0.0 && floor * models as f64 <= 1.0) {
            return Err(("probability_floor", floor, "positive, at most 1 / the number of models"));
        }
        if !(0.0 < self.clear_probability && self.clear_probability < self.declare_probability) {
            return Err(("clear_probability", self.clear_probability, "in (0, declare_probability)"));
        }
        if !(self.declare_probability < 1.0 && self.declare_probability.is_finite()) {
            return Err(("declare_probability", self.declare_probability, "below 1"));
        }
        Ok(())
    }

    /// The threshold on the rule's decision statistic ([`held_s`] of [`DeclareClear::held_samples`]) that
    /// `declare_hold_s` sets at the sample period `dt_s`.
    pub fn alarm_threshold_s(&self, dt_s: f64) -> f64 {
        hold_threshold_s(self.declare_hold_s, dt_s)
    }

    /// The declare/clear rule at the sample period `dt_s`, a declaration clearing once the probability has
    /// stayed below `clear_probability` for `clear_hold_s` (0: the first sample below).
    pub fn rule(&self, clear_hold_s: f64, dt_s: f64) -> DeclareClear {
        DeclareClear::with_holds_s(
            self.declare_probability,
            self.clear_probability,
            self.declare_hold_s,
            clear_hold_s,
            dt_s,
        )
    }
}

impl DeclareClear {
    pub fn new(declare: f64, clear: f64, hold_steps: u32, clear_hold_steps: u32) -> Self {
        assert!(0.0 < clear && clear < declare && declare < 1.0);
        DeclareClear {
            declare,
            clear,
            hold_steps,
            clear_hold_steps,
            declared: None,
            candidate: None,
            below_clear: 0,
            above: Vec::new(),
        }
    }

    /// The rule with its holds given in seconds at the sample period `dt_s` (at least one sample each).
    pub fn with_holds_s(declare: f64, clear: f64, declare_hold_s: f64, clear_hold_s: f64, dt_s: f64) -> Self {
        DeclareClear::new(declare, clear, hold_steps(declare_hold_s, dt_s), hold_steps(clear_hold_s, dt_s))
    }

    pub fn declared(&self) -> Option<usize> {
        self.declared
    }

    /// The decision statistic after the last [`DeclareClear::observe`] (type docs): the most samples in a
    /// row any fault model has stayed above `declare`, and the first model with that many (none before
    /// any sample). With `declare >= 0.5` (or one fault model) at most one model is above it at a time,
    /// and a declaration is made exactly when this reaches `hold_steps` with no declaration standing.
    pub fn held_samples(&self) -> (u32, Option<usize>) {
        let mut best = (0, None);
        for (i, &n) in self.above.iter().enumerate().skip(1) {
            if n > best.0 {
                best = (n, Some(i));
            }
        }
        best
    }

    /// Feeds one step's probabilities (index 0: no fault); returns what changed, if anything.
    pub fn observe(&mut self, p: &[f64]) -> Option<Decision> {
        self.above.resize(p.len(), 0);
        for (n, &p) in self.above.iter_mut().zip(p).skip(1) {
            *n = if p > self.declare { *n + 1 } else { 0 };
        }
        let mut cleared = None;
        if let Some(i) = self.declared {
            self.below_clear = if p[i] < self.clear { self.below_clear + 1 } else { 0 };
            if self.below_clear >= self.clear_hold_steps.max(1) {
                self.declared = None;
                self.below_clear = 0;
                cleared = Some(Decision::Cleared(i));
            }
        }
        let leader = (1..p.len()).find(|&i| p[i] > self.declare && Some(i) != self.declared);
        self.candidate = match (leader, self.candidate) {
            (Some(i), Some((j, n))) if i == j => Some((i, n + 1)),
            (Some(i), _) => Some((i, 1)),
            (None, _) => None,
        };
        match self.candidate {
            Some((i, n)) if n >= self.hold_steps.max(1) => {
                self.declared = Some(i);
                self.candidate = None;
                self.below_clear = 0;
                Some(Decision::Declared(i))
            }
            _ => cleared,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};

    fn innovation(gamma: Vector2<f64>, S: Matrix2<f64>) -> Innovation<2> {
        Innovation { gamma, S, S_inverse: S.try_inverse(), S_determinant: None }
    }

    #[test]
    fn gaussian_log_likelihood_is_the_bivariate_normal_density() {
        let S = Matrix2::new(2.0, 0.5, 0.5, 1.0);
        let gamma = Vector2::new(0.7, -0.4);
        // Written out: det = 1.75, S^-1 = [1, -0.5; -0.5, 2] / 1.75.
        let quadratic: f64 = (0.49 + 2.0 * 0.7 * 0.4 * 0.5 + 2.0 * 0.16) / 1.75;
        let density = (-0.5 * quadratic).exp() / (2.0 * std::f64::consts::PI * 1.75f64.sqrt());
        let got = LikelihoodForm::Gaussian.log_likelihood(&innovation(gamma, S));
        assert!((got - density.ln()).abs() < 1e-12, "{got} vs {}", density.ln());
        let euclid = LikelihoodForm::EuclideanNorm.log_likelihood(&innovation(gamma, S));
        let s: f64 = 1.5;
        let want = (-(0.49 + 0.16) / (2.0 * s)).exp() / (2.0 * std::f64::consts::PI * s);
        assert!((euclid - want.ln()).abs() < 1e-12);
        // The 1-D density of |gamma| with variance tr S = 3: exp(-0.65 / 6) / sqrt(6 pi).
        let one_d = LikelihoodForm::EuclideanNormOneDimensional.log_likelihood(&innovation(gamma, S));
        let want: f64 = (-0.65f64 / 6.0).exp() / (6.0 * std::f64::consts::PI).sqrt();
        assert!((one_d - want.ln()).abs() < 1e-12, "{one_d} vs {}", want.ln());
        let singular = innovation(gamma, Matrix2::new(1.0, 1.0, 1.0, 1.0));
        assert_eq!(LikelihoodForm::Gaussian.log_likelihood(&singular), f64::NEG_INFINITY);
    }

    #[test]
    fn bayes_step_normalises_and_the_floor_holds_the_losers() {
        let mut probs = ModelProbabilities::new([0.5, 0.25, 0.25], 0.001);
        // Likelihoods 1 : 2 : 4 -> posterior 0.5 : 0.5 : 1, normalised 0.25 : 0.25 : 0.5.
        probs.update(&[0.0, 2f64.ln(), 4f64.ln()]);
        let p = probs.probabilities();
        assert!((p[0] - 0.25).abs() < 1e-15 && (p[1] - 0.25).abs() < 1e-15 && (p[2] - 0.5).abs() < 1e-15);
        assert_eq!(probs.floor_steps, 0);
        // A likelihood ratio of e^-800 would underflow to exactly 0 without logarithms and the floor.
        probs.update(&[-800.0, -800.0, 0.0]);
        let p = *probs.probabilities();
        assert_eq!(p[0], 0.001);
        assert_eq!(p[1], 0.001);
        assert!((p[2] - 0.998).abs() < 1e-15);
        assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert_eq!(probs.floor_steps, 1);
        // The floor lets a model come back: ten steps of e^5 likelihood ratio bring model 1 to the top.
        for _ in 0..10 {
            probs.update(&[0.0, 5.0, 0.0]);
        }
        assert!(probs.probabilities()[1] > 0.99);
        // No usable likelihood: nothing changes.
        let before = *probs.probabilities();
        probs.update(&[f64::NEG_INFINITY; 3]);
        assert_eq!(probs.probabilities(), &before);
        assert_eq!(probs.skipped_steps, 1);
    }

    #[test]
    fn reset_at_zero_lets_a_loser_sink_until_it_underflows() {
        let mut every = ModelProbabilities::new([0.5, 0.5], 0.001);
        let mut reset = every.clone().with_floor_rule(FloorRule::ResetAtZero);
        // A likelihood ratio of e^-400: 1.9e-174, below the floor but not 0.
        every.update(&[0.0, -400.0]);
        reset.update(&[0.0, -400.0]);
        assert_eq!(every.probabilities()[1], 0.001);
        let sunk = reset.probabilities()[1];
        assert!(sunk > 0.0 && (sunk.ln() + 400.0).abs() < 1e-9, "{sunk:e}");
        assert_eq!(reset.floor_steps, 0);
        // Another e^-400: exp(-800) underflows to exactly 0, which is reset to the floor.
        reset.update(&[0.0, -400.0]);
        assert_eq!(*reset.probabilities(), [0.999, 0.001]);
        assert_eq!(reset.floor_steps, 1);
        // Climbing back above 0.9 from e^-400 takes (400 + ln 9) / 5 = 80.4, so 81 steps of e^5; from
        // the floor (ln 999 + ln 9) / 5 = 1.8, so 2.
        let mut sunk = ModelProbabilities::new([0.5, 0.5], 0.001).with_floor_rule(FloorRule::ResetAtZero);
        sunk.update(&[0.0, -400.0]);
        let steps_to_lead = |p: &mut ModelProbabilities<2>| {
            (1..)
                .find(|_| {
                    p.update(&[0.0, 5.0]);
                    p.probabilities()[1] > 0.9
                })
                .unwrap()
        };
        assert_eq!((steps_to_lead(&mut sunk), steps_to_lead(&mut every)), (81, 2));
    }

    #[test]
    fn declare_after_the_hold_and_clear_below_the_lower_level() {
        let mut rule = DeclareClear::new(0.9, 0.05, 3, 1);
        let healthy = [0.99, 0.005, 0.005];
        let faulty = [0.02, 0.96, 0.02];
        let fading = [0.5, 0.3, 0.2];
        let gone = [0.97, 0.02, 0.01];
        assert_eq!(rule.observe(&healthy), None);
        assert_eq!(rule.observe(&faulty), None);
        assert_eq!(rule.observe(&faulty), None);
        assert_eq!(rule.observe(&faulty), Some(Decision::Declared(1)));
        assert_eq!(rule.observe(&fading), None, "0.3 is below 0.9 but above 0.05: still declared");
        assert_eq!(rule.declared(), Some(1));
        assert_eq!(rule.observe(&gone), Some(Decision::Cleared(1)));
        assert_eq!(rule.declared(), None);
        // An interrupted run above 0.9 restarts the hold.
        rule.observe(&faulty);
        rule.observe(&faulty);
        rule.observe(&healthy);
        rule.observe(&faulty);
        assert_eq!(rule.observe(&faulty), None);
        assert_eq!(rule.observe(&faulty), Some(Decision::Declared(1)));
    }

    /// The statistic on pseudo-random probabilities of three models hovering about the declare level:
    /// with no declaration standing, the rule declares exactly when the statistic reaches the hold, and
    /// names the model that has it; the statistic also counts on while a declaration stands.
    #[test]
    fn the_held_statistic_reaches_the_hold_exactly_when_the_rule_declares() {
        let mut rule = DeclareClear::new(0.9, 0.05, 4, 2);
        let mut state = 12345u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut declarations, mut standing_runs, mut leader) = (0, 0, 0);
        for _ in 0..20_000 {
            // One model leads for about 10 samples, above 0.9 about half the time.
            if next() < 0.1 {
                leader = (next() * 3.0) as usize;
            }
            let lead = 0.85 + 0.12 * next();
            let p = match leader {
                0 => [lead, 1.0 - lead - 0.001, 0.001],
                1 => [1.0 - lead - 0.001, lead, 0.001],
                _ => [1.0 - lead - 0.001, 0.001, lead],
            };
            let standing = rule.declared();
            let decision = rule.observe(&p);
            let (held, model) = rule.held_samples();
            if standing.is_none() {
                let declares = matches!(decision, Some(Decision::Declared(_)));
                assert_eq!(declares, held >= 4, "{p:?} held {held}");
                if let Some(Decision::Declared(i)) = decision {
                    assert_eq!(model, Some(i));
                    declarations += 1;
                }
            } else if held > 4 {
                standing_runs += 1;
            }
        }
        assert!(declarations > 100 && standing_runs > 10, "{declarations} {standing_runs}");
    }

    #[test]
    fn clearing_waits_for_its_hold() {
        // 0.05 s at 100 Hz: five samples below 0.05 in a row; one above restarts the count.
        let mut rule = DeclareClear::with_holds_s(0.9, 0.05, 0.02, 0.05, 0.01);
        assert_eq!((rule.hold_steps, rule.clear_hold_steps), (2, 5));
        let faulty = [0.02, 0.96, 0.02];
        let gone = [0.97, 0.02, 0.01];
        let between = [0.8, 0.1, 0.1];
        rule.observe(&faulty);
        assert_eq!(rule.observe(&faulty), Some(Decision::Declared(1)));
        for _ in 0..4 {
            assert_eq!(rule.observe(&gone), None);
        }
        assert_eq!(rule.observe(&between), None, "0.1 is above 0.05: the count restarts");
        for _ in 0..4 {
            assert_eq!(rule.observe(&gone), None);
        }
        assert_eq!(rule.declared(), Some(1));
        assert_eq!(rule.observe(&gone), Some(Decision::Cleared(1)));
        assert_eq!(rule.declared(), None);
    }
}
