//! Numbers as the console and the report print them, one way for both: rates to their significant
//! digits (a rate of 4.4e-4 does not read 0.000), intervals beside them.

/// A rate or probability: 3 decimals from 0.1 up (4 when 3 would round it to 1), two significant
/// digits below (`4.4e-4`), `0` for none, `-` for no value.
pub fn rate(x: f64) -> String {
    if x.is_nan() {
        return "-".into();
    }
    if x == 0.0 {
        return "0".into();
    }
    if x < 0.1 {
        return format!("{x:.1e}");
    }
    let three = format!("{x:.3}");
    if three == "1.000" && x < 1.0 { format!("{x:.4}") } else { three }
}

/// A rate with its interval: `4.4e-4 [1.7e-4, 1.1e-3]`.
pub fn rate_interval(x: f64, lo: f64, hi: f64) -> String {
    if x.is_nan() {
        return "-".into();
    }
    format!("{} [{}, {}]", rate(x), rate(lo), rate(hi))
}

/// `values` to the fewest significant digits, 2 to 6, at which those that differ print apart (an
/// interval that does not collapse onto its estimate: `1.9e-4 [1.9e-4, 1.9e-4]` becomes `1.894e-4
/// [1.887e-4, 1.901e-4]`); below 0.1 in exponent form, as [`rate`].
pub fn apart(values: &[f64]) -> Vec<String> {
    let at = |x: f64, digits: usize| -> String {
        if x.is_nan() {
            "-".into()
        } else if x == 0.0 {
            "0".into()
        } else if x.abs() < 0.1 || x.abs() >= 1e4 {
            format!("{x:.*e}", digits - 1)
        } else {
            let decimals = (digits as i32 - 1 - x.abs().log10().floor() as i32).max(0) as usize;
            format!("{x:.decimals$}")
        }
    };
    let mut digits = 2;
    loop {
        let shown: Vec<String> = values.iter().map(|&x| at(x, digits)).collect();
        let collapsed = (0..values.len()).any(|i| {
            (0..i)
                .any(|j| values[i] != values[j] && !(values[i].is_nan() && values[j].is_nan()) && shown[i] == shown[j])
        });
        if !collapsed || digits == 6 {
            return shown;
        }
        digits += 1;
    }
}

/// `k` of `n` as a rate with its 95 % Wilson interval; `-` when `n` is 0.
pub fn proportion(k: u64, n: u64) -> String {
    if n == 0 {
        return "-".into();
    }
    let (lo, hi) = crate::engine::stats::intervals::wilson(k, n, crate::engine::stats::intervals::Z95);
    rate_interval(k as f64 / n as f64, lo, hi)
}

/// A number to 4 significant digits, without trailing zeros; scientific when very small or large.
pub fn significant(x: f64) -> String {
    if x.is_nan() {
        return "-".into();
    }
    if x == 0.0 {
        return "0".into();
    }
    let a = x.abs();
    if !(1e-3..1e6).contains(&a) {
        return format!("{x:.3e}");
    }
    let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s }
}

/// Values by name, `v_m_s 0.474, alpha_rad 0.01004`: a threshold set per statistic.
pub fn named(names: &[String], values: &[f64]) -> String {
    names.iter().zip(values).map(|(n, v)| format!("{n} {}", significant(*v))).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_rates_keep_their_significant_digits() {
        // The case: a target of 0.001 read "0.000 [0.000, 0.001]".
        assert_eq!(rate_interval(4.4e-4, 1.7e-4, 1.1e-3), "4.4e-4 [1.7e-4, 1.1e-3]");
        assert_eq!(rate(0.0099), "9.9e-3");
        assert_eq!(rate(0.801134), "0.801");
        assert_eq!(rate(0.99971), "0.9997");
        assert_eq!(rate(1.0), "1.000");
        assert_eq!(rate(0.0), "0");
        assert_eq!(rate(f64::NAN), "-");
        assert_eq!(significant(0.030343), "0.03034");
        assert_eq!(significant(54999.59), "55000");
        assert_eq!(significant(2.5e7), "2.500e7");
        assert_eq!(significant(2.5), "2.5");
    }
}

#[cfg(test)]
mod apart_tests {
    use super::apart;

    /// Two digits where they tell the numbers apart; more where an interval would collapse; equal
    /// values stay equal; six at most.
    #[test]
    fn numbers_print_apart_with_the_fewest_digits() {
        assert_eq!(apart(&[1.9e-4, 1.2e-4, 2.8e-4]), ["1.9e-4", "1.2e-4", "2.8e-4"]);
        assert_eq!(apart(&[1.894e-4, 1.887e-4, 1.901e-4]), ["1.894e-4", "1.887e-4", "1.901e-4"]);
        assert_eq!(apart(&[0.25, 0.25, 0.31]), ["0.25", "0.25", "0.31"]);
        assert_eq!(apart(&[0.5, 0.5000001]), ["0.500000", "0.500000"]);
        assert_eq!(apart(&[f64::NAN, 0.0, 3e-9]), ["-", "0", "3.0e-9"]);
    }
}
