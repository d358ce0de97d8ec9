//! Bad input at scale (issue 49, item 5): every bundled deck (the FMU decks with their FMUs built) and
//! flight log, mutated many thousand times, must give a result or an error a user can act on, never a
//! panic. The tests run [`DECK_CASES`] cases per deck and [`LOG_CASES`] per log on a new stream of
//! mutations each run (issue 82: the same cases every run find nothing new), its seed printed and in
//! every failure, so `FDIMC_FUZZ_SEED=S` replays it; `FDIMC_FUZZ_CASES` raises the cases, never below
//! those floors. As a fuzz harness on the stable toolchain, `bash scripts/fuzz_inputs.sh [CASES] [SEED]`
//! runs 20,000 per deck.

#![cfg(test)]

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;

use crate::engine::logs::flight_log::{TopicRequest, read_ulog};
use crate::engine::method::method_of;
use crate::engine::run::runner::RunError;
use crate::methods::REGISTRY;

/// Mutated decks per bundled deck in the tests (39 decks: 58,500 cases, 12 s on 2 cores on 2026-12-06);
/// `scripts/fuzz_inputs.sh` runs 20,000 per deck on a new seed.
const DECK_CASES: u64 = 1500;
/// Mutated logs per bundled log in the CI.
const LOG_CASES: u64 = 1000;

/// `FDIMC_FUZZ_CASES` where it asks for more than `floor`, else `floor`.
fn cases(floor: u64) -> u64 {
    std::env::var("FDIMC_FUZZ_CASES").ok().and_then(|s| s.parse().ok()).map_or(floor, |n: u64| n.max(floor))
}

/// `FDIMC_FUZZ_SEED`, else one of the clock's, the same for the whole test binary; printed.
fn seed() -> u64 {
    static SEED: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *SEED.get_or_init(|| {
        let seed = std::env::var("FDIMC_FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or_else(|| {
            let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
            now.as_nanos() as u64 ^ u64::from(std::process::id())
        });
        println!("fuzz seed {seed} (replay: FDIMC_FUZZ_SEED={seed})");
        seed
    })
}

