//! One Parquet file from several of the same schema, by copying their row groups byte for byte: the
//! encoded and compressed pages are moved, never decoded or encoded again. This is how trials.parquet
//! is assembled from its part files (each chunk of trials is encoded once, into its part) and how
//! `fdimc merge` joins the shards' tables.
//!
//! A file written by polars is `PAR1`, its row groups (each column chunk's pages, then that chunk's
//! metadata), the page indexes (every column index, then every offset index), the footer (thrift
//! `FileMetaData`), its length and `PAR1`. The copied region is everything before the page indexes;
//! the footer's offsets into it are shifted by where it lands, the column indexes copied as they are
//! (they hold values, not offsets) and the offset indexes' page locations shifted, then all of them
//! written after the last row group, as polars writes them.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use polars_parquet_format::thrift::protocol::{TCompactInputProtocol, TCompactOutputProtocol};
use polars_parquet_format::{FileMetaData, OffsetIndex, RowGroup};

use crate::engine::run::output::temporary_sibling;

/// Why files could not be joined: a file's path and the I/O error, an input that is not a Parquet
/// file of the others' schema (the user's input: exit 2), or a misuse.
#[derive(Debug, thiserror::Error)]
pub enum RowGroupError {
    #[error("{file}: {source}")]
    Io { file: PathBuf, source: std::io::Error },
    #[error("{0}")]
    Invalid(String),
    #[error("{0}")]
    Internal(String),
}

const MAGIC: &[u8; 4] = b"PAR1";

/// The largest footer or page index read (a corrupt length would otherwise ask for any amount).
const MAX_THRIFT_BYTES: usize = 1 << 30;

/// The row groups are copied through a buffer of this size.
const COPY_BUFFER_BYTES: usize = 1 << 20;

/// Appends whole Parquet files' row groups to a new file (under a temporary name until
/// [`finish`](Self::finish)).
pub struct RowGroupWriter {
    out: PathBuf,
    tmp: PathBuf,
    file: BufWriter<File>,
    /// Bytes written so far (the next row group's position).
    offset: u64,
    /// The first input's footer: its schema, key-value metadata (polars' Arrow schema) and writer.
    first: Option<FileMetaData>,
    row_groups: Vec<RowGroup>,
    /// Per row group, per column: the column index as it was, the offset index shifted.
    indexes: Vec<Vec<(Option<Vec<u8>>, Option<OffsetIndex>)>>,
    rows: u64,
    /// The row groups are copied through a buffer of this size ([`COPY_BUFFER_BYTES`]; smaller in a
    /// test, so that one file takes several pieces).
    piece_bytes: usize,
}

impl RowGroupWriter {
    pub fn create(out: &Path) -> Result<Self, RowGroupError> {
        let tmp = temporary_sibling(out);
        let mut file = BufWriter::new(File::create(&tmp).map_err(io(out))?);
        file.write_all(MAGIC).map_err(io(out))?;
        Ok(RowGroupWriter {
            out: out.to_path_buf(),
            tmp,
            file,
            offset: MAGIC.len() as u64,
            first: None,
            row_groups: Vec::new(),
            indexes: Vec::new(),
            rows: 0,
            piece_bytes: COPY_BUFFER_BYTES,
        })
    }

    /// Appends the row groups of the Parquet file `bytes` (read from, or written to, `name`).
    pub fn append(&mut self, bytes: &[u8], name: &Path) -> Result<(), RowGroupError> {
        self.append_from(&mut std::io::Cursor::new(bytes), name)
    }

    /// Appends the row groups of the Parquet file at `path`, read piece by piece: a shard of any size
    /// needs only its footer and page indexes in memory.
    pub fn append_file(&mut self, path: &Path) -> Result<(), RowGroupError> {
        let mut file = File::open(path).map_err(io(path))?;
        self.append_from(&mut file, path)
    }

