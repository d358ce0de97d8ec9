//! False-alarm probabilities below what the trials can show: a peaks-over-threshold fit of the
//! fault-free maxima's upper tail (generalised Pareto, Coles 2001 ch. 4), with profile-likelihood 95 %
//! intervals and the diagnostics that say when to trust it.
//!
//! Of `n` maxima, the `k` largest above the fit threshold `u` (the `(k + 1)`-th largest) are taken; the
//! model is `P(X > x) = zeta (1 + xi (x - u) / sigma)^(-1 / xi)` for `x > u` (`exp(-(x - u) / sigma)` at
//! `xi = 0`), where `zeta = P(X > u)` is binomial (estimate `k / n`). The intervals profile the joint
//! likelihood of `(zeta, sigma, xi)`, so they carry the uncertainty of `zeta` as well as the shape's,
//! and they are asymmetric as the extrapolation is. They assume the generalised Pareto law holds beyond
//! the data: [`TailFit::concerns`] lists what the data say against it.

use crate::engine::stats::intervals::Z95;

/// The 95 % point of chi-square with one degree of freedom: the profile deviance's cut-off.
const CHI2_1_95: f64 = Z95 * Z95;
/// The fewest exceedances a fit is made on, and the most (a higher threshold has less bias, and the
/// profile's cost grows with `k`).
pub const MIN_EXCEEDANCES: usize = 30;
pub const MAX_EXCEEDANCES: usize = 1000;

/// How many of `n` values the fit takes as exceedances: a tenth, between [`MIN_EXCEEDANCES`] and
/// [`MAX_EXCEEDANCES`]; `None` below `10 * MIN_EXCEEDANCES` values.
pub fn exceedances_for(n: u64) -> Option<usize> {
    (n >= 10 * MIN_EXCEEDANCES as u64).then(|| ((n / 10) as usize).min(MAX_EXCEEDANCES))
}

/// A generalised Pareto fit of the upper tail of `n` values.
#[derive(Clone)]
pub struct TailFit {
    pub n: u64,
    /// The fit threshold: the largest value not taken as an exceedance.
    pub u: f64,
    pub sigma: f64,
    pub xi: f64,
    /// The exceedances `x - u`, all > 0.
    excess: Vec<f64>,
    /// The maximised joint log-likelihood.
    loglik: f64,
}

impl std::fmt::Debug for TailFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TailFit {{ n: {}, k: {}, u: {}, sigma: {}, xi: {} }}", self.n, self.k(), self.u, self.sigma, self.xi)
    }
}

/// A 95 % interval; `hi` may be infinite (the data bound it from one side only).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    pub estimate: f64,
    pub lo: f64,
    pub hi: f64,
}

impl TailFit {
    /// Fits the `k` largest of `top` (the largest values of `n`, in any order, at least `k + 1` of
    /// them, finite) over the `(k + 1)`-th largest. Values tied with the threshold are not exceedances.
    /// `None` when fewer than [`MIN_EXCEEDANCES`] values lie strictly above it.
    pub fn fit(top: &[f64], n: u64, k: usize) -> Option<TailFit> {
        let mut sorted: Vec<f64> = top.iter().copied().filter(|v| v.is_finite()).collect();
        sorted.sort_by(|a, b| b.total_cmp(a));
        let u = *sorted.get(k)?;
        let excess: Vec<f64> = sorted[..k].iter().map(|x| x - u).filter(|y| *y > 0.0).collect();
        if excess.len() < MIN_EXCEEDANCES || (n as usize) <= excess.len() {
            return None;
        }
        let (sigma, xi) = gpd_mle(&excess);
        let mut fit = TailFit { n, u, sigma, xi, excess, loglik: 0.0 };
        fit.loglik = fit.joint(fit.zeta(), sigma, xi);
        Some(fit)
    }

    pub fn k(&self) -> usize {
        self.excess.len()
    }

    /// `P(X > u)` estimated: `k / n`.
    pub fn zeta(&self) -> f64 {
        self.k() as f64 / self.n as f64
    }

    pub fn mean_excess(&self) -> f64 {
        self.excess.iter().sum::<f64>() / self.k() as f64
    }

    /// `P(X > x)` for `x >= u`.
    pub fn survival(&self, x: f64) -> f64 {
        self.zeta() * gpd_survival(x - self.u, self.sigma, self.xi)
    }

    /// The `x` with `P(X > x) = p`, for `p <= zeta`.
    pub fn quantile(&self, p: f64) -> f64 {
        self.u + excess_at(p / self.zeta(), self.sigma, self.xi)
    }

    /// `P(X > x)` with its profile-likelihood interval (`x > u`).
    pub fn survival_interval(&self, x: f64) -> Interval {
        let d = x - self.u;
        let estimate = self.survival(x);
        let deviance = |ln_p: f64| 2.0 * (self.loglik - self.profile(d, ln_p.exp()));
        if estimate <= 0.0 {
            // Beyond the fitted endpoint of a bounded tail: 0, and how far up the data allow (from a
            // probability too small to matter, where the deviance is the endpoint's).
            let floor = -700.0;
            let hi = if deviance(floor) > CHI2_1_95 {
                0.0
            } else {
                bound(deviance, floor, std::f64::consts::LN_2, -1e-12).map_or(1.0, f64::exp)
            };
            return Interval { estimate, lo: 0.0, hi };
        }
        let ln_p = estimate.ln();
        let lo = bound(deviance, ln_p, -std::f64::consts::LN_2, -700.0).map_or(0.0, f64::exp);
        let hi = bound(deviance, ln_p, std::f64::consts::LN_2, -1e-12).map_or(1.0, f64::exp);
        Interval { estimate, lo, hi }
    }

    /// The `x` with `P(X > x) = p` with its profile-likelihood interval (`p < zeta`); `hi` is infinite
    /// when the data allow any heavier tail.
    pub fn quantile_interval(&self, p: f64) -> Interval {
        let estimate = self.quantile(p);
        let d = (estimate - self.u).max(f64::MIN_POSITIVE);
        let deviance = |ln_d: f64| 2.0 * (self.loglik - self.profile(ln_d.exp(), p));
        let ln_d = d.ln();
        let lo = bound(deviance, ln_d, -std::f64::consts::LN_2, ln_d - 60.0).map_or(self.u, |l| self.u + l.exp());
        let hi = bound(deviance, ln_d, std::f64::consts::LN_2, ln_d + 40.0).map_or(f64::INFINITY, |h| self.u + h.exp());
        Interval { estimate, lo, hi }
    }

