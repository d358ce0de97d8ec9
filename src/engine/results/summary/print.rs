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

/// What `run`, `summarize` and `merge` print: the thresholds (kinds with a statistic; the tail fits'
/// figures with `--verbose`), per threshold set and detector Pd, isolation, delay and Pfa with the
/// kind's printed aggregates, a classifier's confusion matrices, warnings, the files written and, last,
/// the answer ([`super::answer`]).
pub fn print(spec: &SummarySpec, s: &Summary) {
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
        if VERBOSE.load(std::sync::atomic::Ordering::Relaxed) {
            crate::engine::results::tails::print_tails(&s.tails);
        } else if !s.tails.is_empty() {
            println!("  rare false alarms: the tail fits are in tail.csv (and printed with --verbose)");
        }
    }
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
    if spec.isolates == Isolates::Kind {
        let c = Table(&s.confusion);
        let (det, truth, isolated, n) =
            (c.strs(col::DETECTOR), c.strs("truth"), c.strs(col::ISOLATED), c.u64s("units"));
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
    println!("  wrote {} in {}", s.files.join(", "), s.out_dir.display());
    super::answer::print(&s.answer);
    super::safety::print(&s.safety);
    for w in &s.warnings {
        println!("  warning: {w}");
    }
}
