//! Writing tables: CSV or Parquet chosen by the file extension, always through a temporary file in
//! the same folder renamed into place, so a killed run never leaves a half-written file under the
//! final name and an existing file is replaced only by a complete one.

use std::fs::File;
use std::path::{Path, PathBuf};

use polars::prelude::*;

#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{file}: unknown table format: use a .csv or .parquet file name")]
    UnknownFormat { file: PathBuf },
    #[error("{file}: {source}")]
    Io { file: PathBuf, source: std::io::Error },
    #[error("{file}: {source}")]
    Polars { file: PathBuf, source: PolarsError },
}

/// The tables `summarize` writes for every run (beside them, where they apply: thresholds.csv,
/// comparison.csv; and summarize.json).
pub const SUMMARY_TABLES: [&str; 6] =
    ["summary.csv", "summary.parquet", "curves.csv", "min_detectable.csv", "detectors.csv", "confusion.csv"];

/// Where `summarize --thresholds` writes, inside the run's folder: the run's own tables stay.
pub const VALIDATION_DIR: &str = "validation";
/// Where `summarize --target-pfa`, `--target-pfa-per-hour` and `--confidence` write, inside the run's
/// folder, each calibration in a folder of its own (`Calibration::folder_name` of the results layer): the
/// run's own tables stay at the deck's calibration.
pub const CALIBRATIONS_DIR: &str = "calibrations";

/// Table formats fdimc writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableFormat {
    Csv,
    Parquet,
}

impl TableFormat {
    pub fn from_path(path: &Path) -> Result<TableFormat, OutputError> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("csv") => Ok(TableFormat::Csv),
            Some("parquet") => Ok(TableFormat::Parquet),
            _ => Err(OutputError::UnknownFormat { file: path.into() }),
        }
    }
}

/// Per-sample trace of one trial, column by column (names carry units).
#[derive(Debug, Default, Clone)]
pub struct Trace {
    pub float_columns: Vec<(String, Vec<f64>)>,
    pub bool_columns: Vec<(String, Vec<bool>)>,
}

impl Trace {
    /// The next sample's values, given column by column in the same order every sample: the first
    /// sample names the columns (the name closures run only then).
    pub fn row(&mut self) -> TraceRow<'_> {
        TraceRow { trace: self, float: 0, flag: 0 }
    }

    /// Writes the trace to `out` (format by extension, atomically); returns the number of samples.
    pub fn write(&self, out: &Path) -> Result<usize, OutputError> {
        let mut df = trace_frame(self).map_err(|source| OutputError::Polars { file: out.into(), source })?;
        write_table(&mut df, out)?;
        Ok(df.height())
    }
}

/// One sample of a [`Trace`] being written, see [`Trace::row`].
pub struct TraceRow<'t> {
    trace: &'t mut Trace,
    float: usize,
    flag: usize,
}

impl TraceRow<'_> {
    pub fn float(&mut self, name: impl FnOnce() -> String, value: f64) -> &mut Self {
        push(&mut self.trace.float_columns, &mut self.float, name, value);
        self
    }

    pub fn flag(&mut self, name: impl FnOnce() -> String, value: bool) -> &mut Self {
        push(&mut self.trace.bool_columns, &mut self.flag, name, value);
        self
    }
}

/// `value` into column `*next` of `columns` (named by `name` the first time), then the next column.
fn push<T>(columns: &mut Vec<(String, Vec<T>)>, next: &mut usize, name: impl FnOnce() -> String, value: T) {
    if columns.len() <= *next {
        columns.push((name(), Vec::new()));
    }
    columns[*next].1.push(value);
    *next += 1;
}

/// Turns a trace into a data frame, columns in trace order.
pub fn trace_frame(trace: &Trace) -> PolarsResult<DataFrame> {
    let mut columns: Vec<Column> =
        trace.float_columns.iter().map(|(name, v)| Column::new(name.as_str().into(), v.as_slice())).collect();
    columns.extend(trace.bool_columns.iter().map(|(name, v)| Column::new(name.as_str().into(), v.as_slice())));
    DataFrame::new_infer_height(columns)
}

/// Writes `df` to `path` (format by extension) atomically.
pub fn write_table(df: &mut DataFrame, path: &Path) -> Result<(), OutputError> {
    let format = TableFormat::from_path(path)?;
    let tmp = temporary_sibling(path);
    let io = |source| OutputError::Io { file: path.into(), source };
    let result = (|| {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        let file = File::create(&tmp).map_err(io)?;
        let pol = |source| OutputError::Polars { file: path.into(), source };
        match format {
            TableFormat::Csv => CsvWriter::new(file).finish(df).map_err(pol)?,
            TableFormat::Parquet => {
                ParquetWriter::new(file).finish(df).map_err(pol)?;
            }
        }
        std::fs::rename(&tmp, path).map_err(io)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// `dir/.name.tmp-<pid>`: same folder (so the rename is atomic), hidden, unique per process.
pub fn temporary_sibling(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Removes the temporary siblings of `path` that killed processes left (call it holding the folder's
/// lock, so none is being written): a run killed while finishing trials.parquet would otherwise keep a
/// file the size of its records.
pub fn remove_stale_temporaries(path: &Path) {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else { return };
    let prefix = format!(".{}.tmp-", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        if entry.file_name().to_string_lossy().starts_with(&prefix) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}