    /// A one-sided upper bound on the `x` with `P(X > x) = p` at `confidence` (the profile deviance's
    /// cut-off `z_c^2`) over shapes `xi >= 0` only; infinite when the data allow any heavier tail.
    ///
    /// Why the shape is held at 0 or above: the statistics fdimc calibrates (maxima of Gaussian
    /// residuals, of chi-square tests) lie in the Gumbel domain, where the excesses over a finite
    /// threshold look like a slightly negative shape that tends to 0 as the threshold rises; a bound
    /// that trusts the fitted negative shape extrapolates too light a tail. On the maxima of 200
    /// `|N(0, 1)|` the free shape's 95 % bound for 1e-3 from 400 values fell below the truth in 7 % to
    /// 12 % of the sets, this one in 1 of 400 (test
    /// `the_confident_bound_holds_its_confidence_on_gaussian_maxima`). A fit with `xi >= 0` is
    /// unchanged at its estimate; the price is a higher threshold where the tail is truly bounded.
    pub fn quantile_upper(&self, p: f64, confidence: f64) -> f64 {
        use statrs::distribution::{ContinuousCDF, Normal};
        let z = Normal::standard().inverse_cdf(confidence);
        let profile = |ln_d: f64| self.profile_over(ln_d.exp(), p, Some(0.0));
        let (ln_d, best) = if self.xi >= 0.0 {
            ((self.quantile(p) - self.u).max(f64::MIN_POSITIVE).ln(), self.loglik)
        } else {
            // The best fit with xi >= 0 is the exponential's (xi = 0, zeta = k / n, the scale the mean
            // excess: the profile over the shape falls away from the free fit's negative one).
            let ln_exponential = (self.mean_excess() * (self.zeta() / p).ln()).max(f64::MIN_POSITIVE).ln();
            (ln_exponential, self.joint(self.zeta(), self.mean_excess(), 0.0))
        };
        let deviance = |ln_d: f64| 2.0 * (best - profile(ln_d));
        bound_at(z * z, deviance, ln_d, std::f64::consts::LN_2, ln_d + 40.0).map_or(f64::INFINITY, |h| self.u + h.exp())
    }

    /// [`Self::survival_interval`] whose upper end trusts no shape below 0: where the fitted shape is
    /// negative, the upper end is the larger of the free profile's and the profile's over shapes
    /// `xi >= 0` (its deviance against the best fit there, the exponential's: `zeta = k / n`, the
    /// scale the mean excess). The estimate and the lower end are the free fit's.
    ///
    /// Why: fdimc's statistics (maxima of Gaussian residuals, of chi-square tests) lie in the Gumbel
    /// domain, whose excesses over a finite threshold look like a negative shape (see
    /// [`Self::quantile_upper`]). On a 1 s slow mode 200 times past 1/trials the free interval held the
    /// exact per-hour figure on 16 of 20 seeds, every miss too low.
    pub fn survival_interval_conservative(&self, x: f64) -> Interval {
        let free = self.survival_interval(x);
        if self.xi >= 0.0 {
            return free;
        }
        let d = x - self.u;
        let best = self.joint(self.zeta(), self.mean_excess(), 0.0);
        let deviance = |ln_p: f64| 2.0 * (best - self.profile_over(d, ln_p.exp(), Some(0.0)));
        // From the exponential fit's own estimate, where the deviance is 0.
        let from = (self.zeta().ln() - d / self.mean_excess()).max(-700.0);
        let hi = bound(deviance, from, std::f64::consts::LN_2, -1e-12).map_or(1.0, f64::exp);
        Interval { hi: hi.max(free.hi), ..free }
    }

    /// [`Self::quantile_interval`] whose upper end trusts no shape below 0 (as
    /// [`Self::survival_interval_conservative`]'s): the larger of the free profile's and
    /// [`Self::quantile_upper`] at 97.5 %, the same cut-off one-sided.
    pub fn quantile_interval_conservative(&self, p: f64) -> Interval {
        let free = self.quantile_interval(p);
        if self.xi >= 0.0 {
            return free;
        }
        Interval { hi: free.hi.max(self.quantile_upper(p, 0.975)), ..free }
    }

    /// The shape `xi` with its profile-likelihood interval.
    pub fn xi_interval(&self) -> Interval {
        let gpd_best = self.loglik - binomial(self.k(), self.n, self.zeta());
        let deviance = |xi: f64| {
            let ln_sigma = self.sigma.ln();
            let (_, l) = maximize(|s| gpd_loglik(&self.excess, s.exp(), xi), ln_sigma - 8.0, ln_sigma + 8.0);
            2.0 * (gpd_best - l)
        };
        let lo = bound(deviance, self.xi, -0.05, -1.0).unwrap_or(-1.0);
        let hi = bound(deviance, self.xi, 0.05, self.xi + 10.0).unwrap_or(f64::INFINITY);
        Interval { estimate: self.xi, lo, hi }
    }

    /// The joint log-likelihood of `(zeta, sigma, xi)`.
    fn joint(&self, zeta: f64, sigma: f64, xi: f64) -> f64 {
        binomial(self.k(), self.n, zeta) + gpd_loglik(&self.excess, sigma, xi)
    }

    /// The largest joint log-likelihood among the parameters with `P(X > u + d) = p`: over the shape
    /// and `zeta`, the scale then follows.
    fn profile(&self, d: f64, p: f64) -> f64 {
        self.profile_over(d, p, None)
    }

    /// [`Self::profile`] over shapes at or above `xi_floor` where one is given.
    fn profile_over(&self, d: f64, p: f64, xi_floor: Option<f64>) -> f64 {
        if !(d > 0.0 && p > 0.0) {
            return f64::NEG_INFINITY;
        }
        // zeta within 8 of its standard errors (relative 1 / sqrt(k)) of k / n: the binomial term alone
        // costs more than the cut-off beyond.
        let (ln_zeta, spread) = (self.zeta().ln(), 8.0 / (self.k() as f64).sqrt());
        let (lo, hi) = ((ln_zeta - spread).max(p.ln() + 1e-12), (ln_zeta + spread).min(-1e-12));
        if lo >= hi {
            return f64::NEG_INFINITY;
        }
        let given_xi = |xi: f64| {
            maximize(
                |ln_z| {
                    let zeta = ln_z.exp();
                    self.joint(zeta, scale_through(d, p / zeta, xi), xi)
                },
                lo,
                hi,
            )
            .1
        };
        let (xi_lo, xi_hi) = match xi_floor {
            None => ((self.xi - 1.5).max(-0.999), self.xi + 1.5),
            Some(floor) => ((self.xi - 1.5).max(floor), self.xi.max(floor) + 1.5),
        };
        maximize(given_xi, xi_lo, xi_hi).1
    }