    fn append_from<R: Read + Seek>(&mut self, input: &mut R, name: &Path) -> Result<(), RowGroupError> {
        let bad =
            |why: &str| RowGroupError::Invalid(format!("{}: not a readable Parquet file ({why})", name.display()));
        let n = usize::try_from(input.seek(SeekFrom::End(0)).map_err(io(name))?).map_err(|_| bad("its size"))?;
        let (mut head, mut tail) = ([0u8; 4], [0u8; 8]);
        if n >= 12 {
            read_at(input, 0, &mut head).map_err(io(name))?;
            read_at(input, n - 8, &mut tail).map_err(io(name))?;
        }
        if n < 12 || &head != MAGIC || &tail[4..] != MAGIC {
            return Err(bad("no PAR1 at its start and end"));
        }
        let footer_len = u32::from_le_bytes(tail[..4].try_into().expect("4 bytes")) as usize;
        let footer_start = (n - 8).checked_sub(footer_len).filter(|&s| s >= 4).ok_or_else(|| bad("footer length"))?;
        if footer_len > MAX_THRIFT_BYTES {
            return Err(bad("footer length"));
        }
        let mut footer = vec![0u8; footer_len];
        read_at(input, footer_start, &mut footer).map_err(io(name))?;
        let mut meta =
            read_thrift(&footer, FileMetaData::read_from_in_protocol).map_err(|e| bad(&format!("footer: {e}")))?;
        match &self.first {
            Some(first) if first.schema != meta.schema => {
                return Err(RowGroupError::Invalid(format!(
                    "{}: does not match the other parts (schema)",
                    name.display()
                )));
            }
            Some(_) => {}
            None => self.first = Some(FileMetaData { row_groups: Vec::new(), ..meta.clone() }),
        }
        // The row groups end where the first page index (or the footer) starts.
        let index_starts = meta
            .row_groups
            .iter()
            .flat_map(|rg| &rg.columns)
            .flat_map(|c| [c.column_index_offset, c.offset_index_offset].into_iter().flatten().map(|o| o as usize));
        let data_end = index_starts.chain([footer_start]).min().expect("the footer start");
        if data_end < 4 || data_end > footer_start {
            return Err(bad("page index offsets"));
        }
        // The page indexes lie between the row groups and the footer.
        let mut page_indexes = vec![0u8; footer_start - data_end];
        read_at(input, data_end, &mut page_indexes).map_err(io(name))?;
        let shift = self.offset as i64 - 4;
        input.seek(SeekFrom::Start(4)).map_err(io(name))?;
        let mut buffer = vec![0u8; self.piece_bytes.min(data_end - 4)];
        let mut left = data_end - 4;
        while left > 0 {
            let piece = &mut buffer[..left.min(self.piece_bytes)];
            input.read_exact(piece).map_err(io(name))?;
            self.file.write_all(piece).map_err(io(&self.out))?;
            left -= piece.len();
        }
        self.offset += (data_end - 4) as u64;
        let slice = |offset: Option<i64>, len: Option<i32>| -> Result<Option<&[u8]>, RowGroupError> {
            match (offset, len) {
                (Some(o), Some(l)) => {
                    let (o, l) = (usize::try_from(o).ok(), usize::try_from(l).ok());
                    let range =
                        o.zip(l).map(|(o, l)| o..o + l).filter(|r| r.start >= data_end && r.end <= footer_start);
                    range
                        .map(|r| Some(&page_indexes[r.start - data_end..r.end - data_end]))
                        .ok_or_else(|| bad("page index range"))
                }
                _ => Ok(None),
            }
        };
        for mut rg in std::mem::take(&mut meta.row_groups) {
            let mut indexes = Vec::with_capacity(rg.columns.len());
            for c in &mut rg.columns {
                let column_index = slice(c.column_index_offset, c.column_index_length)?.map(<[u8]>::to_vec);
                let offset_index = match slice(c.offset_index_offset, c.offset_index_length)? {
                    Some(b) => {
                        let mut index = read_thrift(b, OffsetIndex::read_from_in_protocol)
                            .map_err(|e| bad(&format!("offset index: {e}")))?;
                        index.page_locations.iter_mut().for_each(|p| p.offset += shift);
                        Some(index)
                    }
                    None => None,
                };
                indexes.push((column_index, offset_index));
                (c.column_index_offset, c.column_index_length) = (None, None);
                (c.offset_index_offset, c.offset_index_length) = (None, None);
                c.file_offset += shift;
                if let Some(m) = &mut c.meta_data {
                    m.data_page_offset += shift;
                    m.dictionary_page_offset = m.dictionary_page_offset.map(|o| o + shift);
                    m.index_page_offset = m.index_page_offset.map(|o| o + shift);
                }
            }
            rg.file_offset = rg.file_offset.map(|o| o + shift);
            rg.ordinal = i16::try_from(self.row_groups.len()).ok();
            self.rows += u64::try_from(rg.num_rows).map_err(|_| bad("row count"))?;
            self.row_groups.push(rg);
            self.indexes.push(indexes);
        }
        Ok(())
    }

