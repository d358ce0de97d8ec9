//! Tables and figures of a report written for reading: counts as integers, rates to their significant
//! digits ([`crate::engine::results::text::rate`]), each interval as
//! `[lo, hi]` next to its rate, other numbers to 4 significant digits, and a column that holds one value
//! on every row said once above the table instead.

use polars::prelude::*;

/// `<`, `>`, `&` and `"` as HTML entities.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// A figure of the report folder: the image `file` (by its name), captioned with it.
pub fn figure(file: &std::path::Path) -> String {
    let name = escape(&file.file_name().unwrap_or_default().to_string_lossy());
    format!("<figure><img src=\"{name}\" alt=\"{name}\"><figcaption>{name}</figcaption></figure>\n")
}

/// Rates and probabilities: shown with 3 decimals.
fn is_rate(name: &str) -> bool {
    let base = name.trim_end_matches("_lo").trim_end_matches("_hi");
    ["pd", "pd_a", "pd_b", "isolated_a", "isolated_b", "share_of_truth", "pfa_achieved"].contains(&base)
        || (base.ends_with("pfa") && base != "target_pfa")
        || base.ends_with("accuracy")
        || base.ends_with("_rate")
        || base.ends_with("_recall")
        || base.starts_with("mcnemar_p")
}

/// One column's cells as text ("-" for a missing value).
fn cells(df: &DataFrame, name: &str) -> Vec<String> {
    let Ok(c) = df.column(name) else { return vec!["-".into(); df.height()] };
    if c.dtype() == &DataType::String {
        let s = c.str().expect("a string column");
        return (0..df.height()).map(|i| s.get(i).map(escape).unwrap_or_else(|| "-".into())).collect();
    }
    if c.dtype() == &DataType::Boolean {
        let b = c.bool().expect("a boolean column");
        return (0..df.height()).map(|i| b.get(i).map(|v| v.to_string()).unwrap_or_else(|| "-".into())).collect();
    }
    let Ok(f) = c.cast(&DataType::Float64) else { return vec!["?".into(); df.height()] };
    let f = f.f64().expect("cast to f64").clone();
    let values: Vec<Option<f64>> = (0..df.height()).map(|i| f.get(i).filter(|v| !v.is_nan())).collect();
    let rate = is_rate(name);
    let integral = !rate && values.iter().flatten().all(|v| v.fract() == 0.0 && v.abs() < 1e15);
    values
        .iter()
        .map(|v| match v {
            None => "-".into(),
            Some(x) if rate && name.starts_with("mcnemar_p") && *x < 1e-3 => "&lt; 0.001".into(),
            Some(x) if rate => crate::engine::results::text::rate(*x),
            Some(x) if integral => format!("{x:.0}"),
            Some(x) => crate::engine::results::text::significant(*x),
        })
        .collect()
}

/// `df` as an HTML table (columns in `skip` left out), preceded by a line naming the columns that hold
/// one value on every row.
pub fn table(df: &DataFrame, skip: &[&str]) -> String {
    let names: Vec<String> = df.get_column_names().iter().map(|n| n.to_string()).collect();
    let has = |n: &str| names.iter().any(|m| m == n);
    let mut header = Vec::new();
    let mut columns: Vec<Vec<String>> = Vec::new();
    let mut constant = Vec::new();
    for n in &names {
        if skip.contains(&n.as_str()) {
            continue;
        }
        // `pfa_achieved` has its interval in `pfa_lo`, `pfa_hi`.
        let base = n.strip_suffix("_achieved").unwrap_or(n);
        let interval = has(&format!("{base}_lo")) && has(&format!("{base}_hi"));
        if let Some(b) = n.strip_suffix("_lo").or_else(|| n.strip_suffix("_hi"))
            && (has(b) || has(&format!("{b}_achieved")))
        {
            continue;
        }
        let mut c = cells(df, n);
        if interval {
            let (lo, hi) = (cells(df, &format!("{base}_lo")), cells(df, &format!("{base}_hi")));
            for i in 0..c.len() {
                if c[i] != "-" {
                    c[i] = format!("{} [{}, {}]", c[i], lo[i], hi[i]);
                }
            }
        }
        if df.height() > 1 && c.iter().all(|v| *v == c[0]) {
            constant.push(format!("<code>{}</code>: {}", escape(n), c[0]));
            continue;
        }
        header.push(if interval { format!("{} [95 % CI]", escape(n)) } else { escape(n) });
        columns.push(c);
    }
    let mut html = String::new();
    if !constant.is_empty() {
        html.push_str(&format!("<p class=\"same\">On every row: {}.</p>\n", constant.join("; ")));
    }
    html.push_str("<table>\n<tr>");
    for h in &header {
        html.push_str(&format!("<th>{h}</th>"));
    }
    html.push_str("</tr>\n");
    for i in 0..df.height() {
        html.push_str("<tr>");
        for c in &columns {
            html.push_str(&format!("<td>{}</td>", c[i]));
        }
        html.push_str("</tr>\n");
    }
    html.push_str("</table>\n");
    html
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_integers_rates_have_significant_digits_intervals_are_brackets_and_repeats_are_said_once() {
        let df = df!(
            "detector" => ["seed", "fast"],
            "calibration_trials" => [869.0, 12.0],
            "pd" => [0.51149, 0.9],
            "pd_lo" => [0.43778, 0.8],
            "pd_hi" => [0.58471, 0.95],
            "threshold" => [9.906793e-6, 0.4377703],
            "pfa_achieved" => [0.0092, 0.01],
            "pfa_lo" => [0.0047, 0.005],
            "pfa_hi" => [0.018, 0.02],
            "source" => ["calibrated at Pfa 0.01", "calibrated at Pfa 0.01"],
        )
        .unwrap();
        let html = table(&df, &[]);
        assert!(html.contains("On every row: <code>source</code>: calibrated at Pfa 0.01."), "{html}");
        assert!(html.contains("<th>pd [95 % CI]</th>") && !html.contains("<th>pd_lo"), "{html}");
        assert!(
            html.contains(
                "<td>seed</td><td>869</td><td>0.511 [0.438, 0.585]</td><td>9.907e-6</td><td>9.2e-3 [4.7e-3, 1.8e-2]</td>"
            ),
            "{html}"
        );
        assert!(
            html.contains(
                "<td>fast</td><td>12</td><td>0.900 [0.800, 0.950]</td><td>0.4378</td><td>1.0e-2 [5.0e-3, 2.0e-2]</td>"
            ),
            "{html}"
        );
    }
}
