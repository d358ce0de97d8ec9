//! Rare false alarms by simulation, unbiased: the probability that a fault-free trial's detection
//! statistic ever exceeds a level, far below what plain trials reach. Two estimators on one model of a
//! trial ([`RareEventModel`]: a Markov path that steps one sample at a time and reports the sample's
//! score, the statistic over its threshold, so the detector alarms at threshold scale `s` when a score
//! exceeds `s`).
//!
//! **Importance sampling on the sensor noise** ([`Importance::adaptive`]), for statistics without
//! memory (the seed's `|residual|`, a one-sample chi-square test). Each trial picks a sample `tau` and
//! a pair from a mixture, changes the law of the draws for it, and counts its alarm with the likelihood
//! ratio of the whole mixture over samples and pairs, `1 / (plain + sum_i alpha_i W_i / N)`, `W_i` the
//! sum over the samples of pair i's density over the plain one: bounded by the mixture's 5 % share of
//! plain trials, so no single trial swamps the estimate and every path stays possible. Two mixtures:
//! - **tilts**, for a [Gaussian](RareEventModel::gaussian_scores) model (a linear loop whose only noise
//!   is the draws, the test `|s_j|` per output): the pairs are (output `j`, sign, level `L`); the draws
//!   of samples up to `tau` are shifted along output j's response so that `s_j(tau)` has mean `+-L`
//!   (the most likely way the path gets there, the filtered part of the residual included), and the
//!   density ratio is read off the score ([`Kernel`]). Every output at every level has its pairs, so no
//!   way the alarm happens is left to the plain share (a mixture over where the excursion happens, as
//!   Adler, Blanchet and Liu 2012 build for Gaussian fields; they condition, this shifts the mean);
//! - **tails**, otherwise: a component of the sample's `m` sensor draws (one draw `j`, or all of them)
//!   from the normal law conditioned beyond a tail probability `P` (half decades, 1e-1 to 1e-24) of its
//!   square (`z_j^2`, or `sum_j z_j^2`); `W_i` is `1 / P_i` where the sample's component passes pair
//!   `i`'s square, 0 elsewhere. What this cannot see: an alarm that needs several samples' noise at
//!   once; there the weights of the few trials that reach it spread and the interval is too narrow.
//!
//! A pilot (the first fifth of the trials, pairs alike) sets the pairs' weights `alpha_i` by one
//! variance-minimising step; the rest's estimate is unbiased for those weights. A trial depends only on
//! its index, as every plain trial does.
//!
//! **Adaptive multilevel splitting (AMS)** ([`splitting`]), for statistics with memory (a CUSUM, a
//! windowed test), where a path that has climbed part way is closer to the alarm (Cérou and Guyader
//! 2007, in the generalised form of Bréhier, Gazeau, Goudenège, Lelièvre and Rousset 2016 that stays
//! unbiased with ties and discrete time). One replica:
//! 1. run `n` particles, each a fault-free trial from its start; a particle's score is its running
//!    maximum at the end of the trial;
//! 2. the level `Z` is the smallest score; kill every particle at or below it (`K` of them, ties
//!    included; all `n`: the estimate is 0 from here on) and multiply the estimate by `1 - K / n`;
//! 3. each killed particle is replaced by a copy of a survivor (drawn uniformly) taken at the first
//!    sample where the survivor's running maximum exceeded `Z`, which then continues with noise of
//!    its own;
//! 4. repeat until `Z` reaches the level asked; the estimate at level `L` is the product so far times
//!    the fraction of particles whose score exceeds `L`, read at the first iteration whose `Z >= L`.
//!
//! The running maximum only rises at a record, so each particle keeps a snapshot of its path at each
//! of its records above the current level: branching costs a copy, not a replay. On a memoryless
//! statistic the splitting is still unbiased but degenerates: a copy taken at `Z` is no closer to a
//! higher level than a fresh trial, families of copies tie and die together, and most replicas end at
//! 0 (the tests show it on white noise).
//!
//! Replica `r` starts its particles from the study's trials `r n .. (r + 1) n` (faults removed) and
//! draws branch noise and survivor choices from streams keyed by `(seed, r)`
//! ([`crate::engine::scenario::streams::branch_rng`]): its numbers depend on nothing else, not on threads, not on
//! which shard ran it. Both estimators' 95 % intervals are Student's t on the spread of independent
//! unbiased units (trials, or replicas).

use rand::RngExt;
use rayon::prelude::*;
use statrs::distribution::{ContinuousCDF, StudentsT};

use crate::engine::scenario::noise::NoiseRng;
use crate::engine::scenario::streams::{BranchStream, branch_noise, branch_rng, importance_rng};
use crate::engine::stats::intervals::Z95;

/// Importance sampling's change to one sample's sensor draws (standard normals).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Condition<'a> {
    /// Draw `draw` (or, `None`, all the draws) taken from the normal law conditioned on its square
    /// (their sum of squares) lying in the upper `tail` of its chi-square law; `u`, uniform in (0, 1),
    /// picks the point of that conditioned tail (the direction stays the draws' own).
    Tail { draw: Option<usize>, tail: f64, u: f64 },
    /// Each draw moved by its shift (a tilted sample: [`Kernel`]).
    Shift(&'a [f64]),
    /// The draws replaced by these values (the probes that measure a [`Kernel`]).
    Set(&'a [f64]),
}

impl Condition<'_> {
    /// Turns standard normal `draws` into the conditioned ones.
    pub fn apply(&self, draws: &mut [f64]) {
        match *self {
            Condition::Tail { draw: Some(j), tail, u } => {
                let s = chi2_isf(1, u * tail);
                draws[j] = if draws[j] < 0.0 { -s.sqrt() } else { s.sqrt() };
            }
            Condition::Tail { draw: None, tail, u } => {
                let s = chi2_isf(draws.len(), u * tail);
                let r = draws.iter().map(|z| z * z).sum::<f64>().sqrt();
                draws.iter_mut().for_each(|z| *z *= s.sqrt() / r);
            }
            Condition::Shift(by) => draws.iter_mut().zip(by).for_each(|(z, d)| *z += d),
            Condition::Set(to) => draws.copy_from_slice(to),
        }
    }
}

/// P(chi-square(d) > x).
pub fn chi2_sf(d: usize, x: f64) -> f64 {
    if x <= 0.0 { 1.0 } else { statrs::function::gamma::gamma_ur(d as f64 / 2.0, x / 2.0) }
}

/// The x with P(chi-square(d) > x) = p (0 < p < 1): Newton on ln P inside a shrinking bracket, to
/// 1e-12 in ln P. (statrs' `inverse_cdf(1 - p)` cannot: `1 - p` is 1 below p = 1e-16.)
pub fn chi2_isf(d: usize, p: f64) -> f64 {
    let a = d as f64 / 2.0;
    let ln_p = p.ln();
    let ln_norm = a * std::f64::consts::LN_2 + statrs::function::gamma::ln_gamma(a);
    let (mut lo, mut hi) = (0.0f64, 2.0 * d as f64 + 10.0);
    while chi2_sf(d, hi) > p {
        lo = hi;
        hi *= 2.0;
    }
    let mut x = 0.5 * (lo + hi);
    for _ in 0..200 {
        let ln_sf = chi2_sf(d, x).ln();
        let miss = ln_sf - ln_p;
        if miss.abs() < 1e-12 {
            break;
        }
        if miss > 0.0 {
            lo = x
        } else {
            hi = x
        }
        // d ln S / dx = -pdf / S, pdf = x^(a-1) e^(-x/2) / (2^a Gamma(a)).
        let ln_pdf = (a - 1.0) * x.ln() - x / 2.0 - ln_norm;
        let next = x + miss * (ln_sf - ln_pdf).exp();
        x = if next > lo && next < hi { next } else { 0.5 * (lo + hi) };
    }
    x
}