    /// What the data say against trusting the fit's extrapolation (empty: nothing), given the shape
    /// at higher thresholds (`higher`, from [`stability`]) and the largest values (`top`).
    pub fn concerns(&self, higher: &[Stability], top: &[f64]) -> Vec<String> {
        let mut out = Vec::new();
        for s in higher.iter().filter(|s| s.u > self.u && s.k >= MIN_EXCEEDANCES) {
            if !(s.xi.lo..=s.xi.hi).contains(&self.xi) {
                out.push(format!(
                    "shape unstable: {:.3} here, [{:.3}, {:.3}] over the {} largest",
                    self.xi, s.xi.lo, s.xi.hi, s.k
                ));
                break;
            }
        }
        let mut sorted: Vec<f64> = top.iter().copied().filter(|v| v.is_finite()).collect();
        sorted.sort_by(|a, b| b.total_cmp(a));
        for m in [3usize, 10, 30] {
            let Some(&x) = sorted.get(m - 1) else { continue };
            // P(X >= x_(m)): the fit just below the m-th largest against m of n.
            let fitted = self.survival(x - 1e-12 * x.abs().max(1.0));
            let (lo, hi) = crate::engine::stats::intervals::wilson(m as u64, self.n, Z95);
            if !(lo..=hi).contains(&fitted) {
                out.push(format!(
                    "misfit at the {m} largest: fitted {fitted:.2e}, observed {:.2e} [{lo:.2e}, {hi:.2e}]",
                    m as f64 / self.n as f64
                ));
            }
        }
        out
    }
}

/// The shape and scale fitted over one threshold, for the parameter-stability diagnostic: above a
/// threshold where the law holds, the shape and the modified scale `sigma - xi u` stay put, and the
/// mean excess is linear in `u`.
#[derive(Debug, Clone)]
pub struct Stability {
    pub k: usize,
    pub u: f64,
    pub xi: Interval,
    pub sigma: f64,
    pub modified_scale: f64,
    pub mean_excess: f64,
}

/// Fits over the thresholds that leave each of `ks` exceedances (skipping those that do not fit).
pub fn stability(top: &[f64], n: u64, ks: &[usize]) -> Vec<Stability> {
    use rayon::prelude::*;
    // Each fit's shape interval is a profile likelihood: the fits run side by side.
    ks.par_iter()
        .filter_map(|&k| TailFit::fit(top, n, k))
        .map(|f| Stability {
            k: f.k(),
            u: f.u,
            xi: f.xi_interval(),
            sigma: f.sigma,
            modified_scale: f.sigma - f.xi * f.u,
            mean_excess: f.mean_excess(),
        })
        .collect()
}

/// The exceedance counts the diagnostics fit over around a chosen `k`: from `2 k` (capped by the values
/// kept) down by factors of 2^(1/2) to [`MIN_EXCEEDANCES`].
pub fn stability_ks(k: usize, kept: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut x = (2 * k).min(kept.saturating_sub(1)) as f64;
    while x >= MIN_EXCEEDANCES as f64 {
        let k = x.round() as usize;
        if out.last() != Some(&k) {
            out.push(k);
        }
        x /= std::f64::consts::SQRT_2;
    }
    out
}

fn binomial(k: usize, n: u64, zeta: f64) -> f64 {
    if !(zeta > 0.0 && zeta < 1.0) {
        return f64::NEG_INFINITY;
    }
    k as f64 * zeta.ln() + (n as f64 - k as f64) * (-zeta).ln_1p()
}

/// The generalised Pareto log-likelihood of excesses `y`.
fn gpd_loglik(y: &[f64], sigma: f64, xi: f64) -> f64 {
    if !(sigma > 0.0 && sigma.is_finite()) {
        return f64::NEG_INFINITY;
    }
    let k = y.len() as f64;
    if xi.abs() < 1e-12 {
        return -k * sigma.ln() - y.iter().sum::<f64>() / sigma;
    }
    let sum =
        if xi.abs() >= PRODUCT_LOG_MIN_XI { sum_ln_1p_by_products(y, xi / sigma) } else { sum_ln_1p(y, xi / sigma) };
    match sum {
        Some(sum) => -k * sigma.ln() - (1.0 + 1.0 / xi) * sum,
        None => f64::NEG_INFINITY,
    }
}

/// `sum(ln(1 + t y))`, a logarithm per term; `None` where a term's `t y <= -1`.
fn sum_ln_1p(y: &[f64], t: f64) -> Option<f64> {
    let mut sum = 0.0;
    for &v in y {
        let z = t * v;
        if z <= -1.0 {
            return None;
        }
        sum += z.ln_1p();
    }
    Some(sum)
}

/// The smallest `|xi|` at which [`gpd_loglik`] sums its logarithms by [`sum_ln_1p_by_products`]: that
/// sum's error, about `k` machine epsilons absolute, is multiplied by `1 + 1 / xi`, so at least 1e-2
/// keeps the log-likelihood within about 1e-10 for `k` up to [`MAX_EXCEEDANCES`] (the profiles'
/// searches stop at 1e-9).
const PRODUCT_LOG_MIN_XI: f64 = 1e-2;

/// Terms per product in [`sum_ln_1p_by_products`]: each factor `1 + t y` is at least about 1e-16 where
/// it is positive (`t y` is a double above -1), so 16 of them cannot underflow; an overflow is caught.
const PRODUCT_TERMS: usize = 16;

/// [`sum_ln_1p`] as a logarithm per product of [`PRODUCT_TERMS`] factors `1 + t y`: the profile
/// likelihoods evaluate this sum millions of times per summary, and a logarithm per term was most of a
/// summary's time. Each factor carries a rounding error of a machine epsilon relative, so the sum is
/// exact to about `y.len()` epsilons absolute (not relative to the terms, as [`sum_ln_1p`]'s: see
/// [`PRODUCT_LOG_MIN_XI`]). A product out of the normal range is summed term by term.
fn sum_ln_1p_by_products(y: &[f64], t: f64) -> Option<f64> {
    let mut sum = 0.0;
    let mut blocks = y.chunks_exact(PRODUCT_TERMS);
    for block in &mut blocks {
        // Four products side by side: independent multiplications, and the smallest factor to catch
        // a `t y <= -1` (two such factors would make a positive product).
        let (mut product, mut least) = ([1.0f64; 4], f64::INFINITY);
        for four in block.chunks_exact(4) {
            for (p, &v) in product.iter_mut().zip(four) {
                let factor = 1.0 + t * v;
                least = least.min(factor);
                *p *= factor;
            }
        }
        if least <= 0.0 {
            return None;
        }
        let product = (product[0] * product[1]) * (product[2] * product[3]);
        sum += if product.is_normal() { product.ln() } else { sum_ln_1p(block, t)? };
    }
    Some(sum + sum_ln_1p(blocks.remainder(), t)?)
}

/// The generalised Pareto survival function at excess `d` (1 at and below 0).
pub fn gpd_survival(d: f64, sigma: f64, xi: f64) -> f64 {
    if d <= 0.0 {
        return 1.0;
    }
    let z = xi * d / sigma;
    if xi.abs() < 1e-12 {
        (-d / sigma).exp()
    } else if z <= -1.0 {
        0.0
    } else {
        (-z.ln_1p() / xi).exp()
    }
}

