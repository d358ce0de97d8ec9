//! Are two `trials.parquet` files the same records? Exit 0 and `same` when every column holds the same
//! values in the same rows (row groups and compression may differ), exit 1 naming the first difference.
//! Used by tests/cluster/slurm.sh to compare a merged SLURM run with a one-machine run.
//!
//!     cargo run --release --example same_records -- A/trials.parquet B/trials.parquet

use polars::prelude::*;

fn read(path: &str) -> DataFrame {
    let file = std::fs::File::open(path).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(2)
    });
    ParquetReader::new(file).finish().unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(2)
    })
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [a, b] = args.as_slice() else {
        eprintln!("usage: same_records A.parquet B.parquet");
        std::process::exit(2)
    };
    let (x, y) = (read(a), read(b));
    if x.shape() != y.shape() {
        println!("different: {a} is {:?} (rows, columns), {b} is {:?}", x.shape(), y.shape());
        std::process::exit(1);
    }
    for (cx, cy) in x.columns().iter().zip(y.columns()) {
        if cx.name() != cy.name() || !cx.as_materialized_series().equals_missing(cy.as_materialized_series()) {
            println!("different: column {} of {a} and column {} of {b}", cx.name(), cy.name());
            std::process::exit(1);
        }
    }
    println!("same: {} rows x {} columns", x.height(), x.width());
}