/// A fault-free trial as a Markov path that can be copied mid-trial.
pub trait RareEventModel: Sync {
    /// Everything the rest of a trial depends on: states, test memory, noise generators.
    type Path: Clone;
    /// Samples per trial.
    fn steps(&self) -> usize;
    /// Sensor-noise draws per sample (the ones importance sampling may condition).
    fn noise_draws(&self) -> usize;
    /// The path of trial `trial` (its own scenario and noise, faults removed) before its first sample.
    fn start(&self, trial: u64) -> Self::Path;
    /// Sample `k` of the path, its sensor draws (standard normals, one per output) changed by
    /// `condition` if given. Writes the draws as used to `draws` (NaN for draws not made: a diverged
    /// path), and returns the sample's score: the statistic over its threshold, largest over
    /// outputs (0 once the path has diverged).
    fn step(&self, path: &mut Self::Path, k: usize, condition: Option<&Condition>, draws: &mut [f64]) -> f64;
    /// Gives the path new noise for its remaining samples, drawn from `rng`'s streams.
    fn renew_noise(&self, path: &mut Self::Path, rng: &mut dyn FnMut(BranchStream) -> NoiseRng);
    /// Whether the path is Gaussian and linear in its draws: every sample's score is `max_j |s_j|`,
    /// each signed score `s_j` an affine, time-invariant function of the trial's draws so far (a linear
    /// time-invariant loop whose only noise is the draws), and the draws standard normal. Importance
    /// sampling then tilts the draws towards each output's level ([`Kernel`]). Default: no.
    fn gaussian_scores(&self) -> bool {
        false
    }
    /// Whether every trial has the same law (no parameter error or noise scale changes it): one
    /// [`Kernel`] for all. Default: no.
    fn trials_alike(&self) -> bool {
        false
    }
    /// After a [`step`](Self::step): each output's signed score `s_j` into `signed`; `false` where the
    /// path has none (a diverged path, a model without [`gaussian_scores`](Self::gaussian_scores)).
    fn last_scores(&self, _path: &Self::Path, _signed: &mut [f64]) -> bool {
        false
    }
}

/// The law of a [Gaussian](RareEventModel::gaussian_scores) trial's signed scores, measured by probing
/// its path: the noise-free scores `mean_j(k)`, the response `h_ji(d)` of output j's score to a unit
/// draw i `d` samples earlier, and the variance `var_j(k) = sum_(d <= k) sum_i h_ji(d)^2`. Tilting
/// the draws of samples `k <= tau` by `theta h_j.(tau - k)` moves `s_j(tau)`'s mean by `theta
/// var_j(tau)` and multiplies the path's density by `exp(theta g - theta^2 var_j(tau) / 2)`, `g =
/// s_j(tau) - mean_j(tau)` the score's noise part: the likelihood ratio is read off the score.
#[derive(Debug, Clone)]
pub struct Kernel {
    outputs: usize,
    /// `mean[k * m + j]`.
    mean: Vec<f64>,
    /// `response[(d * m + j) * m + i]`.
    response: Vec<f64>,
    /// `variance[k * m + j]`.
    variance: Vec<f64>,
}

impl Kernel {
    /// Trial `trial`'s kernel: a noise-free path and one path per draw with a unit draw at sample 0;
    /// `None` if a probe diverges.
    pub fn of<M: RareEventModel>(model: &M, trial: u64) -> Option<Kernel> {
        let (n, m) = (model.steps(), model.noise_draws());
        let zeros = vec![0.0; m];
        let mut draws = vec![0.0; m];
        let mut signed = vec![0.0; m];
        let mut probe = |unit: Option<usize>, out: &mut Vec<f64>| -> Option<()> {
            let mut path = model.start(trial);
            let mut first = zeros.clone();
            if let Some(i) = unit {
                first[i] = 1.0;
            }
            for k in 0..n {
                let to = if k == 0 { &first } else { &zeros };
                model.step(&mut path, k, Some(&Condition::Set(to)), &mut draws);
                model.last_scores(&path, &mut signed).then_some(())?;
                out.extend_from_slice(&signed);
            }
            Some(())
        };
        let mut mean = Vec::with_capacity(n * m);
        probe(None, &mut mean)?;
        let mut response = vec![0.0; n * m * m];
        let mut scores = Vec::with_capacity(n * m);
        for i in 0..m {
            scores.clear();
            probe(Some(i), &mut scores)?;
            for d in 0..n {
                for j in 0..m {
                    response[(d * m + j) * m + i] = scores[d * m + j] - mean[d * m + j];
                }
            }
        }
        let mut variance = vec![0.0; n * m];
        for k in 0..n {
            for j in 0..m {
                let own: f64 = response[(k * m + j) * m..(k * m + j + 1) * m].iter().map(|h| h * h).sum();
                variance[k * m + j] = own + if k > 0 { variance[(k - 1) * m + j] } else { 0.0 };
            }
        }
        Some(Kernel { outputs: m, mean, response, variance })
    }

    /// Output j's noise-free signed score at sample k.
    pub fn mean(&self, k: usize, j: usize) -> f64 {
        self.mean[k * self.outputs + j]
    }

    /// The variance of output j's signed score at sample k.
    pub fn variance(&self, k: usize, j: usize) -> f64 {
        self.variance[k * self.outputs + j]
    }

    /// The tilt towards `s_j(tau) = target`: its `theta`, `None` where output j's score has no noise
    /// at `tau`.
    fn theta(&self, j: usize, tau: usize, target: f64) -> Option<f64> {
        let (mean, var) = (self.mean[tau * self.outputs + j], self.variance[tau * self.outputs + j]);
        (var > 0.0).then(|| (target - mean) / var)
    }

    /// The shifts of sample `k`'s draws for the tilt `theta` of output j at `tau >= k`.
    fn shift(&self, j: usize, tau: usize, k: usize, theta: f64, out: &mut [f64]) {
        let m = self.outputs;
        let d = tau - k;
        for (o, h) in out.iter_mut().zip(&self.response[(d * m + j) * m..(d * m + j + 1) * m]) {
            *o = theta * h;
        }
    }
}

/// How to run the splitting.
#[derive(Debug, Clone)]
pub struct SplitOptions {
    pub seed: u64,
    /// Particles per replica (at least 2).
    pub particles: usize,
    /// Replica indices to run (a shard runs some of them).
    pub replicas: Vec<u64>,
    /// Threshold scales to estimate at, ascending, > 0.
    pub levels: Vec<f64>,
    /// Stop a replica after this many iterations (its unreached levels are reported as not reached).
    pub max_iterations: usize,
}

/// What one replica found.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplicaResult {
    pub replica: u64,
    /// Per level (options order): the estimate, `None` when the iteration cap stopped the replica first.
    pub estimates: Vec<Option<f64>>,
    pub iterations: usize,
    /// Samples simulated (initial trials and branches).
    pub steps_simulated: u64,
}

struct Record<P> {
    value: f64,
    /// The next sample to simulate from `path`.
    next: usize,
    path: P,
}

struct Particle<P> {
    score: f64,
    /// Snapshots at the running maximum's records, ascending; only those above the current level.
    records: Vec<Record<P>>,
}

/// Runs `path` from sample `from` to the trial's end with running maximum `max`; the records it sets
/// go to `records`. Returns the final score and the samples simulated.
fn finish_path<M: RareEventModel>(
    model: &M,
    mut path: M::Path,
    from: usize,
    mut max: f64,
    records: &mut Vec<Record<M::Path>>,
) -> (f64, u64) {
    let steps = model.steps();
    let mut draws = vec![0.0; model.noise_draws()];
    for k in from..steps {
        let v = model.step(&mut path, k, None, &mut draws);
        if v > max {
            max = v;
            records.push(Record { value: v, next: k + 1, path: path.clone() });
        }
    }
    (max, (steps - from) as u64)
}

