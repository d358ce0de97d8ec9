//! The exact false-alarm law of a linear filter's fault-free residual, for tests and for checking any of
//! fdimc's false-alarm estimators against it (issue 81, item 4). Written for that and sharing nothing
//! with fdimc's code: the covariance recursion, the residual's cross-covariances, the normal and
//! bivariate normal tails and the bounds are all here, on nalgebra and statrs' `erfc` only.
//!
//! The filter starts on the truth: `e(0) = 0`, `e(k+1) = Phi e(k) + w(k) - Kd v(k)` with `Phi = Ad - Kd
//! C`, the residual `r(k) = C e(k) + v(k)`, `v ~ N(0, diag(sensor_sigma^2))`, `w ~ N(0,
//! diag(process_sigma_per_step^2))` (a model-exact linear plant: its inputs cancel in `e`). An alarm is
//! `|r_j(k)| > T_j` for some output `j` at some sample `k`; the probability of one in `samples` samples
//! lies between two bounds that are exact statements about this Gaussian law:
//! - above, Sidak's inequality: `P(no alarm) >= prod (1 - p_jk)` for any centred Gaussian vector and
//!   symmetric intervals;
//! - below, the second Bonferroni inequality: `P(alarm) >= sum p_jk - sum over pairs P(both)`, each pair
//!   a bivariate normal tail from the pair's covariance `Cov(r(k + h), r(k)) = C Phi^(h-1) (Phi P(k) C'
//!   - Kd R)` (`h >= 1`) and `C P(k) C' + R` (`h = 0`).
//!
//! Over a long flight the pairs are summed by lag where the law is stationary: the lower bound keeps
//! only the samples after `P(k)` has settled (a subset of the alarms bounds the whole from below), and
//! takes `P(k)` as settled once a step changes it by less than 1e-15 of its size (so both bounds hold
//! to that rounding).
#![allow(non_snake_case)]

use nalgebra::{DMatrix, DVector};

use super::normal_cdf;

/// A probability known to lie in `[lower, upper]`.
#[derive(Debug, Clone, Copy)]
pub struct Bounds {
    pub lower: f64,
    pub upper: f64,
}

/// The fault-free residual of one linear filter.
pub struct ResidualLaw {
    pub Phi: DMatrix<f64>,
    pub Kd: DMatrix<f64>,
    pub C: DMatrix<f64>,
    /// Sensor covariance (diagonal).
    pub R: DMatrix<f64>,
    /// What drives `e` each step: `Kd R Kd' + W`.
    pub drive: DMatrix<f64>,
}

impl ResidualLaw {
    pub fn new(
        Ad: &DMatrix<f64>,
        Kd: &DMatrix<f64>,
        C: &DMatrix<f64>,
        sensor_sigma: &[f64],
        process_sigma_per_step: &[f64],
    ) -> Self {
        let R = DMatrix::from_diagonal(&DVector::from_iterator(C.nrows(), sensor_sigma.iter().map(|s| s * s)));
        let W =
            DMatrix::from_diagonal(&DVector::from_iterator(Ad.nrows(), process_sigma_per_step.iter().map(|s| s * s)));
        let drive = Kd * &R * Kd.transpose() + W;
        Self { Phi: Ad - Kd * C, Kd: Kd.clone(), C: C.clone(), R, drive }
    }

    fn next(&self, P: &DMatrix<f64>) -> DMatrix<f64> {
        &self.Phi * P * self.Phi.transpose() + &self.drive
    }

    /// `Phi P C' - Kd R`: the state error one step on against the residual now.
    fn ahead(&self, P: &DMatrix<f64>) -> DMatrix<f64> {
        &self.Phi * P * self.C.transpose() - &self.Kd * &self.R
    }

    /// Sidak's bound alone (the window's upper bound, without its pairs): for many thresholds where the
    /// pairs' lower bound has been seen to meet it.
    pub fn sidak(&self, thresholds: &[f64], samples: usize) -> f64 {
        let mut P = DMatrix::zeros(self.Phi.nrows(), self.Phi.nrows());
        let mut log_none = 0.0;
        for _ in 0..samples {
            let S = &self.C * &P * self.C.transpose() + &self.R;
            for (j, t) in thresholds.iter().enumerate() {
                log_none += (-two_sided(t / S[(j, j)].sqrt())).ln_1p();
            }
            P = self.next(&P);
        }
        -log_none.exp_m1()
    }

