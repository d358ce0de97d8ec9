//! The design of a sensitivity study (`fdimc sensitivity DECK`): which trial draws what. The analysis
//! of its outcomes, after the run, is [`crate::engine::sensitivity`].
//!
//! **Design** (Saltelli's pick-freeze scheme). For each part of the study, faulty trials and fault-free
//! trials, two independent matrices `A` and `B` of `base_samples` rows draw every sampled factor of the
//! deck (one uniform per factor and row, from the row's own scenario stream, so rows are independent
//! and the bootstrap over rows is valid); `A_B^i` is `A` with factor `i`'s column from `B`. The trials
//! are the rows of `A`, `B`, `A_B^1`, .., `A_B^k` in that order, part after part: `base_samples (k + 2)`
//! trials per part. A listed factor (fault kind, output, listed noise scales or parameter errors) is
//! drawn uniformly from its list instead of cycling on the grid.
//!
//! **The noise realisation is a factor of its own** (`noise_realisation`): the sensor and process
//! noise of a row come from the random streams of its `A` row (of its `B` row in `B` and in `A_B^noise`),
//! so its index is the share of the outcome's variance that no deck factor explains, by itself
//! (`S1`) and with its interactions (`ST`).

use rand::RngExt;
use serde::{Deserialize, Serialize};

use crate::engine::scenario::streams::{Substream, trial_rng};

/// Name of the noise realisation's factor.
pub const NOISE_FACTOR: &str = "noise_realisation";

/// Where a design factor's draw goes in a trial's draws ([`crate::engine::scenario::draws::TrialDraws`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Slot {
    /// The unit draw of continuous dimension `d` (a range, or a listed factor drawn by its dimension).
    Dim(usize),
    /// The `k`-th grid digit the scenario takes (a listed choice: fault kind, output).
    Digit(usize),
    /// The noise realisation: which row's random streams the trial's noise comes from.
    Noise,
}

/// A factor of the design: its name in `sensitivity.csv` and where it goes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DesignFactor {
    pub name: String,
    pub slot: Slot,
}

/// The factors of one part (faulty or fault-free trials), the noise realisation last.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Part {
    pub fault_free: bool,
    pub factors: Vec<DesignFactor>,
}

impl Part {
    /// A part over the deck's sampled `factors`, with the noise realisation added.
    pub fn new(fault_free: bool, mut factors: Vec<DesignFactor>) -> Part {
        factors.push(DesignFactor { name: NOISE_FACTOR.into(), slot: Slot::Noise });
        Part { fault_free, factors }
    }

    pub fn name(&self) -> &'static str {
        if self.fault_free { "fault_free" } else { "faulty" }
    }

    pub fn trials(&self, base: u64) -> u64 {
        base * (self.factors.len() as u64 + 2)
    }
}

/// A method's factors while it lists them: each added only where the deck's trials draw it.
#[derive(Debug, Default)]
pub struct Factors(Vec<DesignFactor>);

impl Factors {
    pub fn add(&mut self, name: &str, slot: Slot, sampled: bool) {
        if sampled {
            self.0.push(DesignFactor { name: name.into(), slot });
        }
    }

    /// The parts of a study: faulty trials over `faulty` and then `shared` (when the deck has faults),
    /// and fault-free trials over `shared`.
    pub fn parts(faulty: Option<Factors>, shared: Factors) -> Vec<Part> {
        let mut parts = Vec::new();
        if let Some(Factors(mut f)) = faulty {
            f.extend(shared.0.iter().cloned());
            parts.push(Part::new(false, f));
        }
        parts.push(Part::new(true, shared.0));
        parts
    }
}

/// A sensitivity study's design, recorded in `manifest.json` (what `merge` and `--resume` check, and
/// what `summarize` needs to compute the indices again).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Design {
    /// Rows of each of `A` and `B`.
    pub base_samples: u64,
    /// Bootstrap resamples of the base rows for the intervals.
    pub bootstrap: u64,
    pub parts: Vec<Part>,
}

/// One trial of the design: which part, block and base row, and the draws it gets.
#[derive(Debug, Clone, PartialEq)]
pub struct DesignDraws {
    pub fault_free: bool,
    /// The unit draw per continuous dimension (0.5 where no factor of the design sets it).
    pub dim_units: Vec<f64>,
    /// The unit draw per grid digit, in the order the scenario takes them (0 where none is set).
    pub digit_units: Vec<f64>,
}

/// Which matrix a trial's row belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Block {
    A,
    B,
    /// `A_B^i`.
    Ab(usize),
}

impl Design {
    pub fn trials(&self) -> u64 {
        self.parts.iter().map(|p| p.trials(self.base_samples)).sum()
    }