/// One replica of AMS (see the module docs).
pub fn splitting_replica<M: RareEventModel>(model: &M, opts: &SplitOptions, replica: u64) -> ReplicaResult {
    let n = opts.particles;
    let mut steps_simulated = 0u64;
    let mut particles: Vec<Particle<M::Path>> = (0..n as u64)
        .map(|i| {
            let mut records = Vec::new();
            let (score, cost) = finish_path(model, model.start(replica * n as u64 + i), 0, 0.0, &mut records);
            steps_simulated += cost;
            Particle { score, records }
        })
        .collect();
    let mut choose = branch_rng(opts.seed, replica, 0, BranchStream::Choice);
    let mut branches = 0u64;
    let mut estimate = 1.0f64;
    let mut estimates: Vec<Option<f64>> = vec![None; opts.levels.len()];
    let mut iterations = 0usize;
    loop {
        let z = particles.iter().map(|p| p.score).fold(f64::INFINITY, f64::min);
        // Levels reached: read off before killing (the fraction above each among the n particles).
        for (l, e) in opts.levels.iter().zip(estimates.iter_mut()) {
            if e.is_none() && z >= *l {
                let above = particles.iter().filter(|p| p.score > *l).count();
                *e = Some(estimate * above as f64 / n as f64);
            }
        }
        if estimates.iter().all(Option::is_some) || iterations >= opts.max_iterations {
            break;
        }
        let killed: Vec<usize> = (0..n).filter(|&i| particles[i].score <= z).collect();
        if killed.len() == n {
            // Every particle ties at the lowest score: none gets past it, the estimate is 0 above it.
            for e in estimates.iter_mut().filter(|e| e.is_none()) {
                *e = Some(0.0);
            }
            break;
        }
        estimate *= 1.0 - killed.len() as f64 / n as f64;
        iterations += 1;
        let survivors: Vec<usize> = (0..n).filter(|&i| particles[i].score > z).collect();
        for p in particles.iter_mut() {
            p.records.retain(|r| r.value > z);
        }
        for &i in &killed {
            let parent = &particles[survivors[choose.random_range(0..survivors.len())]];
            // Records above z are kept ascending, so the first is where the running maximum passed z.
            let at = &parent.records[0];
            let (value, next) = (at.value, at.next);
            let mut path = at.path.clone();
            branches += 1;
            model.renew_noise(&mut path, &mut |stream| branch_noise(opts.seed, replica, branches, stream));
            let mut records = vec![Record { value, next, path: path.clone() }];
            let (score, cost) = finish_path(model, path, next, value, &mut records);
            steps_simulated += cost;
            particles[i] = Particle { score, records };
        }
    }
    ReplicaResult { replica, estimates, iterations, steps_simulated }
}

/// Every replica of `opts`, in parallel; results in replica order.
pub fn splitting<M: RareEventModel>(
    model: &M,
    opts: &SplitOptions,
    progress: &(dyn Fn() + Sync),
) -> Vec<ReplicaResult> {
    opts.replicas
        .par_iter()
        .map(|&r| {
            let result = splitting_replica(model, opts, r);
            progress();
            result
        })
        .collect()
}

/// How a path of a [`SurvivalModel`] stands after a sample of its window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Survival {
    /// No alarm yet; its window goes on.
    Alive,
    /// It alarmed within its window.
    Failed,
    /// Its window ended without an alarm.
    Done,
}

/// Paths that must each get through a window of samples without an alarm: the probability that a fault
/// goes undetected until it is hazardous ([`survival_replica`]).
pub trait SurvivalModel: Sync {
    type Path: Clone;
    /// Unit `unit`'s path, or `None` where the unit has no window (a fault-free trial, a fault without a
    /// time to hazard).
    fn start(&self, unit: u64) -> Option<Self::Path>;
    /// Runs `p` to the next sample of its window (the samples before its window first) at threshold
    /// scale `level`: how it stands, and the samples simulated.
    fn advance(&self, p: &mut Self::Path, level: f64) -> (Survival, u64);
    /// New noise streams for a copy (as [`RareEventModel::renew_noise`]).
    fn renew_noise(&self, p: &mut Self::Path, rng: &mut dyn FnMut(BranchStream) -> NoiseRng);
}

/// Units a replica may look through for its particles: `SURVIVAL_UNIT_SPAN` per particle.
pub const SURVIVAL_UNIT_SPAN: u64 = 64;

/// One replica of splitting in time (a sequential Monte Carlo estimate of a survival probability, Del
/// Moral 2004, ch. 12): `particles` paths, each of its own unit, step through their windows sample by
/// sample together; after a sample where some alarmed, the estimate takes the surviving fraction and
/// the alarmed are replaced by copies of survivors (chosen at random, continued with new noise), so the
/// population stays whole however rare getting through is. The product of the fractions is unbiased
/// for the probability that one unit's path gets through its window without an alarm. `Err`: the
/// replica's span of units holds too few with a window.
pub fn survival_replica<M: SurvivalModel>(
    model: &M,
    seed: u64,
    particles: usize,
    replica: u64,
    level: f64,
) -> Result<(f64, u64), String> {
    let span = particles as u64 * SURVIVAL_UNIT_SPAN;
    let mut paths: Vec<(M::Path, Survival)> = (replica * span..(replica + 1) * span)
        .filter_map(|u| model.start(u))
        .take(particles)
        .map(|p| (p, Survival::Alive))
        .collect();
    if paths.len() < particles {
        return Err(format!(
            "{} of {span} trials have a fault with a time to hazard; {particles} particles need that many",
            paths.len()
        ));
    }
    let mut choose = branch_rng(seed, replica, 0, BranchStream::Choice);
    let (mut branches, mut steps, mut estimate) = (0u64, 0u64, 1.0f64);
    while paths.iter().any(|(_, s)| *s == Survival::Alive) {
        for (p, state) in paths.iter_mut().filter(|(_, s)| *s == Survival::Alive) {
            let (now, cost) = model.advance(p, level);
            *state = now;
            steps += cost;
        }
        let survivors: Vec<usize> = (0..particles).filter(|&i| paths[i].1 != Survival::Failed).collect();
        if survivors.len() == particles {
            continue;
        }
        if survivors.is_empty() {
            return Ok((0.0, steps));
        }
        estimate *= survivors.len() as f64 / particles as f64;
        for i in 0..particles {
            if paths[i].1 == Survival::Failed {
                let (mut copy, state) = paths[survivors[choose.random_range(0..survivors.len())]].clone();
                branches += 1;
                model.renew_noise(&mut copy, &mut |stream| branch_noise(seed, replica, branches, stream));
                paths[i] = (copy, state);
            }
        }
    }
    Ok((estimate, steps))
}

/// Sums over independent unbiased units (trials of importance sampling, replicas of splitting) at one
/// level, mergeable across chunks and shards in a fixed order.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Totals {
    pub units: u64,
    pub sum: f64,
    pub sum_squares: f64,
    /// Units with a non-zero value (alarms, for importance sampling).
    pub hits: u64,
    /// The largest unit value (the heaviest weighted alarm), for the estimate's diagnostics.
    pub largest: f64,
}

impl Totals {
    pub fn add(&mut self, y: f64) {
        self.units += 1;
        self.sum += y;
        self.sum_squares += y * y;
        self.hits += u64::from(y > 0.0);
        self.largest = self.largest.max(y);
    }

    pub fn merge(&mut self, o: &Totals) {
        self.units += o.units;
        self.sum += o.sum;
        self.sum_squares += o.sum_squares;
        self.hits += o.hits;
        self.largest = self.largest.max(o.largest);
    }
}

/// Largest relative 95 % half-width of an answer (our choice: a quarter of the estimate).
pub const ANSWER_RELATIVE_HALF_WIDTH: f64 = 0.25;
/// Largest share of the estimate one unit may carry in an answer (our choice). Beyond it the estimate
/// rests on a handful of heavy weights, and their sample variance, which the interval uses, is itself
/// unreliable (Owen, Monte Carlo theory, methods and examples, 2013, ch. 9.3).
pub const ANSWER_LARGEST_SHARE: f64 = 0.1;

/// An estimate at one level from [`Totals`].
#[derive(Debug, Clone, PartialEq)]
pub struct Combined {
    pub level: f64,
    pub units: u64,
    pub hits: u64,
    pub estimate: f64,
    /// 95 % interval: mean +- t(0.975, units - 1) s / sqrt(units), clipped to [0, 1] (NaN with one
    /// unit). With no hit, `[0, one-sided 95 % upper bound]` (see [`Combined::new`]).
    pub low: f64,
    pub high: f64,
    /// The unclipped half-width over the estimate (NaN with no hit).
    pub relative_half_width: f64,
    /// Effective units, `(sum y)^2 / sum y^2`: the hits for equal weights, fewer the more they spread.
    pub effective_units: f64,
    /// The largest unit's share of the sum.
    pub largest_share: f64,
    /// Whether the estimate is an answer: a hit, a relative half-width of at most
    /// [`ANSWER_RELATIVE_HALF_WIDTH`] and no unit carrying more than [`ANSWER_LARGEST_SHARE`].
    pub answer: bool,
}

