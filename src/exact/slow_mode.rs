//! The exact miss before the hazard of a residual whose filter leaves a slow mode (issue 82, item 1),
//! for checking fdimc's figure where the residual itself has memory. Written for the tests and `fdimc
//! verify`, sharing nothing with fdimc's code (statrs' `erfc` only).
//!
//! The residual is `r(k) = e(k) + v(k)`, plus the bias `b` from the onset sample `k0`, `v` white
//! N(0, `sensor_sigma^2`), and `e` the state error of a gain-0 filter on a one-state plant with process
//! noise: `e(k+1) = phi e(k) + w(k)`, `w ~ N(0, q)`, from `e(0) = 0`. Given `e`'s path the samples
//! alarm independently, so the fault is missed through the window with probability `E[prod g(e(k))]`,
//! `g(e) = P(|e + v + b| <= c) = 1 - Q((c - b - e) / s) - Q((c + b + e) / s)`. `e(k0)` is
//! N(0, `q (1 - phi^(2 k0)) / (1 - phi^2)`); its density is carried through the window on a grid by the Gaussian kernel (trapezoid rule
//! over nine stationary standard deviations, where the kernel's own spread is many grid steps, so the
//! rule converges faster than any power of the step). Checked against its one-sample closed form, its
//! own convergence and `scripts/reference/slow_mode_miss_numpy.py` by its own test.

use super::{normal_cdf, normal_pdf};

/// A bias fault's window on a residual with one slow mode.
pub struct SlowModeWindow {
    /// `e`'s factor per step, `exp(lambda dt)`.
    pub phi: f64,
    /// Process noise variance per step.
    pub q: f64,
    pub sensor_sigma: f64,
    pub threshold: f64,
    /// The onset sample (the samples before it are fault-free; alarms there do not matter).
    pub onset: usize,
    pub window: usize,
}

/// The density one step on: `kept` (the density times the no-alarm weight) through the kernel.
fn carried(kept: &[f64], kernel: &[f64]) -> Vec<f64> {
    let points = kept.len();
    let mut density = vec![0.0; points];
    for (i, &mass) in kept.iter().enumerate() {
        let row = &kernel[i * points..(i + 1) * points];
        density.iter_mut().zip(row).for_each(|(d, k)| *d += mass * k);
    }
    density
}

/// `ln` P(no alarm through `samples` samples), `density` the first sample's (integrating to 1), each
/// sample alarming with probability `alarm` at the grid's points and the density kept carried by `kernel`
/// to the next (trapezoid rule, step `dx`). Summed as `ln(1 - h(k))` of each sample's hazard `h(k)` (its
/// alarm given none before, from the alarm's own tail): `ln` of a survival near 1 would lose a hazard of
/// 1e-17. Once the hazard changes by under 1e-11 of itself from one sample to the next (the density's
/// shape has settled: the kernel's leading eigenvalue), the samples left each take it: an hour's 360,000
/// samples without carrying every one (the drift left moves the hour's logarithm by about 1e-9 of itself).
fn log_survival(mut density: Vec<f64>, alarm: &[f64], kernel: &[f64], dx: f64, samples: usize) -> f64 {
    let (mut log_s, mut before) = (0.0, f64::NAN);
    for k in 0..samples {
        let mass: f64 = density.iter().sum::<f64>() * dx;
        let hazard = density.iter().zip(alarm).map(|(f, a)| f * a).sum::<f64>() * dx / mass;
        log_s += (-hazard).ln_1p();
        if k + 1 == samples {
            break;
        }
        if (hazard / before - 1.0).abs() < 1e-11 {
            return log_s + (-hazard).ln_1p() * (samples - 1 - k) as f64;
        }
        before = hazard;
        let kept: Vec<f64> = density.iter().zip(alarm).map(|(f, a)| f * (1.0 - a)).collect();
        density = carried(&kept, kernel);
    }
    log_s
}

