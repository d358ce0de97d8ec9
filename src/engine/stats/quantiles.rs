//! Quantiles of a stream in bounded memory, mergeable across groups: exact while a group holds at most
//! [`EXACT_VALUES`] values (linear interpolation between order statistics, as polars' `Linear`), then a
//! log-bucket sketch whose answer is within [`RELATIVE_ACCURACY`] (relative) of the value at the
//! requested rank (a DDSketch: bucket `i` holds the values in `(gamma^(i-1), gamma^i]`, `gamma =
//! (1 + a) / (1 - a)`, and answers with `2 gamma^i / (gamma + 1)`). Summaries of 10^8 trials therefore
//! need as much memory for their delay percentiles as summaries of 10^4.

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
    positive: Buckets,
    negative: Buckets,
    zeros: u64,
}

/// One side's bucket counts, held densely from below the lowest bucket seen to the highest: adding a
/// value is an index into a vector (a group's values span few buckets: 1 ms to 100 s is 1,152), where a
/// map's search took a fifth of a large summary's time. At most about 141,000 buckets (8 bytes each)
/// span every normal double.
#[derive(Debug, Clone, Default)]
struct Buckets {
    /// The bucket index of `counts[0]`.
    lowest: i32,
    counts: Vec<u64>,
}

impl Buckets {
    fn add(&mut self, index: i32, count: u64) {
        if self.counts.is_empty() {
            self.lowest = index;
        } else if index < self.lowest {
            // Room below for as many again, so that a descending stream grows the vector in O(1) per value.
            let grow = ((self.lowest - index) as usize).max(self.counts.len());
            self.counts.splice(0..0, std::iter::repeat_n(0, grow));
            self.lowest -= grow as i32;
        }
        let at = (index - self.lowest) as usize;
        if at >= self.counts.len() {
            self.counts.resize(at + 1, 0);
        }
        self.counts[at] += count;
    }

    /// The buckets that hold values, `(index, count)`, ascending.
    fn iter(&self) -> impl DoubleEndedIterator<Item = (i32, u64)> + '_ {
        (self.counts.iter().enumerate()).filter(|(_, c)| **c > 0).map(|(k, c)| (self.lowest + k as i32, *c))
    }

    fn total(&self) -> u64 {
        self.counts.iter().sum()
    }
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
        side.add(index, count);
    }

    fn merge(&mut self, other: &Sketch) {
        for (side, theirs) in [(&mut self.positive, &other.positive), (&mut self.negative, &other.negative)] {
            for (i, c) in theirs.iter() {
                side.add(i, c);
            }
        }
        self.zeros += other.zeros;
    }

    fn count(&self) -> u64 {
        self.zeros + self.positive.total() + self.negative.total()
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
                return -value(i);
            }
        }
        seen += self.zeros;
        if rank < seen {
            return 0.0;
        }
        for (i, c) in self.positive.iter() {
            seen += c;
            if rank < seen {
                return value(i);
            }
        }
        self.positive.iter().next_back().map_or(0.0, |(i, _)| value(i))
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

    /// The sketch answers with the bucket of the true order statistic, `sign 2 gamma^i / (gamma + 1)`
    /// with `i = ceil(ln|x| / ln gamma)` (the closed form of the module docs), at every rank tried: for
    /// values arriving in descending order over 1e-200 to 1e200 on both signs (each new value below the
    /// lowest bucket so far), with zeros, and after merging a stream that extends the range both ways.
    #[test]
    fn the_sketch_gives_the_bucket_of_the_true_order_statistic_over_any_range() {
        let g = (1.0 + RELATIVE_ACCURACY) / (1.0 - RELATIVE_ACCURACY);
        let bucket = |x: f64| {
            if x.abs() < f64::MIN_POSITIVE {
                0.0
            } else {
                x.signum() * 2.0 * g.powi((x.abs().ln() / g.ln()).ceil() as i32) / (g + 1.0)
            }
        };
        let magnitudes: Vec<f64> = (0..6000).map(|k| 10f64.powf(200.0 - k as f64 / 15.0)).collect();
        let mut values: Vec<f64> = magnitudes.iter().flat_map(|&m| [m, -1.0 / m]).collect();
        values.extend([0.0; 7]);
        let (mut q, mut other) = (Quantiles::default(), Quantiles::default());
        values.iter().for_each(|&v| q.push(v));
        let wider = [1e250, -1e250, 1e-250, -1e-250, 3.0];
        wider.iter().for_each(|&v| other.push(v));
        for (stream, merged) in [(&q, false), (&q.clone(), true)] {
            let mut stream = stream.clone();
            let mut all = values.clone();
            if merged {
                stream.merge(&other);
                all.extend(wider);
            }
            all.sort_by(f64::total_cmp);
            assert_eq!(stream.count(), all.len() as u64);
            for p in [0.0, 1e-4, 0.01, 0.25, 0.4999, 0.5, 0.5001, 0.75, 0.99, 1.0] {
                let truth = all[((all.len() - 1) as f64 * p).round() as usize];
                assert_eq!(stream.quantile(p), Some(bucket(truth)), "p {p}, merged {merged}: truth {truth}");
            }
        }
    }
}
