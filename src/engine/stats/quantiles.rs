//! Quantiles of a stream in bounded memory, mergeable across groups: exact while a group holds at most
//! [`EXACT_VALUES`] values (linear interpolation between order statistics, as polars' `Linear`), then a
//! log-bucket sketch whose answer is within [`RELATIVE_ACCURACY`] (relative) of the value at the
//! requested rank (a DDSketch: bucket `i` holds the values in `(gamma^(i-1), gamma^i]`, `gamma =
//! (1 + a) / (1 - a)`, and answers with `2 gamma^i / (gamma + 1)`). Summaries of 10^8 trials therefore
//! need as much memory for their delay percentiles as summaries of 10^4.

use std::collections::BTreeMap;

/// Values a group keeps exactly before it switches to the sketch.
pub const EXACT_VALUES: usize = 4096;
/// Relative accuracy of the sketch.
pub const RELATIVE_ACCURACY: f64 = 0.005;

#[derive(Debug, Clone, Default)]
pub struct Quantiles {
    exact: Vec<f64>,
    sketch: Option<Sketch>,
}

#[derive(Debug, Clone, Default)]
struct Sketch {
    positive: BTreeMap<i32, u64>,
    negative: BTreeMap<i32, u64>,
    zeros: u64,
}

fn gamma() -> f64 {
    (1.0 + RELATIVE_ACCURACY) / (1.0 - RELATIVE_ACCURACY)
}

impl Sketch {
    fn add(&mut self, v: f64, count: u64) {
        let magnitude = v.abs();
        if magnitude < f64::MIN_POSITIVE {
            self.zeros += count;
            return;
        }
        let index = (magnitude.ln() / gamma().ln()).ceil() as i32;
        let side = if v > 0.0 { &mut self.positive } else { &mut self.negative };
        *side.entry(index).or_insert(0) += count;
    }

    fn merge(&mut self, other: &Sketch) {
        for (side, theirs) in [(&mut self.positive, &other.positive), (&mut self.negative, &other.negative)] {
            for (i, c) in theirs {
                *side.entry(*i).or_insert(0) += c;
            }
        }
        self.zeros += other.zeros;
    }

    fn count(&self) -> u64 {
        self.zeros + self.positive.values().sum::<u64>() + self.negative.values().sum::<u64>()
    }

    /// The value at 0-based rank `rank` in ascending order.
    fn at_rank(&self, rank: u64) -> f64 {
        let g = gamma();
        let value = |i: i32| 2.0 * g.powi(i) / (g + 1.0);
        let mut seen = 0;
        // Ascending: the most negative first (largest magnitude), then zeros, then positives.
        for (i, c) in self.negative.iter().rev() {
            seen += c;
            if rank < seen {
                return -value(*i);
            }
        }
        seen += self.zeros;
        if rank < seen {
            return 0.0;
        }
        for (i, c) in &self.positive {
            seen += c;
            if rank < seen {
                return value(*i);
            }
        }
        self.positive.keys().next_back().map_or(0.0, |i| value(*i))
    }
}

impl Quantiles {
    /// Adds a value; NaN is ignored (it has no rank).
    pub fn push(&mut self, v: f64) {
        if v.is_nan() {
            return;
        }
        match &mut self.sketch {
            Some(s) => s.add(v, 1),
            None => {
                self.exact.push(v);
                if self.exact.len() > EXACT_VALUES {
                    self.switch_to_sketch();
                }
            }
        }
    }

    fn switch_to_sketch(&mut self) {
        let mut s = self.sketch.take().unwrap_or_default();
        for v in self.exact.drain(..) {
            s.add(v, 1);
        }
        self.exact = Vec::new();
        self.sketch = Some(s);
    }

    /// Adds every value of `other`.
    pub fn merge(&mut self, other: &Quantiles) {
        match (&mut self.sketch, &other.sketch) {
            (_, Some(theirs)) => {
                self.switch_to_sketch();
                if let Some(s) = &mut self.sketch {
                    s.merge(theirs);
                }
                for &v in &other.exact {
                    self.push(v);
                }
            }
            (_, None) => {
                for &v in &other.exact {
                    self.push(v);
                }
            }
        }
    }

    pub fn count(&self) -> u64 {
        self.exact.len() as u64 + self.sketch.as_ref().map_or(0, Sketch::count)
    }

