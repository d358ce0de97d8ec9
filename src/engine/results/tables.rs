//! Reading results back: a complete run's `trials.parquet` (checked against its manifest), slices of it,
//! typed columns of a frame, summaries (CSV or Parquet), and a table's columns as plain values for
//! printing.

use std::path::{Path, PathBuf};

use polars::prelude::*;
use polars_io::parquet::metadata::FileMetadataRef;

use crate::engine::run::runner::{Manifest, RunError, io, pol, read_parquet};

/// The manifest and the `trials.parquet` path of the complete run in `dir`; a run that is not complete,
/// or whose file disagrees with its manifest, is refused (exit 2).
pub fn complete_run(dir: &Path) -> Result<(Manifest, PathBuf), RunError> {
    let manifest = Manifest::read(dir)?;
    let path = dir.join("trials.parquet");
    if !manifest.complete || !path.exists() {
        return Err(RunError::Invalid(format!(
            "{}: the run is not complete: finish it with `fdimc run ... --resume`",
            dir.display()
        )));
    }
    // A truncated or foreign file is bad input, not an internal error: check its footer first.
    let rows = std::fs::File::open(&path).map_err(io(&path)).and_then(|f| {
        ParquetReader::new(f).num_rows().map_err(|e| {
            RunError::Invalid(format!("{}: not a readable Parquet file ({e}); re-run the study", path.display()))
        })
    })?;
    if rows as u64 != manifest.rows {
        return Err(RunError::Invalid(format!(
            "{}: holds {rows} rows, its manifest.json says {}: re-run the study",
            path.display(),
            manifest.rows
        )));
    }
    Ok((manifest, path))
}

/// The column names of a Parquet file.
pub fn column_names(path: &Path) -> Result<Vec<String>, RunError> {
    let file = std::fs::File::open(path).map_err(io(path))?;
    let schema = ParquetReader::new(file).schema().map_err(pol(path))?;
    Ok(schema.iter_names().map(|n| n.to_string()).collect())
}

/// Reads rows `[offset, offset + len)` of a Parquet file (only the row groups they touch), optionally
/// only some columns: memory stays at one slice whatever the file's size.
pub fn read_slice(path: &Path, offset: usize, len: usize, columns: Option<Vec<String>>) -> Result<DataFrame, RunError> {
    read_slice_of(path, None, offset, len, columns)
}

/// [`read_slice`] with the file's footer already parsed (`footer`): a pass reads the footer once, where
/// each slice would parse it again (at 10^7 trials it describes 2,442 row groups of 80 columns, and a
/// pass of 2,442 slices parsed it for minutes).
fn read_slice_of(
    path: &Path,
    footer: Option<&FileMetadataRef>,
    offset: usize,
    len: usize,
    columns: Option<Vec<String>>,
) -> Result<DataFrame, RunError> {
    let file = std::fs::File::open(path).map_err(io(path))?;
    let mut reader = ParquetReader::new(file);
    if let Some(footer) = footer {
        reader.set_metadata(footer.clone());
    }
    reader.with_columns(columns).with_slice(Some((offset, len))).finish().map_err(pol(path))
}

/// The first `rows` rows of the Parquet file at `path`, about `step` at a time and only `columns`: a full
/// pass whose memory holds one slice. Each slice is whole row groups (as many as fit in `step` rows, at
/// least one): a slice that ends inside a row group has the reader decode that row group twice, once
/// for each slice it touches, and trials.parquet's row groups are its part files (a chunk of trials x
/// the detectors: 12,288 rows for three detectors, against slices of 16,384).
pub fn slices<'a>(
    path: &'a Path,
    rows: usize,
    step: usize,
    columns: &'a [String],
) -> impl Iterator<Item = Result<DataFrame, RunError>> + 'a {
    let (ranges, footer, error) = match slice_ranges(path, rows, step) {
        Ok((ranges, footer)) => (ranges, Some(footer), None),
        Err(e) => (Vec::new(), None, Some(e)),
    };
    error.into_iter().map(Err).chain(
        ranges
            .into_iter()
            .map(move |(offset, len)| read_slice_of(path, footer.as_ref(), offset, len, Some(columns.to_vec()))),
    )
}

