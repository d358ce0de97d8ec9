//! False alarms without simulating: with the model exact, white Gaussian noise and the seed's
//! `|residual_j| > threshold_j` test, a fault-free residual is a Gaussian process whose law follows from
//! the closed loop. From `e(0) = 0` (the filter starts at the plant's state):
//!
//! ```text
//! e(k + 1) = Phi e(k) - Kd v(k) + w(k),   gamma(k) = C e(k) + v(k),   Phi = Ad - Kd C
//! P(k + 1) = Phi P(k) Phi' + Kd R Kd' + W,  Var gamma(k) = C P(k) C' + R
//! Cov(gamma(l), gamma(k)) = C Phi^(l-k) P(k) C' - C Phi^(l-k-1) Kd R      (l > k)
//! ```
//!
//! Each sample's exceedance probability per output is exact (`2 Phi(-T_j / sigma_j(k))`). The
//! probability of at least one alarm over the trial is bounded from both sides by inequalities that
//! need only one- and two-sample probabilities:
//! - above by Sidak's (`1 - prod(1 - p_i)`: a centred Gaussian vector lies in a symmetric slab set at
//!   least as often as if its components were independent) and by Hunter's (`S1 - sum of P(A_i A_j)`
//!   over the edges of a tree; here each output's consecutive samples), whichever is smaller;
//! - below by the larger of de Caen's (`sum_i p_i^2 / sum_j P(A_i A_j)`) over every `L`-th sample (a
//!   sub-family: its union is inside the trial's; `L` chosen among three spacings) and Bonferroni's
//!   `S1 - S2` (nearby pairs exact, farther ones bounded through their largest correlation).
//!
//! Two-sample probabilities `P(|X| > a, |Y| > b)` of a standard bivariate normal pair are integrated
//! in one dimension by adaptive Simpson quadrature, to a relative accuracy of about 1e-9.
//!
//! Where alarms cluster the bounds part; the probability itself then comes from conditional Monte
//! Carlo on the same law (Adler, Blanchet and Liu 2012): with `S = sum_i P(A_i)` over the events
//! `A_i = {|gamma_j(k)| > T_j}`, draw an event with probability `P(A_i) / S`, the residual conditioned
//! on it (its value from the conditioned tail, the rest of the trial by Gaussian conditioning on it:
//! an unconditioned trial plus the covariance column times the difference), and count the events
//! that occur, `N >= 1`. `S / N` is unbiased for `P(any alarm)` and lies in `[S / (samples outputs), S]`:
//! its relative error stays bounded however rare the alarm, so a few thousand draws give it to a few
//! percent at 1e-5 or 1e-12 alike (exactly `S`, interval included, where no draw sees a second event).
#![allow(non_snake_case)]

use nalgebra::{DMatrix, DVector};

use super::filter::DetectionFilter;
use super::study::LtiStudy;
use crate::engine::results::thresholds::{HourConversion, HourLaw};
use crate::engine::stats::intervals::normal_sf;

/// The bounds on one detector's false-alarm probability over a trial.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalyticFalseAlarms {
    pub samples: usize,
    /// The fault-free residual's standard deviation per output at the trial's last sample (settled
    /// from `e(0) = 0`): the scale a first threshold is a multiple of.
    pub residual_sd_end: Vec<f64>,
    /// The largest single sample's exceedance probability over its outputs (Sidak's bound).
    pub largest_sample: f64,
    /// The sum of every sample's and output's exceedance probability (the union bound).
    pub sum: f64,
    pub sidak_upper: f64,
    pub hunter_upper: f64,
    /// The larger lower bound: Bonferroni's (`spacing` 0) or de Caen's over every `spacing`-th sample.
    pub lower: f64,
    pub spacing: usize,
    /// Conditional Monte Carlo: the estimate, its 95 % interval, and the draws.
    pub conditional: f64,
    pub conditional_lo: f64,
    pub conditional_hi: f64,
    /// Its one-sided 95 % upper bound.
    pub conditional_upper_95: f64,
    pub conditional_draws: usize,
    /// What a conversion of the trial's figure to one per flight hour misses (`None`: not computed,
    /// the trial's sample time not given).
    pub hour: Option<HourConversion>,
}

impl AnalyticFalseAlarms {
    pub fn upper(&self) -> f64 {
        self.sidak_upper.min(self.hunter_upper)
    }

    /// Which inequality gave the lower bound.
    pub fn lower_from(&self) -> String {
        match self.spacing {
            0 => "Bonferroni S1 - S2".into(),
            l => format!("de Caen over every {l}th sample"),
        }
    }
}

/// The bounds for a designed detector of `study` at `thresholds` (one per output), or why the deck is
/// outside what they assume. `draws_seed` seeds the conditional Monte Carlo draws ([`CONDITIONAL_SEED`]
/// where a figure must not move with the deck's seed).
pub fn for_detector(
    study: &LtiStudy,
    filter: &DetectionFilter,
    thresholds: &[f64],
    draws_seed: u64,
) -> Result<AnalyticFalseAlarms, String> {
    let sensor_sigma = exact_law_sensor_sigma(study, filter)?;
    let (Ad, Kd, C) = (&filter.model.Ad, &filter.discrete.K, &filter.model.C);
    let (steps, dt_s, process) = (study.header.steps, study.header.dt_s, &study.process_sigma_per_step);
    let mut f = analytic_false_alarms(Ad, Kd, C, &sensor_sigma, process, thresholds, steps, draws_seed);
    f.hour = Some(hour_conversion(Ad, Kd, C, &sensor_sigma, process, thresholds, steps, dt_s));
    Ok(f)
}

