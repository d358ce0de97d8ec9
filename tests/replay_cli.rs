//! Replaying flight logs through the real `fdimc` binary (issue 51, the replay half): `fdimc log`'s
//! messages, time base and plot.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const MOVING: &str = "studies/logs/sample_appended_multiple.ulg";
const BENCH: &str = "studies/logs/sample_log_small.ulg";

fn fdimc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fdimc"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run the binary")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Stdout of a run that must succeed.
fn ok(out: &Output) -> String {
    assert!(out.status.success(), "{}\n{}", text(&out.stdout), text(&out.stderr));
    text(&out.stdout)
}

/// Stderr of a run that must exit 2 (invalid input) without a panic, and with nothing on stdout.
fn refused(out: &Output) -> String {
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(text(&out.stdout), "", "nothing printed before the error: {stderr}");
    stderr
}

/// `studies/<source>` with each `from` replaced once by its `to`, written to `dir/<name>`, its `[log]`
/// file made absolute (the deck no longer sits beside `studies/logs/`).
fn edited_deck(dir: &Path, source: &str, edits: &[(&str, &str)], name: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut deck = std::fs::read_to_string(root.join("studies").join(source)).unwrap();
    for (from, to) in edits {
        assert!(deck.contains(from), "{source}: {from}");
        deck = deck.replacen(from, to, 1);
    }
    let logs = root.join("studies/logs/");
    let path = dir.join(name);
    std::fs::write(&path, deck.replace("file = \"logs/", &format!("file = \"{}", logs.display()))).unwrap();
    path
}

