//! The chi-square tail and its threshold for the dual UKF's isolation test (module docs of [`super`],
//! step 3): the threshold is found to the last bit of the survival function it is read against.

/// Upper tail `Pr(X > x)` of the chi-square distribution with `dof` degrees of freedom: the regularised
/// upper incomplete gamma function `Q(dof/2, x/2)`, by its series below `x/2 = dof/2 + 1` and its
/// continued fraction (modified Lentz) above (Numerical Recipes, 3rd ed., 6.2); `ln Gamma(dof/2)` exactly
/// from `Gamma(1/2) = sqrt(pi)`, `Gamma(1) = 1`, `Gamma(a + 1) = a Gamma(a)`. Relative accuracy about
/// 1e-14 (tested against closed forms). NaN for `dof = 0` or NaN `x`.
pub fn chi_square_survival(dof: u32, x: f64) -> f64 {
    if dof == 0 || x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    let a = dof as f64 / 2.0;
    let z = x / 2.0;
    let ln_prefactor = -z + a * z.ln() - ln_gamma_half(dof);
    if z < a + 1.0 {
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..INCOMPLETE_GAMMA_ITERATIONS {
            ap += 1.0;
            term *= z / ap;
            sum += term;
            if term.abs() < sum.abs() * f64::EPSILON {
                break;
            }
        }
        1.0 - sum * ln_prefactor.exp()
    } else {
        let tiny = f64::MIN_POSITIVE / f64::EPSILON;
        let mut b = z + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..INCOMPLETE_GAMMA_ITERATIONS {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < f64::EPSILON {
                break;
            }
        }
        ln_prefactor.exp() * h
    }
}

/// Enough terms for the series and the continued fraction to converge for any dof used here (they
/// need about `sqrt(a)` to a few tens of terms).
const INCOMPLETE_GAMMA_ITERATIONS: usize = 10_000;

/// `ln Gamma(dof / 2)`, exactly by the recursion.
fn ln_gamma_half(dof: u32) -> f64 {
    if dof.is_multiple_of(2) {
        (1..dof / 2).map(|k| (k as f64).ln()).sum()
    } else {
        0.5 * std::f64::consts::PI.ln() + (0..dof / 2).map(|k| (k as f64 + 0.5).ln()).sum::<f64>()
    }
}

/// The threshold a chi-square(`dof`) variable exceeds with probability `false_alarm_probability`, i.e.
/// its quantile at `1 - false_alarm_probability` (chi-square(1) at 0.99: 6.6349). Bisection on
/// [`chi_square_survival`] to the last bit (given the tail probability directly, so tiny false-alarm
/// probabilities lose nothing to `1 - p`). NaN when `dof = 0` or the probability is not in (0, 1).
pub fn chi_square_threshold(dof: u32, false_alarm_probability: f64) -> f64 {
    let p = false_alarm_probability;
    if dof == 0 || !(p > 0.0 && p < 1.0) {
        return f64::NAN;
    }
    let (mut lo, mut hi) = (0.0f64, dof as f64 + 1.0);
    while chi_square_survival(dof, hi) > p {
        lo = hi;
        hi *= 2.0;
    }
    loop {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            return mid;
        }
        if chi_square_survival(dof, mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
}
