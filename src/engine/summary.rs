//! What every study's summary is made of: reading a complete run, rates with Wilson intervals, threshold
//! calibration on recorded statistics, typed column access.

use std::path::{Path, PathBuf};

use polars::prelude::*;

use crate::engine::intervals::{Z95, wilson};
use crate::engine::runner::{Manifest, RunError, io, pol, read_parquet};

/// Where the calibrated thresholds came from.
#[derive(Debug, Clone, PartialEq)]
pub enum Calibration {
    /// Calibrated here at this false-alarm probability.
    Target(f64),
    /// Read from another run's `thresholds.csv`.
    File(PathBuf),
}

/// A detector's first post-onset alarm at per-output thresholds `thr`, from row `row` of the per-output
/// first-passage profiles (see `sim`): for each output the first profile point above its threshold, then
/// the earliest over outputs.
pub fn alarm_time(
    profile_t_s: &[Vec<Vec<f64>>],
    profile_value: &[Vec<Vec<f64>>],
    row: usize,
    thr: &[f64],
) -> Option<f64> {
    (0..thr.len())
        .filter_map(|j| {
            let (t, v) = (&profile_t_s[j][row], &profile_value[j][row]);
            t.iter().zip(v).find(|(_, v)| **v > thr[j]).map(|(t, _)| *t)
        })
        .reduce(f64::min)
}

/// The `k`-th order statistic such that at most `floor(p n)` values exceed it; `(threshold, exceedances)`.
pub fn calibrate(values: &mut [f64], p: f64) -> (f64, u64) {
    if values.is_empty() {
        return (f64::NAN, 0);
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    let allowed = ((p * n as f64).floor() as usize).min(n - 1);
    let thr = values[n - 1 - allowed];
    (thr, values.iter().filter(|&&v| v > thr).count() as u64)
}

pub(crate) fn str_col<'a>(df: &'a DataFrame, name: &str, file: &Path) -> Result<&'a StringChunked, RunError> {
    df.column(name).and_then(|c| c.str()).map_err(pol(file))
}

pub(crate) fn f64_col<'a>(df: &'a DataFrame, name: &str, file: &Path) -> Result<&'a Float64Chunked, RunError> {
    df.column(name).and_then(|c| c.f64()).map_err(pol(file))
}

/// Reads lists of f64 as vectors, row by row.
pub(crate) fn list_col(df: &DataFrame, name: &str, file: &Path) -> Result<Vec<Vec<f64>>, RunError> {
    let lc = df.column(name).and_then(|c| c.list()).map_err(pol(file))?;
    let mut out = Vec::with_capacity(lc.len());
    for s in lc.amortized_iter() {
        match s {
            Some(s) => out.push(s.as_ref().f64().map_err(pol(file))?.into_no_null_iter().collect()),
            None => out.push(Vec::new()),
        }
    }
    Ok(out)
}

/// Reads rows `[offset, offset + len)` of a Parquet file (only the row groups they touch), optionally
/// only some columns: memory stays at one slice whatever the file's size.
pub(crate) fn read_slice(
    path: &Path,
    offset: usize,
    len: usize,
    columns: Option<Vec<String>>,
) -> Result<DataFrame, RunError> {
    let file = std::fs::File::open(path).map_err(io(path))?;
    ParquetReader::new(file).with_columns(columns).with_slice(Some((offset, len))).finish().map_err(pol(path))
}

/// The manifest and the whole `trials.parquet` of a complete run in `dir` (studies whose records fit in
/// memory: one row per trial and detector, or per fault window).
pub(crate) fn read_run(dir: &Path) -> Result<(Manifest, DataFrame, PathBuf), RunError> {
    let manifest = Manifest::read(dir)?;
    let path = dir.join("trials.parquet");
    if !manifest.complete || !path.exists() {
        return Err(RunError::Invalid(format!(
            "{}: the run is not complete: finish it with `fdimc run ... --resume`",
            dir.display()
        )));
    }
    let trials = read_parquet(&path)?;
    if trials.height() as u64 != manifest.rows {
        return Err(RunError::Invalid(format!(
            "{}: holds {} rows, its manifest.json says {}: re-run the study",
            path.display(),
            trials.height(),
            manifest.rows
        )));
    }
    Ok((manifest, trials, path))
}

/// A count column as numbers (nulls as 0).
pub(crate) fn u64_values(df: &DataFrame, name: &str) -> PolarsResult<Vec<u64>> {
    let c = df.column(name)?.cast(&DataType::UInt64)?;
    let c = c.u64()?;
    Ok((0..c.len()).map(|i| c.get(i).unwrap_or(0)).collect())
}