impl Combined {
    /// `unit_max`: the largest value one unit can take (1 for a splitting replica; one over the plain
    /// share for an importance trial, whose weight `p / q` the plain component bounds). With no hit,
    /// every unit was 0, which a mean `p` makes happen with probability at most `(1 - p / unit_max)^n`:
    /// the upper bound `unit_max (1 - 0.05^(1/n))` holds with 95 % confidence (about `3 unit_max / n`).
    pub fn new(level: f64, t: &Totals, unit_max: f64) -> Self {
        let n = t.units as f64;
        let mean = t.sum / n;
        let (low, high, half) = if t.units >= 2 && t.hits == 0 {
            (0.0, (unit_max * -(0.05f64.ln() / n).exp_m1()).min(1.0), f64::NAN)
        } else if t.units >= 2 {
            let var = ((t.sum_squares - n * mean * mean) / (n - 1.0)).max(0.0);
            let q = StudentsT::new(0.0, 1.0, n - 1.0).map(|d| d.inverse_cdf(0.975)).unwrap_or(f64::NAN);
            let half = q * (var / n).sqrt();
            // A probability: the interval stops at 1 (unless a weighted mean passed it).
            ((mean - half).max(0.0), (mean + half).min(mean.max(1.0)), half)
        } else {
            (f64::NAN, f64::NAN, f64::NAN)
        };
        let relative_half_width = half / mean;
        let largest_share = if t.sum > 0.0 { t.largest / t.sum } else { f64::NAN };
        Combined {
            level,
            units: t.units,
            hits: t.hits,
            estimate: mean,
            low,
            high,
            relative_half_width,
            effective_units: if t.sum_squares > 0.0 { t.sum * t.sum / t.sum_squares } else { 0.0 },
            largest_share,
            answer: t.hits > 0
                && relative_half_width <= ANSWER_RELATIVE_HALF_WIDTH
                && largest_share <= ANSWER_LARGEST_SHARE,
        }
    }

    /// Samples plain Monte Carlo would simulate for the same 95 % half-width (`z^2 (1 - p) / (p h^2)`
    /// trials of `steps_per_trial`), from the unclipped half-width; NaN where the estimate is not an
    /// answer (a factor over a wrong estimate would flatter it).
    pub fn plain_steps_same_precision(&self, steps_per_trial: usize) -> f64 {
        let (p, h) = (self.estimate, self.relative_half_width * self.estimate);
        if self.answer && h > 0.0 { Z95 * Z95 * p * (1.0 - p) / (h * h) * steps_per_trial as f64 } else { f64::NAN }
    }
}

/// The splitting replicas' totals at level index `l` (replicas that reached it).
pub fn replica_totals(results: &[ReplicaResult], l: usize) -> Totals {
    let mut t = Totals::default();
    for e in results.iter().filter_map(|r| r.estimates[l]) {
        t.add(e);
    }
    t
}

/// The tail probabilities of the mixture's conditions: half decades from 1e-1 to 1e-24.
pub fn default_tails() -> Vec<f64> {
    (2..=48).map(|i| 10f64.powf(-(i as f64) / 2.0)).collect()
}

/// The importance mixture's plain share (a trial's weight `p / q` is then at most its inverse).
pub const PLAIN_SHARE: f64 = 0.05;

/// The importance mixture: a plain trial (weight `plain`, never adapted: it keeps every path
/// possible), and pairs (component, point), weights part-major. Two kinds:
/// - [`Mixture::uniform`]: one draw `j` or all draws (`parts` components), conditioned beyond the
///   square whose tail probability is `points[t]`;
/// - [`Mixture::tilts`], for a [Gaussian](RareEventModel::gaussian_scores) model: the draws up to the
///   chosen sample tilted so that output `j`'s signed score there has mean `+-points[t]` (parts `2 j`
///   and `2 j + 1`, [`Kernel`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Mixture {
    pub draws: usize,
    pub parts: usize,
    /// Tail probabilities ([`Mixture::uniform`]) or score levels ([`Mixture::tilts`]).
    pub points: Vec<f64>,
    pub tilted: bool,
    /// Per tail, the square it starts at, for one draw and for all draws (tails only).
    squares: [Vec<f64>; 2],
    pub plain: f64,
    pub weights: Vec<f64>,
}

impl Mixture {
    /// Every pair alike beside a 5 % plain share, for `draws` sensor draws per sample.
    pub fn uniform(tails: &[f64], draws: usize) -> Self {
        let parts = if draws > 1 { draws + 1 } else { 1 };
        let squares = [
            tails.iter().map(|&p| chi2_isf(1, p)).collect(),
            tails.iter().map(|&p| chi2_isf(draws.max(1), p)).collect(),
        ];
        Mixture::with_pairs(draws, parts, tails, false, squares)
    }

    /// Every (output, sign, level) alike beside a 5 % plain share: output `j`'s score tilted to `+-`
    /// the level at the chosen sample.
    pub fn tilts(levels: &[f64], outputs: usize) -> Self {
        Mixture::with_pairs(outputs, 2 * outputs, levels, true, [Vec::new(), Vec::new()])
    }

    fn with_pairs(draws: usize, parts: usize, points: &[f64], tilted: bool, squares: [Vec<f64>; 2]) -> Self {
        let k = parts * points.len();
        let plain = if k == 0 { 1.0 } else { PLAIN_SHARE };
        Mixture {
            draws,
            parts,
            points: points.to_vec(),
            tilted,
            squares,
            plain,
            weights: vec![(1.0 - plain) / k.max(1) as f64; k],
        }
    }

    /// Plain trials only.
    pub fn plain(draws: usize) -> Self {
        Mixture::uniform(&[], draws)
    }

    /// The pairs that carry most of the mixture, for the log.
    pub fn describe(&self) -> String {
        let mut order: Vec<usize> = (0..self.weights.len()).collect();
        order.sort_by(|a, b| self.weights[*b].total_cmp(&self.weights[*a]));
        let name = |i: usize| {
            let (part, t) = (i / self.points.len(), i % self.points.len());
            let share = 100.0 * self.weights[i];
            if self.tilted {
                let sign = if part.is_multiple_of(2) { '+' } else { '-' };
                format!("output {} towards {sign}{:.4} {share:.0} %", part / 2, self.points[t])
            } else {
                let what = if part < self.draws { format!("draw {part}") } else { "all draws".into() };
                format!("{what} beyond its {:.0e} tail {share:.0} %", self.points[t])
            }
        };
        let top: Vec<String> = order.iter().take(4).map(|&i| name(i)).collect();
        format!("importance mixture after the pilot: {}", top.join(", "))
    }

    /// One step of the variance-minimising update of a deterministic mixture (Cappé, Douc, Guillin,
    /// Marin and Robert 2008): `alpha_i <- alpha_i E[y^2 q_i / q] / E[y^2]` from a pilot's
    /// `contributions` ([`ImportanceTotals`]), over the pairs' share `1 - plain`; each weight at least
    /// a tenth of uniform, so no pair is ever left out.
    pub fn adapted(&self, contributions: &[f64]) -> Self {
        let raw: Vec<f64> = self.weights.iter().zip(contributions).map(|(a, c)| a * c).collect();
        let total: f64 = raw.iter().sum();
        if !(total > 0.0) {
            return self.clone();
        }
        let floor = 0.1 / self.weights.len() as f64;
        let raw: Vec<f64> = raw.iter().map(|c| (c / total).max(floor)).collect();
        let norm: f64 = raw.iter().sum::<f64>() / (1.0 - self.plain);
        Mixture { weights: raw.iter().map(|w| w / norm).collect(), ..self.clone() }
    }
}

