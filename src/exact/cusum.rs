//! The exact law of Page's CUSUM on a white Gaussian residual, for checking fdimc's miss-before-the-hazard
//! figures where the statistic has memory (issue 82, item 1). Written for the tests and `fdimc verify`,
//! sharing nothing with fdimc's code (statrs' `erfc` only).
//!
//! The statistic is `g(k) = max(0, g(k-1) + |r(k)| - d)` from `g = 0`, the residual `r(k)` white N(0, 1)
//! before the fault's onset and N(b, 1) from it, as fdimc's `kind = "cusum"` computes it on a gain-0
//! filter. Brook and Evans' (1972) Markov chain: `g`'s range `[0, h + top]` cut into bins of width `w`
//! (`h` a bin edge), an atom at 0; a step moves each bin's mass, taken as spread evenly over the bin, by
//! the increment's exact law `P(|Z + b| - d <= x) = Phi(x + d - b) - Phi(-(x + d) - b)` integrated over
//! the bin in closed form (so the law's kink at `x = -d` costs nothing, wherever it falls). The error
//! falls as `w^2` (checked: it quarters as `w` halves), so two widths and Richardson's step give the
//! answer to well below a Monte Carlo interval's width.

use super::{normal_cdf as phi, normal_pdf};

/// `P(|Z + b| - d <= x)`, `Z ~ N(0, 1)`.
fn increment_cdf(x: f64, drift: f64, bias: f64) -> f64 {
    let y = x + drift;
    if y < 0.0 { 0.0 } else { phi(y - bias) - phi(-y - bias) }
}

/// `int_{-inf}^{x} increment_cdf`: with `u = x + d` and `psi(t) = t Phi(t) + phi(t)` (`psi' = Phi`), it is
/// `psi(u - b) + psi(-u - b) - 2 psi(-b)`.
fn increment_cdf_integral(x: f64, drift: f64, bias: f64) -> f64 {
    let psi = |t: f64| t * phi(t) + normal_pdf(t, 0.0, 1.0);
    let u = x + drift;
    if u < 0.0 { 0.0 } else { psi(u - bias) + psi(-u - bias) - 2.0 * psi(-bias) }
}

/// A CUSUM's window: `before` samples on the fault-free residual, then `window` samples with the bias.
pub struct CusumWindow {
    pub drift: f64,
    pub threshold: f64,
    pub bias: f64,
    pub before: usize,
    pub window: usize,
}

impl CusumWindow {
    /// `P(g(k) <= h for each of the window's samples)`: the fault missed through the window (an alarm
    /// before the onset counts only where `g` is still above `h` in the window, as fdimc's rule has it).
    /// Panics unless the chain has converged (its two widths agree to 1e-3 of the answer) and the mass
    /// lost beyond `h + top` before the onset is below 1e-9 of it (dropping mass can only lower the
    /// answer, by at most that).
    pub fn miss(&self, width: f64, top: f64) -> f64 {
        let (p, lost) = self.extrapolated(width, top);
        assert!(lost < 1e-9 * p, "{lost} of the mass passed h + top = {} before the onset", self.threshold + top);
        p
    }

    /// Richardson's extrapolation of the chain at bins of width at most `width` and half that, and the
    /// mass lost before the onset.
    pub fn extrapolated(&self, width: f64, top: f64) -> (f64, f64) {
        let bins = (self.threshold / width).ceil() as usize;
        let ((coarse, _), (fine, lost)) = (self.chain(bins, top), self.chain(2 * bins, top));
        assert!(
            (coarse - fine).abs() < 1e-3 * fine,
            "the chain has not converged: {coarse} at {bins} bins, {fine} at twice"
        );
        ((4.0 * fine - coarse) / 3.0, lost)
    }