/// What every summary's rates rest on, per group: the trials flown to the end (`trials - failed`) and
/// whether the group is faulty (its boolean `faulty` column, which is dropped).
pub(crate) fn flown_and_faulty(df: &mut DataFrame) -> PolarsResult<(Vec<u64>, Vec<bool>)> {
    let flown = u64_values(df, "trials")?.iter().zip(u64_values(df, "failed")?).map(|(t, f)| t - f).collect();
    let faulty = df.column("faulty")?.bool()?.clone();
    let faulty = (0..faulty.len()).map(|i| faulty.get(i).unwrap_or(false)).collect();
    df.drop_in_place("faulty")?;
    Ok((flown, faulty))
}

/// Adds the columns `name`, `name_lo`, `name_hi`: the rate `k / n` with its 95 % Wilson interval, null
/// where `keep` is false or `n = 0`.
pub(crate) fn add_rate(
    df: &mut DataFrame,
    name: &str,
    k: &[u64],
    n: &[u64],
    keep: &dyn Fn(usize) -> bool,
) -> PolarsResult<()> {
    let mut cols: [Vec<Option<f64>>; 3] = Default::default();
    for i in 0..k.len() {
        let ok = keep(i) && n[i] > 0;
        let (lo, hi) = wilson(k[i], n[i], Z95);
        cols[0].push(ok.then(|| k[i] as f64 / n[i] as f64));
        cols[1].push(ok.then_some(lo));
        cols[2].push(ok.then_some(hi));
    }
    let [rate, lo, hi] = cols;
    df.with_column(Column::new(name.into(), rate))?;
    df.with_column(Column::new(format!("{name}_lo").into(), lo))?;
    df.with_column(Column::new(format!("{name}_hi").into(), hi))?;
    Ok(())
}

/// Loads `summary.parquet` or `summary.csv`.
pub fn read_summary(path: &Path) -> Result<DataFrame, RunError> {
    if path.extension().is_some_and(|e| e == "parquet") {
        return read_parquet(path);
    }
    CsvReadOptions::default()
        .with_has_header(true)
        .try_into_reader_with_file_path(Some(path.into()))
        .and_then(|r| r.finish())
        .map_err(|e| RunError::Invalid(format!("{}: cannot read summary ({e})", path.display())))
}

/// A summary table's columns as plain values for printing: a missing column or a null prints as NaN
/// (numbers), 0 (counts) or "" (text).
pub struct Table<'a>(pub &'a polars::prelude::DataFrame);

impl Table<'_> {
    pub fn f64s(&self, name: &str) -> Vec<f64> {
        use polars::prelude::*;
        let column = self.0.column(name).and_then(|c| c.cast(&DataType::Float64));
        let values = column.as_ref().ok().and_then(|c| c.f64().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or(f64::NAN)).collect()
    }

    pub fn u64s(&self, name: &str) -> Vec<u64> {
        use polars::prelude::*;
        let column = self.0.column(name).and_then(|c| c.cast(&DataType::UInt64));
        let values = column.as_ref().ok().and_then(|c| c.u64().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or(0)).collect()
    }

    pub fn strs(&self, name: &str) -> Vec<String> {
        let values = self.0.column(name).ok().and_then(|c| c.str().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or("").to_string()).collect()
    }

    /// `rate [lo, hi]` per row from the columns `name`, `name_lo`, `name_hi`; "-" where there is no rate.
    pub fn rates(&self, name: &str) -> Vec<String> {
        let (rate, lo, hi) = (self.f64s(name), self.f64s(&format!("{name}_lo")), self.f64s(&format!("{name}_hi")));
        (0..rate.len())
            .map(|i| if rate[i].is_nan() { "-".into() } else { format!("{:.3} [{:.3}, {:.3}]", rate[i], lo[i], hi[i]) })
            .collect()
    }

    /// `p50/p90 s` per row from two percentile columns.
    pub fn delays(&self, p50: &str, p90: &str) -> Vec<String> {
        let (a, b) = (self.f64s(p50), self.f64s(p90));
        a.iter().zip(&b).map(|(a, b)| format!("{a:.2}/{b:.2} s")).collect()
    }
}

/// Warnings, then the files written.
pub fn print_footer(dir: &Path, warnings: &[String], files: &str) {
    for w in warnings {
        println!("  warning: {w}");
    }
    println!("  wrote {files} in {}", dir.display());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calibration_allows_floor_p_n_exceedances() {
        let mut v: Vec<f64> = (1..=1000).map(f64::from).collect();
        assert_eq!(calibrate(&mut v, 0.01), (990.0, 10));
        let mut v: Vec<f64> = (1..=50).map(f64::from).collect();
        assert_eq!(calibrate(&mut v, 0.01), (50.0, 0), "too few trials: the maximum, no exceedance");
        let mut v = vec![3.0, 1.0, 2.0, 2.0];
        assert_eq!(calibrate(&mut v, 0.5), (2.0, 1), "ties never give more exceedances than allowed");
    }
}