/// The excess `d` with survival `q`.
fn excess_at(q: f64, sigma: f64, xi: f64) -> f64 {
    if xi.abs() < 1e-12 { -sigma * q.ln() } else { sigma * (-xi * q.ln()).exp_m1() / xi }
}

/// The scale whose survival at excess `d` is `q` (< 1) at shape `xi`.
fn scale_through(d: f64, q: f64, xi: f64) -> f64 {
    let ln_q = q.ln();
    if xi.abs() < 1e-12 { -d / ln_q } else { xi * d / (-xi * ln_q).exp_m1() }
}

/// The maximum likelihood `(sigma, xi)` of excesses `y` (all > 0) by Grimshaw's reduction: at
/// `theta = xi / sigma` the best `xi` is `mean(ln(1 + theta y))`, leaving one variable. The shape is
/// kept at or above -1.
fn gpd_mle(y: &[f64]) -> (f64, f64) {
    let y_max = y.iter().copied().fold(0.0, f64::max);
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let at = |s: f64| {
        // theta y_max = e^s - 1 covers (-1, inf) with s in R; theta = 0 at s = 0.
        let theta = s.exp_m1() / y_max;
        if (theta * y_max).abs() < 1e-12 {
            return (mean, 0.0);
        }
        let xi = y.iter().map(|v| (theta * v).ln_1p()).sum::<f64>() / y.len() as f64;
        (xi / theta, xi)
    };
    let (s, _) = maximize(
        |s| {
            let (sigma, xi) = at(s);
            // Below -1 the likelihood grows without bound as the endpoint nears the largest excess
            // (no maximum exists there); at -1 the law is uniform on [0, sigma].
            if xi < -1.0 { f64::NEG_INFINITY } else { gpd_loglik(y, sigma, xi) }
        },
        -30.0,
        12.0,
    );
    at(s)
}

