//! Trial scenarios, the part every kind of study shares. A trial's scenario is a function of (deck, seed,
//! trial index) only. Listed factors (`values`, the fault kinds, the faulty components) form a full grid
//! cycled over the trial index (mixed radix, fault kind fastest, [`GridDigits`]), so every combination gets
//! its share. Continuous factors (`range`) are drawn by the deck's sampler ([`UnitSampler`]), one dimension
//! per factor: independent uniforms, a Latin hypercube over all `monte_carlo.trials` (stratum of trial i in
//! dimension d = a seeded permutation of 0..N), or an Owen-scrambled Sobol sequence (sobol_burley;
//! independent scrambles per block of 65,536 trials, since one sequence holds 2^16 points). Whether a
//! trial is fault-free is the first draw of its scenario stream.
//!
//! A sensitivity study ([`crate::engine::sensitivity`]) replaces all of this by its design's rows: the
//! design sets whether a trial is fault-free, each factor's unit draw (a listed factor's too, drawn
//! from its list by its dimension), each grid digit, and which trial's noise streams a trial uses.

use rand::RngExt;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;

use std::sync::Arc;

use crate::engine::scenario::deck::{Factor, MonteCarlo, ParameterError, Sampler, SearchPoint};
use crate::engine::scenario::design::Design;
use crate::engine::scenario::streams::{Substream, trial_rng};

/// Continuous dimensions of the factors every kind draws (the fault size's, where its kind has one); a kind's
/// own factors take [`FIRST_OWN_DIM`] on.
pub const DIM_ONSET: usize = 0;
pub const DIM_SIZE: usize = 1;
pub const DIM_NOISE: usize = 2;
pub const FIRST_OWN_DIM: usize = 3;

/// Uniform draws in [0, 1) per (trial, dimension) by the deck's sampler: independent uniforms, a Latin
/// hypercube over `trials`, or Owen-scrambled Sobol points. Shared by every kind of study.
pub struct UnitSampler {
    sampler: Sampler,
    trials: u64,
    seed: u64,
    /// Continuous dimensions of a trial and the probability that it is fault-free ([`UnitSampler::trial`]).
    dims: usize,
    fault_free_fraction: f64,
    /// Latin-hypercube strata: `lhs[d][i]` for dimension d, trial i.
    lhs: Vec<Vec<u32>>,
    /// A sensitivity study's design, whose rows replace the sampler ([`MonteCarlo::design`]).
    design: Option<Arc<Design>>,
    /// A worst-case search's point ([`MonteCarlo::search_point`]).
    point: Option<Arc<SearchPoint>>,
}

impl UnitSampler {
    /// The sampler of a study's `[monte_carlo]` (seed `seed`) over `dims` continuous dimensions.
    pub fn for_study(mc: &MonteCarlo, seed: u64, dims: usize) -> Self {
        let (sampler, trials) = (mc.sampler, mc.trials);
        let lhs = if sampler == Sampler::LatinHypercube && mc.design.is_none() {
            let n = trials as usize;
            (0..dims)
                .map(|d| {
                    // Fisher-Yates with a stream of its own per dimension.
                    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4c48_535f_7065_726d);
                    rng.set_stream(d as u64);
                    let mut perm: Vec<u32> = (0..n as u32).collect();
                    for i in (1..n).rev() {
                        perm.swap(i, rng.random_range(0..=i));
                    }
                    perm
                })
                .collect()
        } else {
            Vec::new()
        };
        let (design, point) = (mc.design.clone(), mc.search_point.clone());
        UnitSampler { sampler, trials, seed, dims, fault_free_fraction: mc.fault_free_fraction, lhs, design, point }
    }

    /// Trial `trial`'s draws, in the same order for every kind of study: whether it is fault-free (the
    /// first draw of its scenario stream, true with probability `fault_free_fraction`), then one unit
    /// draw per dimension; and its grid digits.
    pub fn trial(&self, trial: u64) -> TrialDraws {
        if let Some(design) = &self.design {
            let d = design.draws(self.seed, trial, self.dims);
            let digits = Some(DesignDigits { units: d.digit_units, taken: 0 });
            return TrialDraws {
                fault_free: d.fault_free,
                units: d.dim_units,
                grid: GridDigits::new(0),
                digits,
                searched: Vec::new(),
            };
        }
        let mut rng = trial_rng(self.seed, trial, Substream::Scenario);
        let mut fault_free = rng.random::<f64>() < self.fault_free_fraction;
        let mut units: Vec<f64> = (0..self.dims).map(|d| self.unit(trial, d, &mut rng)).collect();
        let mut searched = Vec::new();
        if let Some(point) = &self.point {
            fault_free = point.fault_free.unwrap_or(fault_free);
            for (u, set) in units.iter_mut().zip(&point.units) {
                *u = set.unwrap_or(*u);
            }
            searched = point.units.iter().map(Option::is_some).collect();
        }
        TrialDraws { fault_free, units, grid: GridDigits::new(trial), digits: None, searched }
    }

    /// The trial whose noise streams trial `trial` uses: itself, except in a sensitivity design.
    pub fn noise_trial(&self, trial: u64) -> u64 {
        self.design.as_ref().map_or(trial, |d| d.noise_trial(trial))
    }

    /// Uniform in [0, 1) for dimension `dim` of trial `trial`; `rng` is the trial's scenario stream
    /// (one draw per call, whatever the sampler, so later draws do not depend on it).
    fn unit(&self, trial: u64, dim: usize, rng: &mut ChaCha8Rng) -> f64 {
        let jitter: f64 = rng.random();
        match self.sampler {
            Sampler::Random => jitter,
            Sampler::LatinHypercube => {
                let n = self.trials as f64;
                // Trials past the design's count (a --trials override) wrap onto the design.
                let stratum = self.lhs[dim][(trial % self.trials) as usize] as f64;
                (stratum + jitter) / n
            }
            Sampler::Sobol => {
                let block = (trial >> 16) as u32;
                let seed = (self.seed as u32) ^ (self.seed >> 32) as u32 ^ block.wrapping_mul(0x9e37_79b9);
                sobol_burley::sample((trial & 0xffff) as u32, dim as u32, seed) as f64
            }
        }
    }
}