impl SlowModeWindow {
    /// The grid over nine stationary standard deviations of `e`, its step, and the kernel:
    /// `kernel[i * points + j]` from `x_i` to `x_j` times the trapezoid's weight of `x_j` (the ends'
    /// halves are below 1e-17 of the density there and left out).
    fn grid(&self, points: usize) -> (Vec<f64>, f64, Vec<f64>) {
        let spread = 9.0 * (self.q / (1.0 - self.phi * self.phi)).sqrt();
        let dx = 2.0 * spread / (points - 1) as f64;
        let x: Vec<f64> = (0..points).map(|i| -spread + dx * i as f64).collect();
        let step_sd = self.q.sqrt();
        let kernel: Vec<f64> =
            x.iter().flat_map(|&from| x.iter().map(move |&to| normal_pdf(to, self.phi * from, step_sd) * dx)).collect();
        (x, dx, kernel)
    }

    /// `P(|e + v + b| > c)` given `e`, from the two tails: `1 - Phi(c - b - e) + Phi(-c - b - e)` would
    /// lose the tail's digits where alarms are rare (1e-9 a sample at threshold 6).
    fn alarm(&self, e: f64, bias: f64) -> f64 {
        let tail = |z: f64| normal_cdf(-z / self.sensor_sigma);
        tail(self.threshold - bias - e) + tail(self.threshold + bias + e)
    }

    /// `e(onset)`'s variance.
    pub fn onset_variance(&self) -> f64 {
        self.q * (1.0 - self.phi.powi(2 * self.onset as i32)) / (1.0 - self.phi * self.phi)
    }

    /// The miss for bias `b` on a grid of `points` points.
    pub fn miss(&self, bias: f64, points: usize) -> f64 {
        self.miss_sizes(&[bias], points)[0]
    }

    /// The miss for each bias of `biases`, on one grid (its kernel built once).
    pub fn miss_sizes(&self, biases: &[f64], points: usize) -> Vec<f64> {
        let (x, dx, kernel) = self.grid(points);
        let onset_sd = self.onset_variance().sqrt();
        let onset: Vec<f64> = x.iter().map(|&e| normal_pdf(e, 0.0, onset_sd)).collect();
        biases
            .iter()
            .map(|&b| {
                let alarm: Vec<f64> = x.iter().map(|&e| self.alarm(e, b)).collect();
                log_survival(onset.clone(), &alarm, &kernel, dx, self.window).exp()
            })
            .collect()
    }

    /// The fault-free residual's probability of an alarm in its first `samples` samples from `e(0) = 0`.
    pub fn fault_free_alarm(&self, samples: usize, points: usize) -> f64 {
        -self.fault_free_log_no_alarm(samples, points).exp_m1()
    }

    /// `ln` P(no alarm) of the fault-free residual through its first `samples` samples from `e(0) = 0`
    /// (the onset, window and bias not used): the first sample alarms by `|v| > c` alone, `e(1)` is
    /// N(0, q), and the density is carried on as in [`Self::miss_sizes`] (an hour's samples by the
    /// settled hazard, as `log_survival` carries it).
    pub fn fault_free_log_no_alarm(&self, samples: usize, points: usize) -> f64 {
        let first = (-self.alarm(0.0, 0.0)).ln_1p();
        if samples == 1 {
            return first;
        }
        let (x, dx, kernel) = self.grid(points);
        let alarm: Vec<f64> = x.iter().map(|&e| self.alarm(e, 0.0)).collect();
        let step_sd = self.q.sqrt();
        let density: Vec<f64> = x.iter().map(|&e| normal_pdf(e, 0.0, step_sd)).collect();
        first + log_survival(density, &alarm, &kernel, dx, samples - 1)
    }

    /// The miss with the bias uniform on `[lo, hi]` (Simpson's rule on 41 points).
    pub fn miss_uniform(&self, lo: f64, hi: f64, points: usize) -> f64 {
        let h = (hi - lo) / 40.0;
        let biases: Vec<f64> = (0..=40).map(|i| lo + h * i as f64).collect();
        let misses = self.miss_sizes(&biases, points);
        let weighted: f64 = misses
            .iter()
            .enumerate()
            .map(|(i, m)| {
                m * if i == 0 || i == 40 {
                    1.0
                } else if i % 2 == 1 {
                    4.0
                } else {
                    2.0
                }
            })
            .sum();
        weighted * h / 3.0 / (hi - lo)
    }
}