    /// Writes the page indexes and the footer, and renames the file into place. Returns its rows.
    pub fn finish(mut self) -> Result<u64, RowGroupError> {
        let Some(first) = self.first.take() else {
            return Err(RowGroupError::Internal("no file to take row groups from".into()));
        };
        let out = self.out.clone();
        let mut write = |bytes: &[u8], offset: &mut u64| -> Result<(i64, i32), RowGroupError> {
            self.file.write_all(bytes).map_err(io(&out))?;
            let at = *offset;
            *offset += bytes.len() as u64;
            Ok((at as i64, bytes.len() as i32))
        };
        let mut offset = self.offset;
        for (rg, indexes) in self.row_groups.iter_mut().zip(&self.indexes) {
            for (c, (column_index, _)) in rg.columns.iter_mut().zip(indexes) {
                if let Some(b) = column_index {
                    let (o, l) = write(b, &mut offset)?;
                    (c.column_index_offset, c.column_index_length) = (Some(o), Some(l));
                }
            }
        }
        for (rg, indexes) in self.row_groups.iter_mut().zip(&self.indexes) {
            for (c, (_, offset_index)) in rg.columns.iter_mut().zip(indexes) {
                if let Some(index) = offset_index {
                    let b = write_thrift(|p| index.write_to_out_protocol(p))?;
                    let (o, l) = write(&b, &mut offset)?;
                    (c.offset_index_offset, c.offset_index_length) = (Some(o), Some(l));
                }
            }
        }
        let meta = FileMetaData {
            num_rows: i64::try_from(self.rows).map_err(|_| RowGroupError::Internal("row count".into()))?,
            row_groups: std::mem::take(&mut self.row_groups),
            ..first
        };
        let footer = write_thrift(|p| meta.write_to_out_protocol(p))?;
        write(&footer, &mut offset)?;
        write(&(footer.len() as u32).to_le_bytes(), &mut offset)?;
        write(MAGIC, &mut offset)?;
        let file = self.file.into_inner().map_err(|e| io(&self.out)(e.into_error()))?;
        file.sync_all().map_err(io(&self.out))?;
        std::fs::rename(&self.tmp, &self.out).map_err(io(&self.out))?;
        Ok(self.rows)
    }

    /// Removes the unfinished file.
    pub fn abandon(self) {
        let tmp = self.tmp.clone();
        drop(self.file);
        let _ = std::fs::remove_file(tmp);
    }
}

fn read_thrift<'b, T>(
    bytes: &'b [u8],
    read: impl FnOnce(&mut TCompactInputProtocol<&'b [u8]>) -> polars_parquet_format::thrift::Result<T>,
) -> polars_parquet_format::thrift::Result<T> {
    read(&mut TCompactInputProtocol::new(bytes, MAX_THRIFT_BYTES))
}

/// Fills `buf` from `input` at byte `at`.
fn read_at<R: Read + Seek>(input: &mut R, at: usize, buf: &mut [u8]) -> std::io::Result<()> {
    input.seek(SeekFrom::Start(at as u64))?;
    input.read_exact(buf)
}

fn write_thrift(
    write: impl FnOnce(&mut TCompactOutputProtocol<&mut Vec<u8>>) -> polars_parquet_format::thrift::Result<usize>,
) -> Result<Vec<u8>, RowGroupError> {
    let mut bytes = Vec::new();
    write(&mut TCompactOutputProtocol::new(&mut bytes))
        .map_err(|e| RowGroupError::Internal(format!("encoding Parquet metadata: {e}")))?;
    Ok(bytes)
}

fn io(file: &Path) -> impl Fn(std::io::Error) -> RowGroupError + '_ {
    move |source| RowGroupError::Io { file: file.into(), source }
}

#[cfg(test)]
mod tests {
    use super::*;
    use polars::prelude::*;

    fn encoded(df: &mut DataFrame) -> Vec<u8> {
        let mut bytes = Vec::new();
        ParquetWriter::new(&mut bytes).finish(df).unwrap();
        bytes
    }

    fn footer(bytes: &[u8]) -> FileMetaData {
        let n = bytes.len();
        let len = u32::from_le_bytes(bytes[n - 8..n - 4].try_into().unwrap()) as usize;
        read_thrift(&bytes[n - 8 - len..n - 8], FileMetaData::read_from_in_protocol).unwrap()
    }

