//! What `run`, `summarize` and `merge` print of a summary.

use crate::engine::results::schema::col;
use crate::engine::results::summary_spec::{Isolates, SummarySpec};
use crate::engine::results::tables::Table;
use crate::engine::results::text::{named, rate};
use crate::engine::results::thresholds::per_flight_hour;
use crate::engine::stats::intervals::{Z95, wilson};

/// `--verbose`: print the details behind the answer too (the tail fits' figures).
static VERBOSE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Sets `--verbose` for the process (the command line's flag).
pub fn set_verbose(on: bool) {
    VERBOSE.store(on, std::sync::atomic::Ordering::Relaxed);
}

use super::written::{Summary, VALIDATION};

fn verbose() -> bool {
    VERBOSE.load(std::sync::atomic::Ordering::Relaxed)
}

/// What `run`, `summarize` and `merge` print: one screen that answers ([`super::answer`]: per
/// detector Pfa, Pd and delay), the warnings a line each with the file that explains them, and what
/// to look at next. With `--verbose`, first the details behind it (`print_details`), then the answer
/// with its thresholds and smallest detectable faults, the safety sentences and the warnings whole.
pub fn print(spec: &SummarySpec, s: &Summary) {
    let verbose = verbose();
    if verbose {
        print_details(spec, s);
    } else if s.answer.height() == 0 {
        // A kind without an answer table still gets its per-detector rates.
        print_table(spec, s);
    }
    super::answer::print(&s.answer, verbose);
    // A classifier's answer includes which class it named (before the answer with --verbose).
    if !verbose && spec.isolates == Isolates::Kind {
        print_confusion(s);
    }
    if verbose {
        super::safety::print(&s.safety);
        for w in &s.warnings {
            println!("  warning: {w}");
        }
        return;
    }
    let names = Table(&s.answer).strs(col::DETECTOR);
    for w in one_line_warnings(&s.warnings, &names) {
        println!("  warning: {w}");
    }
    // The report draws a run's folder: the nearest one up with a manifest (a validation's or another
    // calibration's tables sit in a folder inside it).
    let run_dir = s.out_dir.ancestors().find(|d| d.join("manifest.json").exists()).unwrap_or(&s.out_dir);
    let safety = if s.safety.height() > 0 { ", safety.csv (the figures to quote, with their assumptions)" } else { "" };
    println!(
        "  next: `fdimc report {}` for {}plots and report.html; in {}: summary.csv (per fault kind and size){safety}; \
         --verbose for the calibration and every table",
        run_dir.display(),
        if run_dir == s.out_dir { "" } else { "the run's " },
        s.out_dir.display()
    );
}

/// Warnings as the console shows them: one line each (parenthesised details dropped, the files named
/// kept, detectors merged), or whole with `--verbose`. `report` prints its warnings (the summary's
/// among them) this way too.
pub fn console_warnings(warnings: &[String], detectors: &[String]) -> Vec<String> {
    if verbose() { warnings.to_vec() } else { one_line_warnings(warnings, detectors) }
}

/// The warnings for the console, one line each: parenthesised details dropped (the full text is in
/// summarize.json and `--verbose`), the files they named kept at the end, and warnings that differ
/// only in the detector named merged into one line naming them all.
fn one_line_warnings(warnings: &[String], detectors: &[String]) -> Vec<String> {
    const LONGEST: usize = 200;
    let mut lines: Vec<(String, Vec<String>)> = Vec::new();
    for w in warnings {
        let (mut text, mut files) = (String::new(), Vec::<String>::new());
        let mut depth = 0usize;
        for c in w.chars() {
            match c {
                '(' => depth += 1,
                ')' => depth = depth.saturating_sub(1),
                _ if depth == 0 => text.push(c),
                _ => {}
            }
        }
        for word in w.split(|c: char| c.is_whitespace() || "();,`'".contains(c)) {
            let word = word.trim_end_matches(['.', ':']);
            let named = [".csv", ".json", ".parquet", ".html", ".toml"].iter().any(|e| word.ends_with(e));
            if named && !files.iter().any(|f| f == word) {
                files.push(word.to_string());
            }
        }
        let mut text = text
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
            .replace(" ;", ";")
            .replace(" :", ":")
            .replace(" ,", ",");
        text = text.trim_end_matches([';', ',', ' ']).to_string();
        if text.chars().count() > LONGEST {
            let cut: String = text.chars().take(LONGEST).collect();
            text = format!("{}...", cut.rsplit_once(' ').map_or(cut.as_str(), |(a, _)| a));
        }
        files.retain(|f| !text.contains(f.as_str()));
        let line = if files.is_empty() { text } else { format!("{text}; {}", files.join(", ")) };
        // Merge with an earlier line that says the same of another detector.
        let named = |line: &str| {
            detectors.iter().find_map(|d| {
                let at = line.match_indices(d.as_str()).find(|&(i, _)| {
                    let before = line[..i].chars().next_back().is_none_or(|c| !c.is_alphanumeric() && c != '_');
                    let after = line[i + d.len()..].chars().next().is_none_or(|c| !c.is_alphanumeric() && c != '_');
                    before && after
                })?;
                Some((format!("{}\u{0}{}", &line[..at.0], &line[at.0 + d.len()..]), d.clone()))
            })
        };
        match named(&line) {
            Some((key, d)) => match lines.iter_mut().find(|(k, _)| *k == key) {
                Some((_, names)) => names.push(d),
                None => lines.push((key, vec![d])),
            },
            None => lines.push((line, Vec::new())),
        }
    }
    lines.into_iter().map(|(key, names)| key.replace('\u{0}', &names.join(", "))).collect()
}

/// The details behind the answer (`--verbose`): the thresholds (kinds with a statistic; the tail
/// fits' figures), per threshold set and detector the table, a classifier's confusion matrices and
/// the files written.
fn print_details(spec: &SummarySpec, s: &Summary) {
    if let Some((thresholds, source)) = &s.thresholds {
        println!("  thresholds: {source}");
        for t in thresholds {
            let (lo, hi) = wilson(t.whole_false_alarms, t.calibration_units, Z95);
            let list = |v: &[f64]| named(&s.statistics, v);
            let (label, trials) = match s.set {
                Some(VALIDATION) => ("applied", "this run's trials"),
                // NaN thresholds from no flown unit: nothing was calibrated.
                _ if t.calibration_units == 0 => ("not calibrated (no calibration unit flown)", "no trial"),
                _ => ("calibrated", "the calibration trials"),
            };
            // No unit: no rate (NaN prints `-`).
            let p = t.whole_false_alarms as f64 / t.calibration_units as f64;
            let per_hour = t.unit_duration_s.map_or(String::new(), |d| {
                let h = |p: f64| per_flight_hour(p, d);
                format!(
                    ", per flight hour {} [{}, {}] (the hour's {d} s segments taken as independent)",
                    rate(h(p)),
                    rate(h(lo)),
                    rate(h(hi))
                )
            });
            println!(
                "    {}: {label} [{}] (deck [{}]); Pfa achieved {}/{} = {} [{}, {}] on {trials}{per_hour}",
                t.detector,
                list(&t.whole),
                list(&t.deck),
                t.whole_false_alarms,
                t.calibration_units,
                rate(p),
                rate(lo),
                rate(hi),
            );
        }
        crate::engine::results::tails::print_tails(&s.tails);
    }
    print_table(spec, s);
    if spec.isolates == Isolates::Kind {
        print_confusion(s);
    }
    println!("  wrote {} in {}", s.files.join(", "), s.out_dir.display());
}

/// Per threshold set and detector: Pd, isolation, delay and Pfa with the kind's printed aggregates.
fn print_table(spec: &SummarySpec, s: &Summary) {
    let t = Table(&s.detectors);
    let (sets, names, units, flights) =
        (t.strs("thresholds"), t.strs(col::DETECTOR), t.u64s("faulty_units"), t.u64s("flights"));
    let (pd, iso, pfa) = (t.rates("pd"), t.rates("isolation_accuracy"), t.rates("pfa"));
    let delay = t.delays("delay_p50_s", "delay_p90_s");
    let own: Vec<Vec<f64>> = spec.printed.iter().map(|(_, c)| t.f64s(c)).collect();
    println!(
        "  per detector, paired over the same trials (summary.csv for groups, comparison.csv for the tests; flights: every flight, Pfa its false alarms before the onset):"
    );
    let mut header = format!(
        "    {:<10} {:<16} {:>7} {:<21} {:<21} {:>14} {:>7} {:<21}",
        "thresholds",
        "detector",
        "faulty",
        "Pd [95 % CI]",
        "isolated [95 % CI]",
        "delay p50/p90",
        "flights",
        "Pfa [95 % CI]"
    );
    for (h, _) in spec.printed {
        header.push_str(&format!(" {h:>12}"));
    }
    println!("{header}");
    for i in 0..names.len() {
        let mut line = format!(
            "    {:<10} {:<16} {:>7} {:<21} {:<21} {:>14} {:>7} {:<21}",
            sets[i], names[i], units[i], pd[i], iso[i], delay[i], flights[i], pfa[i]
        );
        for v in &own {
            line.push_str(&if v[i].is_nan() { format!(" {:>12}", "-") } else { format!(" {:>12.3}", v[i]) });
        }
        println!("{line}");
    }
}

/// A classifier's confusion matrices, per detector.
fn print_confusion(s: &Summary) {
    let c = Table(&s.confusion);
    let (det, truth, isolated, n) = (c.strs(col::DETECTOR), c.strs("truth"), c.strs(col::ISOLATED), c.u64s("units"));
    let mut classes: Vec<&str> = truth.iter().map(String::as_str).collect();
    classes.sort_unstable();
    classes.dedup();
    let mut detectors: Vec<&String> = Vec::new();
    for d in &det {
        if !detectors.contains(&d) {
            detectors.push(d);
        }
    }
    for name in detectors {
        println!("  confusion ({name}): rows the true class, columns the class named: {}", classes.join(" / "));
        for class in &classes {
            let row: Vec<String> = classes
                .iter()
                .map(|p| {
                    let k = (0..det.len())
                        .find(|&i| det[i] == **name && truth[i] == *class && isolated[i] == *p)
                        .map_or(0, |i| n[i]);
                    format!("{k:>6}")
                })
                .collect();
            println!("    {class:<8} {}", row.join(" "));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::one_line_warnings;

    /// The console's one-line form: parenthesised details dropped without leaving a space before the
    /// punctuation that followed them, the files they named kept at the end, and warnings that differ
    /// only in the detector merged into one line naming both (in the order first seen).
    #[test]
    fn one_line_warnings_drop_details_keep_files_and_merge_detectors() {
        let detectors = ["fast".to_string(), "slow".to_string()];
        let warnings = [
            "the largest T is 1.04 times the evaluated part's (394.8 at 9.59 s), more than 1.01".to_string(),
            "detector fast: the tail fit doubts its shape (see tail_diagnostics.csv)".to_string(),
            "detector slow: the tail fit doubts its shape (see tail_diagnostics.csv)".to_string(),
        ];
        let lines = one_line_warnings(&warnings, &detectors);
        assert_eq!(
            lines,
            [
                "the largest T is 1.04 times the evaluated part's, more than 1.01",
                "detector fast, slow: the tail fit doubts its shape; tail_diagnostics.csv",
            ]
        );
    }
}
