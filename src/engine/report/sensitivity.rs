//! The report of a sensitivity run (`fdimc sensitivity`): one bar chart of Sobol indices per outcome and
//! detector, and the table.

use std::path::Path;

use super::html::{escape, figure};
use super::plots::{self, SensitivityBars};
use super::{Report, shell, table_of};
use crate::engine::results::tables::read_summary;
use crate::engine::run::runner::{Manifest, RunError, io, write_atomically};
use crate::engine::sensitivity::index_blocks;

/// Writes `dir/report/`: `sensitivity_<outcome>_<detector>.svg` and `report.html`.
pub(super) fn write(dir: &Path, manifest: &Manifest) -> Result<Report, RunError> {
    let path = dir.join("sensitivity.csv");
    if !path.exists() {
        return Err(RunError::Invalid(format!(
            "{}: missing sensitivity.csv: run `fdimc summarize {}` first",
            dir.display(),
            dir.display()
        )));
    }
    let df = read_summary(&path)?;
    let out = dir.join("report");
    std::fs::create_dir_all(&out).map_err(io(&out))?;
    plots::register_font();
    let mut report = Report::default();
    for b in index_blocks(&df, &path)? {
        let mut factors = match b.factors {
            Ok(f) => f,
            Err(why) => {
                report.warnings.push(format!("{} of detector {}: no indices: {why}", b.outcome, b.detector));
                continue;
            }
        };
        // Largest total index on top (the chart draws the first factor at the bottom).
        factors.sort_by(|a, b| a.1.st.total_cmp(&b.1.st));
        let file = out.join(format!("sensitivity_{}_{}.svg", b.outcome, b.detector));
        let bars = SensitivityBars { outcome: &b.outcome, detector: &b.detector, factors };
        plots::sensitivity_bars(&file, &bars).map_err(|m| RunError::Internal(format!("{}: {m}", file.display())))?;
        report.files.push(file);
    }
    let figures: String = report.files.iter().map(|f| figure(f)).collect();
    let body = format!(
        "<h2>Which factors drive the outcomes: Sobol indices</h2>\n<p>A Saltelli design over the factors the deck's \
         trials draw: {design}. <b>S1</b> (first order, Saltelli 2010) is the share of an outcome's variance that a \
         factor explains alone; <b>ST</b> (total, Jansen 1999) adds its interactions with the others. A factor \
         whose ST interval holds 0 does not matter; ST well above S1 means it matters through others (a fault \
         size that matters only for some fault kinds). <code>noise_realisation</code> is the sensor and process \
         noise of the trial: its index is what no deck factor explains. Outcomes: <code>pd</code> and \
         <code>isolation</code> (isolated correctly) on faulty trials, <code>delay_s</code> (a miss counted as the \
         time left after the onset), <code>pfa</code> on fault-free trials. Intervals: 95 % bootstrap \
         percentiles over the base rows. Table: <code>sensitivity.csv</code>.</p>\n{figures}{table}",
        design = escape(&design_text(manifest)),
        table = table_of(dir, "sensitivity.csv", &[])?.unwrap_or_default(),
    );
    let html = out.join("report.html");
    write_atomically(&html, shell(manifest, "", &report.warnings, &body).as_bytes())?;
    report.files.push(html);
    Ok(report)
}

/// "base N; faulty trials: a, b, c; fault-free trials: ...".
fn design_text(m: &Manifest) -> String {
    let Some(d) = &m.sensitivity else { return String::new() };
    let parts: Vec<String> = d
        .parts
        .iter()
        .map(|p| {
            let names: Vec<&str> = p.factors.iter().map(|f| f.name.as_str()).collect();
            format!("{} trials over {}", if p.fault_free { "fault-free" } else { "faulty" }, names.join(", "))
        })
        .collect();
    format!("{} base rows per matrix, {} bootstrap resamples; {}", d.base_samples, d.bootstrap, parts.join("; "))
}
