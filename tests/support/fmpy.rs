//! FMPy, the reference simulator the FMU tests hold fdimc to (`scripts/fmpy_thirdparty.py`, run now, not
//! numbers pasted from an earlier run). FMPy is found through `FDIMC_FMPY_PYTHON` (a Python with `fmpy`
//! installed; `.ci/run` makes one). Without it the comparisons are skipped with a note, unless
//! `FDIMC_REQUIRE_FMPY=1`, which CI sets.
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

use serde_json::Value;

/// FMPy's answer to `scripts/fmpy_thirdparty.py ARGS`, or `None` (skipped) where no FMPy is set up.
pub fn fmpy(args: &[&str]) -> Option<Value> {
    let Ok(python) = std::env::var("FDIMC_FMPY_PYTHON") else {
        assert!(
            std::env::var("FDIMC_REQUIRE_FMPY").is_err(),
            "FDIMC_REQUIRE_FMPY is set but FDIMC_FMPY_PYTHON is not (a Python with fmpy installed)"
        );
        eprintln!("note: FDIMC_FMPY_PYTHON not set: the comparison with FMPy is skipped");
        return None;
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/fmpy_thirdparty.py");
    let out = Command::new(python).arg(script).args(args).output().expect("the FMPy script runs");
    assert!(out.status.success(), "fmpy_thirdparty.py {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    Some(serde_json::from_slice(&out.stdout).expect("one JSON object"))
}

/// A matrix of FMPy's JSON (a list of rows).
pub fn matrix(v: &Value) -> nalgebra::DMatrix<f64> {
    let rows: Vec<Vec<f64>> = v
        .as_array()
        .expect("a list of rows")
        .iter()
        .map(|r| r.as_array().expect("a row").iter().map(|x| x.as_f64().unwrap_or(f64::NAN)).collect())
        .collect();
    let cols = rows.first().map_or(0, Vec::len);
    nalgebra::DMatrix::from_fn(rows.len(), cols, |i, j| rows[i][j])
}