    /// An alarm within a window of `samples` samples from the start, every pair of events summed.
    pub fn window(&self, thresholds: &[f64], samples: usize) -> Bounds {
        let m = self.C.nrows();
        let mut P = DMatrix::zeros(self.Phi.nrows(), self.Phi.nrows());
        let (mut covs, mut aheads) = (Vec::with_capacity(samples), Vec::with_capacity(samples));
        for _ in 0..samples {
            covs.push(&self.C * &P * self.C.transpose() + &self.R);
            aheads.push(self.ahead(&P));
            P = self.next(&P);
        }
        let sd: Vec<Vec<f64>> = covs.iter().map(|S| (0..m).map(|j| S[(j, j)].sqrt()).collect()).collect();
        let (mut sum, mut log_none) = (0.0, 0.0);
        for k in 0..samples {
            for j in 0..m {
                let p = two_sided(thresholds[j] / sd[k][j]);
                sum += p;
                log_none += (-p).ln_1p();
            }
        }
        use rayon::prelude::*;
        let pairs: f64 = (0..samples)
            .into_par_iter()
            .map(|k| {
                let mut pairs = 0.0;
                for j in 0..m {
                    for i in j + 1..m {
                        let rho = covs[k][(j, i)] / (sd[k][j] * sd[k][i]);
                        pairs += both(thresholds[j] / sd[k][j], thresholds[i] / sd[k][i], rho);
                    }
                }
                // Later samples against this one: C Phi^(h-1) ahead(k).
                let mut G = aheads[k].clone();
                for l in k + 1..samples {
                    let cross = &self.C * &G;
                    for a in 0..m {
                        for b in 0..m {
                            let rho = cross[(a, b)] / (sd[l][a] * sd[k][b]);
                            pairs += both(thresholds[a] / sd[l][a], thresholds[b] / sd[k][b], rho);
                        }
                    }
                    G = &self.Phi * G;
                }
                pairs
            })
            .sum();
        Bounds { lower: sum - pairs, upper: -log_none.exp_m1() }
    }

    /// An alarm within a flight of `samples` samples from the start: Sidak over every sample; the
    /// Bonferroni bound over the samples after `P(k)` has settled, its pairs summed by lag.
    pub fn flight(&self, thresholds: &[f64], samples: usize) -> Bounds {
        let m = self.C.nrows();
        let sd_of = |P: &DMatrix<f64>| -> Vec<f64> {
            let S = &self.C * P * self.C.transpose() + &self.R;
            (0..m).map(|j| S[(j, j)].sqrt()).collect()
        };
        let mut P = DMatrix::zeros(self.Phi.nrows(), self.Phi.nrows());
        let mut log_none = 0.0;
        let mut settled_at = samples;
        for k in 0..samples {
            log_none += sd_of(&P).iter().zip(thresholds).map(|(s, t)| (-two_sided(t / s)).ln_1p()).sum::<f64>();
            let next = self.next(&P);
            let still = (&next - &P).amax() <= 1e-15 * next.amax();
            P = next;
            if still {
                settled_at = k + 1;
                break;
            }
        }
        assert!(settled_at < samples / 2, "the residual does not settle within half the flight");
        let rest = samples - settled_at;
        let sd = sd_of(&P);
        let log_none_settled: f64 = sd.iter().zip(thresholds).map(|(s, t)| (-two_sided(t / s)).ln_1p()).sum();
        log_none += log_none_settled * rest as f64;
        let upper = -log_none.exp_m1();
        // Stationary from here: every pair at lag h has the same law.
        let z: Vec<f64> = sd.iter().zip(thresholds).map(|(s, t)| t / s).collect();
        let p: Vec<f64> = z.iter().map(|z| two_sided(*z)).collect();
        let S = &self.C * &P * self.C.transpose() + &self.R;
        let mut pairs = 0.0;
        for a in 0..m {
            for b in a + 1..m {
                pairs += rest as f64 * both(z[a], z[b], S[(a, b)] / (sd[a] * sd[b]));
            }
        }
        let mut G = self.ahead(&P);
        // |Cov(r_a(k + h), r_b(k))| <= |C| |G_h| (Frobenius): where that bound is negligible the pairs
        // are independent, whatever an oscillating mode does to single entries.
        let (c_norm, sd_min) = (self.C.norm(), sd.iter().copied().fold(f64::INFINITY, f64::min));
        for h in 1..rest {
            if c_norm * G.norm() / (sd_min * sd_min) < 1e-13 {
                // Independent from here to the end (to 13 digits): each pair is p_a p_b.
                let left: f64 = (h..rest).map(|h| (rest - h) as f64).sum();
                pairs += left * p.iter().sum::<f64>().powi(2);
                break;
            }
            let cross = &self.C * &G;
            let mut at_lag = 0.0;
            for a in 0..m {
                for b in 0..m {
                    at_lag += both(z[a], z[b], cross[(a, b)] / (sd[a] * sd[b]));
                }
            }
            pairs += (rest - h) as f64 * at_lag;
            G = &self.Phi * G;
        }
        Bounds { lower: rest as f64 * p.iter().sum::<f64>() - pairs, upper }
    }
}

/// The bounds on the extremal index against the segment conversion, `ln(1 - flight) / (segments x
/// ln(1 - segment))` (as `fdimc rare-event --flight-s` defines it): how many times the conversion
/// under-counts. (A Bonferroni bound at or below 0, where alarms are not rare, leaves the upper end
/// infinite.)
pub fn extremal_index(flight: Bounds, segment: Bounds, segments_per_flight: f64) -> Bounds {
    let hazard = |p: f64| -(-p.max(0.0)).ln_1p();
    Bounds {
        lower: hazard(flight.lower) / (segments_per_flight * hazard(segment.upper)),
        upper: hazard(flight.upper) / (segments_per_flight * hazard(segment.lower)),
    }
}