/// `Method::hour_laws` of detection-filter decks: per detector of the deck in `text` (read from
/// `path`), its [`HourConversion`] at any thresholds (one per statistic, named `statistics`: the deck's
/// outputs in order), where the residual's exact law is the trials' (a linear truth, the model exact,
/// white Gaussian noise, the |residual| test, a stable filter). A deck that flies an FMU (truth,
/// controller or detector) is only parsed, never loaded: loading runs the FMU in this process (its
/// linearisation, its checks), where a user's FMU may crash, and its trials' law is not the linear
/// model's anyway.
pub fn hour_laws(text: &str, path: &std::path::Path, statistics: &[String]) -> Vec<Option<HourLaw>> {
    use crate::engine::scenario::deck::FromDeck;
    let Ok(deck) = crate::engine::scenario::deck::parse_deck::<super::deck::Deck>(text, path) else {
        return Vec::new();
    };
    if deck.flies_fmu() {
        return Vec::new();
    }
    let Ok(study) = LtiStudy::from_toml(text, path) else { return Vec::new() };
    (0..study.detectors.len()).map(|d| hour_law(&study, d, statistics)).collect()
}

fn hour_law(study: &LtiStudy, detector: usize, statistics: &[String]) -> Option<HourLaw> {
    if study.truth.is_some() || statistics != study.plant.output_names.as_slice() {
        return None;
    }
    let filter = study.detectors.get(detector)?.params.design(&study.design_plant, study.header.dt_s).ok()?;
    let sensor_sigma = exact_law_sensor_sigma(study, &filter).ok()?;
    let (Ad, Kd, C) = (&filter.model.Ad, &filter.discrete.K, &filter.model.C);
    let (steps, dt_s) = (study.header.steps, study.header.dt_s);
    let spread = HourSpread::new(Ad, Kd, C, &sensor_sigma, &study.process_sigma_per_step, steps, dt_s)?;
    Some(Box::new(move |thresholds: &[f64]| spread.conversion(thresholds)))
}

/// The sensor sigmas of the residual's exact law for `filter` on `study`, or why the deck is outside
/// what it assumes.
pub fn exact_law_sensor_sigma(study: &LtiStudy, filter: &DetectionFilter) -> Result<DVector<f64>, String> {
    use crate::engine::scenario::deck::Factor;
    let (p, d) = (&study.plant, &study.design_plant);
    if p.A != d.A || p.B != d.B || p.C != d.C || p.D != d.D {
        return Err("the detector's design plant differs from the simulated plant".into());
    }
    if !study.monte_carlo.parameter_errors.is_empty() {
        return Err("the deck draws parameter errors (the residual is then not the model's)".into());
    }
    if study.sensor_law.iter().any(|l| *l != crate::engine::scenario::noise::SensorLaw::Gaussian) {
        return Err("the sensor noise is heavy-tailed (noise.sensor_law; the bounds are for Gaussian noise)".into());
    }
    let scale = match study.monte_carlo.common.noise_scale {
        Factor::Fixed(s) => s,
        _ => return Err("the noise scale varies over the trials (computed for one noise level)".into()),
    };
    if filter.decision.on_lanes() != Some(super::decision::LaneStatistic::Absolute) {
        return Err(format!("the test is {} (computed for the |residual| test)", filter.decision.describe()));
    }
    Ok(&study.sensor_sigma * scale)
}

/// The error's closed loop `Phi = Ad - Kd C`, the sensor noise's covariance `R` and the error's drive
/// per step `Kd R Kd' + W` (`W` the process noise's), which every computation of the residual's law
/// starts from.
fn closed_loop(
    Ad: &DMatrix<f64>,
    Kd: &DMatrix<f64>,
    C: &DMatrix<f64>,
    sensor_sigma: &DVector<f64>,
    process_sigma_per_step: &DVector<f64>,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let R = DMatrix::from_diagonal(&sensor_sigma.map(|s| s * s));
    let W = DMatrix::from_diagonal(&process_sigma_per_step.map(|s| s * s));
    let drive = Kd * &R * Kd.transpose() + W;
    (Ad - Kd * C, R, drive)
}

/// The extremal index against the conversion (see [`HourConversion`]: `-ln` of Sidak's bound on no
/// alarm in an hour flown from `e(0) = 0`, over the hour's trials') for trials of `trial_samples` samples of `dt_s` seconds; the
/// arguments as [`analytic_false_alarms`]'s.
#[allow(clippy::too_many_arguments)]
pub fn hour_conversion(
    Ad: &DMatrix<f64>,
    Kd: &DMatrix<f64>,
    C: &DMatrix<f64>,
    sensor_sigma: &DVector<f64>,
    process_sigma_per_step: &DVector<f64>,
    thresholds: &[f64],
    trial_samples: usize,
    dt_s: f64,
) -> HourConversion {
    match HourSpread::new(Ad, Kd, C, sensor_sigma, process_sigma_per_step, trial_samples, dt_s) {
        Some(spread) => spread.conversion(thresholds),
        // An unstable or undamped filter never settles: no hour to compare.
        None => HourConversion { ratio: f64::NAN, slowest_time_constant_s: f64::INFINITY, trial_upper: f64::NAN },
    }
}

/// The fault-free residual's standard deviation per output over an hour flown from `e(0) = 0`, sample
/// by sample until it settles (and at least over a trial), then settled: what [`HourConversion`]
/// needs at any thresholds, computed once.
pub struct HourSpread {
    ramp: Vec<Vec<f64>>,
    settled: Vec<f64>,
    hour_samples: usize,
    trial_samples: usize,
    slowest_time_constant_s: f64,
}

impl HourSpread {
    /// `None` for an unstable or undamped filter, which never settles.
    pub fn new(
        Ad: &DMatrix<f64>,
        Kd: &DMatrix<f64>,
        C: &DMatrix<f64>,
        sensor_sigma: &DVector<f64>,
        process_sigma_per_step: &DVector<f64>,
        trial_samples: usize,
        dt_s: f64,
    ) -> Option<Self> {
        Self::reaching(Ad, Kd, C, sensor_sigma, process_sigma_per_step, trial_samples, dt_s, 0)
    }