/// Trial `trial` under the importance mixture `mix`: its weighted alarm indicator at each of `levels`
/// into `y`, and each pair's density share into `scratch`. [`Mixture::plain`] gives a plain trial
/// (weight 1). `shared`: the trials' common [`Kernel`] where they share one.
#[allow(clippy::too_many_arguments)]
pub fn importance_trial<M: RareEventModel>(
    model: &M,
    seed: u64,
    trial: u64,
    mix: &Mixture,
    levels: &[f64],
    y: &mut [f64],
    scratch: &mut TrialScratch,
    shared: Option<&Kernel>,
) {
    let (n, m) = (model.steps(), model.noise_draws());
    let mut choice = importance_rng(seed, trial);
    let tau = choice.random_range(0..n);
    let (pick, u): (f64, f64) = (choice.random(), choice.random());
    let mut acc = mix.plain;
    let pair = (pick >= acc).then(|| {
        mix.weights
            .iter()
            .position(|w| {
                acc += w;
                pick < acc
            })
            .unwrap_or(mix.weights.len() - 1)
    });
    let u = u.max(f64::MIN_POSITIVE);
    let mut path = model.start(trial);
    let mut draws = vec![0.0; m];
    // W_i: pair i's density over p, summed over the samples (q / p = plain + sum_i alpha_i W_i / N).
    let shares = &mut scratch.pair_share;
    shares.clear();
    shares.resize(mix.weights.len(), 0.0);
    let max = if mix.tilted {
        let own;
        let kernel = match shared {
            Some(k) => Some(k),
            None => {
                own = Kernel::of(model, trial);
                own.as_ref()
            }
        };
        tilted_trial(model, mix, kernel, &mut path, tau, pair, &mut draws, scratch)
    } else {
        tail_trial(model, mix, &mut path, tau, pair, u, &mut draws, scratch)
    };
    let shares = &mut scratch.pair_share;
    let sum: f64 = mix.plain * n as f64 + mix.weights.iter().zip(shares.iter()).map(|(a, w)| a * w).sum::<f64>();
    let ratio = n as f64 / sum;
    for (yl, l) in y.iter_mut().zip(levels) {
        *yl = if max > *l { ratio } else { 0.0 };
    }
    shares.iter_mut().for_each(|w| *w /= sum);
}

/// The samples of a trial under a [`Mixture::tilts`]: the path's largest score, and each pair's
/// `W_i = sum_k exp(theta_ik g_j(k) - theta_ik^2 var_j(k) / 2)` into `scratch.pair_share` (1 at a
/// sample where the pair cannot tilt: no kernel, no noise on the score, a diverged path).
#[allow(clippy::too_many_arguments)]
fn tilted_trial<M: RareEventModel>(
    model: &M,
    mix: &Mixture,
    kernel: Option<&Kernel>,
    path: &mut M::Path,
    tau: usize,
    pair: Option<usize>,
    draws: &mut [f64],
    scratch: &mut TrialScratch,
) -> f64 {
    let (n, m, nt) = (model.steps(), model.noise_draws(), mix.points.len());
    let sign = |part: usize| if part.is_multiple_of(2) { 1.0 } else { -1.0 };
    let tilt = pair.zip(kernel).and_then(|(i, kernel)| {
        let (part, t) = (i / nt, i % nt);
        kernel.theta(part / 2, tau, sign(part) * mix.points[t]).map(|theta| (kernel, part / 2, theta))
    });
    let (signed, shift) = (&mut scratch.signed, &mut scratch.shift);
    signed.resize(m, 0.0);
    shift.resize(m, 0.0);
    let shares = &mut scratch.pair_share;
    let mut max = 0.0f64;
    for k in 0..n {
        let condition = match tilt {
            Some((kernel, j, theta)) if k <= tau => {
                kernel.shift(j, tau, k, theta, shift);
                Some(Condition::Shift(shift))
            }
            _ => None,
        };
        max = max.max(model.step(path, k, condition.as_ref(), draws));
        let Some(kernel) = kernel.filter(|_| model.last_scores(path, signed)) else {
            shares.iter_mut().for_each(|w| *w += 1.0);
            continue;
        };
        for (j, s) in signed.iter().enumerate() {
            let noise = s - kernel.mean(k, j);
            let var = kernel.variance(k, j);
            for part in [2 * j, 2 * j + 1] {
                for (t, level) in mix.points.iter().enumerate() {
                    shares[part * nt + t] += match kernel.theta(j, k, sign(part) * level) {
                        Some(theta) => (theta * noise - 0.5 * theta * theta * var).exp(),
                        None => 1.0,
                    };
                }
            }
        }
    }
    max
}

/// The samples of a trial under a [`Mixture::uniform`]: the path's largest score, and each pair's
/// `W_i` into `scratch.pair_share`.
#[allow(clippy::too_many_arguments)]
fn tail_trial<M: RareEventModel>(
    model: &M,
    mix: &Mixture,
    path: &mut M::Path,
    tau: usize,
    pair: Option<usize>,
    u: f64,
    draws: &mut [f64],
    scratch: &mut TrialScratch,
) -> f64 {
    let (n, m, nt) = (model.steps(), model.noise_draws(), mix.points.len());
    let condition = pair.map(|i| {
        let (part, t) = (i / nt, i % nt);
        Condition::Tail { draw: (part < m).then_some(part), tail: mix.points[t], u }
    });
    let mut max = 0.0f64;
    // Per component, how many samples passed each square (a histogram over the tail grid), and how
    // many samples made no draws (diverged: weight 1 for every pair).
    let hist = &mut scratch.hist;
    hist.clear();
    hist.resize(mix.parts * (nt + 1), 0);
    let mut not_drawn = 0u64;
    for k in 0..n {
        max = max.max(model.step(path, k, condition.as_ref().filter(|_| k == tau), draws));
        if nt == 0 {
            continue;
        }
        if draws.iter().any(|z| !z.is_finite()) {
            not_drawn += 1;
            continue;
        }
        let total: f64 = draws.iter().map(|z| z * z).sum();
        for part in 0..mix.parts {
            let (sq, squares) =
                if part < m { (draws[part] * draws[part], &mix.squares[0]) } else { (total, &mix.squares[1]) };
            // Squares rise along the grid: count those below this sample's.
            hist[part * (nt + 1) + squares.partition_point(|&x| x < sq)] += 1;
        }
    }
    let shares = &mut scratch.pair_share;
    for part in 0..mix.parts {
        let mut passed = 0u64;
        for t in (0..nt).rev() {
            passed += hist[part * (nt + 1) + t + 1];
            shares[part * nt + t] = passed as f64 / mix.points[t] + not_drawn as f64;
        }
    }
    max
}

/// A trial's buffers, kept across the trials of a chunk.
#[derive(Default)]
pub struct TrialScratch {
    hist: Vec<u64>,
    signed: Vec<f64>,
    shift: Vec<f64>,
    /// After [`importance_trial`]: each pair's density over the mixture's on the trial's path.
    pub pair_share: Vec<f64>,
}

/// Trials per chunk: sums within a chunk run in trial order and chunks merge in order, so the totals
/// do not depend on the thread count.
pub const IMPORTANCE_CHUNK: u64 = 1024;

/// What importance sampling over a range of trials gives: per level the totals, and per pair
/// `sum y^2 q_i / q` over the trials (its part in the estimate's second moment, for the pilot).
#[derive(Debug, Clone, PartialEq)]
pub struct ImportanceTotals {
    pub levels: Vec<Totals>,
    pub contributions: Vec<Vec<f64>>,
}

/// Importance sampling of `model`'s fault-free trials of a study seeded `seed`, at the threshold scales
/// `levels`, reporting finished trials to `progress`: what every run of it shares.
pub struct Importance<'a, M> {
    pub model: &'a M,
    pub seed: u64,
    pub levels: &'a [f64],
    pub progress: &'a (dyn Fn(u64) + Sync),
}