    /// Whether the answers are exact (the group never held more than [`EXACT_VALUES`] values).
    pub fn is_exact(&self) -> bool {
        self.sketch.is_none()
    }

    /// The `p` quantile (0 <= p <= 1); `None` without values.
    pub fn quantile(&self, p: f64) -> Option<f64> {
        let n = self.count();
        if n == 0 {
            return None;
        }
        match &self.sketch {
            Some(s) => Some(s.at_rank(((n - 1) as f64 * p).round() as u64)),
            None => {
                let mut v = self.exact.clone();
                v.sort_by(f64::total_cmp);
                let h = (n - 1) as f64 * p;
                let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
                Some(v[lo] + (h - lo as f64) * (v[hi] - v[lo]))
            }
        }
    }

    /// The median; `None` without values.
    pub fn median(&self) -> Option<f64> {
        self.quantile(0.5)
    }

    /// A distribution-free interval for the median (the sign test's, normal approximation of the
    /// binomial): order statistics `floor(n/2 - z sqrt(n)/2)` and `ceil(1 + n/2 + z sqrt(n)/2)`, clamped
    /// to 1..n (exact values while the group is exact, the sketch's otherwise); `None` without values.
    pub fn median_interval(&self, z: f64) -> Option<(f64, f64)> {
        let n = self.count();
        if n == 0 {
            return None;
        }
        let half = z * (n as f64).sqrt() / 2.0;
        let lo = ((n as f64 / 2.0 - half).floor() as u64).clamp(1, n);
        let hi = ((1.0 + n as f64 / 2.0 + half).ceil() as u64).clamp(1, n);
        let at = |rank: u64| self.quantile(if n == 1 { 0.0 } else { (rank - 1) as f64 / (n - 1) as f64 });
        Some((at(lo)?, at(hi)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// n = 100: the 95 % sign-test interval of the median is the 40th to 61st order statistic (its exact
    /// binomial coverage 0.965); n = 1 gives the value itself; none without values.
    #[test]
    fn median_interval_by_order_statistics() {
        let mut q = Quantiles::default();
        assert_eq!(q.median_interval(1.96), None);
        q.push(7.0);
        assert_eq!(q.median_interval(1.96), Some((7.0, 7.0)));
        let mut q = Quantiles::default();
        for v in (1..=100).rev() {
            q.push(v as f64);
        }
        assert_eq!(q.median_interval(1.96), Some((40.0, 61.0)));
    }

    /// Exact quantiles interpolate between order statistics like polars' `QuantileMethod::Linear`.
    #[test]
    fn exact_quantiles_interpolate_linearly() {
        let mut q = Quantiles::default();
        assert_eq!(q.median(), None);
        for v in [4.0, 1.0, 3.0, 2.0] {
            q.push(v);
        }
        assert_eq!(q.median(), Some(2.5));
        assert_eq!(q.quantile(0.9), Some(3.7));
        assert_eq!(q.quantile(0.0), Some(1.0));
        assert_eq!(q.quantile(1.0), Some(4.0));
        q.push(f64::NAN);
        assert_eq!(q.count(), 4);
    }

    /// Past the exact capacity the answer stays within the stated relative accuracy of the true order
    /// statistic, for a wide, skewed, signed distribution, and merging two halves gives the same as one
    /// stream.
    #[test]
    fn the_sketch_answers_within_its_relative_accuracy_and_merges() {
        let values: Vec<f64> = (0..100_000).map(|i| ((i * 7919) % 100_000) as f64 * 1e-3 - 5.0).collect();
        let (mut whole, mut a, mut b) = (Quantiles::default(), Quantiles::default(), Quantiles::default());
        for (i, &v) in values.iter().enumerate() {
            whole.push(v);
            if i % 2 == 0 { a.push(v) } else { b.push(v) }
        }
        a.merge(&b);
        assert!(!whole.is_exact());
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        for p in [0.01, 0.1, 0.5, 0.9, 0.99] {
            let truth = sorted[((sorted.len() - 1) as f64 * p).round() as usize];
            for q in [&whole, &a] {
                let got = q.quantile(p).unwrap();
                assert!((got - truth).abs() <= RELATIVE_ACCURACY * truth.abs() + 1e-12, "p {p}: {got} vs {truth}");
            }
        }
        assert_eq!(whole.count(), 100_000);
        assert_eq!(a.count(), 100_000);
    }
}