/// `P(|Z| > z)`.
pub fn two_sided(z: f64) -> f64 {
    2.0 * normal_cdf(-z)
}

/// `P(|X| > a, |Y| > b)` for standard normals of correlation `rho`.
pub fn both(a: f64, b: f64, rho: f64) -> f64 {
    2.0 * (upper_both(a, b, rho) + upper_both(a, b, -rho))
}

/// `P(X > a, Y > b)`: `Q(a) Q(b) + 1/(2 pi) int_0^asin(rho) exp(-(a^2 + b^2 - 2 a b sin t) / (2 cos^2 t)) dt`
/// (Plackett's identity, `r = sin t`), by Gauss-Legendre: 48 points where `|rho| > 0.9`, else 16 (the
/// integrand is then smooth over the whole range; the test below holds them to each other).
fn upper_both(a: f64, b: f64, rho: f64) -> f64 {
    upper_both_by(a, b, rho, if rho.abs() > 0.9 { &RULES.1 } else { &RULES.0 })
}

fn upper_both_by(a: f64, b: f64, rho: f64, rule: &Rule) -> f64 {
    let q = |z: f64| normal_cdf(-z);
    let end = rho.clamp(-1.0, 1.0).asin();
    let f = |t: f64| (-(a * a + b * b - 2.0 * a * b * t.sin()) / (2.0 * t.cos().powi(2))).exp();
    let (nodes, weights) = &**rule;
    let half = 0.5 * end;
    let integral: f64 = nodes.iter().zip(weights).map(|(x, w)| w * f(half * (x + 1.0))).sum::<f64>() * half;
    // Far below Q(a) Q(b) the two terms cancel to rounding: the probability is then 0 to 16 digits.
    (q(a) * q(b) + integral / (2.0 * std::f64::consts::PI)).max(0.0)
}

type Rule = std::sync::LazyLock<(Vec<f64>, Vec<f64>)>;
static RULES: (Rule, Rule) = (Rule::new(|| gauss_legendre(16)), Rule::new(|| gauss_legendre(48)));

/// Gauss-Legendre nodes and weights on [-1, 1] (Newton on the Legendre recurrence).
fn gauss_legendre(points: usize) -> (Vec<f64>, Vec<f64>) {
    let n = points as f64;
    // P_n(t) and its derivative.
    let legendre = |t: f64| {
        let (mut p0, mut p1) = (1.0, t);
        for k in 2..=points {
            let k = k as f64;
            (p0, p1) = (p1, ((2.0 * k - 1.0) * t * p1 - (k - 1.0) * p0) / k);
        }
        (p1, n * (t * p1 - p0) / (t * t - 1.0))
    };
    let (mut x, mut w) = (vec![0.0; points], vec![0.0; points]);
    for i in 0..points {
        let mut t = (std::f64::consts::PI * (i as f64 + 0.75) / (n + 0.5)).cos();
        for _ in 0..100 {
            let (p, dp) = legendre(t);
            t -= p / dp;
            if (p / dp).abs() < 1e-16 {
                break;
            }
        }
        let (_, dp) = legendre(t);
        x[i] = t;
        w[i] = 2.0 / ((1.0 - t * t) * dp * dp);
    }
    (x, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bivariate_tail_meets_its_closed_forms() {
        // Sheppard: P(X > 0, Y > 0) = 1/4 + asin(rho) / (2 pi).
        for rho in [-0.9, -0.3, 0.0, 0.5, 0.99] {
            let exact = 0.25 + f64::asin(rho) / (2.0 * std::f64::consts::PI);
            assert!((upper_both(0.0, 0.0, rho) - exact).abs() < 1e-14, "{rho}");
        }
        // Independent, and one variable: the product, and P(|Z| > a) when rho = 1 and a = b.
        let (a, b) = (4.5, 5.2);
        assert!((both(a, b, 0.0) / (two_sided(a) * two_sided(b)) - 1.0).abs() < 1e-12);
        assert!((both(a, a, 1.0) / two_sided(a) - 1.0).abs() < 1e-6, "{}", both(a, a, 1.0) / two_sided(a));
        // The rules integrate x^(2n - 2) exactly, and the 16-point one meets the 48-point one where it is used.
        for (rule, n) in [(&RULES.0, 16), (&RULES.1, 48)] {
            let moment: f64 = rule.0.iter().zip(&rule.1).map(|(x, w)| w * x.powi(2 * n - 2)).sum();
            assert!((moment - 2.0 / (2 * n - 1) as f64).abs() < 1e-14, "{n}: {moment}");
        }
        for (a, b) in [(3.0, 3.0), (4.5, 5.2), (5.5, 5.5)] {
            for rho in [-0.9, -0.5, 0.2, 0.6, 0.9] {
                let by = |rule| upper_both_by(a, b, rho, rule) + upper_both_by(a, b, -rho, rule);
                let (few, many) = (by(&RULES.0), by(&RULES.1));
                assert!((few / many - 1.0).abs() < 1e-10, "{a} {b} {rho}: {few} vs {many}");
            }
        }
    }
}