impl<M: RareEventModel> Importance<'_, M> {
    /// Importance sampling over `trials` with the mixture `mix`, in chunks: each chunk's index and
    /// totals, in order. Chunk boundaries are multiples of [`IMPORTANCE_CHUNK`] from trial 0, so any split
    /// of a range at such multiples (a shard) gives the same chunks.
    pub fn chunks(&self, trials: std::ops::Range<u64>, mix: &Mixture) -> Vec<(u64, ImportanceTotals)> {
        let (model, seed, levels) = (self.model, self.seed, self.levels);
        let first_chunk = trials.start / IMPORTANCE_CHUNK;
        // Trials of one law share their kernel (a few trials' worth of probes); others measure their own.
        let shared = (mix.tilted && model.trials_alike()).then(|| Kernel::of(model, 0)).flatten();
        let last_chunk = trials.end.div_ceil(IMPORTANCE_CHUNK);
        (first_chunk..last_chunk)
            .into_par_iter()
            .map(|ch| {
                let (a, b) = ((ch * IMPORTANCE_CHUNK).max(trials.start), ((ch + 1) * IMPORTANCE_CHUNK).min(trials.end));
                let mut out = ImportanceTotals::empty(levels.len(), mix.weights.len());
                let mut y = vec![0.0; levels.len()];
                let mut scratch = TrialScratch::default();
                for t in a..b {
                    importance_trial(model, seed, t, mix, levels, &mut y, &mut scratch, shared.as_ref());
                    for (l, v) in y.iter().enumerate() {
                        out.levels[l].add(*v);
                        if *v > 0.0 {
                            for (c, share) in out.contributions[l].iter_mut().zip(&scratch.pair_share) {
                                *c += v * v * share;
                            }
                        }
                    }
                }
                (self.progress)(b - a);
                (ch, out)
            })
            .collect()
    }

    /// [`Importance::chunks`] merged in chunk order (the same totals for any thread count).
    pub fn run(&self, trials: std::ops::Range<u64>, mix: &Mixture) -> ImportanceTotals {
        let mut out = ImportanceTotals::empty(self.levels.len(), mix.weights.len());
        for (_, ch) in self.chunks(trials, mix) {
            out.merge(&ch);
        }
        out
    }

    /// The pilot ([`pilot_trials`] of `trials`, every pair alike: [`Mixture::tilts`] towards the levels
    /// for a Gaussian model, else [`Mixture::uniform`] over `tails`) and the mixture it sets: the pairs
    /// weighted by one variance-minimising step ([`Mixture::adapted`]).
    pub fn pilot(&self, trials: u64, tails: &[f64]) -> Mixture {
        let uniform = if self.model.gaussian_scores() {
            Mixture::tilts(self.levels, self.model.noise_draws())
        } else {
            Mixture::uniform(tails, self.model.noise_draws())
        };
        let first = self.run(0..pilot_trials(trials), &uniform);
        first.shares().map_or(uniform.clone(), |s| uniform.adapted(&s))
    }

    /// As `fdimc rare-event` runs it: the pilot, then the rest of `trials` with the pilot's mixture. The
    /// estimate is the rest's alone (unbiased for the weights the pilot fixed); the pilot's samples count
    /// in the cost. Returns the rest's totals and the mixture.
    pub fn adaptive(&self, trials: u64, tails: &[f64]) -> (ImportanceTotals, Mixture) {
        let mix = self.pilot(trials, tails);
        (self.run(pilot_trials(trials)..trials, &mix), mix)
    }
}

impl ImportanceTotals {
    pub fn empty(levels: usize, pairs: usize) -> Self {
        ImportanceTotals { levels: vec![Totals::default(); levels], contributions: vec![vec![0.0; pairs]; levels] }
    }

    pub fn merge(&mut self, o: &ImportanceTotals) {
        for (a, b) in self.levels.iter_mut().zip(&o.levels) {
            a.merge(b);
        }
        for (a, b) in self.contributions.iter_mut().zip(&o.contributions) {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
        }
    }

    /// The pairs' contributions, each level where at least 10 trials alarmed counting alike (each
    /// level's divided by its `sum y^2`), so the adapted mixture serves every level asked; `None`
    /// when no level has 10 alarms.
    pub fn shares(&self) -> Option<Vec<f64>> {
        let mut out = vec![0.0; self.contributions.first()?.len()];
        let mut any = false;
        for (t, c) in self.levels.iter().zip(&self.contributions) {
            if t.hits >= 10 && t.sum_squares > 0.0 {
                any = true;
                out.iter_mut().zip(c).for_each(|(o, x)| *o += x / t.sum_squares);
            }
        }
        any.then_some(out)
    }
}

