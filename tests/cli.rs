//! Runs the real `fdimc` binary on the bundled deck and on broken copies of it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const DECK: &str = "studies/seed000_pitch_rate.toml";

fn fdimc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fdimc"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run fdimc")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn deck_text() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(DECK)).unwrap()
}

#[test]
fn validate_reports_the_seed_ranks() {
    let out = fdimc(&["validate", DECK]);
    let stdout = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(stdout.contains("rank ctrb(A, B) = 4 of 5, rank obsv(A, C) = 5 of 5"), "{stdout}");
    assert!(stdout.contains("fault       q_rad_s bias 0.1 from 10 s"), "{stdout}");
}

#[test]
fn design_json_has_the_assigned_eigenvalues() {
    let out = fdimc(&["design", DECK, "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let evs = doc["detectors"][0]["continuous"]["closed_loop_eigenvalues"].as_array().unwrap();
    let re: Vec<f64> = evs.iter().map(|e| e["re"].as_f64().unwrap()).collect();
    for (got, want) in re.iter().zip([-1.0, -2.0, -3.0, -4.0, -5.0]) {
        assert!((got - want).abs() < 1e-9, "{re:?}");
    }
    let z: Vec<f64> = doc["detectors"][0]["discrete"]["closed_loop_eigenvalues"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["re"].as_f64().unwrap())
        .collect();
    for (got, l) in z.iter().zip([-1.0f64, -2.0, -3.0, -4.0, -5.0]) {
        assert!((got - (l * 0.01).exp()).abs() < 1e-12, "{z:?}");
    }
    assert_eq!(doc["ranks"]["controllability_rank"], 4);
    assert_eq!(doc["detectors"][0]["continuous"]["K"].as_array().unwrap().len(), 5);
    assert_eq!(doc["detectors"][0]["continuous"]["K"][0].as_array().unwrap().len(), 6);
}

#[test]
fn simulate_writes_a_trace_in_csv_and_parquet() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("trace.csv");
    let out = fdimc(&["simulate", DECK, "--trial", "0", "--out", csv.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("detected            10.0"), "{stdout}");
    assert!(stdout.contains("fault               q_rad_s bias size 0.1 from 10 s"), "{stdout}");
    assert!(stdout.contains("isolated (direction) q_rad_s"), "{stdout}");
    let body = std::fs::read_to_string(&csv).unwrap();
    let mut lines = body.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(lines.count(), 3000, "one row per sample: 30 s at 0.01 s");
    for col in ["t_s", "u_elevator_rad", "y_q_rad_s", "yhat_q_rad_s", "xhat_h_m", "r_q_rad_s", "alarm_q_rad_s"] {
        assert!(header.contains(&col), "missing {col} in {header:?}");
    }
    assert_eq!(header.len(), 1 + 2 + 6 + 6 + 5 + 6 + 6);

    let pq = dir.path().join("trace.parquet");
    let out = fdimc(&["simulate", DECK, "--out", pq.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let bytes = std::fs::read(&pq).unwrap();
    assert_eq!(&bytes[..4], b"PAR1");
    assert_eq!(&bytes[bytes.len() - 4..], b"PAR1");
    // Nothing temporary left behind.
    let names: Vec<PathBuf> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(names.len(), 2, "{names:?}");
}

/// Each broken deck: (what is wrong, replace this, by this, the message must contain).
const BAD_DECKS: &[(&str, &str, &str, &str)] = &[
    ("unknown field", "seed = 20101001", "seed = 20101001\nseeed = 3", "unknown field `seeed`"),
    (
        "matrix row too short",
        "[0.0,    -7.9101, -3.0241, 0.0,    0.0]",
        "[0.0, -7.9101, -3.0241, 0.0]",
        "plant.a[2]: expected 5 numbers",
    ),
    ("too few rows", "  [0.0,  0.0, 0.0, 0.0, 1.0],\n]", "]", "plant.c: expected 6 rows"),
    ("non-finite entry", "[0.0,  -0.2779]", "[0.0, nan]", "plant.b[1][1]: must be a finite number"),
    ("infinite step", "dt_s = 0.01 ", "dt_s = inf ", "study.dt_s: must be a finite number > 0"),
    (
        "unstable eigenvalue",
        "[-1.0, -2.0, -3.0",
        "[1.0, -2.0, -3.0",
        "detector[0].eigenvalues_per_s[0]: must be a finite negative",
    ),
    (
        "repeated eigenvalues",
        "[-1.0, -2.0, -3.0, -4.0, -5.0]",
        "[-1.0, -2.0, -2.0, -4.0, -5.0]",
        "eigenvalues -2 and -2 are not distinct",
    ),
    (
        "too many eigenvalues",
        "[-1.0, -2.0, -3.0, -4.0, -5.0]",
        "[-1.0, -2.0, -3.0, -4.0, -5.0, -6.0]",
        "detector[0].eigenvalues_per_s: expected 1 to 5",
    ),
    (
        "directions not separable",
        "[-1.0, -2.0, -3.0, -4.0, -5.0]",
        "[-1.0, -2.0]\nfault_directions = [[0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0, 0.0]]",
        "rank(C F) = 1",
    ),
    ("unobservable", "  [0.0,  0.0, 0.0, 0.0, 1.0],\n]", "  [0.0,  0.0, 0.0, 0.0, 0.0],\n]", "not observable"),
    (
        "threshold count",
        "thresholds = [0.5, 0.01, 0.05, 0.01, 0.01, 2.5]",
        "thresholds = [0.5, 0.01]",
        "detector[0].thresholds: expected 6 numbers",
    ),
    (
        "unknown output",
        "output = \"q_rad_s\"",
        "output = \"p_rad_s\"",
        "faults[0].output: \"p_rad_s\" is not one of plant.outputs",
    ),
    ("unknown fault kind", "kind = \"bias\"", "kind = \"biased\"", "faults[0].kind: \"biased\": allowed"),
    ("negative onset", "onset_s = 10.0", "onset_s = -1.0", "faults[0].onset_s: must be >= 0"),
    ("wrong type", "amplitude = 0.25", "amplitude = \"big\"", "amplitude"),
    ("syntax error", "[noise]", "[noise", "TOML parse error"),
    ("unknown detector", "kind = \"detection_filter\"", "kind = \"kalman\"", "detector[0].kind: \"kalman\""),
    (
        "algebraic loop",
        "c = [",
        "d = [[0.0, 1.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]]\nc = [",
        "controller.output_feedback: output feedback with a non-zero plant.d",
    ),
];

#[test]
fn bad_decks_exit_2_naming_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let good = deck_text();
    for (i, (what, from, to, expect)) in BAD_DECKS.iter().enumerate() {
        assert!(good.contains(from), "case {what:?}: the bundled deck no longer contains {from:?}");
        let path = dir.path().join(format!("bad_{i}.toml"));
        std::fs::write(&path, good.replacen(from, to, 1)).unwrap();
        let out = fdimc(&["validate", path.to_str().unwrap()]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "case {what:?}: {stderr}");
        assert!(stderr.contains(&format!("bad_{i}.toml")), "case {what:?} does not name the file: {stderr}");
        assert!(stderr.contains(expect), "case {what:?}: expected {expect:?} in: {stderr}");
        assert!(!stderr.contains("panicked"), "case {what:?}: {stderr}");
    }
}

#[test]
fn bad_arguments_exit_2() {
    let out = fdimc(&["validate", "studies/no_such_deck.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("studies/no_such_deck.toml: cannot read"), "{}", text(&out.stderr));

    let dir = tempfile::tempdir().unwrap();
    let txt = dir.path().join("trace.txt");
    let out = fdimc(&["simulate", DECK, "--out", txt.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("use a .csv or .parquet file name"));
    assert!(!txt.exists());

    let out = fdimc(&["simulate", DECK]);
    assert_eq!(out.status.code(), Some(2), "clap: --out is required");
}