    /// As [`HourSpread::new`], the ramp followed for at least `reach_samples` samples when it has not
    /// settled (a flight longer than an hour).
    #[allow(clippy::too_many_arguments)]
    pub fn reaching(
        Ad: &DMatrix<f64>,
        Kd: &DMatrix<f64>,
        C: &DMatrix<f64>,
        sensor_sigma: &DVector<f64>,
        process_sigma_per_step: &DVector<f64>,
        trial_samples: usize,
        dt_s: f64,
        reach_samples: usize,
    ) -> Option<Self> {
        let (Phi, R, drive) = closed_loop(Ad, Kd, C, sensor_sigma, process_sigma_per_step);
        let largest = Phi.clone().complex_eigenvalues().iter().map(|l| l.norm()).fold(0.0, f64::max);
        if largest >= 1.0 {
            return None;
        }
        let hour_samples = (3600.0 / dt_s).round() as usize;
        let sd = |p: &DMatrix<f64>| -> Vec<f64> {
            (C * p * C.transpose() + &R).diagonal().iter().map(|v| v.sqrt()).collect()
        };
        let mut ramp = Vec::new();
        let mut p_k = DMatrix::zeros(Ad.nrows(), Ad.nrows());
        for k in 0..hour_samples.max(reach_samples) {
            ramp.push(sd(&p_k));
            let next = &Phi * &p_k * Phi.transpose() + &drive;
            // Settled (past the trial): every later sample is the same.
            let settled = (&next - &p_k).amax() <= 1e-15 * next.amax();
            p_k = next;
            if settled && k + 1 >= trial_samples {
                break;
            }
        }
        Some(Self {
            settled: sd(&p_k),
            ramp,
            hour_samples,
            trial_samples,
            slowest_time_constant_s: -dt_s / largest.ln(),
        })
    }

    /// `ln` of Sidak's bound on no alarm of output `j` at `threshold` over the first `samples` samples
    /// (the filter started on the truth): `sum_k ln(1 - 2 Q(threshold / sigma_j(k)))`.
    pub fn log_no_alarm(&self, j: usize, threshold: f64, samples: usize) -> f64 {
        let term = |sd: f64| (-2.0 * normal_sf(threshold / sd)).ln_1p();
        let ramp = samples.min(self.ramp.len());
        self.ramp[..ramp].iter().map(|sd| term(sd[j])).sum::<f64>() + term(self.settled[j]) * (samples - ramp) as f64
    }

    /// Each output's settled standard deviation.
    pub fn settled(&self) -> &[f64] {
        &self.settled
    }

    /// The extremal index against the conversion at `thresholds` (one per output), by Sidak's bound.
    pub fn conversion(&self, thresholds: &[f64]) -> HourConversion {
        // ln P(no alarm at a sample) by Sidak: summed, the log of the bound's complement.
        let log_none =
            |sd: &[f64]| -> f64 { sd.iter().zip(thresholds).map(|(s, t)| (-2.0 * normal_sf(t / s)).ln_1p()).sum() };
        let trial: f64 = self.ramp[..self.trial_samples].iter().map(|sd| log_none(sd)).sum();
        let ramp: f64 = self.ramp.iter().take(self.hour_samples).map(|sd| log_none(sd)).sum();
        let hour = ramp + log_none(&self.settled) * self.hour_samples.saturating_sub(self.ramp.len()) as f64;
        let trials_per_hour = self.hour_samples as f64 / self.trial_samples as f64;
        let ratio = if trial < 0.0 { hour / (trials_per_hour * trial) } else { f64::NAN };
        HourConversion { ratio, slowest_time_constant_s: self.slowest_time_constant_s, trial_upper: -trial.exp_m1() }
    }
}

/// The fault-free residual's law sample by sample, the filter started on the truth: per sample `P(k)
/// C'` (every covariance of the residual needs only it) and each output's standard deviation, from
/// `P(k+1) = (Ad - Kd C) P(k) (Ad - Kd C)' + Kd R Kd' + W`, `P(0) = 0`, `Var gamma(k) = C P(k) C' + R`.
pub fn residual_law(
    Ad: &DMatrix<f64>,
    Kd: &DMatrix<f64>,
    C: &DMatrix<f64>,
    sensor_sigma: &DVector<f64>,
    process_sigma_per_step: &DVector<f64>,
    samples: usize,
) -> (Vec<DMatrix<f64>>, Vec<Vec<f64>>) {
    let n = Ad.nrows();
    let (Phi, R, drive) = closed_loop(Ad, Kd, C, sensor_sigma, process_sigma_per_step);
    let (mut H, mut sd): (Vec<DMatrix<f64>>, Vec<Vec<f64>>) =
        (Vec::with_capacity(samples), Vec::with_capacity(samples));
    let mut p_k = DMatrix::zeros(n, n);
    for _ in 0..samples {
        let h: DMatrix<f64> = &p_k * C.transpose();
        sd.push((C * &h + &R).diagonal().map(f64::sqrt).as_slice().to_vec());
        H.push(h);
        p_k = &Phi * &p_k * Phi.transpose() + &drive;
    }
    (H, sd)
}

/// The seed of the conditional Monte Carlo draws of `design`, `report` and `flight-thresholds`' search:
/// fixed, so their printed figures do not move with the deck's seed. `rare-event --flight-s` and
/// `flight-thresholds`' confirmation draw from the deck's (or `--seed`'s) seed instead.
pub const CONDITIONAL_SEED: u64 = 0x5eed_ca11;