/// The bundled FMUs the FMU decks fly, built as `cargo run --example build_fmus` builds them, so that
/// those decks are in every fuzzed set (not only after another test built them).
fn with_fmus() {
    let root = root();
    super::build_fmus::build_all(&root, &root.join("studies").join("fmus")).unwrap();
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The decks in studies/, sorted.
fn bundled_decks() -> Vec<PathBuf> {
    let mut decks: Vec<PathBuf> = std::fs::read_dir(root().join("studies"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    decks.sort();
    decks
}

/// Values a deck field might be given by mistake: other types, extremes, non-finite numbers, long and
/// non-ASCII strings.
fn odd_value(rng: &mut ChaCha8Rng) -> String {
    const VALUES: &[&str] = &[
        "nan",
        "inf",
        "-inf",
        "+nan",
        "0",
        "-1",
        "-0.0",
        "1e308",
        "-1e308",
        "1e-320",
        "18446744073709551616",
        "-9223372036854775809",
        "9223372036854775807",
        "true",
        "\"\"",
        "\"x\"",
        "\"ünïcødé ✈ 飞行\"",
        "[]",
        "[[]]",
        "[1, 2]",
        "[nan, inf]",
        "[\"a\", 1]",
        "{ a = 1 }",
        "{}",
        "1979-05-27T07:32:00Z",
    ];
    match rng.random_range(0..10) {
        0 => format!("\"{}\"", "a".repeat(rng.random_range(1000..20_000))),
        1 => format!("[{}]", vec!["1.0"; rng.random_range(100..5000)].join(", ")),
        2 => format!("{}", rng.random::<f64>() * 10f64.powi(rng.random_range(-300..300))),
        _ => VALUES[rng.random_range(0..VALUES.len())].to_string(),
    }
}

/// One to three edits of a deck's text: a value replaced, a line deleted, duplicated or swapped, a
/// key renamed, the text cut short, or odd characters inserted.
fn mutate_deck(text: &str, rng: &mut ChaCha8Rng) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for _ in 0..rng.random_range(1..=3) {
        if lines.is_empty() {
            break;
        }
        let i = rng.random_range(0..lines.len());
        match rng.random_range(0..8) {
            0..=2 => {
                if let Some(eq) = lines[i].find('=') {
                    lines[i] = format!("{}= {}", &lines[i][..eq], odd_value(rng));
                }
            }
            3 => {
                lines.remove(i);
            }
            4 => {
                let copy = lines[i].clone();
                lines.insert(i, copy);
            }
            5 => {
                let j = rng.random_range(0..lines.len());
                lines.swap(i, j);
            }
            6 => {
                if let Some(eq) = lines[i].find('=') {
                    lines[i] = format!("ünknown_{} {}", rng.random_range(0..100), &lines[i][eq..]);
                }
            }
            _ => {
                let odd = ["\u{0}", "\u{feff}", "é", "[", "]", "\"", "'''", "\n[study]\n", "#", "\\"];
                let at = (0..=lines[i].len()).filter(|&b| lines[i].is_char_boundary(b)).collect::<Vec<_>>();
                let b = at[rng.random_range(0..at.len())];
                lines[i].insert_str(b, odd[rng.random_range(0..odd.len())]);
            }
        }
    }
    let mut out = lines.join("\n");
    if rng.random_range(0..10) == 0 {
        let cut = rng.random_range(0..=out.len());
        let cut = (0..=cut).rev().find(|&b| out.is_char_boundary(b)).unwrap_or(0);
        out.truncate(cut);
    }
    out
}

/// What a failed case reports: its deck, case number and the panic or the error that was not a user's.
fn check_deck(path: &Path, text: &str) -> Result<(), String> {
    let outcome = catch_unwind(AssertUnwindSafe(|| -> Result<(), String> {
        let method = match method_of(REGISTRY, text, path) {
            Ok(m) => m,
            Err(e) => return names_file(path, e.to_string()),
        };
        let study = match (method.load)(text, path) {
            Ok(s) => s,
            Err(e) => return names_file(path, e.to_string()),
        };
        match study.validate() {
            Ok(()) | Err(RunError::Invalid(_)) => Ok(()),
            Err(e) => Err(format!("validate: not an input error (exit 3): {e}")),
        }
    }));
    match outcome {
        Ok(r) => r,
        Err(panic) => Err(format!("panicked: {}", panic_text(&panic))),
    }
}

/// An input error's message must begin with the file it is about.
fn names_file(path: &Path, message: String) -> Result<(), String> {
    if message.starts_with(&path.display().to_string()) {
        Ok(())
    } else {
        Err(format!("error without the file: {message}"))
    }
}

fn panic_text(panic: &Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_default()
}

#[test]
fn mutated_decks_give_errors_that_name_the_file_never_a_panic() {
    with_fmus();
    let (n, seed) = (cases(DECK_CASES), seed());
    let decks = bundled_decks();
    assert!(decks.len() >= 30, "{decks:?}");
    let failures: Vec<String> = decks
        .par_iter()
        .enumerate()
        .flat_map_iter(|(d, path)| {
            let text = std::fs::read_to_string(path).unwrap();
            (0..n).filter_map(move |case| {
                let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ((d as u64) << 40) ^ case);
                let mutated = mutate_deck(&text, &mut rng);
                check_deck(path, &mutated).err().map(|e| {
                    // The lines the mutation changed, to reproduce the case.
                    let changed: Vec<&str> = mutated.lines().filter(|l| !text.lines().any(|o| o == *l)).collect();
                    let shown: Vec<String> = changed.iter().map(|l| l.chars().take(200).collect()).collect();
                    format!("{} case {case} (FDIMC_FUZZ_SEED={seed}): {e}; changed lines: {shown:?}", path.display())
                })
            })
        })
        .collect();
    no_failures(&format!("{} decks x {n} mutations", decks.len()), &failures);
}

/// The error of a deck as `fdimc validate` gives it (None: it loads and validates).
fn deck_error(path: &Path, text: &str) -> Option<String> {
    let method = match method_of(REGISTRY, text, path) {
        Ok(m) => m,
        Err(e) => return Some(e.to_string()),
    };
    match (method.load)(text, path) {
        Ok(study) => study.validate().err().map(|e| e.to_string()),
        Err(e) => Some(e.to_string()),
    }
}

/// A value of the wrong kind on one line names its field (issue 49, item 5: "the file and field"):
/// every one-line `key = value` of every bundled deck (that loads as bundled), given a string, an
/// empty array, NaN and -1e308 in turn; where the deck is then refused for anything but broken TOML
/// syntax, the message names the file and the key.
#[test]
fn a_wrong_value_is_refused_naming_its_field() {
    with_fmus();
    let decks = bundled_decks();
    let counts: Vec<(usize, Vec<String>)> = decks
        .par_iter()
        .map(|path| {
            let text = std::fs::read_to_string(path).unwrap();
            if let Some(e) = deck_error(path, &text) {
                return (0, vec![format!("{}: the bundled deck is refused: {e}", path.display())]);
            }
            let lines: Vec<&str> = text.lines().collect();
            let (mut refused, mut failures) = (0, Vec::new());
            for (i, line) in lines.iter().enumerate() {
                let Some((key, value)) = line.split_once('=') else { continue };
                let (key, value) = (key.trim(), value.split('#').next().unwrap_or("").trim());
                // One-line values only: a multi-line array's first line alone is broken syntax.
                let balanced = value.matches('[').count() == value.matches(']').count();
                if !key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') || key.is_empty() || !balanced {
                    continue;
                }
                for wrong in ["\"x\"", "[]", "nan", "-1e308"] {
                    let mut edited = lines.clone();
                    let replacement = format!("{key} = {wrong}");
                    edited[i] = &replacement;
                    let Some(e) = deck_error(path, &edited.join("\n")) else { continue };
                    if e.contains("TOML parse error") {
                        continue;
                    }
                    refused += 1;
                    if !e.starts_with(&path.display().to_string()) || !e.contains(key) {
                        failures.push(format!("{} line {}: {key} = {wrong}: {e}", path.display(), i + 1));
                    }
                }
            }
            (refused, failures)
        })
        .collect();
    let refused: usize = counts.iter().map(|c| c.0).sum();
    let failures: Vec<String> = counts.into_iter().flat_map(|c| c.1).collect();
    no_failures(&format!("{refused} refused one-line edits"), &failures);
    // 1,887 on 2026-12-04 (35 decks).
    assert!(refused >= 1850, "{refused} refused edits: the decks lost their fields?");
}