    /// The chain with `inside` bins of equal width below the threshold and more up to `h + top`: the
    /// probability, and the mass that passed `h + top` before the onset (dropped).
    pub fn chain(&self, inside: usize, top: f64) -> (f64, f64) {
        let w = self.threshold / inside as f64;
        let n = inside + (top / w - 1e-9).ceil() as usize;
        let step = |p: &[f64], bias: f64| -> Vec<f64> {
            let cdf = |x: f64| increment_cdf(x, self.drift, bias);
            let integral = |x: f64| increment_cdf_integral(x, self.drift, bias);
            // Mass spread evenly over bin i reaches bin j with a probability that depends on j - i only
            // (index j - i + n): the increment's law averaged over the source bin, exactly.
            let between: Vec<f64> = (0..2 * n + 1)
                .map(|s| {
                    let offset = s as f64 - n as f64;
                    (integral((offset + 1.0) * w) - 2.0 * integral(offset * w) + integral((offset - 1.0) * w)) / w
                })
                .collect();
            let mut next = vec![0.0; n + 1];
            next[0] = p[0] * cdf(0.0);
            for j in 0..n {
                next[j + 1] = p[0] * (cdf((j as f64 + 1.0) * w) - cdf(j as f64 * w));
            }
            for i in 0..n {
                let mass = p[i + 1];
                if mass == 0.0 {
                    continue;
                }
                next[0] += mass * (integral(-(i as f64) * w) - integral(-(i as f64 + 1.0) * w)) / w;
                for j in 0..n {
                    next[j + 1] += mass * between[j + n - i];
                }
            }
            next
        };
        let mut p = vec![0.0; n + 1];
        p[0] = 1.0;
        for _ in 0..self.before {
            p = step(&p, 0.0);
        }
        let lost = 1.0 - p.iter().sum::<f64>();
        for _ in 0..self.window {
            p = step(&p, self.bias);
            p[inside + 1..].iter_mut().for_each(|m| *m = 0.0);
        }
        (p.iter().sum(), lost)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chain against a case it must get exactly (one step from 0 stays below `h` with probability
    /// `P(|Z + b| - d <= h)`, whatever the width), against its own order of convergence, and against the
    /// reference script's NumPy chain, another scheme (each bin's mass at its midpoint) on the same range
    /// (`scripts/reference/cusum_miss_numpy.py`: 0.3107492003 and 2.440938496e-4, extrapolated).
    #[test]
    fn the_cusum_chain_meets_one_step_and_numpy() {
        let one = CusumWindow { drift: 1.0, threshold: 4.0, bias: 1.0, before: 0, window: 1 };
        assert!((one.chain(200, 8.0).0 - increment_cdf(4.0, 1.0, 1.0)).abs() < 1e-14);
        let small = CusumWindow { drift: 1.0, threshold: 4.0, bias: 1.0, before: 100, window: 20 };
        // Second order: the change from 0.04 to 0.02 is four times that from 0.02 to 0.01, to 1 %.
        let [a, b, c] = [100, 200, 400].map(|bins| small.chain(bins, 8.0).0);
        assert!(((a - b) / (b - c) - 4.0).abs() < 0.04, "{a} {b} {c}");
        // The script's range (h + 8 and h + 6), which drops 9e-5 of the mass before the onset on the first.
        let (p, lost) = small.extrapolated(0.01, 8.0);
        assert!((p - 0.3107492003).abs() < 2e-9 && (8e-5..1e-4).contains(&lost), "{p} {lost}");
        let rare = CusumWindow { drift: 1.0, threshold: 25.0, bias: 3.0, before: 100, window: 20 };
        let (p, _) = rare.extrapolated(0.02, 6.0);
        assert!((p / 2.440938496e-4 - 1.0).abs() < 1e-6, "{p}");
        // The whole range (h + 30, nothing dropped) raises the answer by less than the mass the script drops.
        let whole = small.miss(0.03, 30.0);
        assert!(whole >= 0.3107492003 && whole - 0.3107492003 < 9e-5, "{whole}");
    }
}