    /// Part index, the part's first trial, block and base row of trial `t`.
    fn locate(&self, t: u64) -> (usize, u64, Block, u64) {
        let n = self.base_samples;
        let mut first = 0;
        for (p, part) in self.parts.iter().enumerate() {
            let end = first + part.trials(n);
            if t < end {
                let (block, j) = ((t - first) / n, (t - first) % n);
                let block = match block {
                    0 => Block::A,
                    1 => Block::B,
                    b => Block::Ab(b as usize - 2),
                };
                return (p, first, block, j);
            }
            first = end;
        }
        panic!("trial {t} is past the design's {} trials", self.trials())
    }

    /// The trial whose noise streams trial `t` uses: its `A` row's, or its `B` row's in `B` and in
    /// `A_B^noise`.
    pub fn noise_trial(&self, t: u64) -> u64 {
        let (p, first, block, j) = self.locate(t);
        let (row_a, row_b) = (first + j, first + self.base_samples + j);
        match block {
            Block::A => row_a,
            Block::B => row_b,
            Block::Ab(i) if self.parts[p].factors[i].slot == Slot::Noise => row_b,
            Block::Ab(_) => row_a,
        }
    }

    /// The draws of trial `t` of a study seeded `seed` whose scenarios have `dims` continuous dimensions.
    pub fn draws(&self, seed: u64, t: u64, dims: usize) -> DesignDraws {
        let (p, first, block, j) = self.locate(t);
        let part = &self.parts[p];
        let n = self.base_samples;
        let (row_a, row_b) = (first + j, first + n + j);
        // One uniform per factor of the row's own scenario stream (the noise's unused).
        let units_of = |row: u64| -> Vec<f64> {
            let mut rng = trial_rng(seed, row, Substream::Scenario);
            part.factors.iter().map(|_| rng.random::<f64>()).collect()
        };
        let mut units = match block {
            Block::A => units_of(row_a),
            Block::B => units_of(row_b),
            Block::Ab(i) => {
                let mut u = units_of(row_a);
                u[i] = units_of(row_b)[i];
                u
            }
        };
        let digits = part.factors.iter().filter_map(|f| if let Slot::Digit(k) = f.slot { Some(k + 1) } else { None });
        let mut draws = DesignDraws {
            fault_free: part.fault_free,
            dim_units: vec![0.5; dims],
            digit_units: vec![0.0; digits.max().unwrap_or(0)],
        };
        for (f, u) in part.factors.iter().zip(units.drain(..)) {
            match f.slot {
                Slot::Dim(d) => draws.dim_units[d] = u,
                Slot::Digit(k) => draws.digit_units[k] = u,
                Slot::Noise => {}
            }
        }
        draws
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The layout: A, B, then A_B^i; `A_B^i` is `A` with column i of `B`; the noise follows B only in
    /// B and `A_B^noise`; listed factors get their own digit.
    #[test]
    fn design_rows_pick_and_freeze() {
        let factors = vec![
            DesignFactor { name: "kind".into(), slot: Slot::Digit(0) },
            DesignFactor { name: "onset".into(), slot: Slot::Dim(1) },
        ];
        let design = Design {
            base_samples: 4,
            bootstrap: 10,
            parts: vec![
                Part::new(false, factors),
                Part::new(true, vec![DesignFactor { name: "x".into(), slot: Slot::Dim(0) }]),
            ],
        };
        assert_eq!(design.trials(), 4 * 5 + 4 * 4);
        let d = |t| design.draws(3, t, 2);
        let noise = |t| design.noise_trial(t);
        for j in 0..4 {
            let (a, b) = (d(j), d(4 + j));
            assert_ne!(a.digit_units[0], b.digit_units[0]);
            assert_eq!((noise(j), noise(4 + j)), (j, 4 + j));
            let (ab_kind, ab_onset, ab_noise) = (d(8 + j), d(12 + j), d(16 + j));
            assert_eq!(
                (ab_kind.digit_units[0], ab_kind.dim_units[1], noise(8 + j)),
                (b.digit_units[0], a.dim_units[1], j)
            );
            assert_eq!(
                (ab_onset.digit_units[0], ab_onset.dim_units[1], noise(12 + j)),
                (a.digit_units[0], b.dim_units[1], j)
            );
            assert_eq!(
                (ab_noise.digit_units[0], ab_noise.dim_units[1], noise(16 + j)),
                (a.digit_units[0], a.dim_units[1], 4 + j)
            );
            assert_eq!(a.dim_units[0], 0.5, "a dimension no factor sets");
            assert!(!a.fault_free && d(20 + j).fault_free);
            assert_eq!(noise(20 + j), 20 + j);
        }
    }
}