/// One trial's scenario draws, taken by a kind's scenario in its own fixed order: whether the trial is
/// fault-free, then factors by their dimension (ranges) or the next grid digit (lists).
pub struct TrialDraws {
    pub fault_free: bool,
    units: Vec<f64>,
    grid: GridDigits,
    /// A sensitivity design's digits, which replace the grid's.
    digits: Option<DesignDigits>,
    /// The dimensions a worst-case point sets (a listed factor there is picked by its unit draw).
    searched: Vec<bool>,
}

/// The unit draws of a design row's grid digits, taken in order.
struct DesignDigits {
    units: Vec<f64>,
    taken: usize,
}

/// Index `0..n` of a unit draw.
fn pick(u: f64, n: usize) -> usize {
    ((u * n as f64) as usize).min(n - 1)
}

impl TrialDraws {
    /// The next grid digit, in `0..n` (a listed choice: fault kind, component).
    pub fn digit(&mut self, n: usize) -> usize {
        match &mut self.digits {
            Some(d) => {
                let u = d.units.get(d.taken).copied().unwrap_or(0.0);
                d.taken += 1;
                pick(u, n)
            }
            None => self.grid.next(n),
        }
    }

    /// Factor `f`'s value and group label ([`draw`]) from dimension `dim`. In a sensitivity design a
    /// listed factor is drawn from its list by its dimension's unit draw, not by the grid.
    pub fn factor(&mut self, f: &Factor, dim: usize) -> (f64, f64) {
        let u = self.units[dim];
        if self.digits.is_some() || self.searched.get(dim).copied().unwrap_or(false) {
            return draw(f, u, &mut |n| pick(u, n));
        }
        let grid = &mut self.grid;
        draw(f, u, &mut |n| grid.next(n))
    }

    /// The shared factors of `[monte_carlo]`, onset first: (onset in s, noise scale, its group label).
    pub fn onset_and_noise(&mut self, mc: &MonteCarlo) -> (f64, f64, f64) {
        let (onset_s, _) = self.factor(&mc.onset_s, DIM_ONSET);
        let (noise_scale, noise_bin) = self.factor(&mc.noise_scale, DIM_NOISE);
        (onset_s, noise_scale, noise_bin)
    }

    /// Each parameter error's value (deck order, dimensions from `first_dim` on) and the largest |group
    /// label| among them (0 without any), the trial's `param_error_bin`.
    pub fn parameter_errors<P>(&mut self, errors: &[ParameterError<P>], first_dim: usize) -> (Vec<f64>, f64) {
        let mut bin_max = 0.0f64;
        let values = (errors.iter().enumerate())
            .map(|(k, pe)| {
                let (v, bin) = self.factor(&pe.value, first_dim + k);
                bin_max = bin_max.max(bin.abs());
                v
            })
            .collect();
        (values, bin_max)
    }
}

/// The listed-factor grid of one trial: mixed-radix digits of the trial index, taken in order.
pub struct GridDigits(u64);

impl GridDigits {
    pub fn new(trial: u64) -> Self {
        GridDigits(trial)
    }

