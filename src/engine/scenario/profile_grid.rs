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
    inv_log2_ratio: f64,
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
        let ratio = 1.0 + step;
        ProfileGrid {
            step,
            ratio,
            ln_ratio: step.ln_1p(),
            inv_log2_ratio: 1.0 / ratio.log2(),
            levels: level_table(ratio),
        }
    }

    pub fn valid(step: f64) -> bool {
        step == 0.0 || (0.001..=10.0).contains(&step)
    }

    pub fn step(&self) -> f64 {
        self.step
    }

    /// Level `l`, a power of the ratio (exact where it can be: the powers of 2 of step 1).
    fn level(&self, l: i32) -> f64 {
        match usize::try_from(i64::from(l) + i64::from(TABLE_REACH)) {
            Ok(i) if i < self.levels.len() => self.levels[i],
            _ => self.ratio.powi(l),
        }
    }

    /// The levels around `a > 0`: the largest at or below it and the next one up, and the former's
    /// index (`None` where no finite, positive level is at or below `a`). `from`: an index known to be
    /// at or below the answer, from which a few steps up usually reach it.
    fn bracket(&self, a: f64, from: Option<i32>) -> Option<(f64, f64, i32)> {
        if let Some(mut l) = from {
            // The bar just passed is level `l`, and a statistic rarely rises past more than a level or
            // two between points; past a few, the guess below is cheaper.
            for _ in 0..4 {
                let above = self.level(l + 1);
                if above > a {
                    return Some((self.level(l), above, l));
                }
                l += 1;
            }
        }
        // A first guess at the index; the comparisons below make it exact, whichever guess they start
        // from (the levels rise strictly). The rough logarithm is within a fraction of a level of `ln`'s
        // and a tenth of its cost, on the magnitudes a statistic has; beyond them `ln` guesses.
        let guess =
            if (1e-300..1e300).contains(&a) { rough_log2(a) * self.inv_log2_ratio } else { a.ln() / self.ln_ratio };
        if !guess.is_finite() {
            return None;
        }
        // Floor without a libm call (off by one at negative integers, which the steps below absorb).
        let mut l = guess as i32 - i32::from(guess < 0.0);
        let mut below = self.level(l);
        while below > a {
            l -= 1;
            below = self.level(l);
        }
        let mut above = self.level(l + 1);
        while above <= a {
            l += 1;
            below = above;
            above = self.level(l + 1);
        }
        (below > 0.0).then_some((below, above, l))
    }

    /// A new running maximum `a` after the onset, `next_kept` the bar it must pass (-inf before the
    /// first point) and `next_level` that bar's level index ([`NO_LEVEL`] where it is not a level;
    /// kept beside the bar so the next point needs no logarithm): the value to record if it adds a
    /// point (the first exact, later ones the level at or below `a`; `a` itself with step 0 or where
    /// no level is), and the bar for the next point (the next level above the value recorded). Never
    /// more than `a`, so an alarm replayed from the points is never earlier than the statistic's.
    #[inline]
    pub fn keep(&self, next_kept: &mut f64, next_level: &mut i32, a: f64) -> Option<f64> {
        // Most calls add no point: that test inline, the point's work out of line.
        if a > *next_kept { Some(self.add_point(next_kept, next_level, a)) } else { None }
    }

    #[inline(never)]
    fn add_point(&self, next_kept: &mut f64, next_level: &mut i32, a: f64) -> f64 {
        let first = *next_kept == f64::NEG_INFINITY;
        let from = (*next_level != NO_LEVEL).then_some(*next_level);
        let levels = if self.step == 0.0 || !(a > 0.0) || !a.is_finite() { None } else { self.bracket(a, from) };
        let value = match levels {
            Some((below, _, _)) if !first => below,
            _ => a,
        };
        (*next_kept, *next_level) = match levels {
            // The next level above the value recorded (`a` itself sits at or above the one below).
            Some((_, above, l)) => (above, l + 1),
            None if self.step != 0.0 && !(a > 0.0) => (0.0, NO_LEVEL),
            None => (a, NO_LEVEL),
        };
        value
    }
}

