//! What `run`, `summarize` and `merge` print of a summary.

use crate::engine::results::schema::col;
use crate::engine::results::summary_spec::{Isolates, SummarySpec};
use crate::engine::results::tables::Table;
use crate::engine::results::thresholds::per_flight_hour;
use crate::engine::stats::intervals::{Z95, wilson};

use super::written::{Summary, VALIDATION};

/// What `run`, `summarize` and `merge` print: the thresholds (kinds with a statistic), per threshold set
/// and detector Pd, isolation, delay and Pfa with the kind's printed aggregates, a classifier's
/// confusion matrices, warnings and the files written.
pub fn print(spec: &SummarySpec, s: &Summary) {
    if let Some((thresholds, source)) = &s.thresholds {
        println!("  thresholds: {source}");
        for t in thresholds {
            let (lo, hi) = wilson(t.whole_false_alarms, t.calibration_units, Z95);
            let list = |v: &[f64]| {
                let named = s.statistics.iter().zip(v).map(|(n, v)| format!("{n} {}", significant(*v)));
                named.collect::<Vec<_>>().join(", ")
            };
            let (label, trials) = match s.set {
                Some(VALIDATION) => ("applied", "this run's trials"),
                _ => ("calibrated", "the calibration trials"),
            };
            let rate = t.whole_false_alarms as f64 / t.calibration_units.max(1) as f64;
            let per_hour = t.unit_duration_s.map_or(String::new(), |d| {
                let h = |p: f64| per_flight_hour(p, d);
                format!(
                    ", per flight hour {:.4} [{:.4}, {:.4}] (the hour's {d} s segments taken as independent)",
                    h(rate),
                    h(lo),
                    h(hi)
                )
            });
            println!(
                "    {}: {label} [{}] (deck [{}]); Pfa achieved {}/{} = {rate:.4} [{lo:.4}, {hi:.4}] on {trials}{per_hour}",
                t.detector,
                list(&t.whole),
                list(&t.deck),
                t.whole_false_alarms,
                t.calibration_units,
            );
        }
        crate::engine::results::tails::print_tails(&s.tails);
    }
    let t = Table(&s.detectors);
    let (sets, names, units, flights) =
        (t.strs("thresholds"), t.strs(col::DETECTOR), t.u64s("faulty_units"), t.u64s("flights"));
    let (pd, iso, pfa) = (t.rates("pd"), t.rates("isolation_accuracy"), t.rates("pfa"));
    let delay = t.delays("delay_p50_s", "delay_p90_s");
    let own: Vec<Vec<f64>> = spec.printed.iter().map(|(_, c)| t.f64s(c)).collect();
    println!("  per detector, paired over the same trials (summary.csv for groups, comparison.csv for the tests):");
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
    for w in &s.warnings {
        println!("  warning: {w}");
    }
    println!("  wrote {} in {}", s.files.join(", "), s.out_dir.display());
}

/// A threshold with four significant digits, in scientific notation when it is very small or large.
pub(super) fn significant(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) { format!("{v:.3e}") } else { format!("{v:.4}") }
}