/// The `(offset, rows)` of [`slices`]' slices: whole row groups of the file at `path`, up to `step` rows
/// each unless one row group is larger, covering its first `rows` rows; and the file's parsed footer.
fn slice_ranges(path: &Path, rows: usize, step: usize) -> Result<(Vec<(usize, usize)>, FileMetadataRef), RunError> {
    let file = std::fs::File::open(path).map_err(io(path))?;
    let mut reader = ParquetReader::new(file);
    let footer = reader.get_metadata().map_err(pol(path))?.clone();
    let groups: Vec<usize> = footer.row_groups.iter().map(|g| g.num_rows()).collect();
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    let mut start = 0;
    for group in groups {
        if start >= rows {
            break;
        }
        let group = group.min(rows - start);
        match ranges.last_mut() {
            Some((_, len)) if *len + group <= step => *len += group,
            _ => ranges.push((start, group)),
        }
        start += group;
    }
    // Rows past the footer's row groups (none in a file fdimc wrote) are read as before, a step at a time.
    ranges.extend((start..rows).step_by(step.max(1)).map(|offset| (offset, step.min(rows - offset))));
    Ok((ranges, footer))
}

/// [`slices`] handed to `visit` one by one, each read (decoded on polars' threads) while `visit` works
/// on the one before: a summary's pass costs the larger of the two, not their sum.
pub fn for_each_slice_read_ahead(
    path: &Path,
    rows: usize,
    step: usize,
    columns: &[String],
    mut visit: impl FnMut(DataFrame) -> Result<(), RunError>,
) -> Result<(), RunError> {
    std::thread::scope(|scope| {
        let (send, receive) = std::sync::mpsc::sync_channel(1);
        scope.spawn(move || {
            for slice in slices(path, rows, step, columns) {
                // The receiver is gone when `visit` failed: stop reading.
                if send.send(slice).is_err() {
                    break;
                }
            }
        });
        // Dropping the receiver on an error stops the reader, whose scope then ends.
        receive.into_iter().try_for_each(|slice| visit(slice?))
    })
}

/// The first `failure` of a run's records and how many rows have one, read a slice at a time: why a run
/// whose trials mostly failed did (a kind without the column has none).
pub fn failures(path: &Path, rows: usize) -> Result<(u64, Option<String>), RunError> {
    if !column_names(path)?.iter().any(|c| c == "failure") {
        return Ok((0, None));
    }
    let (mut count, mut first) = (0, None);
    for slice in slices(path, rows, 1 << 16, &["failure".to_string()]) {
        let slice = slice?;
        let failure = str_col(&slice, "failure", path)?;
        count += (failure.len() - failure.null_count()) as u64;
        if first.is_none() {
            first = failure.iter().flatten().next().map(str::to_string);
        }
    }
    Ok((count, first))
}

pub fn str_col<'a>(df: &'a DataFrame, name: &str, file: &Path) -> Result<&'a StringChunked, RunError> {
    df.column(name).and_then(|c| c.str()).map_err(pol(file))
}

pub fn f64_col<'a>(df: &'a DataFrame, name: &str, file: &Path) -> Result<&'a Float64Chunked, RunError> {
    df.column(name).and_then(|c| c.f64()).map_err(pol(file))
}

pub fn bool_col<'a>(df: &'a DataFrame, name: &str, file: &Path) -> Result<&'a BooleanChunked, RunError> {
    df.column(name).and_then(|c| c.bool()).map_err(pol(file))
}

pub fn u64_col<'a>(df: &'a DataFrame, name: &str, file: &Path) -> Result<&'a UInt64Chunked, RunError> {
    df.column(name).and_then(|c| c.u64()).map_err(pol(file))
}

/// A column as numbers whatever its type (booleans as 0 and 1); nulls as NaN.
pub fn numbers(df: &DataFrame, name: &str, file: &Path) -> Result<Vec<f64>, RunError> {
    let c = df.column(name).and_then(|c| c.cast(&DataType::Float64)).map_err(pol(file))?;
    Ok(c.f64().map_err(pol(file))?.iter().map(|v| v.unwrap_or(f64::NAN)).collect())
}

/// Reads lists of f64 as vectors, row by row.
pub fn list_col(df: &DataFrame, name: &str, file: &Path) -> Result<Vec<Vec<f64>>, RunError> {
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

/// Loads `summary.parquet` or `summary.csv` (or any table fdimc writes).
pub fn read_summary(path: &Path) -> Result<DataFrame, RunError> {
    if path.extension().is_some_and(|e| e == "parquet") {
        return read_parquet(path);
    }
    CsvReadOptions::default()
        .with_has_header(true)
        .try_into_reader_with_file_path(Some(path.into()))
        .and_then(|r| r.finish())
        .map_err(|e| RunError::Invalid(format!("{}: cannot read the table ({e})", path.display())))
}

/// A table's columns as plain values for printing: a missing column or a null prints as NaN (numbers),
/// 0 (counts) or "" (text).
pub struct Table<'a>(pub &'a DataFrame);

