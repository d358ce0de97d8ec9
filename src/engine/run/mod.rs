//! Running trials: the runner (the only parallel code) with its manifest, chunks, shards, lock and
//! resume, its progress line, and the atomic writing of tables.

pub mod output;
pub mod progress;
pub mod row_groups;
pub mod runner;
