//! What method 003 adds to the shared report (`fdimc report`): for a run that replayed a flight log,
//! the section "Replay of a flight log" from the run's `fault_free_replay.json` (the log's file,
//! SHA-256 and topic, the parts, the resampling, the debias values removed, the threshold and where
//! each part's largest statistic occurred, the fault-free log's alarms per flight hour) and the
//! replay's warnings. A simulated run has no such file, and the part adds nothing.

use std::path::Path;

use crate::engine::report::html::escape;
use crate::engine::report::{ReportContext, ReportPart};
use crate::engine::run::runner::{RunError, read_record};
use crate::methods::accelerometer::replay::{FaultFreeReplay, ReplayRecord};

/// The section's title.
pub const TITLE: &str = "Replay of a flight log";

/// The kind's report hook ([`crate::engine::method::Method::report`]).
pub fn report_part(ctx: &ReportContext) -> Result<ReportPart, RunError> {
    part_of(ctx.dir)
}

/// The part for the run in `dir`: empty unless the run replayed a log.
pub fn part_of(dir: &Path) -> Result<ReportPart, RunError> {
    let path = dir.join("fault_free_replay.json");
    if !path.exists() {
        return Ok(ReportPart::default());
    }
    let record: ReplayRecord = read_record(&path, "a replay's results folder", "fault-free replay record")?;
    Ok(ReportPart {
        files: Vec::new(),
        warnings: record.warnings.clone(),
        sections: vec![(TITLE.to_string(), section(&record))],
    })
}

/// A number for the page: `-` for NaN (nothing watched).
fn num(x: f64, decimals: usize) -> String {
    if x.is_nan() { "-".into() } else { format!("{x:.decimals$}") }
}

