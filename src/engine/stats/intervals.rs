//! Binomial intervals and tests.

/// Two-sided 95 % normal quantile.
pub const Z95: f64 = 1.959_963_984_540_054;
/// The standard normal quantile of a one-sided 95 % bound.
pub const Z_ONE_SIDED_95: f64 = 1.644_853_626_951_472_2;

/// Wilson score interval for `k` successes in `n` trials at normal quantile `z` (`(NaN, NaN)` if n = 0).
pub fn wilson(k: u64, n: u64, z: f64) -> (f64, f64) {
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let n_f = n as f64;
    let p = k as f64 / n_f;
    let z2 = z * z;
    let centre = p + z2 / (2.0 * n_f);
    let half = z * (p * (1.0 - p) / n_f + z2 / (4.0 * n_f * n_f)).sqrt();
    let denom = 1.0 + z2 / n_f;
    // At k = 0 and k = n the bound is exactly 0 or 1; the formula leaves rounding dust (1e-19).
    let lo = if k == 0 { 0.0 } else { ((centre - half) / denom).max(0.0) };
    let hi = if k == n { 1.0 } else { ((centre + half) / denom).min(1.0) };
    (lo, hi)
}

/// Exact two-sided McNemar test: p-value of `b` vs `c` discordant pairs (binomial(b + c, 1/2)).
pub fn mcnemar_exact(b: u64, c: u64) -> f64 {
    let n = b + c;
    if n == 0 {
        return 1.0;
    }
    let k = b.min(c);
    // P(X <= k) for X ~ Bin(n, 1/2), summed in log space.
    let ln_half_n = -(n as f64) * std::f64::consts::LN_2;
    let mut ln_term = ln_half_n; // ln C(n, 0) + n ln(1/2)
    let mut tail = ln_term.exp();
    for i in 1..=k {
        ln_term += ((n - i + 1) as f64).ln() - (i as f64).ln();
        tail += ln_term.exp();
    }
    (2.0 * tail).min(1.0)
}

/// Standard normal upper tail `P(Z > z)`.
pub fn normal_sf(z: f64) -> f64 {
    // statrs' erfc keeps its relative accuracy far into the tail, where Bonferroni levels of 1e-5 and
    // below are decided (a polynomial approximation of erf is only good to 1.5e-7 absolute).
    0.5 * statrs::function::erf::erfc(z / std::f64::consts::SQRT_2)
}

/// One-sided p-value that proportion `k1/n1` is below `k0/n0` (pooled two-proportion z-test with
/// continuity correction). 1 when either sample is empty.
pub fn p_lower(k1: u64, n1: u64, k0: u64, n0: u64) -> f64 {
    if n0 == 0 || n1 == 0 {
        return 1.0;
    }
    let (n0f, n1f) = (n0 as f64, n1 as f64);
    let (p0, p1) = (k0 as f64 / n0f, k1 as f64 / n1f);
    let pooled = (k0 + k1) as f64 / (n0f + n1f);
    let se = (pooled * (1.0 - pooled) * (1.0 / n0f + 1.0 / n1f)).sqrt();
    if se == 0.0 {
        return if p1 < p0 { 0.0 } else { 1.0 };
    }
    let correction = 0.5 * (1.0 / n0f + 1.0 / n1f);
    let z = ((p0 - p1) - correction).max(0.0) / se;
    normal_sf(z)
}

/// The exact one-sided 95 % upper bound on a Poisson mean from `k` events (Garwood):
/// `chi2_0.95(2k + 2) / 2` (3.0 for no event).
pub fn poisson_upper95(k: u64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    ChiSquared::new(2.0 * k as f64 + 2.0).map(|c| 0.5 * c.inverse_cdf(0.95)).unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poisson_upper_bounds_are_garwoods() {
        // -ln 0.05 for no event; chi2_0.95(4) / 2 for one (tables: 9.4877 / 2).
        assert!((poisson_upper95(0) - 2.995732273553991).abs() < 1e-9);
        assert!((poisson_upper95(1) - 4.743864518390723).abs() < 1e-9);
        assert!((poisson_upper95(10) - 33.924 / 2.0).abs() < 1e-3, "chi2_0.95(22) = 33.924");
    }

    #[test]
    fn wilson_matches_published_values() {
        // 8 of 10 at 95 %: Wilson interval [0.4902, 0.9433] (Newcombe 1998, table I).
        let (lo, hi) = wilson(8, 10, Z95);
        assert!((lo - 0.4902).abs() < 1e-4 && (hi - 0.9433).abs() < 1e-4, "{lo} {hi}");
        let (lo, hi) = wilson(0, 10, Z95);
        assert_eq!(lo, 0.0);
        assert!((hi - 0.2775).abs() < 1e-4, "{hi}");
        // The ends are exact, not rounding dust: every k = n interval reaches 1, every k = 0 one 0.
        for n in 1..2000 {
            assert_eq!(wilson(n, n, Z95).1, 1.0, "{n}");
            assert_eq!(wilson(0, n, Z95).0, 0.0, "{n}");
        }
    }

    #[test]
    fn mcnemar_exact_values() {
        // b = 0, c = 5: p = 2 / 32.
        assert!((mcnemar_exact(0, 5) - 0.0625).abs() < 1e-12);
        assert!((mcnemar_exact(3, 3) - 1.0).abs() < 1e-12);
        // b = 2, c = 10: 2 * P(X <= 2), X ~ Bin(12, 1/2) = 2 * 79 / 4096.
        assert!((mcnemar_exact(2, 10) - 2.0 * 79.0 / 4096.0).abs() < 1e-12);
    }

    #[test]
    fn normal_tail_and_proportion_test() {
        assert!((normal_sf(1.959_964) - 0.025).abs() < 1e-6);
        assert!((normal_sf(0.0) - 0.5).abs() < 1e-7);
        // 900/1000 against 800/1000 is far below 1e-6; equal proportions are not a drop.
        assert!(p_lower(800, 1000, 900, 1000) < 1e-6);
        assert!(p_lower(900, 1000, 900, 1000) > 0.4);
    }
}