/// Truncation, flipped bytes, a duplicated or zeroed run of bytes (a record twice, a record lost).
fn mutate_log(bytes: &[u8], rng: &mut ChaCha8Rng) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for _ in 0..rng.random_range(1..=3) {
        let len = out.len().max(1);
        match rng.random_range(0..5) {
            0 => out.truncate(rng.random_range(0..len)),
            1 => {
                for _ in 0..rng.random_range(1..20) {
                    let i = rng.random_range(0..len.min(out.len()).max(1));
                    if i < out.len() {
                        out[i] ^= 1 << rng.random_range(0..8);
                    }
                }
            }
            2 | 3 => {
                let a = rng.random_range(0..len);
                let b = (a + rng.random_range(1..200)).min(out.len());
                let copy = out[a.min(out.len())..b].to_vec();
                let at = rng.random_range(0..=out.len());
                out.splice(at..at, copy);
            }
            _ => {
                let a = rng.random_range(0..len).min(out.len());
                let b = (a + rng.random_range(1..64)).min(out.len());
                out[a..b].fill(if rng.random() { 0 } else { 0xff });
            }
        }
    }
    out
}

#[test]
fn mutated_flight_logs_give_errors_that_name_the_file_never_a_panic() {
    let (n, seed) = (cases(LOG_CASES), seed());
    let logs = ["sample_appended_multiple.ulg", "sample_log_small.ulg"];
    let fields = ["gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]", "accelerometer_m_s2[0]"];
    let request = TopicRequest {
        topic: "sensor_combined".into(),
        instance: 0,
        fields: fields.iter().map(|f| f.to_string()).collect(),
        max_gap_s: 0.05,
    };
    let tmp = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for (l, name) in logs.iter().enumerate() {
        let bytes = std::fs::read(root().join("studies/logs").join(name)).unwrap();
        // The unmutated log reads (the small one has no gap of 50 ms at most: an input error).
        let plain = read_ulog(&root().join("studies/logs").join(name), &request);
        assert!(plain.is_ok() || l == 1, "{name}: {plain:?}");
        let found: Vec<String> = (0..n)
            .into_par_iter()
            .filter_map(|case| {
                let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ((l as u64) << 40) ^ case);
                let path = tmp.path().join(format!("{case}_{name}"));
                std::fs::write(&path, mutate_log(&bytes, &mut rng)).unwrap();
                let outcome = catch_unwind(AssertUnwindSafe(|| read_ulog(&path, &request)));
                let _ = std::fs::remove_file(&path);
                match outcome {
                    Ok(Ok(_)) => None,
                    Ok(Err(e)) => names_file(&path, e.to_string())
                        .err()
                        .map(|e| format!("{name} case {case} (FDIMC_FUZZ_SEED={seed}): {e}")),
                    Err(panic) => {
                        Some(format!("{name} case {case} (FDIMC_FUZZ_SEED={seed}): panicked: {}", panic_text(&panic)))
                    }
                }
            })
            .collect();
        failures.extend(found);
    }
    no_failures(&format!("{} logs x {n} mutations", logs.len()), &failures);
}

/// Prints how many of `what` failed and fails the test with the first ten.
fn no_failures(what: &str, failures: &[String]) {
    println!("{what}: {} failures", failures.len());
    assert!(
        failures.is_empty(),
        "{} failures, the first:\n{}",
        failures.len(),
        failures[..failures.len().min(10)].join("\n")
    );
}