/// The section's HTML: a two-column table.
fn section(r: &ReplayRecord) -> String {
    let mut rows: Vec<(String, String)> = Vec::new();
    let part = |p: [f64; 2]| format!("[{:.2}, {:.2}) s", p[0], p[1]);
    if let Some(log) = &r.log {
        rows.push(("log file".into(), escape(&log.file)));
        rows.push(("SHA-256".into(), format!("<code>{}</code>", escape(&log.sha256))));
        rows.push(("topic".into(), escape(&log.origin)));
        rows.push((
            "log samples".into(),
            format!(
                "{} at {} Hz (largest gap {} s, bridged); times from its first sample, at {} s on the log's clock",
                log.log_samples,
                num(log.log_rate_hz, 2),
                num(log.largest_gap_s, 3),
                num(log.first_sample_s, 3)
            ),
        ));
        rows.push((
            "resampled to".into(),
            format!(
                "{} Hz (a step of {} s: each step the mean of the log's samples within it)",
                num(1.0 / log.dt_s, 1),
                log.dt_s
            ),
        ));
        rows.push(("evaluated part (evaluate_s)".into(), part(log.evaluate_s)));
        rows.push(("training part (train_s)".into(), log.train_s.map_or("none".into(), part)));
        let removed: Vec<String> =
            log.removed_means.iter().map(|(name, mean)| format!("{} {mean:.6e}", escape(name))).collect();
        rows.push((
            "debias: training-part means removed".into(),
            if removed.is_empty() { "none".into() } else { removed.join(", ") },
        ));
    }
    let e = &r.evaluate;
    rows.push((
        "threshold on T".into(),
        match (r.calibration_margin, &r.train) {
            (Some(m), Some(t)) => format!(
                "{} = {m} x the training part's largest T ({})",
                num(e.threshold, 1),
                num(t.largest_statistic, 1)
            ),
            _ => format!("{} (the deck's)", num(e.threshold, 1)),
        },
    ));
    let largest = |p: &FaultFreeReplay| {
        format!(
            "{} at {} s (of {} s watched after settling)",
            num(p.largest_statistic, 1),
            num(p.largest_at_s, 2),
            num(p.watched_s, 1)
        )
    };
    if let Some(t) = &r.train {
        rows.push(("largest fault-free T, training part".into(), largest(t)));
    }
    rows.push(("largest fault-free T, evaluated part".into(), largest(e)));
    rows.push((
        "fault-free log, evaluated part".into(),
        format!(
            "{} alarm(s): {} per flight hour (95 % interval [0, {}], one-sided Poisson upper bound)",
            e.alarms,
            num(e.alarms_per_flight_hour, 0),
            num(e.alarms_per_flight_hour_upper95, 0)
        ),
    ));
    let body: String = rows.iter().map(|(k, v)| format!("<tr><th>{}</th><td>{v}</td></tr>\n", escape(k))).collect();
    format!(
        "<p>The trials flew segments of a recorded flight with faults injected; the rows below are the fault-free log itself at the run's threshold.</p>\n<table>\n{body}</table>\n"
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::methods::accelerometer::replay::LogProvenance;

    /// The replay section holds what the issue asked for (51, item 8) from the record a replay run
    /// writes: file, SHA-256, topic, windows, resampling, the debias values, the calibrated threshold and
    /// where each part's largest T occurred, the alarms per flight hour with their bound; the record's
    /// warnings become the report's. A run without the record (a simulated one) gets an empty part.
    #[test]
    fn a_replay_run_gets_its_section_and_a_simulated_one_nothing() {
        let tmp = tempfile::tempdir().unwrap();
        let empty = part_of(tmp.path()).unwrap();
        assert!(empty.sections.is_empty() && empty.warnings.is_empty() && empty.files.is_empty());

        let part = |part_s: [f64; 2], largest: f64, at: f64| FaultFreeReplay {
            part_s,
            watched_s: 3.3,
            threshold: 616.7,
            largest_statistic: largest,
            largest_at_s: at,
            alarms: 0,
            alarms_per_flight_hour: 0.0,
            alarms_per_flight_hour_upper95: 3268.0,
        };
        let record = ReplayRecord {
            evaluate: part([4.8, 9.6], 31.5, 7.25),
            train: Some(part([0.0, 4.8], 411.2, 2.31)),
            calibration_margin: Some(1.5),
            log: Some(LogProvenance {
                file: "studies/logs/sample_appended_multiple.ulg".into(),
                sha256: "ab12".repeat(16),
                origin: "topic \"sensor_combined\" instance 0".into(),
                first_sample_s: 12.262822,
                log_samples: 2373,
                log_rate_hz: 246.63,
                largest_gap_s: 0.016,
                dt_s: 0.01,
                evaluate_s: [4.8, 9.6],
                train_s: Some([0.0, 4.8]),
                removed_means: vec![("gyro_z_rad_s".into(), -2.9e-3)],
            }),
            warnings: vec!["the threshold was calibrated on a training part whose largest T ...".into()],
        };
        std::fs::write(tmp.path().join("fault_free_replay.json"), serde_json::to_string(&record).unwrap()).unwrap();
        let got = part_of(tmp.path()).unwrap();
        assert_eq!(got.warnings, record.warnings);
        // NaN (nothing with a decision) is written as null and read back.
        let mut undecided = record.clone();
        undecided.train.as_mut().unwrap().largest_statistic = f64::NAN;
        std::fs::write(tmp.path().join("fault_free_replay.json"), serde_json::to_string(&undecided).unwrap()).unwrap();
        let html = &part_of(tmp.path()).unwrap().sections[0].1;
        assert!(html.contains("<th>largest fault-free T, training part</th><td>- at 2.31 s"), "{html}");
        std::fs::write(tmp.path().join("fault_free_replay.json"), serde_json::to_string(&record).unwrap()).unwrap();
        let [(title, html)] = got.sections.as_slice() else { panic!("{:?}", got.sections) };
        assert_eq!(title, TITLE);
        for want in [
            "<th>log file</th><td>studies/logs/sample_appended_multiple.ulg</td>",
            &format!("<code>{}</code>", "ab12".repeat(16)),
            "topic &quot;sensor_combined&quot; instance 0",
            "<th>resampled to</th><td>100.0 Hz",
            "<th>evaluated part (evaluate_s)</th><td>[4.80, 9.60) s</td>",
            "<th>training part (train_s)</th><td>[0.00, 4.80) s</td>",
            "gyro_z_rad_s -2.900000e-3",
            "616.7 = 1.5 x the training part's largest T (411.2)",
            "<th>largest fault-free T, training part</th><td>411.2 at 2.31 s",
            "<th>largest fault-free T, evaluated part</th><td>31.5 at 7.25 s",
            "0 alarm(s): 0 per flight hour (95 % interval [0, 3268]",
        ] {
            assert!(html.contains(want), "{want}\n{html}");
        }
    }
}