/// The deck of the slow-mode miss test: `exp(-0.01)` per 0.01 s step, `q = 0.141067^2`, unit sensor
/// noise, threshold 4, onset at sample 100, a window of 20 samples.
pub fn slow_mode_window() -> SlowModeWindow {
    SlowModeWindow {
        phi: (-0.01f64).exp(),
        q: 0.141067 * 0.141067,
        sensor_sigma: 1.0,
        threshold: 4.0,
        onset: 100,
        window: 20,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid against a case it must get exactly (one sample: `e + v` is N(0, 1 + P), so the miss is
    /// `Phi((c - b) / sd) - Phi((-c - b) / sd)`), against itself on a finer grid, and against the reference
    /// script's NumPy (`scripts/reference/slow_mode_miss_numpy.py`: 0.531727682059 at b = 2, 0.526233355692
    /// with b uniform on [1, 3]; fault-free at threshold 6, 1.908491708269e-3 in 200 samples and
    /// 3.615708384512e-2 in 2,000; at threshold 8, 1.114097939833e-6 in 200 and 5.708425809165e-3 in an
    /// hour's 360,000; two samples: `1 - (1 - 2 Q(c)) (1 - 2 Q(c / sqrt(1 + q)))`); and the memory matters: each sample alone would give 0.2197543974.
    #[test]
    fn the_slow_mode_window_meets_its_closed_form_and_numpy() {
        let one = SlowModeWindow { window: 1, ..slow_mode_window() };
        let sd = (1.0 + one.onset_variance()).sqrt();
        let closed = normal_cdf((4.0 - 2.0) / sd) - normal_cdf((-4.0 - 2.0) / sd);
        assert!((one.miss(2.0, 801) - closed).abs() < 1e-11, "{} {closed}", one.miss(2.0, 801));
        let window = slow_mode_window();
        let (coarse, fine) = (window.miss(2.0, 401), window.miss(2.0, 801));
        assert!((coarse - fine).abs() < 1e-11, "{coarse} {fine}");
        assert!((fine - 0.531727682059).abs() < 1e-10, "{fine}");
        let uniform = window.miss_uniform(1.0, 3.0, 401);
        assert!((uniform - 0.526233355692).abs() < 1e-10, "{uniform}");
        let fault_free = SlowModeWindow { threshold: 6.0, ..slow_mode_window() };
        let (segment, flight) = (fault_free.fault_free_alarm(200, 801), fault_free.fault_free_alarm(2000, 801));
        // SciPy's and statrs' tails part by about 3e-11.
        assert!((segment / 1.908491708269e-3 - 1.0).abs() < 1e-9, "{segment}");
        assert!((flight / 3.615708384512e-2 - 1.0).abs() < 1e-9, "{flight}");
        // Two samples: the first alarms by |v| > c, the second by |e(1) + v| > c with e(1) N(0, q). A sum of
        // the grid's survival (not of each sample's hazard) was 7.6e-6 off here: the trapezoid's Gaussian
        // weighs 1 - 3.6e-14 in doubles, a lost mass it counted as alarms.
        let q = |z: f64| normal_cdf(-z);
        let two = -((-2.0 * q(6.0)).ln_1p() + (-2.0 * q(6.0 / (1.0 + fault_free.q).sqrt())).ln_1p()).exp_m1();
        assert!((fault_free.fault_free_alarm(2, 801) / two - 1.0).abs() < 1e-12, "{two}");
        let rare = SlowModeWindow { threshold: 8.0, ..slow_mode_window() };
        let (trial, hour) = (rare.fault_free_alarm(200, 801), rare.fault_free_alarm(360_000, 801));
        assert!((trial / 1.114097939833e-6 - 1.0).abs() < 1e-9, "{trial}");
        assert!((hour / 5.708425809165e-3 - 1.0).abs() < 1e-9, "{hour}");
    }
}