/// The maximum of `f` on `[lo, hi]`: the best of a coarse grid, refined between its neighbours by
/// Brent's method (parabolic steps through the last three points, golden section where they do not
/// shrink the bracket) to `1e-9 (1 + |x|)`; `(argmax, max)`. The profiles call it inside one another
/// and inside root searches, so each evaluation saved is saved thousands of times.
fn maximize(f: impl Fn(f64) -> f64, lo: f64, hi: f64) -> (f64, f64) {
    const GRID: usize = 24;
    const MAX_STEPS: usize = 60;
    let step = (hi - lo) / GRID as f64;
    let (mut best_x, mut best) = (lo, f(lo));
    for i in 1..=GRID {
        let x = lo + step * i as f64;
        let v = f(x);
        if v > best {
            (best_x, best) = (x, v);
        }
    }
    // Brent's minimisation of -f (Brent 1973, ch. 5), started at the grid's best point.
    let golden = (3.0 - 5f64.sqrt()) / 2.0;
    let (mut a, mut b) = ((best_x - step).max(lo), (best_x + step).min(hi));
    let (mut x, mut w, mut v) = (best_x, best_x, best_x);
    let (mut fx, mut fw, mut fv) = (-best, -best, -best);
    let (mut d, mut e) = (0.0f64, 0.0f64);
    for _ in 0..MAX_STEPS {
        let m = 0.5 * (a + b);
        let tol = 1e-9 * (1.0 + x.abs());
        if (x - m).abs() <= 2.0 * tol - 0.5 * (b - a) || !fx.is_finite() {
            break;
        }
        let mut golden_step = true;
        if e.abs() > tol {
            // The parabola through (x, fx), (w, fw), (v, fv).
            let r = (x - w) * (fx - fv);
            let mut q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            if p.abs() < (0.5 * q * e).abs() && p > q * (a - x) && p < q * (b - x) {
                e = d;
                d = p / q;
                let u = x + d;
                if u - a < 2.0 * tol || b - u < 2.0 * tol {
                    d = if x < m { tol } else { -tol };
                }
                golden_step = false;
            }
        }
        if golden_step {
            e = if x < m { b - x } else { a - x };
            d = golden * e;
        }
        let u = if d.abs() >= tol { x + d } else { x + tol.copysign(d) };
        let fu = -f(u);
        if fu <= fx {
            if u < x {
                b = x;
            } else {
                a = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    if -fx > best { (x, -fx) } else { (best_x, best) }
}

/// Where `deviance` (below the cut-off at `from`) first reaches the 95 % cut-off going from `from` in
/// steps of `step` (doubling) up to `limit`, refined by bisection; `None` when it stays below.
fn bound(deviance: impl Fn(f64) -> f64, from: f64, step: f64, limit: f64) -> Option<f64> {
    bound_at(CHI2_1_95, deviance, from, step, limit)
}

/// [`bound`] at another deviance cut-off.
fn bound_at(cutoff: f64, deviance: impl Fn(f64) -> f64, from: f64, step: f64, limit: f64) -> Option<f64> {
    let beyond = |x: f64| if step > 0.0 { x >= limit } else { x <= limit };
    let g = |x: f64| deviance(x) - cutoff;
    // The deviance at `inside`, once known (at `from` it is not evaluated unless needed).
    let (mut inside, mut g_inside, mut h) = (from, None, step);
    loop {
        let x = if beyond(inside + h) { limit } else { inside + h };
        let g_x = g(x);
        if g_x > 0.0 {
            let g_inside = g_inside.unwrap_or_else(|| g(inside));
            return Some(crossing(g, (inside, g_inside), (x, g_x)));
        }
        if x == limit {
            return None;
        }
        (inside, g_inside) = (x, Some(g_x));
        h *= 2.0;
    }
}

/// Where `g` (at most 0 at `inside`, `g_outside` > 0 at `outside`) crosses 0, to `1e-7 (1 + |x|)` or
/// `|g| < 1e-9`: regula falsi with Illinois' halving of the stale end (a smooth deviance crosses in a few
/// steps where bisection to the same width takes twenty).
fn crossing(
    g: impl Fn(f64) -> f64,
    (mut inside, g_inside): (f64, f64),
    (mut outside, mut g_outside): (f64, f64),
) -> f64 {
    // (A profile maximised a little better than the fit gives a deviance just below 0 at the estimate.)
    let mut g_inside = g_inside.min(0.0);
    let mut stale = 0i8; // which end the last steps kept: -1 inside, 1 outside
    for _ in 0..60 {
        let width = (outside - inside).abs();
        if width < 1e-7 * (1.0 + inside.abs()) {
            break;
        }
        let secant = inside - g_inside * (outside - inside) / (g_outside - g_inside);
        // Keep it strictly inside the bracket (a non-finite g at an end makes the secant useless).
        let x = if secant.is_finite() && (secant - inside) * (secant - outside) < 0.0 {
            secant
        } else {
            0.5 * (inside + outside)
        };
        let g_x = g(x);
        if g_x.abs() < 1e-9 {
            return x;
        }
        if g_x > 0.0 {
            (outside, g_outside) = (x, g_x);
            if stale == -1 {
                g_inside *= 0.5;
            }
            stale = -1;
        } else {
            (inside, g_inside) = (x, g_x);
            if stale == 1 {
                g_outside *= 0.5;
            }
            stale = 1;
        }
    }
    0.5 * (inside + outside)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Exp1, StandardNormal};

    fn exponential(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| Exp1.sample(&mut rng)).collect()
    }

    /// The products' sum of logarithms against one logarithm per term: within the error its docs
    /// state (a few epsilons per term, absolute), `None` where one factor is not positive (also two
    /// of them, whose product is), and term by term where a product leaves the normal range.
    #[test]
    fn logarithms_of_products_sum_as_the_terms_do() {
        let y = exponential(1000, 7);
        let per_term = |t: f64| y.iter().map(|v| (t * v).ln_1p()).sum::<f64>();
        for t in [-0.05, -1e-3, 2e-3, 0.4, 30.0] {
            let (fast, exact) = (sum_ln_1p_by_products(&y, t).unwrap(), per_term(t));
            // A few epsilons per term, and the summation's own rounding (relative to the sum, both ways).
            let tolerance = 4.0 * f64::EPSILON * (y.len() as f64 + exact.abs());
            assert!((fast - exact).abs() <= tolerance, "t {t}: {fast} against {exact}");
            assert_eq!(sum_ln_1p(&y, t), Some(exact));
        }
        // Factors near 0 (the endpoint of a bounded tail): 1 + t y down to about 1e-15, exact in floating
        // point there, so the sum keeps its accuracy.
        let y_max = y.iter().copied().fold(0.0, f64::max);
        let t = -(1.0 - 1e-15) / y_max;
        let (fast, exact) = (sum_ln_1p_by_products(&y, t).unwrap(), per_term(t));
        assert!((fast - exact).abs() <= 4.0 * f64::EPSILON * (y.len() as f64 + exact.abs()), "{fast} {exact}");
        // Past the endpoint, one factor or two in a block: no likelihood.
        assert_eq!(sum_ln_1p_by_products(&y, -1.01 / y_max), None);
        let mut two = vec![1.0; 16];
        two[3] = 3.0;
        two[9] = 3.0;
        assert_eq!(sum_ln_1p_by_products(&two, -0.5), None, "two factors of -0.5: a positive product");
        // Products that overflow are summed term by term: 16 factors of 1e30 overflow, the sum does not.
        let big = vec![1e30; 40];
        let fast = sum_ln_1p_by_products(&big, 1.0).unwrap();
        assert!((fast - 40.0 * (1e30f64).ln()).abs() < 1e-10, "{fast}");
        // The log-likelihood takes the products from |xi| = 0.01 on and agrees with the terms there.
        let (sigma, xi): (f64, f64) = (0.7, PRODUCT_LOG_MIN_XI);
        let exact = -(y.len() as f64) * sigma.ln() - (1.0 + 1.0 / xi) * per_term(xi / sigma);
        assert!((gpd_loglik(&y, sigma, xi) - exact).abs() < 1e-10, "{} {exact}", gpd_loglik(&y, sigma, xi));
    }

    /// The profile-likelihood optimiser on closed forms: an interior smooth maximum (pi / 3 and, on a
    /// skewed curve, x e^-x at 1), a kink (-|x - 0.3|) and a maximum at the range's end.
    #[test]
    fn maximize_finds_closed_form_maxima() {
        let (x, v) = maximize(|x| -(x - std::f64::consts::FRAC_PI_3).powi(2), 0.0, 2.0);
        assert!((x - std::f64::consts::FRAC_PI_3).abs() < 1e-7 && v.abs() < 1e-13, "{x} {v}");
        let (x, v) = maximize(|x| x * (-x).exp(), 0.0, 5.0);
        assert!((x - 1.0).abs() < 1e-6 && (v - (-1f64).exp()).abs() < 1e-12, "{x} {v}");
        let (x, _) = maximize(|x| -(x - 0.3).abs(), 0.0, 1.0);
        assert!((x - 0.3).abs() < 1e-7, "{x}");
        let (x, v) = maximize(|x| x, 0.0, 1.0);
        assert!((x - 1.0).abs() < 1e-7 && (v - 1.0).abs() < 1e-7, "{x} {v}");
    }

    /// The interval ends' root finder on closed forms, and its step count: x^3 = 2 and e^x = 10 to the
    /// stated tolerance within 12 evaluations (bisection to 1e-7 of a width of 2 takes 25), and a
    /// near-step tanh(50 (x - 0.7)), where plain regula falsi stalls at one end, to 0.7.
    #[test]
    fn crossing_finds_closed_form_roots_in_few_steps() {
        let calls = &std::cell::Cell::new(0);
        let counted = |g: fn(f64) -> f64| {
            move |x: f64| {
                calls.set(calls.get() + 1);
                g(x)
            }
        };
        let cube: fn(f64) -> f64 = |x| x * x * x - 2.0;
        let x = crossing(counted(cube), (0.0, -2.0), (2.0, 6.0));
        assert!((x - 2f64.cbrt()).abs() < 3e-7 && calls.get() <= 12, "{x} in {} calls", calls.get());
        calls.set(0);
        let exp: fn(f64) -> f64 = |x| x.exp() - 10.0;
        let x = crossing(counted(exp), (0.0, -9.0), (5.0, 5f64.exp() - 10.0));
        assert!((x - 10f64.ln()).abs() < 4e-7 && calls.get() <= 12, "{x} in {} calls", calls.get());
        calls.set(0);
        let step: fn(f64) -> f64 = |x| (50.0 * (x - 0.7)).tanh();
        let x = crossing(counted(step), (0.0, step(0.0)), (1.0, step(1.0)));
        assert!((x - 0.7).abs() < 2e-7 && calls.get() <= 40, "{x} in {} calls", calls.get());
    }

    /// `bound_at` walks out from the estimate with doubling steps to the cutoff's crossing: a deviance
    /// x^2 crosses 3.8415 at +-1.95999 (the chi-square 95 % point's root), either way; none before a
    /// limit that comes first.
    #[test]
    fn bound_at_finds_where_a_deviance_crosses_its_cutoff() {
        let cutoff = 3.841458820694124;
        let up = bound_at(cutoff, |x| x * x, 0.0, 0.1, 10.0).unwrap();
        let down = bound_at(cutoff, |x| x * x, 0.0, -0.1, -10.0).unwrap();
        assert!((up - 1.959963984540054).abs() < 5e-7 && (down + 1.959963984540054).abs() < 5e-7, "{up} {down}");
        assert_eq!(bound_at(cutoff, |x| x * x, 0.0, 0.1, 1.5), None);
    }

    /// On exact generalised Pareto excesses the fit recovers the law: 20,000 draws of xi = 0.25,
    /// sigma = 2 by inversion give estimates within 3 standard errors (sd(xi) ~ (1 + xi) / sqrt(k) =
    /// 0.009, sd(sigma) / sigma ~ 0.011), and the profile interval of xi covers 0.25.
    #[test]
    fn the_fit_recovers_a_known_generalised_pareto_law() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(7);
        let (xi, sigma) = (0.25, 2.0);
        // All n values exceed u = 0 except one placed at 0 to be the threshold.
        let mut top: Vec<f64> = (0..20_000)
            .map(|_| {
                let v: f64 = rand::RngExt::random(&mut rng);
                excess_at(1.0 - v, sigma, xi)
            })
            .collect();
        top.push(0.0);
        let fit = TailFit::fit(&top, 40_002, 20_000).unwrap();
        assert_eq!(fit.u, 0.0);
        assert!((fit.xi - xi).abs() < 0.03, "xi {}", fit.xi);
        assert!((fit.sigma / sigma - 1.0).abs() < 0.035, "sigma {}", fit.sigma);
        let i = fit.xi_interval();
        assert!(i.lo < xi && xi < i.hi, "{i:?}");
        assert!(i.hi - i.lo < 0.06 && i.hi - i.lo > 0.02, "width {}", i.hi - i.lo);
    }

    /// 300 generalised Pareto excesses of shape `xi0` and scale 1.5 at the golden-ratio points
    /// `u_i = frac((i + 1) 0.618...)` (`scripts/reference/gpd_scipy.py` draws the same numbers), and a
    /// 0 to be the threshold: the fixed sample of the SciPy comparisons.
    fn golden_excesses_over_zero(xi0: f64) -> Vec<f64> {
        let phi = (5f64.sqrt() - 1.0) / 2.0;
        let mut top: Vec<f64> = (0..300)
            .map(|i| {
                let u = ((i + 1) as f64 * phi) % 1.0;
                1.5 / xi0 * ((1.0 - u).powf(-xi0) - 1.0)
            })
            .collect();
        top.push(0.0);
        top
    }

    /// Issue 49, item 4: the maximum-likelihood fit and the shape's profile interval against SciPy 1.17.1,
    /// which shares no code with fdimc. The sample: 300 generalised Pareto excesses at the golden-ratio
    /// points `u_i = frac((i + 1) 0.618...)` (the same numbers in both), of (xi, sigma) = (0.2, 1.5) and
    /// (-0.2, 1.5). Reference (`scripts/reference/gpd_scipy.py`): `genpareto.fit(y, floc=0)` refined by
    /// Nelder-Mead to 1e-12 gives (xi, sigma, max log-likelihood) = (0.1760108, 1.5284000, -480.069657)
    /// and (-0.2250580, 1.5322424, -360.502293) (`genpareto.fit` alone stops at 0.1759982 and -0.2250522);
    /// the 95 % profile interval of xi, sigma maximised at each xi (`minimize_scalar`) and the deviance's
    /// 3.841459 crossings found by `brentq`: [0.0547133, 0.3291340] and [-0.3130479, -0.1113016].
    #[test]
    fn the_fit_and_its_shape_interval_match_scipy() {
        for (xi0, expected, interval) in [
            (0.2, (0.1760108, 1.5284000, -480.069657), (0.0547133, 0.3291340)),
            (-0.2, (-0.2250580, 1.5322424, -360.502293), (-0.3130479, -0.1113016)),
        ] {
            let fit = TailFit::fit(&golden_excesses_over_zero(xi0), 3000, 300).unwrap();
            assert!((fit.xi - expected.0).abs() < 2e-5 && (fit.sigma / expected.1 - 1.0).abs() < 2e-5, "{fit:?}");
            let gpd = gpd_loglik(&fit.excess, fit.sigma, fit.xi);
            assert!((gpd - expected.2).abs() < 1e-5, "log-likelihood {gpd} vs SciPy's {}", expected.2);
            let i = fit.xi_interval();
            assert!((i.lo - interval.0).abs() < 1e-4 && (i.hi - interval.1).abs() < 1e-4, "{i:?} vs {interval:?}");
        }
    }

    /// Issue 49, item 4: a tail probability's profile interval against an independent profile
    /// likelihood in SciPy (`scripts/reference/gpd_scipy.py`, second part): the same 300 excesses as
    /// above, read as the largest of n = 3000 (zeta = 0.1); the joint binomial and generalised Pareto
    /// log-likelihood maximised over (zeta, xi) by Nelder-Mead at each p, its 3.841459 crossings by
    /// `brentq`. P(X > u + 20) for xi = 0.2: 1.12637905e-4 in [1.11038202e-5, 5.01451445e-4];
    /// P(X > u + 5) for xi = -0.2 (a bounded tail): 2.76452413e-4 in [3.02050745e-5, 1.08754204e-3].
    #[test]
    fn the_tail_probability_interval_matches_scipy() {
        for (xi0, d, expected) in [
            (0.2, 20.0, (1.12637905e-4, 1.11038202e-5, 5.01451445e-4)),
            (-0.2, 5.0, (2.76452413e-4, 3.02050745e-5, 1.08754204e-3)),
        ] {
            let fit = TailFit::fit(&golden_excesses_over_zero(xi0), 3000, 300).unwrap();
            assert_eq!(fit.u, 0.0);
            let p = fit.survival_interval(d);
            let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-4;
            assert!(
                close(p.estimate, expected.0) && close(p.lo, expected.1) && close(p.hi, expected.2),
                "xi {xi0}: {p:?} vs SciPy's {expected:?}"
            );
        }
    }

    /// The estimate and the profile's maximum agree: the profile at the fitted point is the maximised
    /// likelihood, and the quantile and survival invert each other.
    #[test]
    fn the_profile_peaks_at_the_estimate() {
        let v = exponential(3000, 1);
        let fit = TailFit::fit(&v, 3000, 300).unwrap();
        let x = fit.quantile(1e-5);
        assert!((fit.survival(x) / 1e-5 - 1.0).abs() < 1e-9);
        let p = fit.profile(x - fit.u, 1e-5);
        assert!((fit.loglik - p).abs() < 1e-3, "profile {p} vs maximum {}", fit.loglik);
        assert!(fit.profile(x - fit.u, 1e-7) < p - 1.0, "a probability 100x off is less likely");
    }

    /// Exponential values (xi = 0, P(X > x) = e^-x): over 200 sets of 1000, the fit on the 100 largest
    /// puts P(X > ln 1e6) = 1e-6 (three decades below what 1000 values can show) inside its interval in
    /// 90.5 % of the sets, and the threshold for 1e-6 (13.8) inside its own in the same sets (the two
    /// test the same point of one profile). Nominal 95 %: profile intervals are asymptotic, and 100
    /// exceedances extrapolated three decades cover a little less.
    #[test]
    fn profile_intervals_cover_an_extrapolated_exponential_tail() {
        let (sets, x_true, p_true) = (200, (1e6f64).ln(), 1e-6);
        let (mut p_in, mut x_in) = (0, 0);
        for seed in 0..sets {
            let v = exponential(1000, 100 + seed);
            let fit = TailFit::fit(&v, 1000, 100).unwrap();
            let p = fit.survival_interval(x_true);
            p_in += (p.lo <= p_true && p_true <= p.hi) as u32;
            let x = fit.quantile_interval(p_true);
            x_in += (x.lo <= x_true && x_true <= x.hi) as u32;
        }
        let p = p_in as f64 / sets as f64;
        assert_eq!(p_in, x_in, "the two intervals test the same point");
        assert!((0.88..=0.985).contains(&p), "probability intervals cover in {p}");
    }

    /// The maximum of 1000 independent |N(0, 1)| (a white residual's largest magnitude over a trial): the
    /// tail is known exactly, P(M > x) = 1 - (2 Phi(x) - 1)^1000. Over 40 sets of 5000 such maxima, the fit
    /// on each set's 500 largest puts P(M > 5.45) = 5.0e-5 (a decade below what 5000 values show) inside
    /// its interval in at least 34 of the 40 (binomial spread at 95 %: 35-40), by intervals no wider than
    /// the data allow (today the median interval's hi / lo is 254: below 1,000 asked, so that coverage
    /// cannot be bought by width), and the middle estimate is within a factor of 2 of it. That factor is
    /// the resolution of 40 sets, not slack: one set's ln(estimate / truth) spreads with sd 1.14 (a
    /// decade's extrapolation from 500 values), so the median's standard error is about 0.22 in ln and
    /// a factor of 2 is 3 of them (today: 0.66). (A Gaussian tail reaches the generalised Pareto law
    /// slowly, so one set's shape is often negative and its estimate low; the intervals carry that.)
    #[test]
    fn the_fit_extrapolates_the_maximum_of_a_white_gaussian_residual() {
        let exact = |x: f64| -(1000.0 * (-2.0 * crate::engine::stats::intervals::normal_sf(x)).ln_1p()).exp_m1();
        let truth = exact(5.45);
        assert!((truth / 5.0e-5 - 1.0).abs() < 0.02, "exact {truth}");
        let mut covered = 0;
        let mut ratios = Vec::new();
        let mut widths = Vec::new();
        for seed in 0..40 {
            let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(300 + seed);
            let maxima: Vec<f64> = (0..5000)
                .map(|_| (0..1000).map(|_| f64::abs(StandardNormal.sample(&mut rng))).fold(0.0, f64::max))
                .collect();
            let fit = TailFit::fit(&maxima, 5000, 500).unwrap();
            let p = fit.survival_interval(5.45);
            covered += (p.lo <= truth && truth <= p.hi) as u32;
            ratios.push(p.estimate / truth);
            widths.push(p.hi / p.lo);
        }
        ratios.sort_by(f64::total_cmp);
        let middle = 0.5 * (ratios[19] + ratios[20]);
        assert!(covered >= 34, "covered in {covered} of 40");
        widths.sort_by(f64::total_cmp);
        assert!(widths[19] < 1000.0, "the median interval spans {} (hi / lo): {widths:?}", widths[19]);
        assert!((0.5..2.0).contains(&middle), "middle estimate / truth {middle}: {ratios:?}");
    }

    /// The confident calibration's bound past Wilks' count (issue 82): the 95 % upper bound on the
    /// threshold for 1e-3 from 400 values (Wilks needs 2,995), over 200 sets each of two laws whose
    /// quantile is known. Maxima of 200 `|N(0, 1)|` (the white residual's fault-free statistic;
    /// `1 - (1 - 2 Q(x))^200 = 1e-3` at x = 4.5647): the bound falls below the truth in at most 4 of 200
    /// (2 %: the Gumbel domain's negative-looking shape is not trusted; the free shape's bound fell below
    /// in 7 % to 12 %, 14 to 24 of 200). Exponential values (x = ln 1000), the shape 0 the truth: at most
    /// 10 of 200 (5 %; on the boundary of the shapes allowed the bound is conservative too). Its
    /// price: the true probability beyond the median set's bound is about 0.5 % (Gaussian) and 2 %
    /// (exponential) of the target, asserted within [0.2 %, 10 %].
    #[test]
    fn the_confident_bound_holds_its_confidence_on_gaussian_maxima() {
        use statrs::distribution::{ContinuousCDF, Normal};
        let (n, k, p) = (400u64, 40usize, 1e-3f64);
        let per_sample = -((1.0 - p).ln() / 200.0).exp_m1();
        let x_gauss = Normal::standard().inverse_cdf(1.0 - per_sample / 2.0);
        assert!((x_gauss - 4.5647).abs() < 1e-3, "{x_gauss}");
        let (mut gauss_below, mut exp_below) = (0, 0);
        // What the bound costs: the true probability beyond it over the target, per set.
        let (mut gauss_cost, mut exp_cost) = (Vec::new(), Vec::new());
        for seed in 0..200 {
            let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(5000 + seed);
            let maxima: Vec<f64> = (0..n)
                .map(|_| (0..200).map(|_| f64::abs(StandardNormal.sample(&mut rng))).fold(0.0, f64::max))
                .collect();
            let bound = TailFit::fit(&maxima, n, k).unwrap().quantile_upper(p, 0.95);
            gauss_below += (bound < x_gauss) as u32;
            let sf = crate::engine::stats::intervals::normal_sf(bound);
            gauss_cost.push(-(200.0 * (-2.0 * sf).ln_1p()).exp_m1() / p);
            let bound = TailFit::fit(&exponential(n as usize, 9000 + seed), n, k).unwrap().quantile_upper(p, 0.95);
            exp_below += (bound < 1000f64.ln()) as u32;
            exp_cost.push((-bound).exp() / p);
        }
        gauss_cost.sort_by(f64::total_cmp);
        exp_cost.sort_by(f64::total_cmp);
        println!(
            "of 200 sets the bound fell below the truth: Gaussian maxima {gauss_below}, exponential {exp_below}; \
             the law's probability beyond it over the target, median and 90 %: Gaussian {:.3} {:.3}, exponential {:.3} {:.3}",
            gauss_cost[100], gauss_cost[180], exp_cost[100], exp_cost[180]
        );
        assert!(gauss_below <= 4, "Gaussian maxima: below the truth in {gauss_below} of 200");
        assert!(exp_below <= 10, "exponential: below the truth in {exp_below} of 200");
        // The price, stated in the docs (statistics.md): the median set's threshold lets through 0.5 %
        // (Gaussian) and 2 % (exponential) of the target; a bound far above would be useless.
        for (law, cost) in [("Gaussian", &gauss_cost), ("exponential", &exp_cost)] {
            assert!((0.002..0.1).contains(&cost[100]), "{law}: median probability over target {}", cost[100]);
        }
    }

    /// The conservative intervals' upper ends on Gaussian maxima, where the free shape's fail (issue
    /// 82: on a slow mode the per-hour row held the exact figure on 16 of 20 seeds, every miss too
    /// low). Over 100 sets of 1,000 maxima of 100 `|N(0, 1)|`, fitted on the 100 largest, the
    /// probability `P(M > x) = 2e-5` (x = 5.1993, fifty times past 1 / n) and the threshold for it:
    /// the free profile's upper end falls below the truth in 13 of 100 sets (2.5 % is a 95 %
    /// interval's one-sided level), the conservative one in none, asked at most 6 (a binomial of 100
    /// at 0.025 exceeds 6 with probability 1.4 %); the threshold's upper end likewise. Its price: the conservative upper end is 39
    /// times the truth in the median set (the free one 25), asserted below 100.
    #[test]
    fn the_conservative_upper_ends_hold_on_gaussian_maxima() {
        use statrs::distribution::{ContinuousCDF, Normal};
        let (n, k, p, sets) = (1000u64, 100usize, 2e-5f64, 100usize);
        let per_sample = -((1.0 - p).ln() / 100.0).exp_m1();
        let x_true = Normal::standard().inverse_cdf(1.0 - per_sample / 2.0);
        assert!((x_true - 5.1993).abs() < 1e-4, "{x_true}");
        let (mut free_below, mut conservative_below, mut threshold_below, mut widths) = (0, 0, 0, Vec::new());
        for seed in 0..sets as u64 {
            let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(7000 + seed);
            let maxima: Vec<f64> = (0..n)
                .map(|_| (0..100).map(|_| f64::abs(StandardNormal.sample(&mut rng))).fold(0.0, f64::max))
                .collect();
            let fit = TailFit::fit(&maxima, n, k).unwrap();
            let (free, conservative) = (fit.survival_interval(x_true), fit.survival_interval_conservative(x_true));
            assert_eq!((free.estimate, free.lo), (conservative.estimate, conservative.lo));
            assert!(conservative.hi >= free.hi);
            free_below += (free.hi < p) as u32;
            conservative_below += (conservative.hi < p) as u32;
            threshold_below += (fit.quantile_interval_conservative(p).hi < x_true) as u32;
            widths.push(conservative.hi / p);
        }
        widths.sort_by(f64::total_cmp);
        println!(
            "upper end below the truth in {free_below} of {sets} (free), {conservative_below} (conservative), the \
             threshold's in {threshold_below}; conservative upper end over the truth: median {:.1}",
            widths[sets / 2]
        );
        assert!(conservative_below <= 6 && threshold_below <= 6, "{conservative_below}, {threshold_below}");
        assert!(widths[sets / 2] < 100.0, "median upper end {} times the truth", widths[sets / 2]);
    }

    /// A bounded tail (uniform values on (0, 1], xi = -1 in the limit) puts the probability beyond its
    /// largest value at 0. The 200 exceedances pin the endpoint to about 1/200 of their range: 1 %
    /// of it past the largest value the data allow a little (upper bound 2.7e-4 < 1/n), 10 % past they
    /// allow nothing (moving the endpoint there costs a deviance of about 2 k ln(1.1) = 38).
    #[test]
    fn a_bounded_tail_gives_zero_beyond_its_endpoint() {
        let v: Vec<f64> = (1..=2000).map(|i| i as f64 / 2000.0).collect();
        let fit = TailFit::fit(&v, 2000, 200).unwrap();
        assert!(fit.xi < -0.8, "xi {}", fit.xi);
        let near = fit.survival_interval(1.001);
        assert_eq!((near.estimate, near.lo), (0.0, 0.0));
        assert!(near.hi > 0.0 && near.hi < 1.0 / 2000.0, "{near:?}");
        assert_eq!(fit.survival_interval(1.01), Interval { estimate: 0.0, lo: 0.0, hi: 0.0 });
    }

    #[test]
    fn too_few_exceedances_do_not_fit() {
        assert_eq!(exceedances_for(299), None);
        assert_eq!(exceedances_for(869), Some(86));
        assert_eq!(exceedances_for(1_000_000), Some(1000));
        let v = exponential(100, 2);
        assert!(TailFit::fit(&v, 100, 29).is_none());
        let ties = vec![1.0; 500];
        assert!(TailFit::fit(&ties, 500, 50).is_none(), "no value above the threshold");
        assert_eq!(stability_ks(86, 173), vec![172, 122, 86, 61, 43, 30]);
    }

    /// The diagnostics on exponential values: every threshold's shape interval covers 0, the modified
    /// scale stays near 1, and no concern is raised; on a mixture whose far tail is heavier than its
    /// body the fit over the body is flagged.
    #[test]
    fn concerns_flag_a_tail_that_changes_law() {
        let v = exponential(20_000, 5);
        let fit = TailFit::fit(&v, 20_000, 1000).unwrap();
        let st = stability(&v, 20_000, &stability_ks(1000, 2001));
        assert!(st.iter().all(|s| s.xi.lo < 0.0 && 0.0 < s.xi.hi), "{st:?}");
        // The modified scale sigma - xi u magnifies the shape's noise at high thresholds: from 100 up.
        assert!(st.iter().filter(|s| s.k >= 100).all(|s| (s.modified_scale - 1.0).abs() < 0.3), "{st:?}");
        assert!(fit.concerns(&st, &v).is_empty(), "{:?}", fit.concerns(&st, &v));
        // A statistic that saturates: exponential up to 4.5, then squeezed into [4.5, 4.8] (1 % of the
        // values). A fit over the top 10 % sees an exponential body (shape -0.56); higher up the law is
        // bounded (-0.9 to -1), and the fit overstates the top values' rate 3-8 fold.
        let mixed: Vec<f64> =
            v.iter().map(|&x| if x > 4.5 { 4.5 + 0.3 * (1.0 - (4.5 - x).exp()) } else { x }).collect();
        let fit = TailFit::fit(&mixed, 20_000, 2000).unwrap();
        let st = stability(&mixed, 20_000, &stability_ks(2000, 4001));
        let concerns = fit.concerns(&st, &mixed);
        assert!(concerns.iter().any(|c| c.starts_with("shape unstable")), "fit {fit:?}: {concerns:?}");
        assert!(concerns.iter().any(|c| c.starts_with("misfit at the 3 largest")), "fit {fit:?}: {concerns:?}");
    }
}