/// Issue 51, items 10 and 11: `fdimc log` counts time from the replayed topic's first sample and says
/// once where that is on the log's clock; a topic with one sample has no rate; the column of bad
/// timestamps is named and explained. Refusals exit 2 with a plain message and nothing printed before
/// it: random bytes ("not a PX4 ULog", not Rust's debug text), a topic the log lacks (listing those it
/// has); in a deck, a missing topic is `log.topic`'s and a long gap `log.max_gap_s`'s, with the log's
/// largest gap, the value that bridges it, and the gap's time from the first sample.
#[test]
fn log_speaks_one_time_base_and_plain_messages() {
    let out = ok(&fdimc(&["log", BENCH, "--topic", "sensor_combined"]));
    let first = out.lines().next().unwrap();
    assert!(first.contains("times in s from the first sensor_combined sample"), "{first}");
    assert!(first.contains("at 20.326716 s on the log's clock (boot time"), "{first}");
    let cells = |topic: &str| -> Vec<String> {
        let row = out.lines().find(|l| l.starts_with(&format!("{topic} "))).unwrap();
        row.split_whitespace().map(String::from).collect()
    };
    // Was 20.327 and 26.823 (boot time): now from the first sample, as decks count.
    assert_eq!(cells("sensor_combined"), ["sensor_combined", "0", "1298", "0.000", "6.496", "199.66", "0.1613", "0"]);
    assert!(out.lines().nth(1).unwrap().ends_with("largest_gap_s  bad_times"), "{out}");
    assert!(out.contains("bad_times: samples whose timestamp repeats or goes back"), "{out}");
    let all = ok(&fdimc(&["log", BENCH]));
    let mission: Vec<&str> = all.lines().find(|l| l.starts_with("mission ")).unwrap().split_whitespace().collect();
    assert_eq!(mission[2..], ["1", "1174.041", "1174.041", "-", "-", "0"], "one sample: no rate, no gap");

    let tmp = tempfile::tempdir().unwrap();
    let random = tmp.path().join("random.ulg");
    // Bytes of no format (a fixed linear congruential sequence).
    let bytes: Vec<u8> =
        (0..4096u32).map(|i| (i.wrapping_mul(1_103_515_245).wrapping_add(12_345) >> 16) as u8).collect();
    std::fs::write(&random, bytes).unwrap();
    let err = refused(&fdimc(&["log", random.to_str().unwrap()]));
    assert!(
        err.starts_with(&format!(
            "error: {}: not a PX4 ULog: it does not begin with the ULog header",
            random.display()
        ))
    );
    assert!(!err.contains("UlogParseError") && !err.contains("error_type"), "{err}");
    let err = refused(&fdimc(&["log", BENCH, "--topic", "nosuch"]));
    assert!(err.starts_with(&format!("error: {BENCH}: no topic \"nosuch\" instance 0 (the log has: ")), "{err}");
    assert!(err.contains("sensor_combined") && err.contains("vehicle_attitude"), "{err}");

    let on_bench = [("file = \"logs/sample_appended_multiple.ulg\"", "file = \"logs/sample_log_small.ulg\"")];
    let gap = edited_deck(tmp.path(), "replay_px4.toml", &on_bench, "gap.toml");
    let err = refused(&fdimc(&["validate", gap.to_str().unwrap()]));
    assert!(err.contains("gap.toml: log.max_gap_s: "), "{err}");
    assert!(
        err.contains(
            "the deck allows 0.02 s (max_gap_s). The log's largest gap is 0.161 s: max_gap_s = 0.162 bridges every gap"
        ),
        "{err}"
    );
    // The first gap over 0.02 s, in seconds from the first sample (the log spans 6.5 s; boot time would be 20 s on).
    let after: f64 = err.split(" s after ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
    assert!((0.0..6.5).contains(&after), "{err}");
    let topic = edited_deck(
        tmp.path(),
        "replay_px4.toml",
        &[("topic = \"sensor_combined\"", "topic = \"nosuch\"")],
        "topic.toml",
    );
    let err = refused(&fdimc(&["validate", topic.to_str().unwrap()]));
    assert!(
        err.contains("topic.toml: log.topic: ") && err.contains("no topic \"nosuch\" instance 0 (the log has: "),
        "{err}"
    );
    assert!(err.contains("sensor_combined"), "{err}");
}

/// `fdimc log --plot`: the chosen fields over seconds from the first sample, one panel each, with the
/// deck's train_s and evaluate_s shaded (two rectangles per panel, the training one over the first
/// half of the plot's width); without a deck nothing is shaded. A field the topic lacks, a deck of
/// another log and --signals without --plot are refused.
#[test]
fn log_plot_draws_the_signals_and_the_decks_parts() {
    let tmp = tempfile::tempdir().unwrap();
    let svg = tmp.path().join("imu.svg");
    let (svg_s, deck) = (svg.to_str().unwrap(), "studies/replay_px4.toml");
    let signals = "gyro_rad[2],accelerometer_m_s2[2]";
    let out = ok(&fdimc(&["log", MOVING, "--plot", svg_s, "--signals", signals, "--deck", deck]));
    assert!(out.contains("the deck's train_s [0.00, 4.80) and evaluate_s [4.80, 9.60) shaded"), "{out}");
    let drawn = std::fs::read_to_string(&svg).unwrap();
    for want in ["gyro_rad[2]", "accelerometer_m_s2[2]", "train_s [0.00, 4.80) s", "evaluate_s [4.80, 9.60) s"] {
        assert!(drawn.contains(want), "{want}");
    }
    assert!(drawn.contains("t (s from the first sensor_combined sample)"));
    let shaded: Vec<&str> =
        drawn.lines().filter(|l| l.starts_with("<rect") && l.contains("opacity=\"0.15\"")).collect();
    assert_eq!(shaded.len(), 4, "train_s and evaluate_s in each of two panels: {shaded:?}");
    let width = |l: &str| -> f64 { l.split("width=\"").nth(1).unwrap().split('"').next().unwrap().parse().unwrap() };
    // 4.8 s of the log's 9.618 s: half the plot.
    let share = width(shaded[0]) / (width(shaded[0]) + width(shaded[1]));
    assert!((share - 4.8 / 9.6).abs() < 0.01, "{share}");

    ok(&fdimc(&["log", MOVING, "--plot", svg_s, "--signals", signals]));
    assert!(!std::fs::read_to_string(&svg).unwrap().contains("opacity=\"0.15\""), "no deck, no parts");

    let err = refused(&fdimc(&["log", MOVING, "--plot", svg_s, "--signals", "gyro_rad[7]"]));
    assert!(
        err.contains("has no number field \"gyro_rad[7]\" (its number fields: ") && err.contains("gyro_rad[0]"),
        "{err}"
    );
    let err = refused(&fdimc(&["log", BENCH, "--plot", svg_s, "--signals", signals, "--deck", deck]));
    assert!(
        err.contains("replay_px4.toml: log.file: ") && err.contains("--deck marks the parts of the log it replays"),
        "{err}"
    );
    let out = fdimc(&["log", MOVING, "--signals", signals]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
}