impl Table<'_> {
    pub fn f64s(&self, name: &str) -> Vec<f64> {
        let column = self.0.column(name).and_then(|c| c.cast(&DataType::Float64));
        let values = column.as_ref().ok().and_then(|c| c.f64().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or(f64::NAN)).collect()
    }

    pub fn u64s(&self, name: &str) -> Vec<u64> {
        let column = self.0.column(name).and_then(|c| c.cast(&DataType::UInt64));
        let values = column.as_ref().ok().and_then(|c| c.u64().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or(0)).collect()
    }

    /// A missing column or a null reads as false; text reads as its words ("true").
    pub fn bools(&self, name: &str) -> Vec<bool> {
        let column = self.0.column(name).ok();
        match column.and_then(|c| c.bool().ok()) {
            Some(v) => (0..self.0.height()).map(|i| v.get(i).unwrap_or(false)).collect(),
            None => self.strs(name).iter().map(|s| s.eq_ignore_ascii_case("true")).collect(),
        }
    }

    pub fn strs(&self, name: &str) -> Vec<String> {
        let values = self.0.column(name).ok().and_then(|c| c.str().ok());
        (0..self.0.height()).map(|i| values.and_then(|v| v.get(i)).unwrap_or("").to_string()).collect()
    }

    /// `rate [lo, hi]` per row from the columns `name`, `name_lo`, `name_hi`; "-" where there is no rate.
    pub fn rates(&self, name: &str) -> Vec<String> {
        let (rate, lo, hi) = (self.f64s(name), self.f64s(&format!("{name}_lo")), self.f64s(&format!("{name}_hi")));
        (0..rate.len()).map(|i| crate::engine::results::text::rate_interval(rate[i], lo[i], hi[i])).collect()
    }

    /// `p50/p90 s` per row from two percentile columns.
    pub fn delays(&self, p50: &str, p90: &str) -> Vec<String> {
        let (a, b) = (self.f64s(p50), self.f64s(p90));
        a.iter().zip(&b).map(|(a, b)| if a.is_nan() { "-".into() } else { format!("{a:.2}/{b:.2} s") }).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Slices are whole row groups, as many as fit in a step (at least one), and together the file's
    /// first `rows` rows in order: a file of 100 rows in row groups of 30, 30, 30 and 10.
    #[test]
    fn slices_are_whole_row_groups() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("groups.parquet");
        // As trials.parquet is made: part files of one row group each, their row groups joined.
        let mut joined = crate::engine::run::row_groups::RowGroupWriter::create(&path).unwrap();
        for rows in [0..30u64, 30..60, 60..90, 90..100] {
            let mut part =
                DataFrame::new_infer_height(vec![Column::new("x".into(), rows.collect::<Vec<_>>())]).unwrap();
            let mut bytes = Vec::new();
            ParquetWriter::new(&mut bytes).finish(&mut part).unwrap();
            joined.append(&bytes, Path::new("part")).unwrap();
        }
        assert_eq!(joined.finish().unwrap(), 100);
        assert_eq!(slice_ranges(&path, 100, 64).unwrap().0, [(0, 60), (60, 40)]);
        assert_eq!(slice_ranges(&path, 100, 16).unwrap().0, [(0, 30), (30, 30), (60, 30), (90, 10)]);
        assert_eq!(slice_ranges(&path, 45, 64).unwrap().0, [(0, 45)]);
        assert_eq!(slice_ranges(&path, 45, 16).unwrap().0, [(0, 30), (30, 15)]);
        let columns = ["x".to_string()];
        let read: Vec<u64> = slices(&path, 100, 64, &columns)
            .flat_map(|s| s.unwrap().column("x").unwrap().u64().unwrap().into_no_null_iter().collect::<Vec<_>>())
            .collect();
        assert_eq!(read, (0..100).collect::<Vec<_>>());
        let missing = dir.path().join("missing.parquet");
        assert!(matches!(slices(&missing, 10, 4, &columns).collect::<Vec<_>>()[..], [Err(_)]));
    }
}
