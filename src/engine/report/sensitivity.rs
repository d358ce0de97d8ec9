//! The report of a sensitivity run (`fdimc sensitivity`): one bar chart of Sobol indices per outcome and
//! detector, and the table.

use std::path::Path;

use super::html::escape;
use super::plots::{self, SensitivityBars};
use super::{Report, shell, table_of};
use crate::engine::runner::{Manifest, RunError, io, write_atomically};
use crate::engine::tables::{f64_col, read_summary, str_col};

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
    let (outcome, detector, factor) =
        (str_col(&df, "outcome", &path)?, str_col(&df, "detector", &path)?, str_col(&df, "factor", &path)?);
    let num = |name: &str| -> Result<Vec<Option<f64>>, RunError> { Ok(f64_col(&df, name, &path)?.iter().collect()) };
    let (s1, s1_lo, s1_hi, st, st_lo, st_hi) =
        (num("s1")?, num("s1_lo")?, num("s1_hi")?, num("st")?, num("st_lo")?, num("st_hi")?);
    let note = str_col(&df, "note", &path)?;
    let out = dir.join("report");
    std::fs::create_dir_all(&out).map_err(io(&out))?;
    plots::register_font();
    let mut report = Report::default();
    let mut r = 0;
    while r < df.height() {
        let key = (outcome.get(r).unwrap_or(""), detector.get(r).unwrap_or(""));
        let end = (r..df.height()).find(|&i| (outcome.get(i), detector.get(i)) != (Some(key.0), Some(key.1)));
        let end = end.unwrap_or(df.height());
        if s1[r].is_none() {
            let why = note.get(r).unwrap_or("the outcome does not vary");
            report.warnings.push(format!("{} of detector {}: no indices: {why}", key.0, key.1));
            r = end;
            continue;
        }
        let get = |v: &[Option<f64>], i: usize| v[i].unwrap_or(f64::NAN);
        let mut factors: Vec<_> = (r..end)
            .map(|i| {
                let name = factor.get(i).unwrap_or("").to_string();
                (name, get(&s1, i), (get(&s1_lo, i), get(&s1_hi, i)), get(&st, i), (get(&st_lo, i), get(&st_hi, i)))
            })
            .collect();
        // Largest total index on top (the chart draws the first factor at the bottom).
        factors.sort_by(|a, b| a.3.total_cmp(&b.3));
        let file = out.join(format!("sensitivity_{}_{}.svg", key.0, key.1));
        let bars = SensitivityBars { outcome: key.0, detector: key.1, factors };
        plots::sensitivity_bars(&file, &bars).map_err(|m| RunError::Internal(format!("{}: {m}", file.display())))?;
        report.files.push(file);
        r = end;
    }
    let figures: String = report
        .files
        .iter()
        .map(|f| {
            let name = escape(&f.file_name().unwrap_or_default().to_string_lossy());
            format!("<figure><img src=\"{name}\" alt=\"{name}\"><figcaption>{name}</figcaption></figure>\n")
        })
        .collect();
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
    write_atomically(&html, shell(manifest, &report.warnings, &body).as_bytes())?;
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