    /// The next digit, in `0..n`.
    pub fn next(&mut self, n: usize) -> usize {
        let d = (self.0 % n as u64) as usize;
        self.0 /= n as u64;
        d
    }
}

/// A factor's value where a unit draw `u` sets it alone (a list picked by `u`), as a sensitivity
/// design's or a worst-case point's trials take it.
pub fn value_at(f: &Factor, u: f64) -> f64 {
    draw(f, u, &mut |n| pick(u, n)).0
}

/// A factor's value and group label, from the unit draw `u` (ranges) or the next grid digit (lists).
pub fn draw(f: &Factor, u: f64, digit: &mut impl FnMut(usize) -> usize) -> (f64, f64) {
    match f {
        Factor::Fixed(v) => (*v, *v),
        Factor::Values(v) => {
            let x = v[digit(v.len())];
            (x, x)
        }
        Factor::Range { lo, hi, bins } => {
            let bin = ((u * *bins as f64) as usize).min(bins - 1);
            (lo + u * (hi - lo), bin_centre(*lo, *hi, bin, *bins))
        }
    }
}

/// The label of bin `bin` of `bins` equal bins over `[lo, hi]`: its centre, as a group name can carry
/// it. The weighted mean is exactly symmetric about 0 on a symmetric range (so that `-x` and `x` make
/// one |error| group and the middle bin is 0, not 1.4e-17), and rounding to 1e-10 of the bin's width
/// drops the last-bit noise that would split one bin into two groups (0.06666666666666665 and ...68)
/// while staying well inside the 1e-9 the summary matches a centre to its bin's edges with.
pub fn bin_centre(lo: f64, hi: f64, bin: usize, bins: usize) -> f64 {
    let (w_lo, w_hi) = ((bins - bin) as f64 - 0.5, bin as f64 + 0.5);
    let centre = (w_lo * lo + w_hi * hi) / bins as f64;
    let bin_width = (hi - lo).abs() / bins as f64;
    if !(bin_width > 0.0 && bin_width.is_finite()) {
        return centre;
    }
    // At most 15 significant digits in all: a decimal a double holds exactly to its last digit.
    let whole_digits = if centre.abs() >= 1.0 { centre.abs().log10().floor() as i64 + 1 } else { 0 };
    let decimals = (10 - bin_width.log10().floor() as i64).min(15 - whole_digits).clamp(0, 330) as usize;
    let rounded: f64 = format!("{centre:.decimals$}").parse().unwrap_or(centre);
    // -0.0 and 0.0 name one group.
    if rounded == 0.0 { 0.0 } else { rounded }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_draw_and_bins() {
        let f = Factor::Range { lo: 2.0, hi: 10.0, bins: 4 };
        let mut no_digit = |_: usize| -> usize { unreachable!() };
        assert_eq!(draw(&f, 0.0, &mut no_digit), (2.0, 3.0));
        assert_eq!(draw(&f, 0.5, &mut no_digit), (6.0, 7.0));
        assert_eq!(draw(&f, 0.999, &mut no_digit).1, 9.0);
    }

    #[test]
    fn bin_labels_are_symmetric_and_free_of_last_bit_noise() {
        // The case: relative errors in [-0.1, 0.1] in 3 bins gave 1.39e-17 for the middle bin,
        // and |-0.0667| and 0.0667 differing in the last bit.
        let labels: Vec<f64> = (0..3).map(|b| bin_centre(-0.1, 0.1, b, 3)).collect();
        assert_eq!(labels[1], 0.0);
        assert_eq!(labels[0], -labels[2]);
        assert_eq!(labels[2].to_string(), "0.066666666667");
        assert_eq!(bin_centre(1000.0, 1000.001, 1, 2), 1000.00075);
        assert_eq!(bin_centre(0.5, 0.95, 0, 3).to_string(), "0.575");
        assert_eq!(bin_centre(-0.2, 0.2, 2, 5), 0.0);
        // Asymmetric ranges keep their centres.
        assert_eq!(bin_centre(1.0, 25.0, 0, 6), 3.0);
        assert_eq!(bin_centre(-0.1, 0.3, 0, 2), 0.0);
    }

    #[test]
    fn listed_values_cycle_with_the_grid() {
        let f = Factor::Values(vec![1.0, 2.0, 3.0]);
        let picks: Vec<f64> = (0..6u64)
            .map(|i| {
                let mut grid = GridDigits::new(i);
                draw(&f, 0.0, &mut |n| grid.next(n)).0
            })
            .collect();
        assert_eq!(picks, [1.0, 2.0, 3.0, 1.0, 2.0, 3.0]);
    }
}