    /// Two files with list columns (as the profiles are) joined: polars reads the rows of both in order,
    /// every column chunk's offsets point at its pages (the offset index's first page is the chunk's
    /// first page, as polars writes it), the column statistics and column indexes are the inputs'.
    #[test]
    fn row_groups_copied_read_as_the_rows_of_both_in_order() {
        let frame = |first: i64, rows: i64| {
            df!(
                "trial" => (first..first + rows).collect::<Vec<i64>>(),
                "name" => (first..first + rows).map(|i| format!("n{}", i % 3)).collect::<Vec<_>>(),
                "profile" => (first..first + rows).map(|i| Series::new("".into(), vec![i as f64 * 0.5; (i % 4) as usize])).collect::<Vec<_>>(),
            )
            .unwrap()
        };
        let (mut a, mut b) = (frame(0, 300), frame(300, 41));
        let (bytes_a, bytes_b) = (encoded(&mut a), encoded(&mut b));
        let dir = std::env::temp_dir().join(format!("fdimc-row-groups-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("joined.parquet");
        let mut w = RowGroupWriter::create(&out).unwrap();
        w.append(&bytes_a, Path::new("a")).unwrap();
        w.append(&bytes_b, Path::new("b")).unwrap();
        assert_eq!(w.finish().unwrap(), 341);
        let joined = ParquetReader::new(File::open(&out).unwrap()).finish().unwrap();
        assert!(joined.equals_missing(&a.vstack(&b).unwrap()));
        let bytes = std::fs::read(&out).unwrap();

        // From files, copied in pieces of 100 bytes (a shard is never whole in memory): the same bytes.
        let (file_a, file_b, from_files) = (dir.join("a.parquet"), dir.join("b.parquet"), dir.join("files.parquet"));
        std::fs::write(&file_a, &bytes_a).unwrap();
        std::fs::write(&file_b, &bytes_b).unwrap();
        let mut w = RowGroupWriter::create(&from_files).unwrap();
        w.piece_bytes = 100;
        w.append_file(&file_a).unwrap();
        w.append_file(&file_b).unwrap();
        assert_eq!(w.finish().unwrap(), 341);
        assert!(bytes_a.len() > 1000, "several pieces: {} bytes", bytes_a.len());
        assert_eq!(std::fs::read(&from_files).unwrap(), bytes);
        for f in [file_a, file_b, from_files] {
            std::fs::remove_file(f).unwrap();
        }

        let meta = footer(&bytes);
        assert_eq!((meta.num_rows, meta.row_groups.len()), (341, 2));
        assert_eq!(meta.schema, footer(&bytes_a).schema);
        let inputs = [footer(&bytes_a), footer(&bytes_b)];
        for (rg, input) in meta.row_groups.iter().zip(&inputs) {
            for (c, c_in) in rg.columns.iter().zip(&input.row_groups[0].columns) {
                let m = c.meta_data.as_ref().unwrap();
                let oi = (c.offset_index_offset.unwrap() as usize, c.offset_index_length.unwrap() as usize);
                let index = read_thrift(&bytes[oi.0..oi.0 + oi.1], OffsetIndex::read_from_in_protocol).unwrap();
                // The offset index lists the data pages (not a dictionary page before them).
                assert_eq!(index.page_locations[0].offset, m.data_page_offset);
                assert_eq!(m.statistics, c_in.meta_data.as_ref().unwrap().statistics);
                let ci = (c.column_index_offset.unwrap() as usize, c.column_index_length.unwrap() as usize);
                let ci_in = (c_in.column_index_offset.unwrap() as usize, c_in.column_index_length.unwrap() as usize);
                let input_bytes = if std::ptr::eq(input, &inputs[0]) { &bytes_a } else { &bytes_b };
                assert_eq!(&bytes[ci.0..ci.0 + ci.1], &input_bytes[ci_in.0..ci_in.0 + ci_in.1]);
            }
        }

        // Another schema, a truncated file: refused by name, and nothing left behind.
        let mut other = df!("x" => [1.0f64]).unwrap();
        let mut w = RowGroupWriter::create(&out).unwrap();
        w.append(&bytes_a, Path::new("a")).unwrap();
        let e = w.append(&encoded(&mut other), Path::new("other.parquet")).unwrap_err().to_string();
        assert!(e.contains("other.parquet: does not match the other parts"), "{e}");
        let e = w.append(&bytes_b[..bytes_b.len() - 3], Path::new("cut.parquet")).unwrap_err().to_string();
        assert!(e.contains("cut.parquet: not a readable Parquet file"), "{e}");
        w.abandon();
        assert!(std::fs::read_dir(&dir).unwrap().all(|f| f.unwrap().path() == out), "only the finished file stays");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