/// The trials of importance sampling's pilot among `trials`: the first fifth.
pub fn pilot_trials(trials: u64) -> u64 {
    (trials / 5).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::streams::{Substream, noise_rng};
    use crate::engine::stats::intervals::normal_sf;
    use rand_distr::StandardNormal;

    /// `x_k = rho x_(k-1) + sqrt(1 - rho^2) e_k` from a stationary start: white for `rho = 0`, where
    /// P(max of N > L) = 1 - Phi(L)^N exactly.
    struct Gaussian {
        steps: usize,
        seed: u64,
        rho: f64,
    }

    impl RareEventModel for Gaussian {
        type Path = (NoiseRng, f64);
        fn steps(&self) -> usize {
            self.steps
        }
        fn start(&self, trial: u64) -> (NoiseRng, f64) {
            let mut rng = noise_rng(self.seed, trial, Substream::SensorNoise);
            let x0: f64 = rng.sample(StandardNormal);
            (rng, x0)
        }
        fn noise_draws(&self) -> usize {
            1
        }
        fn step(&self, path: &mut (NoiseRng, f64), k: usize, condition: Option<&Condition>, draws: &mut [f64]) -> f64 {
            draws[0] = path.0.sample::<f64, _>(StandardNormal);
            if let Some(c) = condition {
                c.apply(draws);
            }
            let e = draws[0];
            path.1 = if k == 0 && self.rho != 0.0 {
                path.1
            } else {
                self.rho * path.1 + (1.0 - self.rho * self.rho).sqrt() * e
            };
            path.1
        }
        fn renew_noise(&self, path: &mut (NoiseRng, f64), rng: &mut dyn FnMut(BranchStream) -> NoiseRng) {
            path.0 = rng(BranchStream::Sensor);
        }
    }

    /// White outputs of unequal thresholds: a sample alarms at scale `L` when some `|z_j| > L c_j`, so
    /// P(alarm in `steps` samples) = 1 - prod_j (1 - 2 Q(L c_j))^steps exactly.
    struct WhiteOutputs {
        steps: usize,
        seed: u64,
        scales: Vec<f64>,
        /// Whether importance sampling may tilt the draws ([`Mixture::tilts`]) or only condition their
        /// squares ([`Mixture::uniform`]).
        gaussian: bool,
    }

    impl WhiteOutputs {
        fn exact(&self, level: f64) -> f64 {
            let per_sample: f64 = self.scales.iter().map(|c| (-2.0 * normal_sf(level * c)).ln_1p()).sum();
            -(self.steps as f64 * per_sample).exp_m1()
        }

        /// The scale whose exact probability is `p` (bisection: the probability falls with the scale).
        fn level_for(&self, p: f64) -> f64 {
            let (mut lo, mut hi) = (0.0, 40.0);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if self.exact(mid) > p { lo = mid } else { hi = mid }
            }
            0.5 * (lo + hi)
        }
    }

    impl RareEventModel for WhiteOutputs {
        /// The noise, and the last sample's signed scores.
        type Path = (NoiseRng, Vec<f64>);
        fn steps(&self) -> usize {
            self.steps
        }
        fn start(&self, trial: u64) -> Self::Path {
            (noise_rng(self.seed, trial, Substream::SensorNoise), vec![0.0; self.scales.len()])
        }
        fn noise_draws(&self) -> usize {
            self.scales.len()
        }
        fn step(&self, path: &mut Self::Path, _k: usize, condition: Option<&Condition>, draws: &mut [f64]) -> f64 {
            draws.iter_mut().for_each(|z| *z = path.0.sample::<f64, _>(StandardNormal));
            if let Some(c) = condition {
                c.apply(draws);
            }
            path.1.iter_mut().zip(draws.iter().zip(&self.scales)).for_each(|(s, (z, c))| *s = z / c);
            path.1.iter().map(|s| s.abs()).fold(0.0, f64::max)
        }
        fn renew_noise(&self, path: &mut Self::Path, rng: &mut dyn FnMut(BranchStream) -> NoiseRng) {
            path.0 = rng(BranchStream::Sensor);
        }
        fn gaussian_scores(&self) -> bool {
            self.gaussian
        }
        fn trials_alike(&self) -> bool {
            true
        }
        fn last_scores(&self, path: &Self::Path, signed: &mut [f64]) -> bool {
            signed.copy_from_slice(&path.1);
            true
        }
    }

    /// Issue 49, item 1: over `seeds` fixed seeds, how many 95 % importance-sampling intervals (20,000
    /// trials, the first fifth the pilot's) are answers that cover the exact probability, at 1e-5 and
    /// 1e-8, on three white outputs whose thresholds split the probability about 30/30/40 (the mixture
    /// must not leave an output out); and the widest answer's relative half-width.
    fn importance_coverage(seeds: u64) -> ([u64; 2], f64) {
        let mut covered = [0u64; 2];
        let mut widest = 0.0f64;
        for seed in 0..seeds {
            let model = WhiteOutputs { steps: 20, seed: 1000 + seed, scales: vec![1.0, 1.0, 0.99], gaussian: true };
            let targets = [1e-5, 1e-8];
            let levels: Vec<f64> = targets.iter().map(|&p| model.level_for(p)).collect();
            let run = Importance { model: &model, seed: model.seed, levels: &levels, progress: &|_| {} };
            let (totals, _) = run.adaptive(20_000, &default_tails());
            for (l, &p) in targets.iter().enumerate() {
                let e = Combined::new(levels[l], &totals.levels[l], 1.0 / PLAIN_SHARE);
                covered[l] += u64::from(e.answer && e.low <= p && p <= e.high);
                if e.answer {
                    widest = widest.max(e.relative_half_width);
                }
            }
        }
        (covered, widest)
    }

    /// The CI's share of the coverage check: the first 40 seeds, at least 34 answers that cover at each
    /// level (the 200 seeds of `scripts/rare_event_coverage.py` need 180: 185 and 195 on 2026-12-04),
    /// every answer within +-8 % (about +-5 % seen), so neither refusing nor widening passes.
    #[test]
    fn importance_intervals_cover_on_unequal_outputs() {
        // FDIMC_COVERAGE_SEEDS raises the seeds (scripts/rare_event_coverage.py), never below the CI's 40.
        let seeds =
            std::env::var("FDIMC_COVERAGE_SEEDS").ok().and_then(|s| s.parse().ok()).map_or(40, |n: u64| n.max(40));
        let (covered, widest) = importance_coverage(seeds);
        let needed = if seeds == 40 { 34 } else { seeds * 9 / 10 };
        println!(
            "importance sampling, {seeds} seeds: covered {covered:?} (1e-5, 1e-8); needed {needed}; widest answer \
             +-{:.1} %",
            100.0 * widest
        );
        assert!(covered.iter().all(|&c| c >= needed), "covered {covered:?} of {seeds}");
        assert!(widest <= 0.08, "an answer +-{widest}");
    }

    fn white_exact(level: f64, steps: usize) -> f64 {
        -(steps as f64 * (-normal_sf(level)).ln_1p()).exp_m1()
    }

    fn split<M: RareEventModel>(
        model: &M,
        seed: u64,
        levels: &[f64],
        particles: usize,
        replicas: u64,
    ) -> Vec<ReplicaResult> {
        let opts = SplitOptions {
            seed,
            particles,
            replicas: (0..replicas).collect(),
            levels: levels.to_vec(),
            max_iterations: 100_000,
        };
        let results = splitting(model, &opts, &|| {});
        // A replica's numbers depend only on (seed, replica), not on what ran beside it.
        assert_eq!(splitting_replica(model, &opts, 3), results[3]);
        results
    }

    #[test]
    fn importance_sampling_recovers_white_noise_maxima_five_decades_down() {
        let model = Gaussian { steps: 100, seed: 7, rho: 0.0 };
        let levels = [3.0, 4.5, 5.5];
        let run = Importance { model: &model, seed: 7, levels: &levels, progress: &|_| {} };
        let (totals, mix) = run.adaptive(20_000, &default_tails());
        for (l, &level) in levels.iter().enumerate() {
            let e = Combined::new(level, &totals.levels[l], 1.0 / PLAIN_SHARE);
            let truth = white_exact(level, 100);
            assert!(e.low <= truth && truth <= e.high, "level {level}: {truth:e} outside {e:?}");
            assert!((e.estimate / truth - 1.0).abs() < 0.2, "level {level}: {e:?} vs {truth:e}");
        }
        // 5.5 sigma in 100 samples, 1.9e-6, to about +-10 % from 20,000 trials (a fifth of them the
        // pilot's); plain trials would need about 2e8 for that.
        let e = Combined::new(5.5, &totals.levels[2], 1.0 / PLAIN_SHARE);
        assert!((1.8e-6..2.0e-6).contains(&white_exact(5.5, 100)));
        assert!(e.relative_half_width < 0.15, "{e:?}");
        assert!(e.plain_steps_same_precision(100) > 1e3 * 20_000.0 * 100.0, "{e:?}");
        // The pilot moves the weight to the tails the levels need (one sample past 4.5 sigma: 3.4e-6,
        // past 5.5: 1.9e-8): 1e-8 to 1e-4 hold 9 of the 47 tails, 18 % of the weight before it.
        let used: f64 =
            mix.weights.iter().zip(&mix.points).filter(|(_, p)| (1e-8..=1e-4).contains(*p)).map(|(w, _)| w).sum();
        assert!(used > 0.5, "{mix:?}");
        // Thread count and chunking do not change the totals: a split at a chunk boundary merges back.
        let mut merged = run.run(4_000..5_120, &mix);
        merged.merge(&run.run(5_120..20_000, &mix));
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let single = one.install(|| run.run(4_000..20_000, &mix));
        assert_eq!(totals, single);
        assert_eq!(totals.levels[2].units, merged.levels[2].units);
        assert_eq!(totals.levels[2].hits, merged.levels[2].hits);
        assert!((totals.levels[2].sum / merged.levels[2].sum - 1.0).abs() < 1e-12);
    }

    #[test]
    fn splitting_degenerates_on_a_statistic_without_memory() {
        // Unbiased at a level most trials pass, but a copy at a level is no closer to a higher one:
        // copies tie and die together, and most replicas end at 0 two decades further down.
        let model = Gaussian { steps: 100, seed: 7, rho: 0.0 };
        let results = split(&model, model.seed, &[3.0, 4.5], 100, 30);
        let e = Combined::new(3.0, &replica_totals(&results, 0), 1.0);
        let truth = white_exact(3.0, 100);
        assert!(e.low <= truth && truth <= e.high, "{truth} outside {e:?}");
        let zeros = results.iter().filter(|r| r.estimates[1] == Some(0.0)).count();
        assert!(zeros >= 20, "{zeros} of 30 replicas at 0");
    }

    #[test]
    fn splitting_matches_brute_force_where_the_statistic_has_memory() {
        // rho = 0.95: a path high now stays high for about 20 samples, so a copy taken part way up is
        // closer to the alarm. Plain trials at 3.5 (about 3e-3 over 200 samples) and at 4.5 (about
        // 1e-4, from 400,000 trials), against 40 replicas of 100 particles.
        let model = Gaussian { steps: 200, seed: 11, rho: 0.95 };
        let levels = [3.5, 4.5];
        let mut plain = [Totals::default(); 2];
        let mut y = [0.0; 2];
        let mut scratch = TrialScratch::default();
        for t in 0..400_000 {
            importance_trial(&model, 11, t, &Mixture::plain(1), &levels, &mut y, &mut scratch, None);
            plain[0].add(y[0]);
            plain[1].add(y[1]);
        }
        let results = split(&model, model.seed, &levels, 100, 40);
        let cost = results.iter().map(|r| r.steps_simulated).sum::<u64>() as f64;
        for l in 0..2 {
            let brute = Combined::new(levels[l], &plain[l], 1.0);
            let ams = Combined::new(levels[l], &replica_totals(&results, l), 1.0);
            assert!(ams.low <= brute.high && brute.low <= ams.high, "AMS {ams:?} vs brute force {brute:?}");
            // The splitting's samples buy a narrower interval than the brute force's 80 million.
            assert!(ams.relative_half_width.powi(2) * cost < brute.relative_half_width.powi(2) * 8e7, "{ams:?} {cost}");
        }
    }

    /// A simple random walk, `S_k = S_(k-1) + sign(z_k)`, scored by `S_k`: the law of its running
    /// maximum is exact by dynamic programming ([`walk_exact`]).
    struct LatticeWalk {
        steps: usize,
        seed: u64,
    }

    impl RareEventModel for LatticeWalk {
        type Path = (NoiseRng, f64);
        fn steps(&self) -> usize {
            self.steps
        }
        fn start(&self, trial: u64) -> (NoiseRng, f64) {
            (noise_rng(self.seed, trial, Substream::SensorNoise), 0.0)
        }
        fn noise_draws(&self) -> usize {
            1
        }
        fn step(&self, path: &mut (NoiseRng, f64), _k: usize, condition: Option<&Condition>, draws: &mut [f64]) -> f64 {
            draws[0] = path.0.sample::<f64, _>(StandardNormal);
            if let Some(c) = condition {
                c.apply(draws);
            }
            path.1 += draws[0].signum();
            path.1
        }
        fn renew_noise(&self, path: &mut (NoiseRng, f64), rng: &mut dyn FnMut(BranchStream) -> NoiseRng) {
            path.0 = rng(BranchStream::Sensor);
        }
    }

    /// P(max_(k <= steps) S_k >= a) for the simple random walk from 0: the mass below `a`, stepped
    /// `steps` times, the mass that reaches `a` absorbed.
    fn walk_exact(steps: usize, a: i64) -> f64 {
        let offset = steps as i64;
        let mut mass = vec![0.0f64; 2 * steps + 2];
        mass[offset as usize] = 1.0;
        let mut absorbed = 0.0;
        for _ in 0..steps {
            let mut next = vec![0.0f64; mass.len()];
            for (i, m) in mass.iter().enumerate().filter(|(_, m)| **m > 0.0) {
                for to in [i - 1, i + 1] {
                    if to as i64 - offset >= a { absorbed += 0.5 * m } else { next[to] += 0.5 * m }
                }
            }
            mass = next;
        }
        absorbed
    }

    /// Issue 49, item 4: splitting at a rare level against an exact answer, not against brute force.
    /// The walk of 200 steps reaches 60 with probability 2.01931e-5 and 70 with 6.11619e-7 (dynamic
    /// programming; the reflection principle, 2 P(S_200 >= a) - P(S_200 = a), gives the same, and so
    /// does Python's `math.comb`). Ties are everywhere on a lattice, which the generalised splitting must
    /// handle without bias. Eight seeds of 256 replicas of 100 particles: at least 7 of the 8 intervals
    /// cover each exact value, and the eight seeds together are within 6 % of it (their pooled 95 %
    /// half-width is about 4 %; a splitting that forgot the ties' share `K / n`, or counted a particle at
    /// the level as past it, is off by tens of percent). Measured: seed 5 is the one whose intervals
    /// miss, 18 % low at 60 with every other level of its replicas low too (they share their paths).
    #[test]
    fn splitting_meets_the_exact_law_of_a_lattice_walk_s_maximum() {
        let exact = [walk_exact(200, 60), walk_exact(200, 70)];
        assert!((exact[0] / 2.01931e-5 - 1.0).abs() < 1e-5 && (exact[1] / 6.11619e-7 - 1.0).abs() < 1e-5, "{exact:?}");
        // Reflection: P(M >= a) = 2 P(S >= a) - P(S = a), S = 2 B - 200 with B binomial(200, 1/2).
        let ln_choose = |k: u64| -> f64 { (1..=k).map(|i| ((200 - k + i) as f64 / i as f64).ln()).sum() };
        let binom = |k: u64| (ln_choose(k) - 200.0 * 2f64.ln()).exp();
        for (a, e) in [(60u64, exact[0]), (70, exact[1])] {
            let k = 100 + a / 2;
            let reflected = 2.0 * (k..=200).map(binom).sum::<f64>() - binom(k);
            assert!((reflected / e - 1.0).abs() < 1e-9, "a = {a}: {reflected:e} vs {e:e}");
        }
        // Scores pass a level strictly: 59.5 and 69.5 are "S reaches 60" and "S reaches 70".
        let levels = [59.5, 69.5];
        let (mut covered, mut pooled) = ([0; 2], [Totals::default(); 2]);
        for seed in 5..13 {
            let model = LatticeWalk { steps: 200, seed };
            let results = split(&model, seed, &levels, 100, 256);
            for l in 0..2 {
                let t = replica_totals(&results, l);
                let e = Combined::new(levels[l], &t, 1.0);
                covered[l] += u32::from(e.low <= exact[l] && exact[l] <= e.high);
                pooled[l].merge(&t);
            }
        }
        for l in 0..2 {
            let e = Combined::new(levels[l], &pooled[l], 1.0);
            assert!(covered[l] >= 7, "level {}: {} of 8 cover", levels[l], covered[l]);
            assert!(
                (e.estimate / exact[l] - 1.0).abs() < 0.06 && e.answer,
                "level {}: {e:?} vs {:e}",
                levels[l],
                exact[l]
            );
        }
    }

    /// Issue 49, item 2: no interval claims a certainty it does not have. Numbers by hand: with no hit
    /// in 1,000 units, the one-sided 95 % bound `unit_max (1 - 0.05^(1/1000))` = 2.991250e-3 per unit of
    /// `unit_max`; with two hits of 1 in 1,000 units, s^2 = (2 - 1000 x 0.002^2) / 999, t(0.975, 999) =
    /// 1.962341 (statistical tables), half-width 2.77388e-3: the relative half-width 1.3869 (the clipped
    /// interval [0, 4.774e-3] would say 1.19); a unit carrying 11 % of the sum is not an answer, however
    /// narrow its interval.
    #[test]
    fn zero_hits_give_an_upper_bound_and_half_widths_are_unclipped() {
        let mut none = Totals::default();
        (0..1000).for_each(|_| none.add(0.0));
        for unit_max in [1.0, 20.0] {
            let e = Combined::new(2.0, &none, unit_max);
            assert_eq!((e.estimate, e.low, e.answer), (0.0, 0.0, false));
            assert!((e.high / (unit_max * 2.991250e-3) - 1.0).abs() < 1e-5, "{e:?}");
            assert!(e.relative_half_width.is_nan() && e.plain_steps_same_precision(100).is_nan());
        }
        let mut two = Totals::default();
        (0..998).for_each(|_| two.add(0.0));
        two.add(1.0);
        two.add(1.0);
        let e = Combined::new(1.0, &two, 1.0);
        assert!((e.relative_half_width / 1.3869 - 1.0).abs() < 1e-4, "{e:?}");
        assert_eq!((e.low, e.effective_units, e.largest_share, e.answer), (0.0, 2.0, 0.5, false));
        assert!(e.plain_steps_same_precision(100).is_nan(), "no factor for a non-answer");
        // 400 equal hits: an answer; one heavy weight among them makes it none, however narrow.
        let mut many = Totals::default();
        (0..9600).for_each(|_| many.add(0.0));
        (0..400).for_each(|_| many.add(1e-3));
        let e = Combined::new(1.0, &many, 20.0);
        assert!(e.answer && (e.effective_units - 400.0).abs() < 1e-6 && e.relative_half_width < 0.1, "{e:?}");
        assert!(e.plain_steps_same_precision(1) > 0.0);
        // 100,000 hits of 1e-6 and one of 0.01236: +-22 %, yet one trial carries 11 % of the estimate.
        let mut heavy = Totals::default();
        (0..99_999).for_each(|_| heavy.add(0.0));
        (0..100_000).for_each(|_| heavy.add(1e-6));
        heavy.add(0.01236);
        let e = Combined::new(1.0, &heavy, 20.0);
        assert!(e.relative_half_width < 0.22 && (e.largest_share - 0.11).abs() < 1e-4 && !e.answer, "{e:?}");
    }

    #[test]
    fn a_statistic_that_never_moves_gives_zero_not_a_loop() {
        struct Flat;
        impl RareEventModel for Flat {
            type Path = ();
            fn steps(&self) -> usize {
                10
            }
            fn start(&self, _: u64) {}
            fn noise_draws(&self) -> usize {
                0
            }
            fn step(&self, _: &mut (), _: usize, _: Option<&Condition>, _: &mut [f64]) -> f64 {
                0.5
            }
            fn renew_noise(&self, _: &mut (), _: &mut dyn FnMut(BranchStream) -> NoiseRng) {}
        }
        let opts =
            SplitOptions { seed: 1, particles: 10, replicas: vec![0], levels: vec![0.4, 1.0], max_iterations: 100 };
        let r = splitting_replica(&Flat, &opts, 0);
        assert_eq!(r.estimates, vec![Some(1.0), Some(0.0)]);
        assert_eq!(r.iterations, 0);
    }
}