/// The residual's law over `samples` samples and the bounds at `thresholds` (one per output).
/// `sensor_sigma` and `process_sigma_per_step` are the noise standard deviations; `draws_seed` seeds
/// the conditional Monte Carlo draws.
#[allow(clippy::too_many_arguments)]
pub fn analytic_false_alarms(
    Ad: &DMatrix<f64>,
    Kd: &DMatrix<f64>,
    C: &DMatrix<f64>,
    sensor_sigma: &DVector<f64>,
    process_sigma_per_step: &DVector<f64>,
    thresholds: &[f64],
    samples: usize,
    draws_seed: u64,
) -> AnalyticFalseAlarms {
    let noise = (sensor_sigma, process_sigma_per_step);
    bounds_reusing_settled_pairs(Ad, Kd, C, noise, thresholds, samples, draws_seed, true)
}

/// [`analytic_false_alarms`]; `reuse` false integrates every settled pair afresh (the test of the
/// reuse's bits).
#[allow(clippy::too_many_arguments)]
fn bounds_reusing_settled_pairs(
    Ad: &DMatrix<f64>,
    Kd: &DMatrix<f64>,
    C: &DMatrix<f64>,
    (sensor_sigma, process_sigma_per_step): (&DVector<f64>, &DVector<f64>),
    thresholds: &[f64],
    samples: usize,
    draws_seed: u64,
    reuse: bool,
) -> AnalyticFalseAlarms {
    let (n, ny) = (Ad.nrows(), C.nrows());
    let (Phi, R, _) = closed_loop(Ad, Kd, C, sensor_sigma, process_sigma_per_step);
    let (H, sd) = residual_law(Ad, Kd, C, sensor_sigma, process_sigma_per_step, samples);
    let single = |k: usize, j: usize| 2.0 * normal_sf(thresholds[j] / sd[k][j]);
    let (mut sum, mut log_none, mut largest_sample) = (0.0, 0.0, 0.0f64);
    for k in 0..samples {
        let mut none_here = 0.0;
        for j in 0..ny {
            let p = single(k, j);
            sum += p;
            log_none += (-p).ln_1p();
            none_here += (-p).ln_1p();
        }
        // Sidak again within the sample: a bound, reported as the sample's largest.
        largest_sample = largest_sample.max(-none_here.exp_m1());
    }
    // C Phi^h (G), P(k) C' (H) and C Phi^h Kd R (GKR): Cov(gamma(k + h), gamma(k)) = G_h H_k - GKR_(h-1).
    let KdR = Kd * &R;
    let mut G = Vec::with_capacity(samples + 1);
    let mut power = DMatrix::<f64>::identity(n, n);
    for _ in 0..=samples {
        G.push(C * &power);
        power = &Phi * power;
    }
    let GKR: Vec<DMatrix<f64>> = G.iter().map(|g| g * &KdR).collect();
    let covariance = |l: usize, k: usize| -> DMatrix<f64> {
        match l - k {
            0 => &G[0] * &H[k] + &R,
            h => &G[h] * &H[k] - &GKR[h - 1],
        }
    };
    // From `settled` on, P(k) C' and the standard deviations repeat to the bit (the ramp from e(0) = 0
    // has reached its fixed point in doubles), so a pair of samples there depends only on their lag:
    // its probability is integrated once per lag and outputs and reused, the same bits as integrating
    // it again (an hour's flight is mostly such pairs).
    let settled = (0..samples).rev().take_while(|&k| H[k] == H[samples - 1] && sd[k] == sd[samples - 1]).last();
    let settled = settled.filter(|_| reuse).unwrap_or(samples);
    let stationary = std::sync::Mutex::new(std::collections::HashMap::<(usize, usize, usize, u64), f64>::new());
    // P(|gamma_jl(l)| > T_jl, |gamma_je(k)| > T_je) from `cov` = Cov(gamma(l), gamma(k)), to `relative`.
    let pair = |cov: &DMatrix<f64>, (l, jl): (usize, usize), (k, je): (usize, usize), relative: f64| -> f64 {
        let integrate = || {
            let rho = (cov[(jl, je)] / (sd[l][jl] * sd[k][je])).clamp(-1.0, 1.0);
            both_exceed_to(thresholds[je] / sd[k][je], thresholds[jl] / sd[l][jl], rho, relative)
        };
        if k < settled {
            return integrate();
        }
        let key = (l - k, jl, je, relative.to_bits());
        if let Some(&p) = stationary.lock().unwrap().get(&key) {
            return p;
        }
        let p = integrate();
        stationary.lock().unwrap().insert(key, p);
        p
    };
    let mut chains = 0.0;
    for k in 0..samples.saturating_sub(1) {
        let cov = covariance(k + 1, k);
        chains += (0..ny).map(|j| pair(&cov, (k + 1, j), (k, j), 1e-10)).sum::<f64>();
    }
    let hunter_upper = (sum - chains).max(0.0);
    let sidak_upper = -log_none.exp_m1();

    // Bonferroni's S1 - S2: the pairs up to `local` samples apart exactly (up to 4, fewer on long
    // trials of many outputs to bound the work); the farther ones each at most the pair probability
    // at the smallest standardised thresholds and a bound on their correlation (P(|X| > a, |Y| > b)
    // grows with |rho| and falls with a and b). Tight when the residual decorrelates within a few
    // samples, where the thinned family below loses most events.
    let local = (300_000 / (samples * ny * ny).max(1)).clamp(2, 5) - 1;
    // Parallel sums are collected and added in sample order: rayon's own `sum` adds in an order its
    // work stealing picks, which moved the bounds' last bits between runs and thread counts.
    let near: f64 = {
        use rayon::prelude::*;
        (0..samples)
            .into_par_iter()
            .map(|l| {
                let mut near = 0.0;
                for k in (l.saturating_sub(local)..=l).rev() {
                    let cov = covariance(l, k);
                    for jl in 0..ny {
                        for je in 0..ny {
                            if l == k && je >= jl {
                                continue; // each same-sample pair once, no event with itself
                            }
                            near += pair(&cov, (l, jl), (k, je), 1e-6);
                        }
                    }
                }
                near
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum()
    };
    // Every far pair's correlation exactly where the work allows (samples^2 ny^2 n / 2 multiply-adds up
    // to 2e9); beyond, per lag through |Cov(gamma_jl(k + h), gamma_je(k))| <= |row jl of G_h|
    // |column je of H_k| + |GKR_(h-1)[jl, je]| over the smallest standard deviations.
    let sd_min: Vec<f64> = (0..ny).map(|j| (0..samples).map(|k| sd[k][j]).fold(f64::INFINITY, f64::min)).collect();
    let mut far_rho = vec![0.0f64; ny * ny];
    let mut far_count = vec![0.0f64; ny * ny];
    for h in local + 1..samples {
        for c in far_count.iter_mut() {
            *c += (samples - h) as f64;
        }
    }
    if (samples * samples * ny * ny * n) as f64 / 2.0 <= 2e9 {
        use rayon::prelude::*;
        far_rho = (local + 1..samples)
            .into_par_iter()
            .map(|l| {
                let mut m = vec![0.0f64; ny * ny];
                for k in 0..l - local {
                    let h = l - k;
                    for jl in 0..ny {
                        for je in 0..ny {
                            let cov = G[h].row(jl).dot(&H[k].column(je).transpose()) - GKR[h - 1][(jl, je)];
                            let c = je * ny + jl;
                            m[c] = m[c].max((cov / (sd[l][jl] * sd[k][je])).abs().min(1.0));
                        }
                    }
                }
                m
            })
            .reduce(|| vec![0.0; ny * ny], |a, b| a.iter().zip(&b).map(|(x, y)| x.max(*y)).collect());
    } else {
        let h_norm: Vec<f64> =
            (0..ny).map(|j| (0..samples).map(|k| H[k].column(j).norm() / sd[k][j]).fold(0.0, f64::max)).collect();
        for h in local + 1..samples {
            for jl in 0..ny {
                let g = G[h].row(jl).norm();
                for je in 0..ny {
                    let c = je * ny + jl;
                    let r = g * h_norm[je] / sd_min[jl] + GKR[h - 1][(jl, je)].abs() / (sd_min[jl] * sd_min[je]);
                    far_rho[c] = far_rho[c].max(r.min(1.0));
                }
            }
        }
    }
    // The smallest standardised thresholds: at each output's largest standard deviation.
    let a_min: Vec<f64> = (0..ny).map(|j| thresholds[j] / (0..samples).map(|k| sd[k][j]).fold(0.0, f64::max)).collect();
    let far: f64 = (0..ny * ny)
        .filter(|&c| far_count[c] > 0.0)
        .map(|c| far_count[c] * both_exceed(a_min[c / ny], a_min[c % ny], far_rho[c]))
        .sum();
    let bonferroni = sum - near - far;
    // de Caen over every L-th sample, aligned to the last (the stationary end): at most
    // MAX_EVENTS events (their pairs are the cost), three spacings tried.
    const MAX_EVENTS: usize = 300;
    let min_spacing = (ny * samples).div_ceil(MAX_EVENTS).max(1);
    let (mut lower, mut spacing) = (bonferroni.max(0.0), 0);
    // Only where Bonferroni's is not already close to the upper bound (correlated residuals).
    let spacings = if lower >= 0.9 * sidak_upper.min(hunter_upper) {
        vec![]
    } else {
        vec![min_spacing, 2 * min_spacing, 4 * min_spacing]
    };
    for l in spacings.into_iter().filter(|&l| l <= samples.max(1)) {
        use rayon::prelude::*;
        let ks: Vec<usize> = (0..samples).rev().step_by(l).collect();
        // Per event (k, j): its probability, and the sum of its pairs with every other event (one
        // covariance matrix per pair of samples).
        let bound: f64 = ks
            .par_iter()
            .map(|&k| {
                let mut others = vec![0.0; ny];
                for &m in &ks {
                    let (early, late) = if k <= m { (k, m) } else { (m, k) };
                    let cov = covariance(late, early);
                    for (j, other) in others.iter_mut().enumerate() {
                        for i in (0..ny).filter(|&i| m != k || i != j) {
                            let (later, earlier) = if k <= m { ((m, i), (k, j)) } else { ((k, j), (m, i)) };
                            *other += pair(&cov, later, earlier, 1e-10);
                        }
                    }
                }
                (0..ny)
                    .map(|j| {
                        let p = single(k, j);
                        if p > 0.0 { p * p / (p + others[j]) } else { 0.0 }
                    })
                    .sum::<f64>()
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum();
        if bound > lower {
            (lower, spacing) = (bound, l);
        }
    }
    let law = Law {
        Phi: &Phi,
        Kd,
        C,
        sensor_sigma,
        process_sigma_per_step,
        thresholds,
        G: &G,
        H: &H,
        GKR: &GKR,
        R: &R,
        sd: &sd,
    };
    // Draws: 4,000, fewer where a trial's work (samples (n^2 + 3 n ny)) would make them slow (the
    // 747 deck: about 640, 3 s).
    let per_draw = (samples * (n * n + 3 * n * ny)) as f64;
    let draws = ((5e9 / per_draw) as usize).clamp(200, 4_000);
    let (conditional, conditional_lo, conditional_hi, conditional_upper_95) =
        law.conditional_monte_carlo(sum, draws, draws_seed);
    AnalyticFalseAlarms {
        residual_sd_end: sd.last().cloned().unwrap_or_default(),
        samples,
        largest_sample,
        sum,
        sidak_upper,
        hunter_upper,
        lower,
        spacing,
        conditional,
        conditional_lo,
        conditional_hi,
        conditional_upper_95,
        conditional_draws: draws,
        hour: None,
    }
}

/// The residual's law, for conditional Monte Carlo.
struct Law<'a> {
    Phi: &'a DMatrix<f64>,
    Kd: &'a DMatrix<f64>,
    C: &'a DMatrix<f64>,
    sensor_sigma: &'a DVector<f64>,
    process_sigma_per_step: &'a DVector<f64>,
    thresholds: &'a [f64],
    G: &'a [DMatrix<f64>],
    H: &'a [DMatrix<f64>],
    GKR: &'a [DMatrix<f64>],
    R: &'a DMatrix<f64>,
    sd: &'a [Vec<f64>],
}

impl Law<'_> {
    /// `Cov(gamma_i(m), gamma_j(k))`.
    fn cov(&self, (m, i): (usize, usize), (k, j): (usize, usize)) -> f64 {
        let ((l, a), (e, b)) = if m >= k { ((m, i), (k, j)) } else { ((k, j), (m, i)) };
        let h = l - e;
        let shared = self.G[h].row(a).dot(&self.H[e].column(b).transpose());
        if h == 0 { shared + self.R[(a, b)] } else { shared - self.GKR[h - 1][(a, b)] }
    }

    /// `S / N` averaged over `draws` draws (see the module docs), with its 95 % interval. Draw `d`
    /// takes its numbers from trial stream `d` of a fixed seed: the same answer every time.
    /// The estimate, its 95 % interval and its one-sided 95 % upper bound.
    fn conditional_monte_carlo(&self, sum: f64, draws: usize, seed: u64) -> (f64, f64, f64, f64) {
        use crate::engine::scenario::streams::{Substream, noise_rng};
        use rand::RngExt;
        use rand_distr::StandardNormal;
        use rayon::prelude::*;
        let (samples, ny, n) = (self.sd.len(), self.C.nrows(), self.Phi.nrows());
        if samples == 0 || !(sum > 0.0) {
            return (0.0, 0.0, 0.0, 0.0);
        }
        // Events in order (k, j), their probabilities accumulated for the draw.
        let p: Vec<f64> =
            (0..samples * ny).map(|e| 2.0 * normal_sf(self.thresholds[e % ny] / self.sd[e / ny][e % ny])).collect();
        let mut cumulative = Vec::with_capacity(p.len());
        let mut acc = 0.0;
        for v in &p {
            acc += v;
            cumulative.push(acc);
        }
        let values: Vec<f64> = (0..draws as u64)
            .into_par_iter()
            .map(|d| {
                let mut rng = noise_rng(seed, d, Substream::SensorNoise);
                let at = rng.random::<f64>() * acc;
                let event = cumulative.partition_point(|c| *c < at).min(p.len() - 1);
                let (k, j) = (event / ny, event % ny);
                // The event's value from its conditioned tail: |x| / sigma is chi-square(1) beyond.
                let sigma = self.sd[k][j];
                let u: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
                let magnitude = sigma * crate::engine::rare_event::estimators::chi2_isf(1, u * p[event]).sqrt();
                let x = if rng.random::<bool>() { magnitude } else { -magnitude };
                // An unconditioned trial of the same recursion.
                let mut e = vec![0.0; n];
                let mut next = vec![0.0; n];
                let mut gamma = vec![0.0; samples * ny];
                let mut v = vec![0.0; ny];
                for m in 0..samples {
                    for (vi, s) in v.iter_mut().zip(self.sensor_sigma.iter()) {
                        *vi = s * rng.sample::<f64, _>(StandardNormal);
                    }
                    for i in 0..ny {
                        gamma[m * ny + i] = (0..n).map(|c| self.C[(i, c)] * e[c]).sum::<f64>() + v[i];
                    }
                    for r in 0..n {
                        let w = self.process_sigma_per_step[r] * rng.sample::<f64, _>(StandardNormal);
                        next[r] = (0..n).map(|c| self.Phi[(r, c)] * e[c]).sum::<f64>()
                            - (0..ny).map(|c| self.Kd[(r, c)] * v[c]).sum::<f64>()
                            + w;
                    }
                    std::mem::swap(&mut e, &mut next);
                }
                // Conditioned on gamma_j(k) = x: add the covariance column times the difference.
                let shift = (x - gamma[event]) / (sigma * sigma);
                let mut count = 0u32;
                for m in 0..samples {
                    for i in 0..ny {
                        let g = gamma[m * ny + i] + self.cov((m, i), (k, j)) * shift;
                        count += u32::from(g.abs() > self.thresholds[i]);
                    }
                }
                sum / count.max(1) as f64
            })
            .collect();
        let mean = values.iter().sum::<f64>() / draws as f64;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (draws.max(2) - 1) as f64;
        let se = (var / draws as f64).sqrt();
        let half = crate::engine::stats::intervals::Z95 * se;
        let upper_95 = (mean + crate::engine::stats::intervals::Z_ONE_SIDED_95 * se).min(sum);
        // S / N <= S always. When no draw saw a second event (every value S), the share of draws that
        // would is still up to about 3 / draws (95 %), each worth at most S / 2 less: say so.
        let unresolved = if values.iter().all(|v| *v == sum) { sum * 1.5 / draws as f64 } else { 0.0 };
        (mean, (mean - half - unresolved).max(0.0), (mean + half).min(sum), upper_95)
    }
}

/// `P(|X| > a, |Y| > b)` for a standard bivariate normal pair with correlation `rho` (`a, b > 0`).
pub fn both_exceed(a: f64, b: f64, rho: f64) -> f64 {
    both_exceed_to(a, b, rho, 1e-10)
}

/// [`both_exceed`] to an absolute tolerance of `relative` times the independent pair's probability.
fn both_exceed_to(a: f64, b: f64, rho: f64, relative: f64) -> f64 {
    2.0 * (upper_orthant(a, b, rho, relative) + upper_orthant(a, b, -rho, relative))
}

/// `P(X > a, Y > b)` = the integral over `x > a` of `phi(x) P(Y > b | x)`.
fn upper_orthant(a: f64, b: f64, rho: f64, relative: f64) -> f64 {
    let s2 = 1.0 - rho * rho;
    if s2 < 1e-24 {
        // Y = +/- X.
        return if rho > 0.0 { normal_sf(a.max(b)) } else { 0.0 };
    }
    let s = s2.sqrt();
    let phi = |x: f64| (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let f = |x: f64| phi(x) * normal_sf((b - rho * x) / s);
    // Beyond a + 15 the integrand is below phi(a) e^(-15 a) / 1e48: nothing. The conditional tail
    // steps near x = b / rho; start the adaptive rule there so it sees the step.
    let end = a + 15.0;
    // Tolerance: relative to the independent pair's probability (the smallest the sum over both signs
    // of rho can be), but no finer than 1e-12 of the largest it can be (min of the two tails), which
    // doubles can still resolve: a finer one would split every interval to the depth limit.
    let scale = (normal_sf(a) * normal_sf(b) * relative).max(1e-12 * normal_sf(a.max(b)));
    let mut cuts = vec![a];
    if rho > 0.0 {
        let x_step = b / rho;
        if x_step > a && x_step < end {
            cuts.push(x_step);
        }
    }
    cuts.push(end);
    cuts.windows(2).map(|w| simpson(&f, w[0], w[1], scale, 30)).sum()
}

/// Adaptive Simpson's rule on `[a, b]` to an absolute tolerance `tol`.
fn simpson(f: &impl Fn(f64) -> f64, a: f64, b: f64, tol: f64, depth: u32) -> f64 {
    let m = 0.5 * (a + b);
    let (fa, fm, fb) = (f(a), f(m), f(b));
    let whole = (b - a) / 6.0 * (fa + 4.0 * fm + fb);
    simpson_step(f, a, b, fa, fm, fb, whole, tol, depth)
}

#[allow(clippy::too_many_arguments)]
fn simpson_step(
    f: &impl Fn(f64) -> f64,
    a: f64,
    b: f64,
    fa: f64,
    fm: f64,
    fb: f64,
    whole: f64,
    tol: f64,
    depth: u32,
) -> f64 {
    let m = 0.5 * (a + b);
    let (lm, rm) = (0.5 * (a + m), 0.5 * (m + b));
    let (flm, frm) = (f(lm), f(rm));
    let left = (m - a) / 6.0 * (fa + 4.0 * flm + fm);
    let right = (b - m) / 6.0 * (fm + 4.0 * frm + fb);
    let delta = left + right - whole;
    if depth == 0 || delta.abs() <= 15.0 * tol {
        return left + right + delta / 15.0;
    }
    simpson_step(f, a, m, fa, flm, fm, left, tol / 2.0, depth - 1)
        + simpson_step(f, m, b, fm, frm, fb, right, tol / 2.0, depth - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One state with no gain and a mode of time constant tau: the residual's variance from `e(0) =
    /// 0` is `q^2 (1 - phi^(2k)) / (1 - phi^2) + r^2` in closed form (`phi = exp(-dt / tau)`), Sidak's
    /// bounds taken here sample by sample. A 7.7 s mode against 10 s trials leaves most of a trial
    /// unsettled: at 4.5 settled sigmas an hour's `-ln P(no alarm)` is 9.353 times its trials' (Python's
    /// math.erfc, the same sums); a 0.1 s mode settles at once (1.007).
    #[test]
    fn the_hour_over_the_conversion_matches_the_closed_form() {
        let (dt, trial, r, q) = (0.01f64, 1000usize, 0.1f64, 0.02f64);
        for (tau, want_above) in [(7.7f64, 1.5), (0.1, 0.0)] {
            let phi: f64 = (-dt / tau).exp();
            let settled_sd = (q * q / (1.0 - phi * phi) + r * r).sqrt();
            let threshold = 4.5 * settled_sd;
            let sd = |k: usize| (q * q * (1.0 - phi.powi(2 * k as i32)) / (1.0 - phi * phi) + r * r).sqrt();
            let p = |k: usize| 2.0 * normal_sf(threshold / sd(k));
            let log_none = |k: usize| (-p(k)).ln_1p();
            let trial_log: f64 = (0..trial).map(log_none).sum();
            let hour_log: f64 = (0..360_000).map(log_none).sum();
            let want = hour_log / (360.0 * trial_log);
            let m = |v: f64| DMatrix::from_element(1, 1, v);
            let got = hour_conversion(
                &m(phi),
                &m(0.0),
                &m(1.0),
                &DVector::from_element(1, r),
                &DVector::from_element(1, q),
                &[threshold],
                trial,
                dt,
            );
            assert!((got.ratio / want - 1.0).abs() < 1e-9, "tau {tau}: {} against {want}", got.ratio);
            assert!((got.slowest_time_constant_s / tau - 1.0).abs() < 1e-9, "{got:?}");
            assert!(want > want_above && (tau > 1.0 || want < 1.01), "tau {tau}: {want}");
            let python = if tau > 1.0 { 9.35299091943232 } else { 1.0071667611049149 };
            assert!((want / python - 1.0).abs() < 1e-9, "tau {tau}: {want} against Python's {python}");
        }
    }

    /// Independent coordinates multiply; a perfectly correlated pair is one variable; a correlated
    /// pair matches Monte Carlo (10^6 pairs: 4 standard errors).
    #[test]
    fn two_sample_probabilities_are_exact_where_known() {
        let (a, b) = (2.0, 3.0);
        let independent = 4.0 * normal_sf(a) * normal_sf(b);
        assert!((both_exceed(a, b, 0.0) / independent - 1.0).abs() < 1e-7);
        assert!((both_exceed(a, a, 1.0) / (2.0 * normal_sf(a)) - 1.0).abs() < 1e-7);
        assert!((both_exceed(a, a, 0.999_999) / (2.0 * normal_sf(a)) - 1.0).abs() < 2e-3);
        assert!((both_exceed(5.0, 5.0, 0.0) / (4.0 * normal_sf(5.0).powi(2)) - 1.0).abs() < 1e-6, "deep tail");
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(1);
        let (rho, a, b, n) = (0.7, 1.0, 1.5, 1_000_000);
        let hits = (0..n)
            .filter(|_| {
                let x: f64 = StandardNormal.sample(&mut rng);
                let z: f64 = StandardNormal.sample(&mut rng);
                let y = rho * x + (1.0 - rho * rho).sqrt() * z;
                x.abs() > a && y.abs() > b
            })
            .count() as f64
            / n as f64;
        let p = both_exceed(a, b, rho);
        assert!((hits - p).abs() < 4.0 * (p * (1.0 - p) / n as f64).sqrt(), "{hits} vs {p}");
        assert_eq!(both_exceed(a, b, -rho), p, "|X| and |Y| do not see the sign");
    }

    /// The settled pairs integrated once per lag give the bits a fresh integration of each gives: two
    /// coupled modes (poles 0.9 and 0.8) seen by two outputs, 600 samples of which the last 300 are
    /// settled to the bit, every bound and the conditional estimate equal with and without the reuse.
    #[test]
    fn settled_pairs_reused_give_the_bits_of_fresh_integration() {
        let ad = DMatrix::from_row_slice(2, 2, &[0.9, 0.05, 0.0, 0.8]);
        let (kd, c) = (DMatrix::zeros(2, 2), DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.5, 1.0]));
        let (sensor, process) = (DVector::from_vec(vec![0.1, 0.2]), DVector::from_vec(vec![0.3, 0.2]));
        let (samples, thresholds) = (600, [3.0, 2.4]);
        let (h, sd) = residual_law(&ad, &kd, &c, &sensor, &process, samples);
        assert!(h[samples / 2] == h[samples - 1] && sd[samples / 2] == sd[samples - 1], "not settled by mid-trial");
        assert!(h[10] != h[samples - 1], "settled from the start: nothing to reuse");
        let run =
            |reuse| bounds_reusing_settled_pairs(&ad, &kd, &c, (&sensor, &process), &thresholds, samples, 7, reuse);
        let (reused, fresh) = (run(true), run(false));
        assert!(
            reused.sidak_upper > 1e-3 && reused.sidak_upper < 0.5 && reused.hunter_upper < reused.sidak_upper,
            "{reused:?}"
        );
        assert_eq!(reused, fresh);
    }

    /// A correlated residual (an AR(1) state, pole 0.95, seen through a little sensor noise): alarms come
    /// in clusters, so the union bound overstates. The bounds bracket a plain Monte Carlo of 100,000
    /// trials of 200 samples (0.0560 +/- 0.0007; within 4 standard errors): [0.028, 0.080], Hunter's
    /// chain bound half Sidak's (0.168), both sides within a factor of 2.5 of the truth.
    #[test]
    fn a_correlated_residual_is_bracketed_by_brute_force() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let (pole, sensor, process, threshold, samples, trials) = (0.95, 0.1, 1.0, 10.5, 200, 100_000);
        let one = |v: f64| DMatrix::from_element(1, 1, v);
        let f = analytic_false_alarms(
            &one(pole),
            &one(0.0),
            &one(1.0),
            &DVector::from_element(1, sensor),
            &DVector::from_element(1, process),
            &[threshold],
            samples,
            CONDITIONAL_SEED,
        );
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(4);
        let mut alarms = 0;
        for _ in 0..trials {
            let mut e = 0.0f64;
            let mut alarmed = false;
            for _ in 0..samples {
                let v: f64 = StandardNormal.sample(&mut rng);
                alarmed |= (e + sensor * v).abs() > threshold;
                let w: f64 = StandardNormal.sample(&mut rng);
                e = pole * e + process * w;
            }
            alarms += alarmed as u32;
        }
        let p = alarms as f64 / trials as f64;
        let se = (p * (1.0 - p) / trials as f64).sqrt();
        assert!(f.lower <= p + 4.0 * se && p - 4.0 * se <= f.upper(), "{f:?} vs {p} +/- {se}");
        assert!(f.hunter_upper < f.sidak_upper, "{f:?}");
        assert!(f.lower > 0.4 * p && f.upper() < 2.5 * p, "{f:?} vs {p}");
        // Conditional Monte Carlo on the same law gives the probability itself, to about +-3 %.
        assert!(f.conditional_lo <= p + 4.0 * se && p - 4.0 * se <= f.conditional_hi, "{f:?} vs {p} +/- {se}");
        assert!(f.conditional_hi - f.conditional_lo < 0.07 * p, "{f:?}");
    }

    /// A white residual (Kd = 0, no process noise: gamma = v): the samples are independent, the
    /// probability of an alarm in N = 300 samples (every one in de Caen's family) is exactly
    /// 1 - (1 - p)^N, Sidak's bound is it, and the lower bound is within 1 % of it.
    #[test]
    fn a_white_residual_is_bracketed_by_its_exact_answer() {
        let n = 2;
        let Ad = DMatrix::from_row_slice(n, n, &[0.9, 0.1, 0.0, 0.8]);
        let Kd = DMatrix::zeros(n, 1);
        let C = DMatrix::from_row_slice(1, n, &[1.0, 0.0]);
        let (sigma, threshold, samples) = (0.5, 2.4, 300);
        let f = analytic_false_alarms(
            &Ad,
            &Kd,
            &C,
            &DVector::from_element(1, sigma),
            &DVector::zeros(n),
            &[threshold],
            samples,
            CONDITIONAL_SEED,
        );
        let p = 2.0 * normal_sf(threshold / sigma);
        let exact = 1.0 - (1.0 - p).powi(samples as i32);
        assert!((f.sidak_upper / exact - 1.0).abs() < 1e-9, "{f:?} vs {exact}");
        assert!(f.lower <= exact && f.lower > 0.99 * exact, "{f:?} vs {exact}");
        assert!(f.hunter_upper >= exact, "{f:?}");
        assert!(f.conditional_lo <= exact && exact <= f.conditional_hi, "{f:?} vs {exact}");
    }
}
