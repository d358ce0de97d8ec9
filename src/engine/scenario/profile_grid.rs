//! The value grid of the recorded first-passage profiles (`monte_carlo.profile_resolution`): which
//! rises of a statistic's running maximum a profile keeps, and at what value
//! ([`crate::engine::results::schema::FirstPassage`] keeps them).

/// The default relative step of the profiles' value grid (`monte_carlo.profile_resolution`).
pub const DEFAULT_PROFILE_RESOLUTION: f64 = 0.05;

/// The value grid of first-passage profiles: a point is added when the running maximum rises past the
/// next level `(1 + step)^l` (integer `l`), and records that level, the largest at or below it, so the
/// lists are short and their values repeat from trial to trial (Parquet stores them in a few bits);
/// the first point after the onset and the final maximum are exact. Step 0: every rise is a point, at
/// its exact value (the full profile).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileGrid {
    step: f64,
    ratio: f64,
    ln_ratio: f64,
    /// `ratio^l` for `l` in `-TABLE_REACH..=TABLE_REACH`, computed once per step: a profile point
    /// looks up several levels, and `powi` there was a tenth of the lane path's time.
    levels: &'static [f64],
}

/// The levels `-TABLE_REACH..=TABLE_REACH` come from the table, the rest from `powi` (the same numbers:
/// the table holds `powi`'s). For the default step that is `e^+-199`.
const TABLE_REACH: i32 = 4096;

/// The level table of `ratio`, made once per process and kept (a few steps per process at most).
fn level_table(ratio: f64) -> &'static [f64] {
    use std::sync::{Mutex, OnceLock};
    static TABLES: OnceLock<Mutex<Vec<(u64, &'static [f64])>>> = OnceLock::new();
    let mut tables = TABLES.get_or_init(Default::default).lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, table)) = tables.iter().find(|(bits, _)| *bits == ratio.to_bits()) {
        return table;
    }
    let table: &'static [f64] =
        Box::leak((-TABLE_REACH..=TABLE_REACH).map(|l| ratio.powi(l)).collect::<Vec<f64>>().into_boxed_slice());
    tables.push((ratio.to_bits(), table));
    table
}

impl Default for ProfileGrid {
    fn default() -> Self {
        ProfileGrid::new(DEFAULT_PROFILE_RESOLUTION)
    }
}

impl ProfileGrid {
    /// Steps a deck may give: 0 (every rise), or from 0.001 to 10 (a level per factor 11).
    pub const ALLOWED: &'static str = "0 (every rise, exact values) or 0.001 <= step <= 10 (relative, e.g. 0.05 = 5 %)";

    /// The grid of relative step `step` (validated by the deck: [`ProfileGrid::valid`]).
    pub fn new(step: f64) -> Self {
        ProfileGrid { step, ratio: 1.0 + step, ln_ratio: step.ln_1p(), levels: level_table(1.0 + step) }
    }

    pub fn valid(step: f64) -> bool {
        step == 0.0 || (0.001..=10.0).contains(&step)
    }

    pub fn step(&self) -> f64 {
        self.step
    }

    /// Level `l`, a power of the ratio (exact where it can be: the powers of 2 of step 1).
    fn level(&self, l: f64) -> f64 {
        let l = l as i32;
        match l.checked_add(TABLE_REACH).and_then(|i| usize::try_from(i).ok()) {
            Some(i) if i < self.levels.len() => self.levels[i],
            _ => self.ratio.powi(l),
        }
    }

    /// The index of the largest level at or below `a > 0` (`None` where no finite, positive level is).
    fn index_at_or_below(&self, a: f64) -> Option<f64> {
        let mut l = (a.ln() / self.ln_ratio).floor();
        if !l.is_finite() {
            return None;
        }
        // ln and exp round: step to the level the comparison with `a` itself gives.
        while self.level(l) > a {
            l -= 1.0;
        }
        while self.level(l + 1.0) <= a {
            l += 1.0;
        }
        (self.level(l) > 0.0).then_some(l)
    }

    /// A new running maximum `a` after the onset, `next_kept` the bar it must pass (-inf before the
    /// first point): the value to record if it adds a point (the first exact, later ones the level at
    /// or below `a`; `a` itself with step 0 or where no level is), and the bar for the next point (the
    /// next level above the value recorded). Never more than `a`, so an alarm replayed from the points
    /// is never earlier than the statistic's.
    pub fn keep(&self, next_kept: &mut f64, a: f64) -> Option<f64> {
        if !(a > *next_kept) {
            return None;
        }
        let first = *next_kept == f64::NEG_INFINITY;
        let l = if self.step == 0.0 || !(a > 0.0) || !a.is_finite() { None } else { self.index_at_or_below(a) };
        let value = match l {
            Some(l) if !first => self.level(l),
            _ => a,
        };
        *next_kept = match l {
            // The next level above the value recorded (`a` itself sits at or above level l).
            Some(l) => self.level(l + 1.0),
            None if self.step != 0.0 && !(a > 0.0) => 0.0,
            None => a,
        };
        Some(value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table gives `powi`'s numbers to the bit, at its ends and past them (where `powi` takes over),
    /// so a profile is the same whichever gives a level; an index off by one would move every point
    /// by one step.
    #[test]
    fn the_level_table_is_powi() {
        for step in [0.05, 1.0, 0.001] {
            let grid = ProfileGrid::new(step);
            for l in [-5000, -4097, -4096, -4095, -1, 0, 1, 7, 4095, 4096, 4097, 5000] {
                assert_eq!(grid.level(l as f64).to_bits(), (1.0 + step).powi(l).to_bits(), "step {step}, level {l}");
            }
            assert_eq!(grid.level(1e12), (1.0 + step).powi(i32::MAX), "saturated index, no overflow");
        }
        assert_eq!(ProfileGrid::new(1.0).level(3.0), 8.0);
        assert!(std::ptr::eq(ProfileGrid::new(0.05).levels, ProfileGrid::default().levels), "one table per step");
    }
}