/// The level index of a profile bar that is not a level (before the first point, 0, or a value off
/// the grid).
pub const NO_LEVEL: i32 = i32::MIN;

/// `log2(a)` for a positive, normal `a`, to within 0.008: the exponent, and the chord of `log2` over the
/// mantissa lifted by a parabola.
#[inline]
fn rough_log2(a: f64) -> f64 {
    const MANTISSA: u64 = (1 << 52) - 1;
    let bits = a.to_bits();
    let exponent = ((bits >> 52) & 0x7ff) as i32 - 1023;
    let m = f64::from_bits((bits & MANTISSA) | 1.0f64.to_bits()) - 1.0;
    f64::from(exponent) + m + 0.3466 * m * (1.0 - m)
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
                assert_eq!(grid.level(l).to_bits(), (1.0 + step).powi(l).to_bits(), "step {step}, level {l}");
            }
            assert_eq!(grid.level(i32::MAX), (1.0 + step).powi(i32::MAX), "no overflow at the last index");
        }
        assert_eq!(ProfileGrid::new(1.0).level(3), 8.0);
        assert!(std::ptr::eq(ProfileGrid::new(0.05).levels, ProfileGrid::default().levels), "one table per step");
    }

    /// The levels around a value are the same whether the search starts from the rough logarithm, from
    /// `ln` or from a bar below it (the profiles of a study do not change with the start): on levels,
    /// one bit either side of them, between them, and at the magnitudes where the guess switches to `ln`.
    #[test]
    fn the_bracket_is_the_one_ln_finds() {
        let by_ln = |grid: &ProfileGrid, a: f64| {
            let mut l = (a.ln() / grid.ln_ratio).floor() as i32;
            while grid.level(l) > a {
                l -= 1;
            }
            while grid.level(l + 1) <= a {
                l += 1;
            }
            (grid.level(l) > 0.0).then(|| (grid.level(l), grid.level(l + 1)))
        };
        let mut checked = 0;
        for step in [0.05, 0.02, 1.0, 0.001, 10.0] {
            let grid = ProfileGrid::new(step);
            let mut values = vec![5e-324, 1e-310, 1e-300, 0.999e-300, 1e300, 1.001e300, f64::MAX, 1.0, 2.0, 0.5];
            for l in (-3000..3000).step_by(7) {
                let level = grid.level(l);
                if level > 0.0 && level.is_finite() {
                    let bits = level.to_bits();
                    values.extend([
                        level,
                        f64::from_bits(bits - 1),
                        f64::from_bits(bits + 1),
                        level * (1.0 + step / 2.0),
                    ]);
                }
            }
            for a in values {
                let bracket = grid.bracket(a, None);
                assert_eq!(bracket.map(|(below, above, _)| (below, above)), by_ln(&grid, a), "step {step}, a {a:e}");
                if let Some((below, above, l)) = bracket {
                    assert!(below <= a && a < above, "step {step}, a {a:e}: {below:e} {above:e}");
                    assert_eq!((grid.level(l), grid.level(l + 1)), (below, above), "step {step}, a {a:e}");
                    // From a bar at or below it, near (the usual next point) or far (the guess).
                    for back in [0, 1, 3, 4, 5, 40] {
                        assert_eq!(grid.bracket(a, Some(l - back)), bracket, "step {step}, a {a:e}, {back} below");
                    }
                }
                checked += 1;
            }
        }
        assert!(checked > 5000, "{checked} values");
        // The rough logarithm's promise, over a decade of mantissas and exponents.
        for k in 0..10_000 {
            let a = (1.0 + k as f64 / 10_000.0) * 2f64.powi(k % 600 - 300);
            assert!((rough_log2(a) - a.log2()).abs() < 0.008, "{a:e}");
        }
    }
}
