//! Runs the real `fdimc` binary on the bundled deck and on broken copies of it.

#[path = "support/build_fmus.rs"]
mod build_fmus;
#[path = "support/fmpy.rs"]
mod fmpy;

use std::path::{Path, PathBuf};

use fdimc::cli::verify::slow_mode_deck;
use fdimc::exact::{
    cusum as exact_cusum, false_alarms as exact_false_alarms, fewest_covered, slow_mode as exact_slow_mode,
};
use std::process::{Command, Output};

const DECK: &str = "studies/seed000_pitch_rate.toml";

fn fdimc(args: &[&str]) -> Output {
    run_binary(Path::new(env!("CARGO_BIN_EXE_fdimc")), args)
}

/// `bin` (fdimc, or a user's binary built on its command line) run from the repository's root.
fn run_binary(bin: &Path, args: &[&str]) -> Output {
    Command::new(bin).args(args).current_dir(env!("CARGO_MANIFEST_DIR")).output().expect("run the binary")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// `studies/<source>` with each `from` replaced once by its `to`, written to `dir/<name>`.
fn edited_deck(dir: &Path, source: &str, edits: &[(&str, &str)], name: &str) -> PathBuf {
    let mut text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("studies").join(source)).unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "{source}: {from}");
        text = text.replacen(from, to, 1);
    }
    let path = dir.join(name);
    std::fs::write(&path, with_absolute_logs(&text)).unwrap();
    path
}

/// A deck written outside `studies/` still finds the bundled logs its `[log]` names relatively.
fn with_absolute_logs(deck: &str) -> String {
    let logs = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/logs/");
    deck.replace("file = \"logs/", &format!("file = \"{}", logs.display()))
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

/// Analytic false alarms (issue 23, item 3): on `studies/seed000_rare_false_alarms.toml` the bounds
/// from the residual's exact Gaussian law bracket what 2,000,000 plain trials measured (seed 2: 145
/// alarms at thresholds x 1.16, Wilson [6.2e-5, 8.5e-5]; 17 at x 1.24, [5.3e-6, 1.36e-5]), and meet
/// the same bounds computed independently (issue 49, item 4): `scripts/reference/rare_false_alarm_numpy.py`
/// writes the residual's covariance recursion in NumPy from the deck's continuous model (SciPy's
/// `expm`) and design's discrete gain only, giving union bounds 6.5243696e-5 and 6.1985073e-6 and
/// Sidak bounds 6.5241568e-5 and 6.1984881e-6 (its own plain simulation at thresholds x 0.75 counts
/// 3,659 and 1,012 alarms in 40,000 trials, against Sidak's 0.0934 and 0.0249). The truth lies between
/// fdimc's lower bound (S1 - S2) and Sidak's. A deck drawing parameter errors says why it has none.
#[test]
fn analytic_false_alarm_bounds_bracket_the_brute_force() {
    let out = fdimc(&["design", "studies/seed000_rare_false_alarms.toml", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (i, (brute_lo, brute_hi, numpy_union, numpy_sidak)) in
        [(6.2e-5, 8.5e-5, 6.5243696e-5, 6.5241568e-5), (5.3e-6, 1.36e-5, 6.1985073e-6, 6.1984881e-6)]
            .into_iter()
            .enumerate()
    {
        let f = &doc["detectors"][i]["false_alarms_at_deck_thresholds"];
        let v = |name: &str| f[name].as_f64().unwrap();
        let (lo, hi) = (v("lower"), v("upper"));
        assert!(lo <= brute_hi && brute_lo <= hi, "detector {i}: [{lo}, {hi}] against [{brute_lo}, {brute_hi}]");
        let close = |a: f64, b: f64| (a / b - 1.0).abs() < 2e-7;
        assert!(close(v("union_bound"), numpy_union) && close(v("sidak_upper"), numpy_sidak), "detector {i}: {f}");
        assert_eq!(hi, v("sidak_upper"), "Sidak's is the tighter upper bound here");
        assert!(lo <= numpy_sidak && (lo / numpy_sidak - 1.0).abs() < 5e-5, "detector {i}: {f}");
        assert_eq!(f["lower_from"], "Bonferroni S1 - S2");
        let (c, c_lo) = (v("conditional_monte_carlo"), v("conditional_monte_carlo_lo"));
        assert!(c_lo <= numpy_sidak && (c / numpy_sidak - 1.0).abs() < 1e-4 && c_lo < c, "detector {i}: {f}");
    }
    let out = ok(&fdimc(&["design", "studies/seed000_robustness.toml"]));
    assert!(out.contains("false alarms, analytic: not computed: the deck draws parameter errors"), "{out}");
}

/// The per-hour conversion where it holds (issue 81, item 2): `design` says how much more a whole hour
/// counts than the hour's trials converted (the closed form is the unit test's). The rare-false-alarm
/// deck's slowest mode, 1 s, settles early in its 10 s trials. Made 7.7 s (-0.13/s, the issue's
/// sideslip mode) on the airspeed, with process noise there that the slow mode accumulates (its
/// settled residual about 0.22 m/s against 0.1 at the start: thresholds 1.0 and 1.05 m/s, about 4.5
/// settled sigmas, all choices of this test), it does not, and `design` flags the converted figures as
/// lower bounds.
#[test]
fn design_flags_a_per_hour_conversion_that_a_slow_mode_undercounts() {
    let deck = "studies/seed000_rare_false_alarms.toml";
    let ratio = |path: &str| -> (Vec<f64>, String) {
        let out = fdimc(&["design", path, "--json"]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let f = |i: usize| doc["detectors"][i]["false_alarms_at_deck_thresholds"].clone();
        let r = (0..2).map(|i| f(i)["hour_over_conversion"].as_f64().unwrap()).collect();
        (r, text(&out.stderr))
    };
    let (settled, said) = ratio(deck);
    assert!(settled.iter().all(|r| (1.0..1.5).contains(r)), "{settled:?}");
    assert!(!said.contains("under-count"), "{said}");
    let dir = tempfile::tempdir().unwrap();
    let slow = dir.path().join("slow.toml");
    let text_of = std::fs::read_to_string(deck).unwrap();
    assert_eq!(text_of.matches("eigenvalues_per_s = [-1.0,").count(), 2);
    let slow_text = text_of
        .replace("eigenvalues_per_s = [-1.0,", "eigenvalues_per_s = [-0.13,")
        .replace("sensor_sigma = [0.1,", "process_sigma_per_step = [0.01, 0.0, 0.0, 0.0, 0.0]\nsensor_sigma = [0.1,")
        .replace("thresholds = [0.58,", "thresholds = [1.0,")
        .replace("thresholds = [0.62,", "thresholds = [1.05,");
    assert!(slow_text.contains("process_sigma_per_step") && slow_text.contains("[1.05,"));
    std::fs::write(&slow, slow_text).unwrap();
    let (slow_ratio, _) = ratio(slow.to_str().unwrap());
    // 6.92 and 8.15 (the seed's and the raised thresholds).
    assert!(slow_ratio.iter().all(|r| *r > 6.0 && *r < 9.0), "{slow_ratio:?}");
    let out = fdimc(&["design", slow.to_str().unwrap()]);
    let said = text(&out.stderr);
    assert_eq!(said.matches("under-count false alarms about").count(), 2, "{said}");
    assert!(said.contains("under-count false alarms about") && said.contains("time constant 7.69"), "{said}");
    assert!(said.contains("rare-event DECK --flight-s 3600"), "{said}");
}

/// The bundled slow-unassigned-mode deck's exact law (`src/exact/false_alarms.rs`), its
/// thresholds and `design --json`'s detector: the plant from the deck, the filter's gain `Kd` from
/// `design`, checked (Ad - Kd C has the three assigned eigenvalues, -1, -2 and -3 per s, and leaves a
/// slow mode: sideslip's, 16.7 s in the discrete filter).
fn lateral_slow_mode_law(deck: &str) -> (exact_false_alarms::ResidualLaw, Vec<f64>, serde_json::Value) {
    let (law, thresholds, det) = deck_law(deck, 0);
    let dt = 0.01;
    let mut z: Vec<f64> = law.Phi.complex_eigenvalues().iter().map(|l| l.re).collect();
    z.sort_by(f64::total_cmp);
    for (z, l) in z.iter().zip([-3.0, -2.0, -1.0]) {
        assert!((z - f64::exp(l * dt)).abs() < 1e-9, "{z} vs exp({l} dt)");
    }
    let slowest_s = -dt / z[3].ln();
    assert!((16.6..16.7).contains(&slowest_s), "{z:?}");
    (law, thresholds, det)
}

/// The exact law of detector `i` of a linear deck without process noise (`src/exact/false_alarms.rs`):
/// the plant, sample time, sensor noise and thresholds from the deck, only the filter's discrete gain
/// from `fdimc design --json` (and its design record).
#[allow(non_snake_case)]
fn deck_law(deck: &str, i: usize) -> (exact_false_alarms::ResidualLaw, Vec<f64>, serde_json::Value) {
    use nalgebra::DMatrix;
    let parsed: toml::Table = std::fs::read_to_string(deck).unwrap().parse().unwrap();
    let matrix = |v: &toml::Value| -> DMatrix<f64> {
        let rows: Vec<Vec<f64>> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r.as_array().unwrap().iter().map(|x| x.as_float().unwrap()).collect())
            .collect();
        DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
    };
    let floats =
        |v: &toml::Value| -> Vec<f64> { v.as_array().unwrap().iter().map(|x| x.as_float().unwrap()).collect() };
    let (A, C) = (matrix(&parsed["plant"]["a"]), matrix(&parsed["plant"]["c"]));
    let dt = parsed["study"]["dt_s"].as_float().unwrap();
    let sigma = floats(&parsed["noise"]["sensor_sigma"]);
    assert!(parsed["noise"].get("process_sigma_per_step").is_none(), "{deck}: the law here has no process noise");
    let thresholds = floats(&parsed["detector"][i]["thresholds"]);
    let out = fdimc(&["design", deck, "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let det = doc["detectors"][i].clone();
    let Kd = matrix(&toml::Value::try_from(&det["discrete"]["K"]).unwrap());
    let Ad = (&A * dt).exp();
    let process = vec![0.0; A.nrows()];
    (exact_false_alarms::ResidualLaw::new(&Ad, &Kd, &C, &sigma, &process), thresholds, det)
}

/// `fdimc flight-thresholds` against the exact law (issue 84, item 4): the project's lateral deck (three
/// outputs, a slow unassigned sideslip mode of 16.7 s) at a sample time of 0.05 s, flights of 30 s (600
/// samples, so `src/exact/false_alarms.rs` sums every pair of events). At the thresholds found
/// for 1e-5, 1e-7 and 1e-9 per flight (each output an equal share; at 1e-7 also the deck's thresholds
/// scaled together), the exact law's bracket on the per-flight probability (Bonferroni below, Sidak
/// above) lies between half the target and the target; the confirmation's one-sided bound is below
/// the target and `thresholds.csv` holds the three thresholds for `summarize --thresholds`.
/// `FDIMC_FLIGHT_HOUR=1` checks one-hour flights of the deck as bundled (0.01 s, 360,000 samples; the
/// exact law's pairs summed by lag once settled) instead, outside CI (docs/verification.md).
#[test]
fn flight_thresholds_meet_the_exact_law_on_a_slow_mode_and_several_outputs() {
    let hour = std::env::var("FDIMC_FLIGHT_HOUR").is_ok_and(|v| v == "1");
    let tmp = tempfile::tempdir().unwrap();
    let deck = tmp.path().join("lateral_coarse.toml");
    let bundled = std::fs::read_to_string("studies/seed000_lateral_slow_mode.toml").unwrap();
    let lateral = if hour { bundled } else { bundled.replace("dt_s = 0.01", "dt_s = 0.05") };
    assert!(lateral.contains(if hour { "dt_s = 0.01" } else { "dt_s = 0.05" }));
    std::fs::write(&deck, &lateral).unwrap();
    let deck = deck.to_str().unwrap();
    let (law, deck_thresholds, _) = deck_law(deck, 0);
    let (flight_s, samples) = if hour { ("3600", 360_000) } else { ("30", 600) };
    for (target, allocation) in [(1e-5, "equal"), (1e-7, "equal"), (1e-9, "equal"), (1e-7, "deck")] {
        let out = tmp.path().join(format!("{target:e}_{allocation}"));
        let args = ["flight-thresholds", deck, "--per-flight", &target.to_string(), "--flight-s", flight_s];
        let o = fdimc(&[&args[..], &["--allocation", allocation, "--out", out.to_str().unwrap()]].concat());
        assert_eq!(o.status.code(), Some(0), "{}{}", text(&o.stdout), text(&o.stderr));
        let t = csv_frame(&out.join("flight_thresholds.csv"));
        assert_eq!(t.height(), 3);
        let f = |name: &str| -> Vec<f64> { t.column(name).unwrap().f64().unwrap().into_no_null_iter().collect() };
        let thresholds = f("threshold");
        let exact = if hour { law.flight(&thresholds, samples) } else { law.window(&thresholds, samples) };
        let (estimate, bound) = (f("per_flight")[0], f("per_flight_upper_95")[0]);
        println!(
            "{target:e} {allocation}: thresholds {thresholds:?}; exact [{:e}, {:e}], fdimc {estimate:e} (bound {bound:e})",
            exact.lower, exact.upper
        );
        assert!(
            exact.lower >= target / 2.0 && exact.upper <= target,
            "[{:e}, {:e}] vs {target:e}",
            exact.lower,
            exact.upper
        );
        assert!(bound < target && exact.lower <= bound, "{estimate:e} bound {bound:e}");
        if allocation == "deck" {
            let scale: Vec<f64> = thresholds.iter().zip(&deck_thresholds).map(|(t, d)| t / d).collect();
            assert!(scale.iter().all(|s| (s / scale[0] - 1.0).abs() < 1e-12), "{scale:?}");
        }
        let calibration = csv_frame(&out.join("thresholds.csv"));
        let per: Vec<f64> =
            calibration.column("per_statistic_threshold").unwrap().f64().unwrap().into_no_null_iter().collect();
        assert_eq!(per, thresholds);
    }
}

/// `fdimc flight-thresholds` refuses what it cannot answer with exit 2, a message that names the file
/// or the option and what to do, and nothing written: a kind without an exact law (told to run
/// `rare-event --flight-s` or `summarize --target-pfa-per-hour` instead), a deck that flies an FMU (never
/// loaded), an unknown detector, a target outside (0, 0.5), a flight of no samples, both targets or none.
#[test]
fn flight_thresholds_refuses_what_it_cannot_answer() {
    let tmp = tempfile::tempdir().unwrap();
    // A deck beside a CUSUM: the CUSUM is skipped with why, the |residual| filters are searched; named,
    // the CUSUM is refused.
    let mixed = tmp.path().join("mixed.toml");
    let ci = std::fs::read_to_string("studies/ci_seed000.toml").unwrap();
    let cusum = "[[detector]]\nname = \"cusum\"\nkind = \"cusum\"\neigenvalues_per_s = [-1.0, -2.0, -3.0, -4.0, -5.0]\n\
                 drift = [0.2, 0.004, 0.01, 0.004, 0.004, 1.0]\nthresholds = [1.0, 0.02, 0.05, 0.02, 0.02, 5.0]\n\n[monte_carlo]";
    std::fs::write(&mixed, ci.replacen("[monte_carlo]", cusum, 1)).unwrap();
    let searched = tmp.path().join("searched");
    let args = ["flight-thresholds", mixed.to_str().unwrap(), "--per-flight", "1e-5", "--flight-s", "10", "--out"];
    let said = ok(&fdimc(&[&args[..], &[searched.to_str().unwrap()]].concat()));
    assert!(said.contains("skipped cusum: not the exact law's setting: the test is"), "{said}");
    assert_eq!(said.matches(": confirmed").count(), 2, "{said}");
    assert_eq!(csv_frame(&searched.join("thresholds.csv")).height(), 12);
    let out = tmp.path().join("out");
    let o = out.to_str().unwrap();
    let lateral = "studies/seed000_lateral_slow_mode.toml";
    for (args, says) in [
        (vec!["studies/ci_seed001.toml", "--per-hour", "1e-7"], "ci_seed001.toml: a thrust_loss study"),
        (vec!["studies/ci_seed004.toml", "--per-hour", "1e-7"], "fdimc summarize RUN --target-pfa-per-hour P"),
        (vec!["studies/fmu_aircraft.toml", "--per-hour", "1e-7"], "fmu_aircraft.toml: flies an FMU"),
        (vec![lateral, "--per-hour", "1e-7", "--detector", "none"], "no detector \"none\" (the deck has lateral)"),
        (
            vec![mixed.to_str().unwrap(), "--per-hour", "1e-7", "--detector", "cusum"],
            "cusum: not the exact law's setting: the test is",
        ),
        (vec![lateral, "--per-hour", "0"], "--per-hour 0: a false-alarm probability, allowed > 0 and < 0.5"),
        (vec![lateral, "--per-flight", "0.5"], "--per-flight 0.5: a false-alarm probability"),
        (vec![lateral, "--per-hour", "0.4", "--flight-s", "36000"], "--per-hour 0.4 over flights of 36000 s is 0.994"),
        (vec![lateral, "--per-hour", "1e-7", "--flight-s", "0.001"], "--flight-s 0.001: 0 samples"),
        (vec![lateral, "--per-hour", "1e-7", "--flight-s=-3"], "--flight-s -3: a flight's length in seconds"),
        (vec![lateral, "--per-hour", "1e-7", "--per-flight", "1e-7"], "cannot be used with"),
        (vec![lateral], "--per-hour <P>"),
    ] {
        let o = fdimc(&[&["flight-thresholds"][..], &args, &["--out", o]].concat());
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o.stderr));
        assert!(text(&o.stderr).contains(says), "{args:?}: {}", text(&o.stderr));
        assert!(!out.exists(), "{args:?} wrote nothing");
    }
}

/// The exact law against fdimc's figures (issue 81, item 4), on the project's deck with a slow unassigned
/// mode and three outputs: `src/exact/false_alarms.rs` (sharing no code with fdimc's
/// estimators) brackets a 10 s trial's false-alarm probability and a one-hour flight's from `e(0) = 0`.
/// `design`'s bounds hold and lie within 0.2 % of the trial's; the extremal index against the
/// conversion exceeds 1.5 by the exact law (2.53 to 2.74), and `design` flags the conversion there with
/// the bracket's upper end (its Sidak bounds); the calibration at Pfa 0.01 per trial gives thresholds
/// whose exact Pfa its interval covers; a per-hour target the run cannot resolve is refused with
/// nothing written.
#[test]
fn the_exact_law_confirms_the_flagged_conversion_and_the_calibration_on_a_slow_unassigned_mode() {
    use exact_false_alarms::extremal_index;
    let deck = "studies/seed000_lateral_slow_mode.toml";
    let (law, thresholds, det) = lateral_slow_mode_law(deck);
    let trial = law.window(&thresholds, 1000);
    let hour = law.flight(&thresholds, 360_000);
    // Tight enough to decide: the trial's bounds within 0.2 %, the hour's within 8 % (its lower bound
    // leaves out the first minutes, before P(k) settles).
    assert!(trial.upper / trial.lower - 1.0 < 2e-3, "{trial:?}");
    assert!(hour.upper / hour.lower - 1.0 < 8e-2, "{hour:?}");
    let fa = &det["false_alarms_at_deck_thresholds"];
    let (lower, upper) = (fa["lower"].as_f64().unwrap(), fa["upper"].as_f64().unwrap());
    // design's Sidak bound is the exact one; its Bonferroni bound sums the far pairs at a bound on their
    // correlation, so lies below the exact pairwise sum, here by 0.1 %.
    assert!((upper / trial.upper - 1.0).abs() < 1e-6, "design's upper {upper} vs exact {trial:?}");
    assert!(lower <= trial.lower && lower > trial.lower * (1.0 - 2e-3), "design's lower {lower} vs exact {trial:?}");
    let theta = extremal_index(hour, trial, 360.0);
    println!("trial {trial:?} hour {hour:?} extremal index {theta:?}");
    assert!(theta.lower > 1.5 && theta.upper < 3.0, "{theta:?}");
    assert_eq!(fa["conversion_undercounts"], serde_json::json!(true));
    let ratio = fa["hour_over_conversion"].as_f64().unwrap();
    assert!(theta.lower <= ratio && ratio <= theta.upper * (1.0 + 1e-9), "design's {ratio} vs exact {theta:?}");
    // The calibration at Pfa 0.01 per trial on 4,000 fault-free trials, for seeds 1 to 8: the exact Pfa
    // at the calibrated thresholds is a draw around 0.01 (sd 0.0016 for the 41st largest of 4,000)
    // that the calibration's 95 % interval covers (6 or more of 8: at 95 % coverage, with probability
    // 0.994), and the draws average near 0.01 (0.0103 expected, sd 0.0006).
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let (mut covered, mut mean, mut last) = (0, 0.0, Vec::new());
    for seed in 1..=8 {
        ok(&fdimc(&["run", deck, "--out", run.to_str().unwrap(), "--seed", &seed.to_string(), "--quiet", "--force"]));
        let t = csv_frame(&run.join("thresholds.csv"));
        let stat = t.column("statistic").unwrap().str().unwrap().clone();
        let f = |name: &str, i: usize| t.column(name).unwrap().f64().unwrap().get(i).unwrap();
        let rows: Vec<usize> = (0..t.height()).filter(|&i| stat.get(i) != Some("all")).collect();
        let all = (0..t.height()).find(|&i| stat.get(i) == Some("all")).unwrap();
        let calibrated: Vec<f64> = rows.iter().map(|&i| f("detector_threshold", i)).collect();
        assert_eq!(calibrated.len(), 3, "{t}");
        let at = law.window(&calibrated, 1000);
        covered += (f("detector_pfa_lo", all) <= at.lower && at.upper <= f("detector_pfa_hi", all)) as usize;
        mean += at.upper / 8.0;
        last = calibrated;
    }
    assert!(covered >= 6, "{covered} of 8 intervals hold the exact Pfa");
    assert!((0.0085..0.012).contains(&mean), "{mean}");
    // The tail fit's thresholds for 1e-7 per flight hour (issue 81, item 2): tail.csv gives the
    // conversion's under-count there, inside the exact law's bracket and above 1.5, and the summary
    // says they are too low; at the calibrated thresholds (0.97 per hour converted, where an hour flown
    // through alarms with probability 0.999) the safety rows are lower bounds too, their extremal
    // index at most the exact law's upper bound (its lower bound says nothing where alarms are this
    // common).
    let tail = csv_frame(&run.join("tail.csv"));
    let s = |name: &str, i: usize| tail.column(name).unwrap().str().unwrap().get(i).map(str::to_string);
    let f = |name: &str, i: usize| tail.column(name).unwrap().f64().unwrap().get(i);
    let rows: Vec<usize> = (0..tail.height())
        .filter(|&i| f("target_pfa_per_hour", i) == Some(1e-7) && f("threshold", i).is_some())
        .collect();
    assert_eq!(rows.len(), 3, "{tail}");
    let at_target: Vec<f64> = rows.iter().map(|&i| f("threshold", i).unwrap()).collect();
    let said = f("hour_over_conversion", rows[0]).unwrap();
    let theta = extremal_index(law.flight(&at_target, 360_000), law.window(&at_target, 1000), 360.0);
    assert!(
        theta.lower > 1.5 && theta.lower <= said && said <= theta.upper * (1.0 + 1e-9),
        "{said} vs exact {theta:?}"
    );
    // The fit itself is far off there (issue 84, item 3): 1e-7 per hour is 2.78e-10 per 10 s trial, and
    // the exact law's bracket on a trial at the fit's thresholds is far above it; tail.csv's trust says
    // so with Sidak's bound (the bracket's upper end) and the summary warns.
    let per_trial = 1.0 - (1.0 - 1e-7f64).powf(10.0 / 3600.0);
    let trial = law.window(&at_target, 1000);
    println!(
        "the fit's thresholds for 1e-7 per hour: a trial's Pfa in [{:e}, {:e}], the target {per_trial:e}",
        trial.lower, trial.upper
    );
    assert!(trial.lower > 100.0 * per_trial, "{trial:?}");
    let trust = s("trust", rows[0]).unwrap();
    let bound: f64 = trust.split("at up to ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
    assert!((bound / trial.upper - 1.0).abs() < 1e-3, "{trust} vs exact {trial:?}");
    assert!(trust.contains("the fit may be far too low (fdimc flight-thresholds"), "{trust}");
    let out = ok(&fdimc(&["summarize", run.to_str().unwrap()]));
    assert!(out.contains("tail.csv's thresholds of lateral for per-flight-hour targets convert from trials"), "{out}");
    assert!(
        out.contains("tail.csv's thresholds of lateral for per-flight-hour targets may be far too low by the residual's exact law: fdimc flight-thresholds"),
        "{out}"
    );
    let safety = csv_frame(&run.join("safety.csv"));
    let roles = safety.column("role").unwrap().str().unwrap().clone();
    assert_eq!(roles.len(), 2, "{safety}");
    let theta = extremal_index(law.flight(&last, 360_000), law.window(&last, 1000), 360.0);
    for r in roles.iter().map(|r| r.unwrap()) {
        assert!(r.starts_with("a lower bound: the segment conversion under-counts here"), "{safety}");
        let index: f64 = r.split("extremal index ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
        assert!(1.5 < index && index <= theta.upper * 1.001, "{index} vs exact {theta:?} at {last:?}");
    }
    assert_eq!(s("statistic", rows[0]).as_deref(), Some("r_rad_s"));
    // 1e-7 per flight hour is 2.8e-10 per trial: refused, nothing written.
    let out = fdimc(&["summarize", run.to_str().unwrap(), "--target-pfa-per-hour", "1e-7"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stdout));
    assert!(text(&out.stderr).contains("needs >= 3599999821"), "{}", text(&out.stderr));
    assert!(!run.join("calibrations").exists());
}

/// The tail fit's intervals against the exact law over seeds (issue 82, item 1): on
/// `studies/seed000_rare_false_alarms.toml` (two detection filters whose residuals forget within a second,
/// so a trial's figure converts to an hour: extremal index 1.01 to 1.03), 4,000 fault-free trials a seed.
/// Per seed and detector, `tail.csv`'s interval for the Pfa at the deck's thresholds, and its threshold
/// intervals for 1e-5, 1e-7 and 1e-9 per flight hour (2.8e-8 to 2.8e-12 per trial: 4 to 8 decades
/// past what 4,000 trials see), each against the exact law (Sidak's bound; the pairs' lower bound meets
/// it to 0.01 % where alarms are this rare): the 95 % interval holds the truth in at least 15 of 20 seeds
/// (16 seen; over 100 seeds 92 to 95, the misses mostly with the truth above the interval).
#[test]
fn the_tail_fits_intervals_meet_the_exact_law_over_seeds() {
    let deck = "studies/seed000_rare_false_alarms.toml";
    let laws: Vec<_> = (0..2).map(|i| deck_law(deck, i)).collect();
    let outputs = ["v_m_s", "alpha_rad", "q_rad_s", "theta_rad", "gamma_rad", "h_m"];
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    // FDIMC_TAIL_SEEDS raises the seeds (100 took 171 s here), never below CI's 20.
    let seeds: u64 = std::env::var("FDIMC_TAIL_SEEDS").ok().and_then(|s| s.parse().ok()).map_or(20, |n: u64| n.max(20));
    // Per (detector, query or target): seeds covered, seeds trusted, trusted and covered, the truth above.
    let mut tally: std::collections::BTreeMap<(String, String), [usize; 4]> = Default::default();
    for seed in 1..=seeds {
        let args = ["run", deck, "--trials", "4000", "--seed", &seed.to_string(), "--quiet", "--force", "--out"];
        ok(&fdimc(&[&args[..], &[run.to_str().unwrap()]].concat()));
        let tail = csv_frame(&run.join("tail.csv"));
        let s = |name: &str, i: usize| tail.column(name).unwrap().str().unwrap().get(i).unwrap_or("").to_string();
        let f = |name: &str, i: usize| tail.column(name).unwrap().f64().unwrap().get(i).unwrap_or(f64::NAN);
        for (d, (law, deck_thresholds, _)) in laws.iter().enumerate() {
            let name = ["seed_x116", "seed_x124"][d];
            let rows: Vec<usize> = (0..tail.height()).filter(|&i| s("detector", i) == name).collect();
            // Per statistic, a row's thresholds in the deck's output order.
            let at = |rows: &[usize], column: &str| -> Vec<f64> {
                outputs.iter().map(|o| f(column, *rows.iter().find(|&&i| s("statistic", i) == *o).unwrap())).collect()
            };
            let mut add = |key: String, covered: bool, trusted: bool, above: bool| {
                let t = tally.entry((name.to_string(), key)).or_default();
                t[0] += covered as usize;
                t[1] += trusted as usize;
                t[2] += (covered && trusted) as usize;
                t[3] += above as usize;
            };
            let deck_row =
                *rows.iter().find(|&&i| s("thresholds", i) == "deck" && s("query", i) == "pfa_at_thresholds").unwrap();
            let exact = law.sidak(deck_thresholds, 1000);
            add(
                "Pfa at the deck's thresholds".into(),
                f("pfa_lo", deck_row) <= exact && exact <= f("pfa_hi", deck_row),
                s("trust", deck_row) == "ok",
                exact > f("pfa_hi", deck_row),
            );
            for target in [1e-5, 1e-7, 1e-9] {
                let rows: Vec<usize> = rows
                    .iter()
                    .copied()
                    .filter(|&i| s("query", i) == "threshold_for_pfa" && f("target_pfa_per_hour", i) == target)
                    .collect();
                assert_eq!(rows.len(), outputs.len(), "{tail}");
                let per_trial = f("pfa", rows[0]);
                let (lo, hi) = (at(&rows, "threshold_lo"), at(&rows, "threshold_hi"));
                let (at_lo, at_hi) = (law.sidak(&lo, 1000), law.sidak(&hi, 1000));
                let covered = at_lo >= per_trial && per_trial >= at_hi;
                // The trust check's doubt from the exact law (issue 84, item 3) fires exactly where Sidak's
                // bound at the fit's thresholds is above twice the target per trial.
                let at_estimate = law.sidak(&at(&rows, "threshold"), 1000);
                let doubted = s("trust", rows[0]).contains("the residual's exact law puts");
                assert_eq!(doubted, at_estimate > 2.0 * per_trial, "seed {seed}: {at_estimate:e} vs {per_trial:e}");
                // Above: the threshold the target needs is above the interval (the fit's lets through more).
                add(
                    format!("threshold for {target:e} per hour"),
                    covered,
                    s("trust", rows[0]) == "ok",
                    at_hi > per_trial,
                );
            }
        }
    }
    // What 100 seeds showed (2026-12-06): 92 to 95 % covered, the misses mostly with the truth above the
    // interval (the fit's thresholds let through more than the target); 3.1 standard deviations below 92 %
    // fails (14 or fewer of 20: probability 0.004 at 92 %, 3e-4 at 95 %).
    let least = 0.92 * seeds as f64 - 3.1 * (seeds as f64 * 0.92 * 0.08).sqrt();
    for ((name, what), [covered, trusted, both, above]) in &tally {
        println!(
            "{name} {what}: covered in {covered} of {seeds} (the truth above in {above}); trusted in {trusted}, of which covered {both}"
        );
        assert!(*covered as f64 >= least, "{name} {what}: covered in {covered} of {seeds}, fewer than {least}");
    }
}

/// `rare-event --flight-s` against the exact law (issue 82, item 1), on the slow-unassigned-mode deck
/// at its thresholds over one-hour flights: the conditional estimates per segment and per flight, and
/// the extremal index between them, each meet the exact law's bracket within their 95 % intervals, and
/// the importance-sampled flights' interval holds the exact flight (not an answer here: at 0.19 per
/// flight the event is not rare enough for the tilt).
#[test]
fn rare_event_flights_meet_the_exact_law_on_a_slow_unassigned_mode() {
    use exact_false_alarms::extremal_index;
    let deck = "studies/seed000_lateral_slow_mode.toml";
    let (law, thresholds, _) = lateral_slow_mode_law(deck);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("re");
    let args = ["rare-event", deck, "--flight-s", "3600", "--flight-trials", "20", "--trials", "1000", "--quiet"];
    ok(&fdimc(&[&args[..], &["--out", out.to_str().unwrap()]].concat()));
    let t = csv_frame(&out.join("per_hour.csv"));
    assert_eq!(t.height(), 1, "{t}");
    let v = |name: &str| t.column(name).unwrap().f64().unwrap().get(0).unwrap();
    let segment = law.window(&thresholds, 1000);
    let flight = law.flight(&thresholds, 360_000);
    let theta = extremal_index(flight, segment, 360.0);
    println!("segment {segment:?} flight {flight:?} extremal index {theta:?}");
    let overlaps = |name: &str, lower: f64, upper: f64| {
        let (lo, hi) = (v(&format!("{name}_lo")), v(&format!("{name}_hi")));
        assert!(lo <= upper && lower <= hi, "{name} [{lo}, {hi}] vs exact [{lower}, {upper}]");
    };
    overlaps("conditional_per_segment", segment.lower, segment.upper);
    overlaps("conditional_per_flight", flight.lower, flight.upper);
    overlaps("extremal_index_conditional", theta.lower, theta.upper);
    overlaps("pfa_per_flight", flight.lower, flight.upper);
    // Tight enough to mean something: the exact flight within 8 %, the conditional within 7 %.
    assert!(flight.upper / flight.lower - 1.0 < 0.08, "{flight:?}");
    assert!(v("conditional_per_flight_hi") / v("conditional_per_flight_lo") - 1.0 < 0.07);
    assert!(theta.lower > 1.5, "{theta:?}");
}

/// Rare-event simulation (issue 23, item 2): `fdimc rare-event` on the bundled rare-false-alarm deck
/// meets the analytic answer (6.524e-5 and 6.198e-6 per trial, the bounds meet there and NumPy's
/// `scripts/reference/rare_false_alarm_numpy.py` gives the same to 7 digits) within its
/// interval, writes the same table for any thread count, and refuses what does not apply (exit 2).
#[test]
fn rare_event_meets_the_analytic_answer_and_refuses_what_does_not_apply() {
    let dir = tempfile::tempdir().unwrap();
    let deck = "studies/seed000_rare_false_alarms.toml";
    let mut tables = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.path().join(format!("t{threads}"));
        let args = ["rare-event", deck, "--levels", "1.5,1", "--trials", "6000", "--quiet", "--threads", threads];
        ok(&fdimc(&[&args[..], &["--out", out.to_str().unwrap()]].concat()));
        tables.push(std::fs::read_to_string(out.join("rare_event.csv")).unwrap());
    }
    assert_eq!(tables[0], tables[1], "the same numbers for 1 and 2 threads");
    // Shards of the trial chunks, merged, give the whole run's table to the bit; a missing shard is refused.
    let mut shards = Vec::new();
    for i in 0..3 {
        let out = dir.path().join(format!("s{i}"));
        let shard = format!("{i}/3");
        let args = ["rare-event", deck, "--levels", "1.5,1", "--trials", "6000", "--quiet", "--shard", &shard];
        ok(&fdimc(&[&args[..], &["--out", out.to_str().unwrap()]].concat()));
        assert!(!out.join("rare_event.csv").exists(), "a shard writes its units only");
        shards.push(out.to_str().unwrap().to_string());
    }
    let merged = dir.path().join("merged");
    ok(&fdimc(&["merge", &shards[2], &shards[0], &shards[1], "--out", merged.to_str().unwrap()]));
    assert_eq!(std::fs::read_to_string(merged.join("rare_event.csv")).unwrap(), tables[0]);
    let out = fdimc(&["merge", &shards[0], &shards[2], "--out", merged.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("need shards 0..3 exactly once each, got [0, 2]"), "{}", text(&out.stderr));
    let rows: Vec<Vec<&str>> = tables[0].lines().map(|l| l.split(',').collect()).collect();
    let at = |name: &str| rows[0].iter().position(|c| *c == name).unwrap();
    assert_eq!(rows.len(), 1 + 4, "2 detectors x 2 levels:\n{}", tables[0]);
    let mut answers = 0;
    for (row, exact) in [(&rows[1], 6.524e-5), (&rows[3], 6.198e-6)] {
        assert_eq!(row[at("threshold_scale")], "1.0", "levels ascending");
        let v = |name: &str| row[at(name)].parse::<f64>().unwrap();
        assert!(v("pfa_per_trial_lo") <= exact && exact <= v("pfa_per_trial_hi"), "{row:?} vs {exact}");
        // An answer carries the factor over plain trials; a row that is not one leaves it blank.
        if row[at("answer")] == "true" {
            answers += 1;
            assert!(v("relative_half_width") <= 0.25 && v("largest_unit_share") <= 0.1, "{row:?}");
            assert!(v("plain_steps_same_precision") > 10.0 * v("steps_simulated"), "{row:?}");
        } else {
            assert!(v("plain_steps_same_precision").is_nan(), "{row:?}");
        }
    }
    assert!(answers >= 1, "6,000 trials answer at 6.198e-6 at least:\n{}", tables[0]);
    let out = dir.path().join("split");
    let split = ok(&fdimc(&[
        "rare-event",
        deck,
        "--estimator",
        "splitting",
        "--particles",
        "20",
        "--replicas",
        "4",
        "--levels",
        "0.8",
        "--detector",
        "seed_x124",
        "--out",
        out.to_str().unwrap(),
    ]));
    assert!(split.contains("seed_x124") && split.contains("replicas"), "{split}");
    assert_eq!(std::fs::read_to_string(out.join("rare_event.csv")).unwrap().lines().count(), 2);
    for (args, says) in [
        (&["--levels", "0"][..], "--levels 0"),
        (&["--particles", "50"][..], "--particles does not apply to --estimator importance"),
        (&["--estimator", "splitting", "--trials", "100"][..], "--trials does not apply to --estimator splitting"),
        (&["--detector", "nope"][..], "seed_x116, seed_x124"),
    ] {
        let out = fdimc(&[&["rare-event", deck][..], args].concat());
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", text(&out.stderr));
        assert!(text(&out.stderr).contains(says), "{args:?}: {}", text(&out.stderr));
    }
    // The run's report shows a rare-event table written into its folder.
    let run = dir.path().join("run");
    run_deck(deck, Some(2000), &run);
    let beside = run.join("rare_event");
    ok(&fdimc(&["rare-event", deck, "--trials", "2000", "--quiet", "--out", beside.to_str().unwrap()]));
    ok(&fdimc(&["report", run.to_str().unwrap()]));
    let page = std::fs::read_to_string(run.join("report/report.html")).unwrap();
    assert!(page.contains("Rare false alarms by simulation") && page.contains("plain_steps_same_precision"));
    let out = fdimc(&["rare-event", "studies/ci_seed002.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("fdimc rare-event applies to detection_filter studies"),
        "{}",
        text(&out.stderr)
    );
}

/// Issue 52, item 1: `rare-event --flight-s` refuses flights that are not whole numbers of trials (and
/// the options that do not go with it) before any work, and its comparison reaches the run's safety
/// summary and report.
#[test]
fn rare_event_flights_are_checked_and_reach_the_safety_summary_and_report() {
    let deck = "studies/seed000_rare_false_alarms.toml";
    for (args, says) in [
        (&["--flight-s", "15"][..], "--flight-s 15: a flight is a whole number (2 or more) of the deck's 10 s trials"),
        (&["--flight-s", "10"][..], "a whole number (2 or more)"),
        (&["--flight-s", "NaN"][..], "--flight-s NaN"),
        (&["--flight-s", "100000"][..], "10000000 samples at dt 0.01 s; allowed at most 1000000"),
        (&["--flight-s", "100", "--shard", "0/2"][..], "drop --shard"),
        (
            &["--flight-s", "100", "--estimator", "splitting", "--flight-trials", "50"][..],
            "--flight-trials does not apply to --estimator splitting",
        ),
        (&["--flight-s", "100", "--flight-trials", "5"][..], "--flight-trials 5: allowed 10"),
        (&["--flight-trials", "50"][..], "--flight-s"),
    ] {
        let out = fdimc(&[&["rare-event", deck][..], args].concat());
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", text(&out.stderr));
        assert!(text(&out.stderr).contains(says), "{args:?}: {}", text(&out.stderr));
    }
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    run_deck(deck, Some(1000), &run);
    let beside = run.join("rare_event");
    let printed = ok(&fdimc(&[
        "rare-event",
        deck,
        "--detector",
        "seed_x116",
        "--trials",
        "4000",
        "--flight-s",
        "20",
        "--flight-trials",
        "2000",
        "--out",
        beside.to_str().unwrap(),
    ]));
    assert!(printed.contains("per flight of 20 s, measured over flights against 2 segments of 10 s"), "{printed}");
    assert!(printed.contains("conditional estimate on the exact law"), "{printed}");
    assert!(beside.join("per_hour.csv").exists() && beside.join("flights/rare_event.csv").exists());
    // --verbose prints the safety sentences.
    let summary = ok(&fdimc(&["--verbose", "summarize", run.to_str().unwrap()]));
    let safety = csv_frame(&run.join("safety.csv"));
    let column = safety.column("method").unwrap().str().unwrap().clone();
    let methods: Vec<String> = (0..column.len()).map(|i| column.get(i).unwrap().to_string()).collect();
    // Per detector at the deck's thresholds: the segments' figure, the flights' and the exact law's.
    assert!(methods.iter().any(|m| m.contains("weighted fault-free trials of 10 s")), "{methods:?}");
    assert!(methods.iter().any(|m| m.contains("weighted fault-free flights of 20 s")), "{methods:?}");
    assert!(
        methods.iter().any(|m| m.contains("conditional Monte Carlo") && m.contains("flights of 20 s")),
        "{methods:?}"
    );
    assert!(summary.contains("extremal index against the segment conversion"), "{summary}");
    // Which row is the figure (issue 81, item 2): the flights', the segments' beside it.
    let role = safety.column("role").unwrap().str().unwrap().clone();
    let detector = safety.column("detector").unwrap().str().unwrap().clone();
    let flown: Vec<&str> = (0..methods.len())
        .filter(|&i| methods[i].contains("flights of 20 s"))
        .filter_map(|i| detector.get(i))
        .collect();
    for (i, m) in methods.iter().enumerate().filter(|(i, _)| flown.contains(&detector.get(*i).unwrap())) {
        let r = role.get(i).unwrap_or("");
        if m.contains("flights of 20 s") {
            assert!(r.starts_with("the figure to quote"), "{m}: {r}");
        } else if m.contains("trials of 10 s") {
            assert!(r.starts_with("consistent with") || r.starts_with("a lower bound"), "{m}: {r}");
        }
    }
    ok(&fdimc(&["report", run.to_str().unwrap()]));
    let page = std::fs::read_to_string(run.join("report/report.html")).unwrap();
    assert!(page.contains("rare_event/per_hour.csv") && page.contains("extremal_index_conditional"));
}

/// Issue 52, item 3: `rare-event --miss-before-hazard` refuses what does not go with it, its interval
/// holds the exact miss (issue 82), and its table reaches the run's safety summary at the deck's
/// thresholds.
#[test]
fn rare_event_miss_before_hazard_is_checked_and_reaches_the_safety_summary() {
    let dir = tempfile::tempdir().unwrap();
    let deck = edited_deck(
        dir.path(),
        "ci_seed000.toml",
        &[("size_sigma = { values = [1.0, 3.0, 6.0] }", "size_sigma = { values = [3.0] }")],
        "miss.toml",
    );
    let mut source = std::fs::read_to_string(&deck).unwrap();
    source.push_str("\n[monte_carlo.time_to_hazard_s]\nbias = 0.3\n");
    std::fs::write(&deck, source).unwrap();
    let deck = deck.to_str().unwrap();
    for (args, says) in [
        (&[deck, "--miss-before-hazard"][..], "--miss-before-hazard splits in time: add --estimator splitting"),
        (
            &[deck, "--miss-before-hazard", "--estimator", "splitting", "--flight-s", "20"][..],
            "--flight-s does not apply to --miss-before-hazard",
        ),
        (&[deck, "--miss-before-hazard", "--estimator", "splitting", "--shard", "0/2"][..], "drop --shard"),
        (
            &["studies/seed000_rare_false_alarms.toml", "--miss-before-hazard", "--estimator", "splitting"][..],
            "needs [monte_carlo.time_to_hazard_s]",
        ),
    ] {
        let out = fdimc(&[&["rare-event"][..], args].concat());
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", text(&out.stderr));
        assert!(text(&out.stderr).contains(says), "{args:?}: {}", text(&out.stderr));
    }
    let run = dir.path().join("run");
    run_deck(deck, Some(600), &run);
    let beside = run.join("rare_event");
    let printed = ok(&fdimc(&[
        "rare-event",
        deck,
        "--miss-before-hazard",
        "--estimator",
        "splitting",
        "--particles",
        "50",
        "--replicas",
        "16",
        "--detector",
        "seed",
        "--quiet",
        "--out",
        beside.to_str().unwrap(),
    ]));
    assert!(printed.is_empty(), "{printed}");
    let table = csv_frame(&beside.join("miss_before_hazard.csv"));
    assert_eq!(table.height(), 1);
    let at = |name: &str| table.column(name).unwrap().f64().unwrap().get(0).unwrap();
    // A 3-sigma bias missed within 0.3 s: exactly 0.6496844 (scripts/reference/miss_gaussian_scipy.py,
    // the window's Gaussian law by Genz's method); the estimate's 95 % interval holds it.
    let (lo, hi) = (at("p_miss_before_hazard_lo"), at("p_miss_before_hazard_hi"));
    assert!(lo <= 0.6496844 && 0.6496844 <= hi, "[{lo}, {hi}]");
    ok(&fdimc(&["summarize", run.to_str().unwrap()]));
    let safety = std::fs::read_to_string(run.join("safety.csv")).unwrap();
    // An answer (16 replicas: none can carry over 10 % of the estimate) at the deck's thresholds.
    assert!(safety.contains("seed,deck,missed detection before the hazard"), "{safety}");
    assert!(safety.contains("splitting in time: 16 replicas of 50 particles"), "{safety}");
}

/// Issue 53: `fdimc worst-case`. `studies/seed000_worst_case.toml`: the CI deck flown without its elevator excitation, a 2.5-sigma bias on
/// alpha or q at 4 s, and the `fast` filter designed on a model whose kinematic couplings (the 1 of
/// q in alpha' and in theta') are off by -50 to +50 % (our choices). Its Pd falls monotonically as
/// either coupling error goes down (at 1.5 sigma, 2,000 trials each: 0.509 at (+0.5, +0.5), 0.498 at
/// (+0.5, -0.5), 0.41 at (0, +0.5), 0.175 at (0, -0.5), 0.067 at (-0.5, +0.5), 0.021 at (-0.5, -0.5)),
/// so the worst point is the vertex (-0.5, -0.5): CMA-ES finds it with 40 candidates of 100 trials and,
/// confirmed on 2,000 fresh trials, misses at least 0.08 more than the best of 40 random points (on
/// this seed 0.85 against 0.72; the deck as drawn 0.48). The same for 1 and 2 threads. Its deck
/// (`--write-deck`) fixes the point and runs. A factor with no effect (a relative error of an entry that
/// is 0) finds nothing worse than the deck as drawn: the same value on the same fresh trials. Bad
/// options are refused before any work.
#[test]
fn worst_case_finds_the_known_vertex_and_nothing_where_nothing_matters() {
    let dir = tempfile::tempdir().unwrap();
    let deck = std::path::PathBuf::from("studies/seed000_worst_case.toml");
    let deck = deck.to_str().unwrap();
    let written = dir.path().join("worst.toml");
    let mut tables = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.path().join(format!("wc{threads}"));
        let printed = ok(&fdimc(&[
            "worst-case",
            deck,
            "--objective",
            "pd",
            "--detector",
            "fast",
            "--budget",
            "4000",
            "--batch",
            "100",
            "--confirm",
            "2000",
            "--threads",
            threads,
            "--write-deck",
            written.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]));
        assert!(printed.contains("perr_alpha_q -0.5 (lower bound), perr_theta_q -0.5 (lower bound)"), "{printed}");
        assert!(printed.contains("significantly worse than the deck as drawn"), "{printed}");
        tables.push(std::fs::read_to_string(out.join("worst_case.csv")).unwrap());
    }
    assert_eq!(tables[0], tables[1], "the same search for any thread count");
    let table = csv_frame(&dir.path().join("wc1/worst_case.csv"));
    let col = |name: &str| table.column(name).unwrap().clone();
    let searches = col("search");
    let confirmed = col("confirmed");
    let value_of = |search: &str| {
        (0..table.height())
            .find(|&i| searches.str().unwrap().get(i) == Some(search))
            .map(|i| confirmed.f64().unwrap().get(i).unwrap())
            .unwrap()
    };
    let (cma, random, drawn) = (value_of("cmaes"), value_of("random"), value_of("as_drawn"));
    assert!(cma >= random + 0.08 && random > drawn, "cmaes {cma}, random {random}, as drawn {drawn}");
    assert_eq!(table.height(), 6, "2 coordinates x (cmaes, random, as drawn)");
    // The written deck fixes the point and flies.
    let fixed = std::fs::read_to_string(&written).unwrap();
    assert_eq!(fixed.matches("relative = -0.5").count(), 2, "{fixed}");
    let said = ok(&fdimc(&["validate", written.to_str().unwrap()]));
    assert!(said.contains("vertex_worst_case") || said.contains("_worst_case"), "{said}");
    let trace = dir.path().join("trace.csv");
    ok(&fdimc(&["simulate", written.to_str().unwrap(), "--trial", "1", "--out", trace.to_str().unwrap()]));
    assert!(trace.exists());

    // No effect: the only searched factor perturbs an entry of A that is 0.
    let inert = edited_deck(
        dir.path(),
        "ci_seed000.toml",
        &[(
            "[[monte_carlo.fault]]\nkind = \"bias\"",
            "[[monte_carlo.parameter_error]]\nname = \"inert\"\nmodel = \"design\"\nmatrix = \"a\"\n\
             entries = [[\"v_m_s\", \"v_m_s\"]]\nrelative = { range = [-0.5, 0.5] }\n\n[[monte_carlo.fault]]\nkind = \"bias\"",
        )],
        "inert.toml",
    );
    let out = dir.path().join("inert");
    let printed = ok(&fdimc(&[
        "worst-case",
        inert.to_str().unwrap(),
        "--objective",
        "pfa",
        "--budget",
        "600",
        "--batch",
        "100",
        "--confirm",
        "1000",
        "--out",
        out.to_str().unwrap(),
    ]));
    assert!(printed.contains("over 2 coordinates") || printed.contains("over 1 coordinates"), "{printed}");
    assert!(printed.contains("no point found significantly worse than the deck as drawn"), "{printed}");
    let table = csv_frame(&out.join("worst_case.csv"));
    let confirmed = table.column("confirmed").unwrap().f64().unwrap().clone();
    let values: Vec<f64> = (0..table.height()).map(|i| confirmed.get(i).unwrap()).collect();
    assert!(values.iter().all(|v| *v == values[0]), "{values:?}");

    for (args, says) in [
        (&[deck, "--objective", "pd", "--batch", "5"][..], "--batch 5: allowed 10"),
        (
            &[deck, "--objective", "pd", "--budget", "100", "--batch", "100"][..],
            "--budget 100: at least two candidates",
        ),
        (&[deck, "--objective", "pd", "--write-deck", "x.txt"][..], "--write-deck x.txt: a deck is a .toml file"),
        (&["studies/seed000_rare_false_alarms.toml", "--objective", "pfa"][..], "nothing to search"),
        (&["studies/ci_seed002.toml", "--objective", "pd"][..], "fdimc worst-case applies to detection_filter studies"),
    ] {
        let out = fdimc(&[&["worst-case"][..], args].concat());
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", text(&out.stderr));
        assert!(text(&out.stderr).contains(says), "{args:?}: {}", text(&out.stderr));
    }
}

/// Issue 19: a 24-state plant measured at 8 states (`tests/data/plant24_outputs8.toml`, written by
/// `scripts/plant_deck.py --states 24 --outputs 8 --seed 1 --trials 256`) with `fault_directions` (r = 8 < n)
/// is observable, designs (the 8 assigned eigenvalues among the 24, residual and conditioning reported,
/// no warning) and runs.
#[test]
fn a_24_state_plant_with_8_outputs_designs_and_runs() {
    let deck = "tests/data/plant24_outputs8.toml";
    let out = fdimc(&["design", deck, "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(!text(&out.stderr).contains("warning"), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (doc["ranks"]["controllability_rank"].as_u64(), doc["ranks"]["observability_rank"].as_u64()),
        (Some(24), Some(24))
    );
    let design = &doc["detectors"][0]["continuous"];
    let re: Vec<f64> =
        design["closed_loop_eigenvalues"].as_array().unwrap().iter().map(|e| e["re"].as_f64().unwrap()).collect();
    assert_eq!(re.len(), 24);
    for l in 1..=8 {
        assert!(re.iter().any(|r| (r + l as f64).abs() < 1e-9), "-{l} assigned: {re:?}");
    }
    assert!(re.iter().all(|&r| r < 0.0), "{re:?}");
    assert!(design["relative_residual"].as_f64().unwrap() < 1e-8);
    let cond = design["eigenvector_condition"].as_f64().unwrap();
    assert!(cond.is_finite() && cond < 1e6, "{cond}");
    assert_eq!(design["K"].as_array().unwrap().len(), 24);
    assert_eq!(design["K"][0].as_array().unwrap().len(), 8);

    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    run_deck(deck, None, &dir);
    assert_eq!(read_frame(&dir.join("trials.parquet")).height(), 256);
}

/// The bundled 24-state 747 deck (scripts/b747_deck.py): the 5 Dryden states are not reached by the
/// commands, every state is seen by the 10 sensors, and the design needs no warning.
#[test]
fn the_bundled_747_deck_validates_with_its_ranks() {
    let out = fdimc(&["validate", "studies/b747_cruise24.toml"]);
    let stdout = ok(&out);
    assert!(stdout.contains("plant       24 states") && stdout.contains("10 outputs"), "{stdout}");
    assert!(stdout.contains("rank ctrb(A, B) = 19 of 24, rank obsv(A, C) = 24 of 24"), "{stdout}");
    assert!(!text(&out.stderr).contains("warning"), "{}", text(&out.stderr));
}

/// Issue 20.1: under the seed's own tuning (no random walk on the surface state) the strong-tracking
/// variants isolate the rudder stuck 1 deg from trim (the seed's third fault) and the EKF banks do not;
/// under this project's random walk none does (README, "Under the seed's own tuning").
#[test]
fn the_seeds_tuning_lets_strong_tracking_find_the_rudder() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    run_deck("studies/seed004_reference_tuning.toml", Some(2), &dir);
    let df = read_frame(&dir.join("trials.parquet"))
        .lazy()
        .filter(col("target").eq(lit("rudder")))
        .group_by([col("detector")])
        .agg([col("isolated_correctly").cast(DataType::UInt32).sum().alias("isolated"), len().alias("flights")])
        .collect()
        .unwrap();
    let isolated = |detector: &str| -> u32 {
        let i = (0..df.height())
            .find(|&i| df.column("detector").unwrap().str().unwrap().get(i) == Some(detector))
            .unwrap_or_else(|| panic!("{detector}: {df}"));
        assert_eq!(df.column("flights").unwrap().u32().unwrap().get(i), Some(2));
        df.column("isolated").unwrap().u32().unwrap().get(i).unwrap_or(0)
    };
    for detector in ["stmmae_seed", "improved_stmmae_seed"] {
        assert_eq!(isolated(detector), 2, "{detector}");
    }
    for detector in ["ekf_fast_seed", "emmae_rw", "ekf_fast_rw", "stmmae_rw", "improved_stmmae_rw"] {
        assert_eq!(isolated(detector), 0, "{detector}");
    }
}

/// `monte_carlo.detection_window_s`: the hi-fi air-data deck (60 trials) with a 2 s window against the
/// same trials without one. Row by row, an alarm within 2 s of the onset stays a detection and a later
/// one becomes a miss with its delay in `late_alarm_s` and nothing isolated; summary.csv counts them;
/// replaying the statistic at the deck's holds repeats the windowed records.
#[test]
fn a_detection_window_turns_late_alarms_into_misses() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let windowed = edited_deck(
        tmp.path(),
        "seed002_hifi_truth.toml",
        &[("[monte_carlo]\n", "[monte_carlo]\ndetection_window_s = 2.0\n")],
        "windowed.toml",
    );
    let (open, closed) = (tmp.path().join("open"), tmp.path().join("closed"));
    run_deck("studies/seed002_hifi_truth.toml", Some(60), &open);
    run_deck(windowed.to_str().unwrap(), Some(60), &closed);
    let (a, b) = (read_frame(&open.join("trials.parquet")), read_frame(&closed.join("trials.parquet")));
    assert_eq!(a.height(), b.height());
    let delay = |df: &DataFrame| df.column("delay_s").unwrap().f64().unwrap().clone();
    let (delay_a, delay_b) = (delay(&a), delay(&b));
    let late_a = a.column("late_alarm_s").unwrap().f64().unwrap().clone();
    let late_b = b.column("late_alarm_s").unwrap().f64().unwrap().clone();
    let isolated_b = b.column("isolated").unwrap().str().unwrap().clone();
    let (mut late, mut kept) = (0, 0);
    for i in 0..a.height() {
        assert_eq!(late_a.get(i), None, "no window, no late alarm");
        match delay_a.get(i) {
            Some(d) if d > 2.0 => {
                assert_eq!((delay_b.get(i), late_b.get(i), isolated_b.get(i)), (None, Some(d), None), "row {i}");
                late += 1;
            }
            d => {
                assert_eq!((delay_b.get(i), late_b.get(i)), (d, None), "row {i}");
                kept += d.is_some() as usize;
            }
        }
    }
    assert!(late >= 20 && kept >= 100, "{late} late, {kept} kept");
    let summary = csv_frame(&closed.join("summary.csv"));
    let deck_late: u64 = summary
        .clone()
        .lazy()
        .filter(col("thresholds").eq(lit("deck")))
        .select([col("late_alarms").cast(DataType::UInt64).sum()])
        .collect()
        .unwrap()
        .column("late_alarms")
        .unwrap()
        .u64()
        .unwrap()
        .get(0)
        .unwrap();
    assert_eq!(deck_late, late as u64);
    assert_replay_repeats_the_trials(&closed);
    let manifest = std::fs::read_to_string(closed.join("manifest.json")).unwrap();
    assert!(manifest.contains("\"detection_window_s\": 2.0"), "{manifest}");
}

/// The hi-fi air-data deck end to end (60 trials): the voting baseline never detects a fault that hits
/// all three lanes alike and detects most that hit one; the patent's detector, on lane 0, detects
/// common-mode faults too; `faulty_lanes` groups the summary; the triplex voter never alarms falsely.
#[test]
fn voting_is_blind_to_common_mode_and_the_dual_ukf_is_not() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    run_deck("studies/seed002_hifi_truth.toml", Some(60), &dir);
    let df = read_frame(&dir.join("trials.parquet"))
        .lazy()
        .filter(col("fault_free").not())
        .group_by([col("detector"), col("faulty_lanes")])
        .agg([col("detected").cast(DataType::UInt32).sum().alias("detected"), len().alias("flights")])
        .sort(["detector", "faulty_lanes"], Default::default())
        .collect()
        .unwrap();
    let get = |detector: &str, lanes: u32| -> (u32, u32) {
        let i = (0..df.height())
            .find(|&i| {
                df.column("detector").unwrap().str().unwrap().get(i) == Some(detector)
                    && df.column("faulty_lanes").unwrap().u32().unwrap().get(i) == Some(lanes)
            })
            .unwrap_or_else(|| panic!("{detector} {lanes}: {df}"));
        let n = |c: &str| df.column(c).unwrap().u32().unwrap().get(i).unwrap();
        (n("detected"), n("flights"))
    };
    let (voted_common, common) = get("voting", 3);
    assert!(common >= 20 && voted_common == 0, "{df}");
    let (voted_single, single) = get("voting", 1);
    assert!(single >= 20 && voted_single * 4 >= single * 3, "{df}");
    let (patent_common, _) = get("patent", 3);
    assert!(patent_common * 4 >= common * 3, "{df}");
    let detectors = csv_frame(&dir.join("detectors.csv"));
    let row = (0..detectors.height())
        .find(|&i| detectors.column("detector").unwrap().str().unwrap().get(i) == Some("voting"))
        .unwrap();
    let false_alarms = detectors.column("flights_with_false_alarm").unwrap().cast(&DataType::UInt32).unwrap();
    assert_eq!(false_alarms.u32().unwrap().get(row), Some(0));
    let summary = csv_frame(&dir.join("summary.csv"));
    assert!(summary.column("faulty_lanes").is_ok(), "a group key");
}

/// Online classification (issue 21.5): a classifier of the alarm's window calls every trial without an
/// alarm normal (here the healthy flights without a false alarm: every fault is detected) and classifies
/// the others; on the alarmed trials the onset-window tree, on another window, disagrees somewhere;
/// the reversed tree is a detector of its own.
#[test]
fn online_classifiers_classify_only_what_the_detector_alarmed_on() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let classifiers = "[[classifier]]\nname = \"tree\"\nscheme = \"tree\"\n\n[[classifier]]\nname = \"tree_online\"\nscheme = \"tree\"\nwindow = \"alarm\"\n\n[[classifier]]\nname = \"tree_reversed\"\nscheme = \"tree_most_separable_first\"\n\n[monte_carlo]";
    let deck = edited_deck(tmp.path(), "ci_seed003.toml", &[("[monte_carlo]", classifiers)], "online.toml");
    let dir = tmp.path().join("run");
    run_deck(deck.to_str().unwrap(), Some(160), &dir);
    let df = read_frame(&dir.join("trials.parquet"));
    assert_eq!(df.height(), 480, "three classifiers per trial");
    let rows = |detector: &str, alarmed: bool| {
        let alarm = col("alarm_s").is_not_null().or(col("false_alarm_s").is_not_null());
        df.clone()
            .lazy()
            .filter(col("detector").eq(lit(detector)).and(if alarmed { alarm } else { alarm.not() }))
            .select([col("isolated")])
            .collect()
            .unwrap()
    };
    let names = |f: DataFrame| -> Vec<String> {
        let c = f.column("isolated").unwrap().str().unwrap().clone();
        (0..c.len()).map(|i| c.get(i).unwrap_or("-").to_string()).collect()
    };
    let quiet = names(rows("tree_online", false));
    assert!(quiet.len() >= 15 && quiet.iter().all(|c| c == "normal"), "{quiet:?}");
    let alarmed = names(rows("tree_online", true));
    assert!(alarmed.len() >= 100 && alarmed.iter().any(|c| c != "normal"), "{alarmed:?}");
    // Another window: somewhere the two trees disagree.
    let (onset, online) = (names(rows("tree", true)), alarmed);
    assert!(onset.iter().zip(&online).any(|(a, b)| a != b), "{onset:?}");
    // Three classifiers x the deck's and the calibrated thresholds of the residual detector.
    let detectors = csv_frame(&dir.join("detectors.csv"));
    assert_eq!(detectors.height(), 6);
}

/// A filter tuned to the noise it meets (issue 21.6): on 200 trials of the noise-tuned deck, at twice the
/// nominal noise the detector raises no false alarm and the tree, trained on nominal sensors only,
/// classifies most trials; the nominal deck on the same trials alarms on most healthy flights and
/// classifies fewer than half.
#[test]
fn a_filter_tuned_to_the_noise_keeps_the_classes_apart_at_twice_the_noise() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let at_twice_the_noise = |deck: &str| -> (f64, u32) {
        let dir = tmp.path().join(deck);
        run_deck(&format!("studies/{deck}.toml"), Some(200), &dir);
        let df = read_frame(&dir.join("trials.parquet"))
            .lazy()
            .filter(col("detector").eq(lit("tree")).and(col("noise_bin").eq(lit(2.0))))
            .select([
                col("isolated_correctly").cast(DataType::Float64).mean().alias("accuracy"),
                col("false_alarm_s").is_not_null().cast(DataType::UInt32).sum().alias("false_alarms"),
                len().alias("n"),
            ])
            .collect()
            .unwrap();
        assert_eq!(df.column("n").unwrap().u32().unwrap().get(0), Some(100));
        let accuracy = df.column("accuracy").unwrap().f64().unwrap().get(0).unwrap();
        (accuracy, df.column("false_alarms").unwrap().u32().unwrap().get(0).unwrap())
    };
    let (tuned, tuned_alarms) = at_twice_the_noise("seed003_noise_tuned");
    let (nominal, nominal_alarms) = at_twice_the_noise("seed003_online");
    assert!(tuned > 0.75 && tuned_alarms == 0, "tuned: accuracy {tuned}, false alarms {tuned_alarms}");
    assert!(nominal < 0.5 && nominal_alarms > 20, "nominal: accuracy {nominal}, false alarms {nominal_alarms}");
}

/// Seed 001's unrelated jumps as a curve (issue 21.3), noise-free: the down-range gust's peak `|fhat|` is
/// linear in its amplitude and equals the 10 % loss's at about 12.6 m/s; the cross-range gust hardly
/// moves the pitch-rate residual. Trial 40 of the gust-sweep deck is the loss without gusts, 14 the full
/// 15 m/s gusts and 37 half of them, both fault-free.
#[test]
fn a_down_range_gust_of_about_13_m_s_looks_like_a_10_percent_loss() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let deck = "studies/seed001_gust_sweep.toml";
    let peak = |trial: &str, from_s: f64, to_s: f64, want: &str| -> f64 {
        let out = tmp.path().join(format!("t{trial}.parquet"));
        let stdout = ok(&fdimc(&["simulate", deck, "--trial", trial, "--out", out.to_str().unwrap()]));
        assert!(stdout.contains(want), "{stdout}");
        let df = read_frame(&out)
            .lazy()
            .filter(col("t_s").gt_eq(lit(from_s)).and(col("t_s").lt(lit(to_s))))
            .select([col("seed_fhat").max().alias("hi"), col("seed_fhat").min().alias("lo")])
            .collect()
            .unwrap();
        let get = |c: &str| df.column(c).unwrap().f64().unwrap().get(0).unwrap();
        get("hi").abs().max(get("lo").abs())
    };
    let loss = peak("40", 40.0, 48.0, "engine 1 loses 10.0 % from 40.000 s");
    let (full, half) = (peak("14", 40.0, 48.0, "gust scale 1"), peak("37", 40.0, 48.0, "gust scale 0.5"));
    assert!((full / half - 2.0).abs() < 0.02, "linear in the amplitude: {full:e} / {half:e}");
    let equal_mps = 15.0 * loss / full;
    assert!((12.0..13.2).contains(&equal_mps), "{equal_mps} m/s");
    assert!(peak("14", 50.0, 58.0, "gust scale 1") < 1e-3 * loss, "the cross-range gust");
}

/// The seed's localisation case (issue 21.4): a 30 % loss on each engine at 25 s, every engine named in
/// every noise draw, as the seed's table reports (16 flights: 4 per engine).
#[test]
fn the_seeds_localisation_case_names_every_engine() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let deck = "studies/seed001_localisation.toml";
    run_deck(deck, Some(16), &dir);
    let df = read_frame(&dir.join("trials.parquet"))
        .lazy()
        .group_by([col("target")])
        .agg([col("isolated_correctly").cast(DataType::UInt32).sum().alias("named"), len().alias("flights")])
        .sort(["target"], Default::default())
        .collect()
        .unwrap();
    assert_eq!(df.height(), 4, "{df}");
    let named: Vec<u32> = df.column("named").unwrap().u32().unwrap().into_no_null_iter().collect();
    let flights: Vec<u32> = df.column("flights").unwrap().u32().unwrap().into_no_null_iter().collect();
    assert_eq!(named, flights, "{df}");
    assert_eq!(flights.iter().sum::<u32>(), 16);
}

/// Fault directions 1e-7 apart make the eigenvectors nearly parallel: validate and design warn.
#[test]
fn nearly_parallel_fault_directions_are_warned_about() {
    let tmp = tempfile::tempdir().unwrap();
    let deck = edited_deck(
        tmp.path(),
        "seed000_pitch_rate.toml",
        &[(
            "eigenvalues_per_s = [-1.0, -2.0, -3.0, -4.0, -5.0]",
            "eigenvalues_per_s = [-1.0, -2.0, -3.0, -4.0, -5.0]\nfault_directions = [[1.0, 0.0, 0.0, 0.0, 0.0], \
             [0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 1e-7, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0]]",
        )],
        "parallel.toml",
    );
    for command in ["validate", "design"] {
        let out = fdimc(&[command, deck.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        let stderr = text(&out.stderr);
        assert!(stderr.contains("warning:") && stderr.contains("exceeds 1e6"), "{command}: {stderr}");
    }
}

#[test]
fn simulate_writes_a_trace_in_csv_and_parquet() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("trace.csv");
    let out = fdimc(&["simulate", DECK, "--trial", "0", "--out", csv.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("detected            10.0"), "{stdout}");
    assert!(stdout.contains("fault               q_rad_s bias 0.1 (output units) from 10 s"), "{stdout}");
    assert!(stdout.contains("isolated (direction) q_rad_s"), "{stdout}");
    let body = std::fs::read_to_string(&csv).unwrap();
    let mut lines = body.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(lines.count(), 3000, "one row per sample: 30 s at 0.01 s");
    for col in
        ["t_s", "u_elevator_rad", "y_q_rad_s", "yhat_q_rad_s", "xhat_h_m", "r_q_rad_s", "stat_q_rad_s", "alarm_q_rad_s"]
    {
        assert!(header.contains(&col), "missing {col} in {header:?}");
    }
    assert_eq!(header.len(), 1 + 2 + 6 + 6 + 5 + 6 + 6 + 6);

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

/// Every case of `tests/data/bad_decks.toml`, every kind: the bundled deck with `from` replaced by `to`
/// exits 2 from `validate` with a message that names the file and says `want`, never a panic.
#[test]
fn bad_decks_exit_2_naming_file_and_field() {
    #[derive(serde::Deserialize)]
    struct Case {
        deck: String,
        what: Option<String>,
        from: String,
        to: String,
        want: String,
    }
    #[derive(serde::Deserialize)]
    struct Catalogue {
        case: Vec<Case>,
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let catalogue: Catalogue =
        toml::from_str(&std::fs::read_to_string(root.join("tests/data/bad_decks.toml")).unwrap()).unwrap();
    assert_eq!(catalogue.case.len(), 135);
    let dir = tempfile::tempdir().unwrap();
    for (i, c) in catalogue.case.iter().enumerate() {
        let what = format!("case {i} ({}, {})", c.deck, c.what.as_deref().unwrap_or(&c.to));
        let good = std::fs::read_to_string(root.join("studies").join(&c.deck)).unwrap();
        assert!(good.contains(&c.from), "{what}: the bundled deck no longer contains {:?}", c.from);
        let path = dir.path().join(format!("bad_{i}.toml"));
        std::fs::write(&path, with_absolute_logs(&good.replacen(&c.from, &c.to, 1))).unwrap();
        let out = fdimc(&["validate", path.to_str().unwrap()]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{what}: {stderr}");
        assert!(stderr.contains(&format!("bad_{i}.toml: ")), "{what} does not name the file: {stderr}");
        assert!(stderr.contains(&c.want), "{what}: expected {:?} in: {stderr}", c.want);
        assert!(!stderr.contains("panicked"), "{what}: {stderr}");
    }
}

#[test]
fn a_closed_pipe_ends_quietly() {
    use std::process::Stdio;
    let child = Command::new(env!("CARGO_BIN_EXE_fdimc"))
        .args(["design", DECK])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut child = child;
    drop(child.stdout.take()); // the reader goes away before fdimc writes
    let out = child.wait_with_output().unwrap();
    let stderr = text(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(out.status.code(), Some(101), "a panic's exit code");
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

    // An option the deck's kind does not take is refused by name, before anything runs.
    let out = fdimc(&["run", DECK, "--classifiers", "x.json", "--out", dir.path().join("r").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains(
            "--classifiers / fdimc train applies to accelerometer studies, not to this detection_filter study"
        ),
        "{stderr}"
    );
    assert!(!dir.path().join("r").exists());
    let out = fdimc(&["train", DECK]);
    assert_eq!(out.status.code(), Some(2));

    // A profile grid step outside what is allowed, from the command line or the deck.
    let r = dir.path().join("r");
    let out = fdimc(&["run", DECK, "--profile-resolution", "-0.1", "--out", r.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--profile-resolution -0.1: allowed 0 (every rise"), "{}", text(&out.stderr));
    assert!(!r.exists());
    let deck = edited_deck(
        dir.path(),
        "ci_seed000.toml",
        &[("trials = 3000", "trials = 3000\nprofile_resolution = 0.0001")],
        "p.toml",
    );
    let out = fdimc(&["validate", deck.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("p.toml") && stderr.contains("monte_carlo.profile_resolution: allowed 0"), "{stderr}");
}

// ---------------------------------------------------------------------------------------------
// Monte Carlo runs

const CI_DECK: &str = "studies/ci_seed000.toml";

/// `fdimc run DECK [--trials N] --quiet --out OUT`, which must succeed; its standard output.
fn run_deck(deck: &str, trials: Option<u64>, out: &Path) -> String {
    let trials = trials.map(|n| n.to_string());
    let mut args = vec!["run", deck];
    if let Some(n) = &trials {
        args.extend(["--trials", n]);
    }
    args.extend(["--quiet", "--out", out.to_str().unwrap()]);
    ok(&fdimc(&args))
}

fn ok(out: &Output) -> String {
    assert_eq!(out.status.code(), Some(0), "stdout:\n{}\nstderr:\n{}", text(&out.stdout), text(&out.stderr));
    text(&out.stdout)
}

fn read_frame(path: &Path) -> polars::prelude::DataFrame {
    use polars::prelude::*;
    ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

fn csv_frame(path: &Path) -> polars::prelude::DataFrame {
    use polars::prelude::*;
    CsvReadOptions::default()
        .with_has_header(true)
        .try_into_reader_with_file_path(Some(path.into()))
        .unwrap()
        .finish()
        .unwrap()
}

/// The test FMUs in studies/fmus/, where the FMU decks find them (`cargo run --example build_fmus`).
fn bundled_fmus() -> &'static Path {
    static BUILT: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    BUILT.get_or_init(|| {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let dir = root.join("studies").join("fmus");
        build_fmus::build_all(root, &dir).unwrap();
        dir
    })
}

#[test]
fn every_bundled_deck_validates() {
    bundled_fmus();
    for entry in std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("studies")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue; // studies/logs/: the flight logs decks replay
        }
        let out = fdimc(&["validate", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(0), "{}: {}", path.display(), text(&out.stderr));
    }
}

#[test]
fn a_surface_deck_validates_simulates_and_design_refuses_it_by_name() {
    let deck = "studies/seed004_surfaces.toml";
    let out = fdimc(&["validate", deck]);
    let stdout = ok(&out);
    assert_eq!(stdout.lines().filter(|l| l.starts_with("fault ")).count(), 5, "{stdout}");
    assert!(stdout.contains("fault       aileron_left: stuck at -15.0 deg, from 10 s to 40 s"), "{stdout}");
    assert_eq!(stdout.lines().filter(|l| l.starts_with("bank ")).count(), 4, "{stdout}");
    assert!(stdout.contains("monte carlo 20 trials"), "{stdout}");
    let dir = tempfile::tempdir().unwrap();
    let trace = dir.path().join("trace.parquet");
    let out = fdimc(&["simulate", deck, "--out", trace.to_str().unwrap()]);
    let stdout = ok(&out);
    assert!(stdout.contains("trial 0, 4 bank(s), 30000 samples"), "{stdout}");
    let improved: Vec<_> = stdout.lines().filter(|l| l.trim_start().starts_with("improved_stmmae  ")).collect();
    assert_eq!(improved.len(), 6, "five fault windows and the health line: {stdout}");
    assert!(improved[0].contains("aileron_left") && improved[0].matches("aileron_left").count() == 2, "{stdout}");
    let df = read_frame(&trace);
    assert_eq!(df.height(), 30_000);
    assert_eq!(df.width(), 1 + 10 + 2 + 10 + 4 * (6 + 5) + 4 * 5);
    let out = fdimc(&["design", deck]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("fdimc design applies to detection_filter studies, not to this surface_bank study")
    );
}

/// The bundled surface Monte Carlo deck cut to 8 s flights and 130 trials (part files of 64: 64 + 64 + 2).
fn small_surface_deck(dir: &Path) -> PathBuf {
    edited_deck(
        dir,
        "seed004_monte_carlo.toml",
        &[
            ("duration_s = 40.0", "duration_s = 8.0"),
            ("onset_s = { range = [5.0, 15.0] }", "onset_s = { range = [2.0, 3.0] }"),
            ("fault_duration_s = 15.0", "fault_duration_s = 3.0"),
            ("trials = 1200", "trials = 130"),
        ],
        "small_surfaces.toml",
    )
}

/// Runs `deck` once with `--trials trials`, 1 thread and `--verbose` into `dir/one`: a kind's own test
/// reads its tables and console (the kind's records are identical for any threads, shards and resume by
/// [`shared_checks`], on its starter deck). Returns the folder and its stdout.
fn one_run(deck: &str, dir: &Path, trials: u64) -> (PathBuf, String) {
    let one = dir.join("one");
    let n = trials.to_string();
    let stdout =
        ok(&fdimc(&["run", deck, "--trials", &n, "--threads", "1", "--verbose", "--out", one.to_str().unwrap()]));
    assert!(stdout.contains(&format!("trials 0..{trials} of {trials} ({trials} run, 0 resumed)")), "{stdout}");
    (one, stdout)
}

/// Runs `deck` with 1 and 2 threads, as two merged shards, and stopped after its first part file of
/// `chunk` trials (a half-written part left behind) then resumed: every trials.parquet and every CSV
/// table identical (`tables` among them). Returns the 1-thread run's folder and its stdout.
fn assert_identical_runs(deck: &str, dir: &Path, trials: u64, chunk: u64, tables: &[&str]) -> (PathBuf, String) {
    assert_identical_runs_of(Path::new(env!("CARGO_BIN_EXE_fdimc")), deck, dir, trials, chunk, tables)
}

/// [`assert_identical_runs`] with the binary `bin` and `--trials trials`.
fn assert_identical_runs_of(
    bin: &Path,
    deck: &str,
    dir: &Path,
    trials: u64,
    chunk: u64,
    tables: &[&str],
) -> (PathBuf, String) {
    let path = |n: &str| dir.join(n);
    let s = |p: PathBuf| p.to_str().unwrap().to_string();
    let fdimc = |args: &[&str]| run_binary(bin, args);
    let n = trials.to_string();
    let run = |extra: &[&str], out: &str| {
        let out = s(path(out));
        let mut args = vec!["run", deck, "--trials", n.as_str(), "--out", out.as_str()];
        args.extend_from_slice(extra);
        fdimc(&args)
    };
    // --verbose: callers read the per-detector table (the details behind the answer).
    let one = ok(&run(&["--threads", "1", "--verbose"], "one"));
    assert!(one.contains(&format!("trials 0..{trials} of {trials} ({trials} run, 0 resumed)")), "{one}");
    ok(&run(&["--threads", "2"], "two"));
    ok(&run(&["--shard", "1/2"], "s1"));
    ok(&run(&["--shard", "0/2", "--threads", "1"], "s0"));
    ok(&fdimc(&["merge", &s(path("s1")), &s(path("s0")), "--out", &s(path("merged"))]));
    let stopped = ok(&run(&["--stop-after", "1"], "resumed"));
    assert!(stopped.contains("continue with the same command and --resume"), "{stopped}");
    let stray = format!(".part-{chunk:020}.parquet.tmp-1");
    std::fs::write(path("resumed").join("parts").join(stray), b"PAR1 junk").unwrap();
    let resumed = ok(&run(&["--resume"], "resumed"));
    assert!(resumed.contains(&format!("({} run, {chunk} resumed)", trials - chunk)), "{resumed}");
    // --low-disk, killed while assembling trials.parquet: the first part already appended and removed,
    // a half-written file left under a temporary name. The resume flies that part's trials again.
    ok(&run(&["--stop-after", "1", "--low-disk"], "low"));
    std::fs::remove_file(path("low").join("parts").join(format!("part-{:020}.parquet", 0))).unwrap();
    std::fs::write(path("low").join(".trials.parquet.tmp-1"), b"PAR1 half").unwrap();
    let low = ok(&run(&["--resume", "--low-disk", "--threads", "1"], "low"));
    assert!(low.contains(&format!("({trials} run, 0 resumed)")), "{low}");
    let left: Vec<_> = std::fs::read_dir(path("low")).unwrap().flatten().map(|e| e.file_name()).collect();
    assert!(!left.iter().any(|n| n.to_string_lossy().contains(".tmp-")), "{left:?}");
    let reference = read_frame(&path("one").join("trials.parquet"));
    for other in ["two", "merged", "resumed", "low"] {
        let df = read_frame(&path(other).join("trials.parquet"));
        assert!(reference.equals_missing(&df), "{other} differs from the 1-thread run");
    }
    // Every table of the run, not only those the caller names (which must be among them).
    let written = csv_tables(&path("one"));
    assert!(tables.iter().all(|t| written.iter().any(|w| w == t)), "{tables:?} among {written:?}");
    assert_eq!(written, csv_tables(&path("merged")), "the merged run's tables");
    for table in &written {
        let a = std::fs::read_to_string(path("one").join(table)).unwrap();
        assert_eq!(a, std::fs::read_to_string(path("merged").join(table)).unwrap(), "{table}");
    }
    (path("one"), one)
}

/// The names of the CSV tables directly in `dir`, sorted.
fn csv_tables(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".csv"))
        .collect();
    names.sort();
    names
}

/// The checks every kind passes, generated from the registry so that a kind is covered by adding it
/// there (a kind added from outside the crate runs them through its own binary): its CI deck (the
/// starter `fdimc new` writes) passes its committed baseline `results/baselines/<deck>.csv`, and its
/// records and every table are identical at 1 and 2 threads, as two merged shards, and stopped after
/// its first part file then resumed, over a part file and a quarter.
fn shared_checks(bin: &Path, deck: &str, baseline: &str, dir: &Path) {
    let check = ok(&run_binary(bin, &["check", deck, "--baseline", baseline, "--threads", "2"]));
    assert!(check.contains(": 0 regression(s)") && !check.contains("REGRESSION"), "{deck}: {check}");
    // The kind's part-file size, from a one-trial run's manifest.
    let probe = dir.join("probe");
    ok(&run_binary(bin, &["run", deck, "--trials", "1", "--quiet", "--out", probe.to_str().unwrap()]));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(probe.join("manifest.json")).unwrap()).unwrap();
    let chunk = manifest["chunk_trials"].as_u64().unwrap();
    let tables = ["summary.csv", "detectors.csv"];
    let (one, _) = assert_identical_runs_of(bin, deck, dir, chunk + chunk.div_ceil(4), chunk, &tables);
    assert_replay_repeats_the_trials(&one);
    assert_the_answer_counts_the_fault_free_flights(&one);
}

/// `answer.csv`'s false-alarm probability is over the fault-free flights, whatever the kind names
/// them (the classifiers' class `normal`): per detector, the records' fault-free rows that flew.
fn assert_the_answer_counts_the_fault_free_flights(dir: &Path) {
    let records = read_frame(&dir.join("trials.parquet"));
    let det = records.column("detector").unwrap().str().unwrap().clone();
    let failure = records.column("failure").unwrap().str().unwrap().clone();
    let fault_free = records.column("fault_free").unwrap().bool().unwrap().clone();
    let answer = csv_frame(&dir.join("answer.csv"));
    let names = answer.column("detector").unwrap().str().unwrap().clone();
    let flights = answer.column("fault_free_flights").unwrap().cast(&polars::prelude::DataType::UInt64).unwrap();
    let flights = flights.u64().unwrap();
    for (name, counted) in names.iter().zip(flights.iter()) {
        let flown = (0..records.height())
            .filter(|&i| det.get(i) == name && fault_free.get(i) == Some(true) && failure.get(i).is_none())
            .count() as u64;
        assert!(flown > 0, "{}: the deck flies fault-free trials", dir.display());
        assert_eq!(counted, Some(flown), "{}: answer.csv's fault-free flights of {name:?}", dir.display());
    }
}

/// A kind that records a detection statistic: replayed at the deck's own thresholds, the recorded
/// statistics give exactly the alarms the trials recorded, row by row (a false alarm when a pre-onset
/// maximum exceeds its threshold, a detection when a first-passage profile does within the detection
/// window).
fn assert_replay_repeats_the_trials(dir: &Path) {
    use polars::prelude::*;
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    let records = read_frame(&dir.join("trials.parquet"));
    let statistics: Vec<String> =
        records.get_column_names().iter().filter_map(|c| c.strip_prefix("pre_max_").map(str::to_string)).collect();
    if statistics.is_empty() {
        return;
    }
    let detectors: Vec<String> =
        manifest["detectors"].as_array().unwrap().iter().map(|d| d.as_str().unwrap().to_string()).collect();
    let thresholds: Vec<Vec<f64>> = manifest["deck_thresholds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect())
        .collect();
    assert_eq!(thresholds.len(), detectors.len(), "{}: the deck's thresholds of every detector", dir.display());
    let det = records.column("detector").unwrap().str().unwrap().clone();
    let failure = records.column("failure").unwrap().str().unwrap().clone();
    let fault_free = records.column("fault_free").unwrap().bool().unwrap().clone();
    let (false_alarm, detected) = (
        records.column("false_alarm").unwrap().bool().unwrap().clone(),
        records.column("detected").unwrap().bool().unwrap().clone(),
    );
    let pre: Vec<Float64Chunked> =
        statistics.iter().map(|s| records.column(&format!("pre_max_{s}")).unwrap().f64().unwrap().clone()).collect();
    let profiles: Vec<ListChunked> =
        statistics.iter().map(|s| records.column(&format!("fp_v_{s}")).unwrap().list().unwrap().clone()).collect();
    let times: Vec<ListChunked> =
        statistics.iter().map(|s| records.column(&format!("fp_t_s_{s}")).unwrap().list().unwrap().clone()).collect();
    let onset = records.column("onset_s").unwrap().f64().unwrap().clone();
    let window_s = manifest["detection_window_s"].as_f64().unwrap_or(f64::INFINITY);
    let mut replayed = 0;
    for i in 0..records.height() {
        if failure.get(i).is_some() {
            continue;
        }
        let d = detectors.iter().position(|x| Some(x.as_str()) == det.get(i)).unwrap();
        let th = &thresholds[d];
        let fa = (0..statistics.len()).any(|j| pre[j].get(i).is_some_and(|v| v > th[j]));
        assert_eq!(Some(fa), false_alarm.get(i), "{}: row {i}: false alarm", dir.display());
        if fault_free.get(i) != Some(true) {
            // Above the threshold within the detection window (the profile rises, so any such point).
            let t0 = onset.get(i).unwrap();
            let hit = (0..statistics.len()).any(|j| {
                let (Some(v), Some(t)) = (profiles[j].get_as_series(i), times[j].get_as_series(i)) else {
                    return false;
                };
                let (v, t) = (v.f64().unwrap().clone(), t.f64().unwrap().clone());
                v.iter().zip(t.iter()).any(|(v, t)| v.unwrap() > th[j] && t.unwrap() - t0 <= window_s)
            });
            assert_eq!(Some(hit), detected.get(i), "{}: row {i}: detection", dir.display());
        }
        replayed += 1;
    }
    assert!(replayed > 0);
}

#[test]
fn every_registered_kind_passes_the_shared_checks() {
    for method in fdimc::methods::REGISTRY {
        let deck = method.starter.0;
        let stem = Path::new(deck).file_stem().unwrap().to_str().unwrap();
        let tmp = tempfile::tempdir().unwrap();
        shared_checks(
            Path::new(env!("CARGO_BIN_EXE_fdimc")),
            deck,
            &format!("results/baselines/{stem}.csv"),
            tmp.path(),
        );
    }
}

/// `examples/custom_method.rs`, a kind of its own on fdimc's command line: validate, run, summarize at
/// another Pfa, check, report, and the checks every registered kind passes.
#[test]
fn a_kind_added_from_outside_the_crate_runs_every_command() {
    // `cargo test` builds the examples beside the test binaries' folder.
    let exe = std::env::current_exe().unwrap();
    let bin = exe.parent().unwrap().parent().unwrap().join("examples").join("custom_method");
    assert!(bin.exists(), "{} (built by cargo test)", bin.display());
    let deck = "examples/random_walk.toml";
    let run = |args: &[&str]| run_binary(&bin, args);
    let valid = ok(&run(&["validate", deck]));
    assert!(valid.contains("detector    cusum_fast: two-sided CUSUM, drift 1, threshold 8.5"), "{valid}");
    // Its decks are its own: fdimc's binary does not know the kind, and names the kinds it does know.
    let foreign = fdimc(&["validate", deck]);
    assert_eq!(foreign.status.code(), Some(2));
    assert!(text(&foreign.stderr).contains("no kind of study matches"), "{}", text(&foreign.stderr));
    let help = ok(&run(&["new", "--help"]));
    assert!(help.contains("random_walk"), "{help}");
    assert!(ok(&run(&["--help"])).contains(
        "Exit codes: 0 ok, 1 regression found (check), thresholds not confirmed (flight-thresholds) or a case failed (verify), 2 invalid input"
    ));

    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let d = dir.to_str().unwrap();
    let stdout = ok(&run(&["run", deck, "--out", d]));
    assert!(stdout.starts_with("random_walk: trials 0..2000 of 2000"), "{stdout}");
    let records = read_frame(&dir.join("trials.parquet"));
    assert_eq!(records.height(), 2 * 2000, "one row per trial and detector");
    // The recorded statistic replays the alarms: at the deck's thresholds, calibrated at 1 %.
    let thresholds = csv_frame(&dir.join("thresholds.csv"));
    // Per detector its statistic's row and the whole detector's; 575 fault-free flights allow 5 alarms at 1 %.
    assert_eq!(thresholds.height(), 4, "{thresholds}");
    assert_eq!(thresholds.column("statistic_false_alarms").unwrap().i64().unwrap().get(0), Some(5), "{thresholds}");
    ok(&run(&["summarize", d, "--target-pfa", "0.05"]));
    let recalibrated = csv_frame(&dir.join("calibrations/pfa_0.05/thresholds.csv"));
    let pfa = recalibrated.column("statistic_pfa").unwrap().f64().unwrap().get(0).unwrap();
    assert!(pfa > 0.02 && pfa <= 0.05, "{pfa}");
    ok(&run(&["summarize", d]));
    let report = ok(&run(&["report", d, "--trials", "3"]));
    assert!(dir.join("report/report.html").exists() && dir.join("report/trace_trial3.svg").exists(), "{report}");
    let trace = std::fs::read_to_string(dir.join("report/trace_trial3.svg")).unwrap();
    assert!(trace.contains("CUSUM statistics") && trace.contains("cusum_fast_statistic"));

    // Its committed baseline (written by this example's run of the deck) holds it as fdimc's own
    // baselines hold theirs.
    shared_checks(&bin, deck, "examples/random_walk_baseline.csv", &tmp.path().join("shared"));
}

/// A surface study (a small copy of the Monte Carlo deck): a row per trial and bank, `simulate --trial`,
/// the regression check, the report and a recalibration at another Pfa.
#[test]
fn a_surface_study_records_each_bank_replays_a_trial_and_recalibrates_apart() {
    let tmp = tempfile::tempdir().unwrap();
    let deck = small_surface_deck(tmp.path());
    let deck = deck.to_str().unwrap();
    let dir = |n: &str| tmp.path().join(n);
    let s = |p: PathBuf| p.to_str().unwrap().to_string();
    let (one_dir, one) = one_run(deck, tmp.path(), 130);
    assert!(one.contains("x 4 detector(s)"), "{one}");
    for bank in ["emmae", "ekf_fast", "stmmae", "improved_stmmae"] {
        assert_eq!(one.lines().filter(|l| l.starts_with(&format!("    deck       {bank} "))).count(), 1, "{one}");
    }
    let reference = read_frame(&one_dir.join("trials.parquet"));
    assert_eq!(reference.height(), 130 * 4, "one row per trial and bank: one fault window per faulty trial");
    assert_eq!(csv_frame(&dir("one").join("detectors.csv")).height(), 2 * 4, "deck and calibrated holds");
    assert_eq!(
        csv_frame(&dir("one").join("comparison.csv")).height(),
        2 * 6,
        "every pair of the four variants, per set"
    );

    // `simulate --trial N` flies trial N of the run: the same declaration delay.
    use polars::prelude::*;
    let row = reference
        .clone()
        .lazy()
        .filter(col("detector").eq(lit("improved_stmmae")).and(col("detected").eq(lit(true))))
        .first()
        .collect()
        .unwrap();
    let trial = row.column("trial").unwrap().u64().unwrap().get(0).unwrap();
    let delay = row.column("delay_s").unwrap().f64().unwrap().get(0).unwrap();
    let trace = s(dir("trace.csv"));
    let t = trial.to_string();
    let sim = ok(&fdimc(&["simulate", deck, "--trial", &t, "--detector", "improved_stmmae", "--out", &trace]));
    assert!(sim.contains(&format!(" {delay:.2} ")), "trial {trial}, delay {delay}: {sim}");

    // The regression check reads surface summaries; report refuses them by name.
    let check = ok(&fdimc(&["check", &s(dir("one")), "--baseline", &s(dir("one").join("summary.csv"))]));
    assert!(check.contains(": 0 regression(s)"), "{check}");
    // The report of a surface study: the shared plots, and the trial re-flown with the banks' probabilities.
    assert_report(
        &dir("one"),
        "3",
        &[
            ("delay_improved_stmmae.svg", &["delay after onset (s)"]),
            ("confusion_improved_stmmae.svg", &["true target", "aileron_left"]),
            ("false_alarms_emmae.svg", &["noise scale (bin)"]),
            ("trace_trial3.svg", &["model probabilities", "improved_stmmae_p_no_fault", "surface positions (rad)"]),
            ("clearing_delay.svg", &["Clearing delay after the fault ends", "clearing_delay_s", "improved_stmmae ("]),
            ("post_fault_declarations.svg", &["post_fault_declarations", "emmae ("]),
        ],
    );
    // The banks record their held time: calibrated at another Pfa, written apart, the run's own tables kept.
    let before = std::fs::read_to_string(dir("one").join("summary.csv")).unwrap();
    // 11 fault-free trials resolve Pfa 0.1, not 0.05 (issue 81, item 1: refused, nothing written).
    let refused = fdimc(&["summarize", &s(dir("one")), "--target-pfa", "0.05"]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused.stderr));
    assert!(text(&refused.stderr).contains("11 fault-free trials per detector"), "{}", text(&refused.stderr));
    assert!(!dir("one").join("calibrations/pfa_0.05").exists());
    ok(&fdimc(&["summarize", &s(dir("one")), "--target-pfa", "0.1"]));
    assert_eq!(std::fs::read_to_string(dir("one").join("summary.csv")).unwrap(), before);
    let thresholds = csv_frame(&dir("one").join("calibrations/pfa_0.1/thresholds.csv"));
    let statistic: Vec<&str> = thresholds.column("statistic").unwrap().str().unwrap().iter().flatten().collect();
    assert_eq!(statistic, ["held_s", "all"].repeat(4), "{thresholds}");
}

#[test]
fn records_are_identical_for_any_threads_shards_and_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = |n: &str| tmp.path().join(n);
    let s = |p: PathBuf| p.to_str().unwrap().to_string();
    // 5000 trials: two chunks (4096 + 904), so shards and resume cut through chunk boundaries.
    let run = |extra: &[&str], out: &str| {
        let mut args = vec!["run", CI_DECK, "--trials", "5000", "--out"];
        let out = s(dir(out));
        args.push(&out);
        args.extend_from_slice(extra);
        fdimc(&args)
    };
    ok(&run(&["--threads", "1"], "one"));
    ok(&run(&["--threads", "2"], "two"));
    ok(&run(&["--shard", "1/2"], "s1"));
    ok(&run(&["--shard", "0/2", "--threads", "1"], "s0"));
    ok(&fdimc(&["merge", &s(dir("s1")), &s(dir("s0")), "--out", &s(dir("merged"))]));
    // Interrupted after its first part file, with a half-written part left by the "killed" writer.
    let stopped = ok(&run(&["--stop-after", "1"], "resumed"));
    assert!(stopped.contains("continue with the same command and --resume"), "{stopped}");
    assert!(!dir("resumed").join("trials.parquet").exists());
    std::fs::write(dir("resumed").join("parts").join(".part-00000000000000004096.parquet.tmp-1"), b"PAR1 garbage")
        .unwrap();
    let resumed = ok(&run(&["--resume"], "resumed"));
    assert!(resumed.contains("(904 run, 4096 resumed)"), "{resumed}");

    let reference = read_frame(&dir("one").join("trials.parquet"));
    assert_eq!(reference.height(), 10_000, "one row per trial and detector");
    for other in ["two", "merged", "resumed"] {
        let df = read_frame(&dir(other).join("trials.parquet"));
        assert!(reference.equals_missing(&df), "{other} differs from the 1-thread run");
    }
    // More shards than trials: the empty shards still merge.
    for i in 0..4 {
        ok(&fdimc(&[
            "run",
            CI_DECK,
            "--trials",
            "3",
            "--shard",
            &format!("{i}/4"),
            "--out",
            &s(dir(&format!("tiny{i}"))),
        ]));
    }
    let tiny: Vec<String> = (0..4).map(|i| s(dir(&format!("tiny{i}")))).collect();
    let mut args = vec!["merge"];
    args.extend(tiny.iter().map(String::as_str));
    let merged_tiny = s(dir("tiny"));
    args.extend(["--out", merged_tiny.as_str()]);
    ok(&fdimc(&args));
    assert_eq!(read_frame(&dir("tiny").join("trials.parquet")).height(), 6);
    // A missing, a doubled or a foreign shard is refused, and nothing is written.
    let other = s(dir("other3"));
    ok(&fdimc(&["run", CI_DECK, "--trials", "3", "--seed", "99", "--shard", "3/4", "--out", &other]));
    let grid = s(dir("grid3"));
    ok(&fdimc(&["run", CI_DECK, "--trials", "3", "--profile-resolution", "0", "--shard", "3/4", "--out", &grid]));
    let bad = s(dir("bad"));
    for (shards, want) in [
        (vec![&tiny[0], &tiny[1], &tiny[2]], "need shards 0..4 exactly once each, got [0, 1, 2]"),
        (vec![&tiny[0], &tiny[1], &tiny[1], &tiny[2], &tiny[3]], "got [0, 1, 1, 2, 3]"),
        (
            vec![&tiny[0], &tiny[1], &tiny[2], &other],
            "other3: from another run (deck, seed, trial count, shard count, profile resolution or the profiles",
        ),
        (vec![&tiny[0], &tiny[1], &tiny[2], &grid], "grid3: from another run"),
    ] {
        let mut args = vec!["merge"];
        args.extend(shards.iter().map(|s| s.as_str()));
        args.extend(["--out", bad.as_str()]);
        let out = fdimc(&args);
        assert_eq!(out.status.code(), Some(2), "{shards:?}");
        assert!(text(&out.stderr).contains(want), "{}", text(&out.stderr));
        assert!(!dir("bad").exists(), "a refused merge writes nothing");
    }
    // The summaries agree too.
    let a = std::fs::read_to_string(dir("one").join("summary.csv")).unwrap();
    assert_eq!(a, std::fs::read_to_string(dir("merged").join("summary.csv")).unwrap());
}

/// A run whose stderr is not a terminal (a cluster job's log) still says how far it is: plain lines,
/// here one per finished group of trials (`FDIMC_PROGRESS_EVERY_S=0`); `--quiet` says nothing.
#[test]
fn a_run_without_a_terminal_logs_plain_progress_lines() {
    let tmp = tempfile::tempdir().unwrap();
    let run = |quiet: bool| {
        let out_dir = tmp.path().join(if quiet { "quiet" } else { "loud" });
        let mut args = vec!["run", CI_DECK, "--trials", "600", "--out", out_dir.to_str().unwrap()];
        if quiet {
            args.push("--quiet");
        }
        Command::new(env!("CARGO_BIN_EXE_fdimc"))
            .args(&args)
            .env("FDIMC_PROGRESS_EVERY_S", "0")
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .expect("run fdimc")
    };
    let out = run(false);
    let stderr = text(&out.stderr);
    let lines: Vec<&str> = stderr.lines().filter(|l| l.starts_with("ci_seed000: ")).collect();
    assert!(lines.len() >= 2, "{stderr}");
    assert!(lines.iter().all(|l| l.contains("/600 trials (") && l.contains(" trials/s, about ")), "{stderr}");
    assert!(lines.last().unwrap().starts_with("ci_seed000: 600/600 trials (100 %)"), "{stderr}");
    assert!(!stderr.contains('\r'), "no terminal control in a log");
    let quiet = run(true);
    assert!(text(&quiet.stderr).lines().all(|l| !l.starts_with("ci_seed000: ")), "{}", text(&quiet.stderr));
}

/// `baseline` with every faulty group detected in full (`detected` = flown, `pd` = 1 where a fault was
/// flown), written to `dir`: a reference the current run falls short of.
fn perfect_detection_baseline(baseline: &str, dir: &Path) -> PathBuf {
    use polars::prelude::*;
    let mut base = csv_frame(&Path::new(env!("CARGO_MANIFEST_DIR")).join(baseline));
    let flown = (base.column("trials").unwrap().as_materialized_series()
        - base.column("failed").unwrap().as_materialized_series())
    .unwrap();
    let faulty = base.column("kind").unwrap().str().unwrap().not_equal("none");
    let detected = flown.zip_with(&faulty, base.column("detected").unwrap().as_materialized_series()).unwrap();
    base.with_column(detected.with_name("detected".into()).into_column()).unwrap();
    // The rate follows its counts (check refuses a baseline whose rates do not).
    let pd: Float64Chunked = base.column("pd").unwrap().f64().unwrap().iter().map(|v| v.map(|_| 1.0)).collect();
    base.with_column(pd.with_name("pd".into()).into_column()).unwrap();
    let doctored = dir.join("perfect.csv");
    CsvWriter::new(std::fs::File::create(&doctored).unwrap()).finish(&mut base).unwrap();
    doctored
}

/// The launch and air-data kinds' checks fail too on a baseline they fall short of (a copy of their own
/// with every fault detected), naming the group: a check that could only pass would prove nothing.
#[test]
fn launch_and_air_data_checks_fail_on_a_baseline_they_fall_short_of() {
    let tmp = tempfile::tempdir().unwrap();
    for (deck, baseline, group) in [
        (
            "studies/ci_seed001.toml",
            "results/baselines/ci_seed001.csv",
            "REGRESSION thresholds=deck detector=seed kind=thrust_loss target=engine_4 ",
        ),
        (
            "studies/ci_seed002.toml",
            "results/baselines/ci_seed002.csv",
            "REGRESSION thresholds=deck detector=patent kind=bias target=beta_rad size_bin=3.0 ",
        ),
    ] {
        let dir = tmp.path().join(&deck[8..18]);
        std::fs::create_dir_all(&dir).unwrap();
        let perfect = perfect_detection_baseline(baseline, &dir);
        let out = fdimc(&["check", deck, "--baseline", perfect.to_str().unwrap()]);
        let stdout = text(&out.stdout);
        assert_eq!(out.status.code(), Some(1), "{deck}: {stdout}{}", text(&out.stderr));
        assert!(stdout.contains(group), "{deck}: {stdout}");
    }
}

/// The accelerometer kind detects every fault of its CI deck (Pd 1 in every group), so its check is
/// shown to fail where it can: on a copy of its baseline without false alarms (counts and rates), the
/// normal class's 39 of 50 misclassified trials per classifier are a false-alarm rise, named by group.
#[test]
fn accelerometer_check_fails_on_a_baseline_without_false_alarms() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let base = csv_frame(&Path::new(env!("CARGO_MANIFEST_DIR")).join("results/baselines/ci_seed003.csv"));
    let flown = base.column("pfa").unwrap().is_not_null();
    let zero = |name: &str, value: AnyValue| {
        let c = base.column(name).unwrap().as_materialized_series().clone();
        let zeros = Series::new(name.into(), vec![value; c.len()]).cast(c.dtype()).unwrap();
        zeros.zip_with(&flown, &c).unwrap().into_column()
    };
    let mut doctored = base.clone();
    doctored.with_column(zero("false_alarms", AnyValue::Int64(0))).unwrap();
    doctored.with_column(zero("pfa", AnyValue::Float64(0.0))).unwrap();
    let file = tmp.path().join("no_false_alarms.csv");
    CsvWriter::new(std::fs::File::create(&file).unwrap()).finish(&mut doctored).unwrap();
    let out = fdimc(&["check", "studies/ci_seed003.toml", "--baseline", file.to_str().unwrap()]);
    let stdout = text(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}{}", text(&out.stderr));
    for detector in ["flat", "tree"] {
        let group = format!("REGRESSION thresholds=deck detector={detector} kind=normal ");
        let line = stdout.lines().find(|l| l.starts_with(&group)).unwrap_or_else(|| panic!("{group}: {stdout}"));
        assert!(line.contains("false-alarm rate 0.0000 (0/50) -> 0.7800 (39/50)"), "{line}");
    }
}

/// Raising `pd` in a copy of the baseline, counts untouched, is refused: check compares counts, and
/// would otherwise pass in silence.
#[test]
fn check_refuses_a_baseline_whose_rates_disagree_with_its_counts() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let mut base = csv_frame(&Path::new(env!("CARGO_MANIFEST_DIR")).join("results/baselines/ci_seed000.csv"));
    let pd: Float64Chunked = base.column("pd").unwrap().f64().unwrap().iter().map(|v| v.map(|_| 0.999)).collect();
    base.with_column(pd.with_name("pd".into()).into_column()).unwrap();
    let edited = tmp.path().join("edited.csv");
    CsvWriter::new(std::fs::File::create(&edited).unwrap()).finish(&mut base).unwrap();
    let out = fdimc(&["check", CI_DECK, "--baseline", edited.to_str().unwrap()]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("edited.csv: line ")
            && stderr.contains(" detector=")
            && stderr.contains("): pd = 0.999 but detected / (trials - failed) = "),
        "{stderr}"
    );
}

#[test]
fn check_passes_on_its_baseline_and_flags_a_drop_where_scipy_does() {
    let baseline = "results/baselines/ci_seed000.csv";
    let out = fdimc(&["check", CI_DECK, "--baseline", baseline]);
    let stdout = ok(&out);
    assert!(stdout.contains(": 0 regression(s)") && !stdout.contains("REGRESSION"), "{stdout}");

    // A baseline where every faulty trial was detected: the current detector now misses some.
    let tmp = tempfile::tempdir().unwrap();
    let doctored = perfect_detection_baseline(baseline, tmp.path());
    let run_dir = tmp.path().join("run");
    run_deck(CI_DECK, None, &run_dir);
    let out = fdimc(&["check", run_dir.to_str().unwrap(), "--baseline", doctored.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stdout));
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("REGRESSION thresholds=deck detector=seed kind=bias target=alpha_rad size_bin=1.0 "),
        "{stdout}"
    );
    // Against the true baseline the same folder passes.
    ok(&fdimc(&["check", run_dir.to_str().unwrap(), "--baseline", baseline]));

    // Where the check draws its line, from an independent answer: the group below detects 71 of 188
    // faulty flights; among the 82 tests at family-wise alpha 0.01 (level 1.2195e-4), SciPy's
    // Yates-corrected chi-square (`chi2_contingency(..., correction=True)`, one-sided) gives
    // p = 1.5012e-4 against a baseline of 107 of 188 (no regression) and 1.0065e-4 against 108 (a
    // regression). A check that tested two-sided, without Bonferroni or without the correction would
    // move this line.
    let group = ("deck", "seed", "bias", "alpha_rad", 3.0);
    for (baseline_detected, regression) in [(107u32, false), (108, true)] {
        let edited = baseline_with_detected(baseline, group, baseline_detected, tmp.path());
        let out = fdimc(&["check", run_dir.to_str().unwrap(), "--baseline", edited.to_str().unwrap()]);
        let stdout = text(&out.stdout);
        assert!(stdout.contains("82 tests at family-wise alpha 0.01"), "{stdout}");
        assert_eq!(out.status.code(), Some(if regression { 1 } else { 0 }), "{baseline_detected}: {stdout}");
        let flagged = stdout.lines().filter(|l| l.starts_with("REGRESSION ")).collect::<Vec<_>>();
        if regression {
            assert_eq!(flagged.len(), 1, "{stdout}");
            assert!(
                flagged[0]
                    .starts_with("REGRESSION thresholds=deck detector=seed kind=bias target=alpha_rad size_bin=3.0 ")
                    && flagged[0].contains("detection probability"),
                "{stdout}"
            );
        } else {
            assert!(flagged.is_empty(), "{stdout}");
        }
    }
}

/// `baseline` with one group's detection count set to `detected` (its `pd` following), in `dir`.
fn baseline_with_detected(baseline: &str, group: (&str, &str, &str, &str, f64), detected: u32, dir: &Path) -> PathBuf {
    use polars::prelude::*;
    let mut base = csv_frame(&Path::new(env!("CARGO_MANIFEST_DIR")).join(baseline));
    let (thresholds, detector, kind, target, size) = group;
    let text_is = |c: &str, v: &str| base.column(c).unwrap().str().unwrap().equal(v);
    let mask = text_is("thresholds", thresholds)
        & text_is("detector", detector)
        & text_is("kind", kind)
        & text_is("target", target)
        & base.column("size_bin").unwrap().f64().unwrap().equal(size);
    assert_eq!(mask.sum(), Some(1), "one group {group:?}");
    let row = mask.iter().position(|m| m == Some(true)).unwrap();
    let flown = base.column("trials").unwrap().cast(&DataType::UInt64).unwrap().u64().unwrap().get(row).unwrap()
        - base.column("failed").unwrap().cast(&DataType::UInt64).unwrap().u64().unwrap().get(row).unwrap();
    let set = |c: &Column, v: AnyValue| {
        let s = c.as_materialized_series();
        let fill = Series::new(c.name().clone(), vec![v; s.len()]).cast(s.dtype()).unwrap();
        fill.zip_with(&mask, s).unwrap().into_column()
    };
    let detected_col = set(base.column("detected").unwrap(), AnyValue::UInt32(detected));
    let pd_col = set(base.column("pd").unwrap(), AnyValue::Float64(detected as f64 / flown as f64));
    base.with_column(detected_col).unwrap();
    base.with_column(pd_col).unwrap();
    let file = dir.join(format!("baseline_{detected}.csv"));
    CsvWriter::new(std::fs::File::create(&file).unwrap()).finish(&mut base).unwrap();
    file
}

/// An air-data study (a small copy of the bundled deck): size bins with their edges, `simulate --trial`,
/// the check and the report.
#[test]
fn an_air_data_study_bins_fault_sizes_replays_a_trial_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    // The bundled deck cut to 30 s flights and 300 trials (part files of 256: 256 + 44).
    let deck_path = edited_deck(
        tmp.path(),
        "seed002_air_data.toml",
        &[
            ("duration_s = 60.0", "duration_s = 30.0"),
            ("onset_s = { range = [10.0, 40.0] }", "onset_s = { range = [5.0, 20.0] }"),
            ("trials = 3000", "trials = 300"),
        ],
        "small_air_data.toml",
    );
    let deck = deck_path.to_str().unwrap();
    let s = |p: PathBuf| p.to_str().unwrap().to_string();
    let (one, stdout) = one_run(deck, tmp.path(), 300);
    // Size bins carry their edges: the deck's 2-20 sigma in 3 bins of 6.
    let summary = csv_frame(&one.join("summary.csv"));
    let f = |name: &str| summary.column(name).unwrap().f64().unwrap().clone();
    let (centre, lo, hi) = (f("size_bin"), f("size_bin_lo"), f("size_bin_hi"));
    let kind = summary.column("kind").unwrap().str().unwrap().clone();
    let mut binned = 0;
    for i in (0..summary.height()).filter(|&i| kind.get(i) == Some("bias")) {
        let c = centre.get(i).unwrap();
        assert!([5.0, 11.0, 17.0].contains(&c), "row {i}: centre {c}");
        assert_eq!((lo.get(i), hi.get(i)), (Some(c - 3.0), Some(c + 3.0)), "row {i}");
        binned += 1;
    }
    assert!(binned >= 3, "{binned} bias rows");
    for detector in ["patent", "patent_wald", "window10"] {
        assert_eq!(
            stdout.lines().filter(|l| l.starts_with(&format!("    deck       {detector} "))).count(),
            1,
            "{stdout}"
        );
    }
    let reference = read_frame(&one.join("trials.parquet"));
    assert_eq!(reference.height(), 300 * 3, "one row per trial and detector");
    assert_eq!(csv_frame(&one.join("detectors.csv")).height(), 2 * 3, "deck and calibrated holds");
    assert_eq!(csv_frame(&one.join("comparison.csv")).height(), 2 * 3, "one row per pair of detectors and set");

    // `simulate --trial N` flies trial N of the run: the same detection delay and isolated set.
    use polars::prelude::*;
    let row = reference
        .clone()
        .lazy()
        .filter(col("detector").eq(lit("patent")).and(col("faulty_sensors").eq(lit(2u32))).and(col("detected")))
        .first()
        .collect()
        .unwrap();
    let trial = row.column("trial").unwrap().u64().unwrap().get(0).unwrap().to_string();
    let delay = row.column("delay_s").unwrap().f64().unwrap().get(0).unwrap();
    let isolated = row.column("isolated").unwrap().str().unwrap().get(0).unwrap().to_string();
    let trace = s(tmp.path().join("trace.parquet"));
    let sim = ok(&fdimc(&["simulate", deck, "--trial", &trial, "--detector", "patent", "--out", &trace]));
    assert!(sim.contains(&format!("delay {delay:.2} s, isolated {isolated},")), "trial {trial}: {sim}");
    assert!(
        sim.contains("airspeed_mps+alpha_rad bias ") && sim.contains("(multiples of the sensor sigma) from"),
        "{sim}"
    );
    let df = read_frame(Path::new(&trace));
    assert_eq!(df.height(), 3000);
    assert_eq!(df.width(), 1 + 8 + 2 * 3 + 1 + 1 + 3 * 4, "time, inertial, air data and truth, one detector");

    let check = ok(&fdimc(&["check", &s(one.clone()), "--baseline", &s(one.join("summary.csv"))]));
    assert!(check.contains(": 0 regression(s)"), "{check}");
    assert_report(
        &one,
        "3",
        &[
            ("delay_patent.svg", &["delay after onset (s)"]),
            ("confusion_patent.svg", &["true target", "airspeed_mps"]),
            ("false_alarms_window10.svg", &["parameter error bin 0"]),
            ("trace_trial3.svg", &["airspeed (m/s)", "patent_airspeed_mps_estimate", "airspeed_mps_true", "P(fault)"]),
            ("air_data_error.svg", &["y = x", "raw_rms_sigma", "estimate_rms_sigma", "window10 ("]),
        ],
    );
}

/// A launch study (a small copy of the thrust-loss deck): calibrated thresholds, `simulate --trial`, a
/// recalibration written apart and the report.
#[test]
fn a_launch_study_calibrates_replays_a_trial_and_recalibrates_apart() {
    let tmp = tempfile::tempdir().unwrap();
    // The bundled deck cut to 30 s flights and 150 trials (part files of 128: 128 + 22).
    let deck_path = edited_deck(
        tmp.path(),
        "seed001_thrust.toml",
        &[
            ("duration_s = 90.0", "duration_s = 30.0"),
            ("onset_s = { range = [15.0, 75.0] }", "onset_s = { range = [5.0, 20.0] }"),
            ("trials = 2000", "trials = 150"),
            ("start_s = 40.0", "start_s = 10.0"),
            ("start_s = 50.0", "start_s = 15.0"),
            ("threshold_fhat = 1.3e-5", "threshold_fhat = 1.3e-5\nloss_fit_onsets_s = [10.0, 20.0]"),
            ("loss_fit_onsets_s = [15.0, 30.0, 45.0, 60.0, 75.0]", "loss_fit_onsets_s = [10.0, 20.0]"),
            ("loss_fit_noisy_flights = 4", "loss_fit_noisy_flights = 2"),
        ],
        "small_launch.toml",
    );
    let deck = deck_path.to_str().unwrap();
    let s = |p: PathBuf| p.to_str().unwrap().to_string();
    let (one, stdout) = one_run(deck, tmp.path(), 150);
    assert!(stdout.contains("    seed: calibrated [fhat ") && stdout.contains("(deck [fhat 1.300e-5])"), "{stdout}");
    let reference = read_frame(&one.join("trials.parquet"));
    assert_eq!(reference.height(), 300, "one row per trial and detector");
    assert_eq!(csv_frame(&one.join("detectors.csv")).height(), 4, "deck and calibrated thresholds, two detectors");

    // `simulate --trial N` flies trial N of the run: the same delay and engine.
    use polars::prelude::*;
    let row = reference.clone().lazy().filter(col("isolated_correctly").eq(lit(true))).first().collect().unwrap();
    let trial = row.column("trial").unwrap().u64().unwrap().get(0).unwrap().to_string();
    let delay = row.column("delay_s").unwrap().f64().unwrap().get(0).unwrap();
    let engine = row.column("target").unwrap().str().unwrap().get(0).unwrap().replace('_', " ");
    let trace = s(tmp.path().join("trace.parquet"));
    let sim = ok(&fdimc(&["simulate", deck, "--trial", &trial, "--out", &trace]));
    assert!(sim.contains(&format!("delay {delay:.2} s, localised {engine},")), "trial {trial}: {sim}");
    let frame = read_frame(Path::new(&trace));
    assert_eq!(frame.height(), 3000);
    // |fhat| over the deck threshold passes 1 in a detected flight, exactly where the alarm is set.
    let over: Vec<f64> = frame.column("seed_fhat_over_threshold").unwrap().f64().unwrap().into_no_null_iter().collect();
    let alarm = frame.column("seed_alarm").unwrap().cast(&DataType::Float64).unwrap();
    let alarm: Vec<bool> = alarm.f64().unwrap().into_no_null_iter().map(|a| a == 1.0).collect();
    assert!(over.iter().any(|&o| o >= 1.0));
    assert!(over.iter().zip(&alarm).all(|(&o, &a)| (o >= 1.0) == a));

    assert_report(
        &one,
        "3",
        &[
            ("roc.svg", &["seed calibrated: Pfa"]),
            ("delay_seed.svg", &["thrust_loss ("]),
            ("confusion_seed.svg", &["engine_1", "true target"]),
            ("trace_trial3.svg", &["estimated fault fhat", "seed_fhat", "thrust_true_n", "seed_fhat_over_threshold"]),
            ("loss_error.svg", &["y = 0", "loss_error_percent", "true fault size (percent of one engine", "seed ("]),
        ],
    );
    // Thresholds recalibrated at another false-alarm probability: a fifth of the flights may alarm. The
    // calibration is written apart, every table saying its target; the run's own tables stay.
    let own = std::fs::read(one.join("summary.csv")).unwrap();
    let stdout = ok(&fdimc(&["summarize", &s(one.clone()), "--target-pfa", "0.2"]));
    let apart = one.join("calibrations/pfa_0.2");
    assert!(stdout.contains(&format!("in {}", apart.display())), "{stdout}");
    let thresholds = csv_frame(&apart.join("thresholds.csv"));
    let pfa = thresholds.column("statistic_pfa").unwrap().f64().unwrap().get(0).unwrap();
    let source = thresholds.column("source").unwrap().str().unwrap().get(0).unwrap().to_string();
    assert_eq!(source, "calibrated at Pfa 0.2 on the fault-free trials");
    assert!(pfa > 0.1 && pfa <= 0.2, "{pfa}");
    for table in ["summary.csv", "curves.csv", "min_detectable.csv", "detectors.csv"] {
        let t = csv_frame(&apart.join(table));
        let (set, target) = (t.column("thresholds").unwrap().str().unwrap(), t.column("target_pfa").unwrap());
        let target = target.cast(&polars::prelude::DataType::Float64).unwrap();
        for i in 0..t.height() {
            let want = (set.get(i) != Some("deck")).then_some(0.2);
            assert_eq!(target.f64().unwrap().get(i), want, "{table} row {i}");
        }
    }
    assert_eq!(std::fs::read(one.join("summary.csv")).unwrap(), own, "the run's own summary is untouched");
    // The deck's own target on too few trials stands, labelled for what it is (issue 81, item 1).
    let thresholds = csv_frame(&one.join("thresholds.csv"));
    let source = thresholds.column("source").unwrap().str().unwrap().get(0).unwrap().to_string();
    assert_eq!(
        source,
        "not calibrated at Pfa 0.01: 29 fault-free trials cannot resolve it (needs >= 100); the thresholds of \
         seed, seed_noisy_table are the largest values seen"
    );
    // check refuses to compare rates calibrated at another target, and says why.
    let out = fdimc(&["check", &s(apart.clone()), "--baseline", &s(one.join("summary.csv"))]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stdout));
    assert!(
        text(&out.stderr).contains("calibrated thresholds are at Pfa 0.2, the baseline's at Pfa 0.01"),
        "{}",
        text(&out.stderr)
    );
    ok(&fdimc(&["check", &s(one.clone()), "--baseline", &s(one.join("summary.csv"))]));
    // The report shows the run's own calibration.
    ok(&fdimc(&["report", &s(one.clone())]));
    let html = std::fs::read_to_string(one.join("report/report.html")).unwrap();
    assert!(html.contains("<tr><th>target Pfa</th><td>0.01</td></tr>"), "{html}");
}

#[test]
fn accelerometer_classifiers_train_save_and_load_to_the_same_records() {
    let tmp = tempfile::tempdir().unwrap();
    // The CI deck cut to 600 trials (part files of 512: 512 + 88) and 40 training trials per class.
    let deck_path = edited_deck(
        tmp.path(),
        "ci_seed003.toml",
        &[("trials = 400", "trials = 600"), ("trials_per_class = 80", "trials_per_class = 40")],
        "small_accelerometer.toml",
    );
    let deck = deck_path.to_str().unwrap();
    let s = |p: PathBuf| p.to_str().unwrap().to_string();
    // The shared checks' runs each train in their own process: identical records there say the
    // training is deterministic.
    let (one, stdout) = one_run(deck, tmp.path(), 600);
    for name in ["tree", "flat"] {
        assert_eq!(stdout.lines().filter(|l| l.starts_with(&format!("    {name}  Pfa "))).count(), 1, "{stdout}");
        assert!(stdout.contains(&format!("  confusion ({name}): rows the true class")), "{stdout}");
    }
    let reference = read_frame(&one.join("trials.parquet"));
    assert_eq!(reference.height(), 600 * 2, "one row per trial and classifier");
    // Every classified trial once per classifier, in its true class's row.
    let confusion = csv_frame(&one.join("confusion.csv"));
    let units: u64 = confusion
        .column("units")
        .unwrap()
        .cast(&polars::prelude::DataType::UInt64)
        .unwrap()
        .u64()
        .unwrap()
        .sum()
        .unwrap();
    let failed = reference.column("failure").unwrap().is_not_null().sum().unwrap() as u64;
    assert_eq!(units, 600 * 2 - failed);
    assert!(confusion.height() <= 2 * 16);
    // Two classifiers x the deck's and the calibrated thresholds of the residual detector.
    assert_eq!(csv_frame(&one.join("detectors.csv")).height(), 4);

    // `fdimc train` writes the classifiers the run trained; a run with them gives the same records.
    let file = s(tmp.path().join("classifiers.json"));
    let trained = ok(&fdimc(&["train", deck, "--out", &file]));
    assert!(trained.contains("merge 1: ") && trained.contains("merge 3: "), "{trained}");
    assert_eq!(std::fs::read(&file).unwrap(), std::fs::read(one.join("classifiers.json")).unwrap());
    let loaded = s(tmp.path().join("loaded"));
    ok(&fdimc(&["run", deck, "--classifiers", &file, "--out", &loaded]));
    assert!(reference.equals_missing(&read_frame(&Path::new(&loaded).join("trials.parquet"))));
    // Classifiers of other features (another sample period) are refused, not applied.
    let coarse = edited_deck(tmp.path(), "ci_seed003.toml", &[("dt_s = 0.01", "dt_s = 0.02")], "coarse.toml");
    let out = fdimc(&["run", coarse.to_str().unwrap(), "--classifiers", &file, "--out", &s(tmp.path().join("c"))]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("classifiers.json: trained for \"ci_seed003\" on windows of 100 samples every 0.01 s, but ")
            && stderr.contains("coarse.toml computes windows of 100 samples every 0.02 s: train for this deck"),
        "{stderr}"
    );
    assert!(!tmp.path().join("c").join("trials.parquet").exists());

    // `simulate --trial N` classifies trial N as the run did.
    use polars::prelude::*;
    let row = reference
        .clone()
        .lazy()
        .filter(col("detector").eq(lit("tree")).and(col("kind").eq(lit("gain"))))
        .first()
        .collect()
        .unwrap();
    let trial = row.column("trial").unwrap().u64().unwrap().get(0).unwrap().to_string();
    let predicted = row.column("isolated").unwrap().str().unwrap().get(0).unwrap().to_string();
    let trace = s(tmp.path().join("trace.csv"));
    let sim = ok(&fdimc(&["simulate", deck, "--trial", &trial, "--classifiers", &file, "--out", &trace]));
    let tree_line = sim.lines().find(|l| l.trim_start().starts_with("tree ")).unwrap_or_else(|| panic!("{sim}"));
    assert!(
        sim.contains("class gain") && tree_line.ends_with(&format!("(onset window) predicts {predicted}")),
        "{sim}"
    );
    assert_eq!(csv_frame(Path::new(&trace)).height(), 2000);

    // An --out under a regular file is refused before training, naming it (exit 2).
    let under_file = s(tmp.path().join("classifiers.json").join("x.json"));
    let out = fdimc(&["train", deck, "--out", &under_file]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains(&format!("--out {under_file}: cannot create the folder")),
        "{}",
        text(&out.stderr)
    );
    // A file that is not classifiers is the user's error, named.
    std::fs::write(tmp.path().join("junk.json"), "{}").unwrap();
    let out =
        fdimc(&["run", deck, "--classifiers", &s(tmp.path().join("junk.json")), "--out", &s(tmp.path().join("x"))]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("junk.json: not classifiers written by `fdimc train`"), "{}", text(&out.stderr));
    assert!(!tmp.path().join("x").exists(), "nothing written for a refused run");
    assert_report(
        &one,
        "3",
        &[
            ("confusion_tree.svg", &["true target", "stuck"]),
            ("delay_tree.svg", &["delay after onset (s)"]),
            ("trace_trial3.svg", &["detection statistic", "residual_x"]),
        ],
    );
}

#[test]
fn surface_check_passes_on_its_baseline_and_fails_on_a_detection_drop() {
    let baseline = "results/baselines/ci_seed004.csv";
    let tmp = tempfile::tempdir().unwrap();
    let run_dir = tmp.path().join("run");
    run_deck("studies/ci_seed004.toml", None, &run_dir);
    let stdout = ok(&fdimc(&["check", run_dir.to_str().unwrap(), "--baseline", baseline]));
    assert!(stdout.contains(": 0 regression(s)") && !stdout.contains("REGRESSION"), "{stdout}");

    // A baseline in which every fault was detected, the 2 deg ones near trim too: they now are not.
    let doctored = perfect_detection_baseline(baseline, tmp.path());
    let out = fdimc(&["check", run_dir.to_str().unwrap(), "--baseline", doctored.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stdout));
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains(
            "REGRESSION thresholds=deck detector=emmae kind=stuck target=aileron_left size_bin=2.0 noise_bin=1.0 \
             param_error_bin=0.0: detection probability"
        ),
        "{stdout}"
    );
    assert!(!stdout.contains("size_bin=-15.0 "), "the large faults are detected as in the baseline: {stdout}");
}

#[test]
fn thresholds_calibrated_on_one_seed_validate_on_another() {
    let tmp = tempfile::tempdir().unwrap();
    let cal = tmp.path().join("cal");
    let val = tmp.path().join("val");
    run_deck(CI_DECK, None, &cal);
    ok(&fdimc(&["run", CI_DECK, "--quiet", "--seed", "12", "--out", val.to_str().unwrap()]));
    let own = std::fs::read(val.join("thresholds.csv")).unwrap();
    let own_summary = std::fs::read(val.join("summary.csv")).unwrap();
    let cal_thr = cal.join("thresholds.csv");
    let stdout =
        ok(&fdimc(&["--verbose", "summarize", val.to_str().unwrap(), "--thresholds", cal_thr.to_str().unwrap()]));
    assert!(
        stdout.contains("thresholds from") && stdout.contains("(calibrated at Pfa 0.01), validated on"),
        "{stdout}"
    );
    assert!(stdout.contains("    seed: applied [") && stdout.contains("on this run's trials"), "{stdout}");
    assert!(stdout.contains("    validation seed "), "the set is labelled validation: {stdout}");
    // Written apart: the run's own tables are untouched.
    assert_eq!(std::fs::read(val.join("thresholds.csv")).unwrap(), own);
    assert_eq!(std::fs::read(val.join("summary.csv")).unwrap(), own_summary);
    let validation = val.join("validation");
    let sets = csv_frame(&validation.join("summary.csv"));
    let sets = sets.column("thresholds").unwrap().str().unwrap().clone();
    assert!(
        sets.iter().all(|v| matches!(v, Some("deck" | "validation"))) && sets.iter().any(|v| v == Some("validation"))
    );
    let all_rows = |path: &Path| -> std::collections::HashMap<String, (f64, f64)> {
        let t = csv_frame(path);
        let col = |c: &str| t.column(c).unwrap().clone();
        let (det, out, lo, hi) = (col("detector"), col("statistic"), col("detector_pfa_lo"), col("detector_pfa_hi"));
        let (det, out, lo, hi) = (det.str().unwrap(), out.str().unwrap(), lo.f64().unwrap(), hi.f64().unwrap());
        (0..t.height())
            .filter(|&i| out.get(i) == Some("all"))
            .map(|i| (det.get(i).unwrap().to_string(), (lo.get(i).unwrap(), hi.get(i).unwrap())))
            .collect()
    };
    let cal_all = all_rows(&cal_thr);
    let t = csv_frame(&validation.join("thresholds.csv"));
    let det = t.column("detector").unwrap().str().unwrap().clone();
    let out = t.column("statistic").unwrap().str().unwrap().clone();
    let (lo, hi) = (
        t.column("detector_pfa_lo").unwrap().f64().unwrap().clone(),
        t.column("detector_pfa_hi").unwrap().f64().unwrap().clone(),
    );
    let n = t.column("trials").unwrap().i64().unwrap().clone();
    // Per-statistic rows count each statistic alone; only the `all` row holds the detector's count.
    let alone = t.column("statistic_false_alarms").unwrap().i64().unwrap().clone();
    let whole = t.column("detector_false_alarms").unwrap().i64().unwrap().clone();
    let mut seen = 0;
    for i in 0..t.height() {
        let is_all = out.get(i) == Some("all");
        assert_eq!((alone.get(i).is_none(), whole.get(i).is_some()), (is_all, is_all), "row {i}");
        if is_all {
            seen += 1;
            // About 900 fresh fault-free trials. The calibration's Pfa is itself an estimate from
            // about 9 alarms (its interval, about [0.005, 0.018]); the validation rate must agree
            // with it: the two intervals overlap.
            assert!(n.get(i).unwrap() > 800);
            let (cal_lo, cal_hi) = cal_all[&det.get(i).unwrap().to_string()];
            assert!(cal_lo <= 0.01 && 0.01 <= cal_hi, "calibration interval [{cal_lo}, {cal_hi}]");
            assert!(
                lo.get(i).unwrap() <= cal_hi && cal_lo <= hi.get(i).unwrap(),
                "row {i}: [{:?}, {:?}] against the calibration's [{cal_lo}, {cal_hi}]",
                lo.get(i),
                hi.get(i)
            );
        }
    }
    assert_eq!(seen, 2, "one whole-detector row per detector");
    // Thresholds that claim a target the fresh trials contradict are flagged (here a file edited to
    // say 0.3: about 1 % of the trials alarm).
    let claimed = tmp.path().join("claimed.csv");
    let edited = std::fs::read_to_string(&cal_thr).unwrap().replace(",0.01,,calibrated at", ",0.3,,calibrated at");
    std::fs::write(&claimed, edited).unwrap();
    let stdout = ok(&fdimc(&["summarize", val.to_str().unwrap(), "--thresholds", claimed.to_str().unwrap()]));
    assert!(
        stdout.contains("warning: detector seed: the thresholds of") && stdout.contains("were calibrated for Pfa 0.3"),
        "{stdout}"
    );
    // Conservative thresholds (issue 23, item 6): with 95 % confidence that the true Pfa is at most
    // 0.01, from about 870 fault-free trials at most 3 may alarm (Wilks), against about 9 for the plain
    // calibration; every threshold is at least the plain one.
    let detector_thresholds = |path: &Path| -> Vec<(String, i64, f64)> {
        let t = csv_frame(path);
        let (det, out) = (
            t.column("detector").unwrap().str().unwrap().clone(),
            t.column("statistic").unwrap().str().unwrap().clone(),
        );
        let fa = t.column("detector_false_alarms").unwrap().i64().unwrap().clone();
        let thr = t.column("detector_threshold").unwrap().f64().unwrap().clone();
        (0..t.height())
            .filter(|&i| out.get(i) != Some("all"))
            .map(|i| (det.get(i).unwrap().to_string(), fa.get(i).unwrap_or(-1), thr.get(i).unwrap()))
            .collect()
    };
    let plain = detector_thresholds(&cal_thr);
    let stdout = ok(&fdimc(&["summarize", cal.to_str().unwrap(), "--target-pfa", "0.01", "--confidence", "0.95"]));
    assert!(stdout.contains("calibrated at Pfa 0.01 with 0.95 confidence (order statistic;"), "{stdout}");
    // The report command the console suggests is the run's (a calibration's folder has no manifest).
    let next = format!(
        "  next: `fdimc report {}` for the run's plots and report.html; in {}: ",
        cal.display(),
        cal.join("calibrations/pfa_0.01_confidence_0.95").display()
    );
    assert!(stdout.contains(&next), "{next:?} not in {stdout}");
    let confident_thr = cal.join("calibrations/pfa_0.01_confidence_0.95/thresholds.csv");
    assert_eq!(detector_thresholds(&cal_thr), plain, "the run's own thresholds stay");
    let confident = detector_thresholds(&confident_thr);
    assert_eq!(plain.len(), confident.len());
    for ((d, _, p), (_, _, c)) in plain.iter().zip(&confident) {
        assert!(c >= p, "{d}: the confident threshold {c} is below the plain {p}");
    }
    let t = csv_frame(&confident_thr);
    assert_eq!(t.column("confidence").unwrap().f64().unwrap().get(0), Some(0.95));
    let out = t.column("statistic").unwrap().str().unwrap().clone();
    let whole = t.column("detector_false_alarms").unwrap().i64().unwrap().clone();
    let n = t.column("trials").unwrap().i64().unwrap().clone();
    for i in (0..t.height()).filter(|&i| out.get(i) == Some("all")) {
        assert!(n.get(i).unwrap() > 800 && whole.get(i).unwrap() <= 3, "row {i}: {t}");
    }
    // The warnings whole (the console's line drops the parenthesised counts).
    let out = fdimc(&["--verbose", "summarize", cal.to_str().unwrap(), "--confidence", "0.9999999"]);
    let stdout = text(&out.stdout);
    assert!(stdout.contains("cannot give Pfa 0.01 with 0.9999999 confidence"), "{stdout}");
    assert!(stdout.contains("needs >= 1604 fault-free trials"), "{stdout}");
    // Where the order statistic cannot reach, the tail fit's upper bound sets the thresholds (item 6):
    // Pfa 1e-4 with 95 % confidence needs 29,956 trials by the order statistic; the fit's 0.95 bound
    // lies above every calibration value, and no calibration trial alarms.
    let stdout =
        ok(&fdimc(&["--verbose", "summarize", cal.to_str().unwrap(), "--target-pfa", "1e-4", "--confidence", "0.95"]));
    assert!(
        stdout.contains("needs >= 29956 fault-free trials): thresholds at the tail fit's 0.95 upper bound"),
        "{stdout}"
    );
    let tail_thr = cal.join("calibrations/pfa_1e-4_confidence_0.95/thresholds.csv");
    let t = csv_frame(&tail_thr);
    let out = t.column("statistic").unwrap().str().unwrap().clone();
    let whole = t.column("detector_false_alarms").unwrap().i64().unwrap().clone();
    for i in (0..t.height()).filter(|&i| out.get(i) == Some("all")) {
        assert_eq!(whole.get(i), Some(0), "row {i}: {t}");
    }
    for ((d, _, p), (_, _, c)) in plain.iter().zip(&detector_thresholds(&tail_thr)) {
        assert!(c > p, "{d}: the tail-bound threshold {c} is not above the plain one at 0.01 ({p})");
    }
    // Per flight hour (issue 23, item 4): 0.5 per hour over 10 s trials is 1 - 0.5^(1/360) per trial,
    // and the achieved rates are printed both ways.
    let stdout = ok(&fdimc(&["--verbose", "summarize", cal.to_str().unwrap(), "--target-pfa-per-hour", "0.5"]));
    let target = "0.5 per flight hour (Pfa 1.9236e-3 per 10 s trial, the hour's trials taken as independent)";
    assert!(stdout.contains(&format!("target {target}")), "{stdout}");
    assert!(stdout.contains(&format!("calibrated at {target} on the fault-free trials")), "{stdout}");
    assert_eq!(stdout.matches("(the hour's 10 s segments taken as independent)").count(), 2, "{stdout}");
    // Named as given (issue 81, item 1): the folder and the thresholds' source.
    let per_hour = csv_frame(&cal.join("calibrations/pfa_per_hour_0.5/thresholds.csv"));
    let source = per_hour.column("source").unwrap().str().unwrap().get(0).unwrap().to_string();
    assert_eq!(source, format!("calibrated at {target} on the fault-free trials"));
    // A target past what the ~870 fault-free trials resolve is refused, nothing written: 1e-7 per hour
    // is Pfa 2.8e-10 per 10 s trial (3.6e9 trials by the order statistic), and a per-trial 1e-4 needs
    // 10,000; each names the ways that reach it.
    for (flag, value, folder, needs) in [
        ("--target-pfa-per-hour", "1e-7", "pfa_per_hour_1e-7", "needs >= 3599999821"),
        ("--target-pfa", "1e-4", "pfa_1e-4", "needs >= 10000"),
    ] {
        let out = fdimc(&["summarize", cal.to_str().unwrap(), flag, value]);
        let said = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {value}: {said}");
        assert!(said.contains("is past what this run resolves") && said.contains(needs), "{said}");
        assert!(said.contains("tail.csv") && said.contains("fdimc rare-event"), "{said}");
        assert!(!cal.join("calibrations").join(folder).exists(), "{flag} {value}: a folder written");
    }
    let out = fdimc(&["summarize", cal.to_str().unwrap(), "--target-pfa-per-hour", "0.5", "--target-pfa", "0.01"]);
    assert_eq!(out.status.code(), Some(2));
    let out = fdimc(&["summarize", cal.to_str().unwrap(), "--confidence", "1.5"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--confidence 1.5: allowed 0 < c < 1"), "{}", text(&out.stderr));
}

/// Rare false alarms (issue 23, item 1): the CI deck's 869 fault-free trials give a generalised Pareto
/// fit per detector and threshold set; `tail.csv` holds, per statistic, the Pfa at the deck's and the
/// calibrated thresholds and the thresholds for 1e-5, 1e-7 and 1e-9 per flight hour.
#[test]
fn the_tail_fit_gives_thresholds_for_per_hour_targets() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    // The console answers first (issue 87): the answer, a line per warning naming its file, what next;
    // the fits' figures, the calibration and the safety sentences print behind --verbose.
    let quiet = ok(&fdimc(&["run", CI_DECK, "--out", dir.to_str().unwrap()]));
    assert!(!quiet.contains("fit on the 86 largest") && !quiet.contains("Pfa achieved"), "{quiet}");
    let lines: Vec<&str> = quiet.lines().collect();
    assert_eq!(lines.len(), 9, "{quiet}");
    assert!(
        lines[1].starts_with("  answer, at the calibrated thresholds (calibrated at Pfa 0.01 on the fault-free"),
        "{quiet}"
    );
    assert!(
        lines[2].trim_start().starts_with("seed  Pfa 9.2e-3 [4.7e-3, 1.8e-2] on 869 fault-free flights; Pd "),
        "{quiet}"
    );
    let warnings = [
        "  warning: tail.csv's thresholds of seed, fast for per-flight-hour targets may be far too low by the residual's exact law: fdimc flight-thresholds finds thresholds on the exact law",
        "  warning: rare false alarms of seed at the calibrated thresholds: do not trust the tail fit's figures; tail.csv",
    ];
    assert_eq!(lines[6..8], warnings, "{quiet}");
    assert!(lines[8].starts_with("  next: `fdimc report "), "{quiet}");
    // Every warning whole is in summarize.json (and --verbose); the console's line is its head.
    let settings = std::fs::read_to_string(dir.join("summarize.json")).unwrap();
    assert!(settings.contains("do not trust the tail fit's figures (misfit at the 3 largest"), "{settings}");
    let stdout = ok(&fdimc(&["--verbose", "run", CI_DECK, "--out", dir.to_str().unwrap(), "--force"]));
    assert!(stdout.contains("seed vs calibrated thresholds: fit on the 86 largest of 869, shape"), "{stdout}");
    assert!(stdout.contains("for 1.00e-9 per flight hour: thresholds x "), "{stdout}");
    let t = csv_frame(&dir.join("tail.csv"));
    // 2 detectors x 6 outputs x (deck + calibrated + 3 targets).
    assert_eq!(t.height(), 60, "{t}");
    let s = |c: &str| t.column(c).unwrap().str().unwrap().clone();
    let f = |c: &str| t.column(c).unwrap().cast(&polars::prelude::DataType::Float64).unwrap().f64().unwrap().clone();
    let (det, set, query, stat) = (s("detector"), s("thresholds"), s("query"), s("statistic"));
    let (pfa, lo, hi, observed, n) = (f("pfa"), f("pfa_lo"), f("pfa_hi"), f("observed_false_alarms"), f("trials"));
    let (thr, scale, scale_lo, target) = (f("threshold"), f("scale"), f("scale_lo"), f("target_pfa_per_hour"));
    let calibrated = csv_frame(&dir.join("thresholds.csv"));
    let cal_thr = |d: &str, o: &str| {
        let (cd, co) = (
            calibrated.column("detector").unwrap().str().unwrap(),
            calibrated.column("statistic").unwrap().str().unwrap(),
        );
        let i = (0..calibrated.height()).find(|&i| cd.get(i) == Some(d) && co.get(i) == Some(o)).unwrap();
        calibrated.column("detector_threshold").unwrap().f64().unwrap().get(i).unwrap()
    };
    let mut last_scale = std::collections::HashMap::new();
    for i in 0..t.height() {
        let (d, o) = (det.get(i).unwrap(), stat.get(i).unwrap());
        match (set.get(i).unwrap(), query.get(i).unwrap()) {
            // Within the data the fit agrees with what was seen: the observed rate is inside its interval.
            (_, "pfa_at_thresholds") => {
                let rate = observed.get(i).unwrap() / n.get(i).unwrap();
                assert_eq!(n.get(i), Some(869.0));
                assert!(
                    lo.get(i).unwrap() <= rate && rate <= hi.get(i).unwrap(),
                    "row {i}: {rate} outside [{:?}, {:?}]",
                    lo.get(i),
                    hi.get(i)
                );
                assert!(
                    (pfa.get(i).unwrap() / rate).ln().abs() < 0.7,
                    "row {i}: fitted {:?} against observed {rate}",
                    pfa.get(i)
                );
            }
            ("calibrated", "threshold_for_pfa") => {
                // Rarer targets need larger thresholds, each beyond the calibrated one (Pfa 0.01) even
                // at its interval's low end; the thresholds are the calibrated ones scaled.
                let x = scale.get(i).unwrap();
                assert!(scale_lo.get(i).unwrap() > 1.0, "row {i}");
                assert!((thr.get(i).unwrap() / (x * cal_thr(d, o)) - 1.0).abs() < 1e-9, "row {i}");
                if let Some(previous) = last_scale.insert((d.to_string(), o.to_string()), x) {
                    assert!(x > previous, "row {i}: {x} after {previous}");
                }
                assert!([1e-5, 1e-7, 1e-9].contains(&target.get(i).unwrap()), "row {i}");
            }
            other => panic!("row {i}: unexpected {other:?}"),
        }
    }
    let diag = csv_frame(&dir.join("tail_diagnostics.csv"));
    let chosen = diag.column("chosen").unwrap().bool().unwrap().clone();
    let k = diag.column("exceedances").unwrap().i64().unwrap().clone();
    assert_eq!(chosen.sum(), Some(4), "one chosen fit per detector and set: {diag}");
    assert!((0..diag.height()).filter(|&i| chosen.get(i) == Some(true)).all(|i| k.get(i) == Some(86)));
    // 172, 122, 86, 61, 43, 30 exceedances per detector and set.
    assert_eq!(diag.height(), 24, "{diag}");
}

/// `run --precision` (issue 23, item 7): on the CI deck with a cap of 40,000 trials, Pd and Pfa of every
/// group reach a 95 % half-width of 0.04 at 12,288 trials (3 chunks; the widest: Pd of seed on a 3-sigma
/// alpha bias, 283/714) and of 0.03 at 20,480. The stop and the records are the same for 1 or 2
/// threads, for a run stopped and resumed, and for a fixed run of that many trials; --resume with 0.03
/// takes the 0.04 run on to where a fresh 0.03 run stops.
#[test]
fn a_run_stops_at_a_precision_whatever_the_threads_or_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    let run = |extra: &[&str], out: &str| {
        let out = path(out);
        let mut args = vec!["run", CI_DECK, "--trials", "40000", "--precision-rates", "pd,pfa", "--out", out.as_str()];
        args.extend_from_slice(extra);
        fdimc(&args)
    };
    let manifest = |dir: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join(dir).join("manifest.json")).unwrap()).unwrap()
    };
    let one = ok(&run(&["--precision", "0.04", "--threads", "1"], "one"));
    assert!(one.contains("trials 0..12288 of 40000 (12288 run, 0 resumed)"), "{one}");
    assert!(
        one.contains("precision 0.04 reached at 12288 of at most 40000 trials: all 34 watched rates (pd, pfa)"),
        "{one}"
    );
    assert!(
        one.contains("the last to get there: pd of detector seed, kind bias, target alpha_rad, size bin 3"),
        "{one}"
    );
    let m = manifest("one");
    assert_eq!((m["end_trial"].as_u64(), m["rows"].as_u64()), (Some(12288), Some(24576)));
    assert_eq!(m["precision"]["met"], serde_json::Value::Bool(true));
    ok(&run(&["--precision", "0.04", "--threads", "2"], "two"));
    let stopped = ok(&run(&["--precision", "0.04", "--stop-after", "1"], "resumed"));
    assert!(stopped.contains("continue with the same command and --resume"), "{stopped}");
    let resumed = ok(&run(&["--precision", "0.04", "--resume"], "resumed"));
    assert!(resumed.contains("(8192 run, 4096 resumed)"), "{resumed}");
    ok(&fdimc(&["run", CI_DECK, "--trials", "12288", "--out", &path("fixed")]));
    let reference = read_frame(&tmp.path().join("one").join("trials.parquet"));
    for other in ["two", "resumed", "fixed"] {
        let df = read_frame(&tmp.path().join(other).join("trials.parquet"));
        assert!(reference.equals_missing(&df), "{other} differs from the 1-thread run");
    }
    // Tighter: a fresh run and the 0.04 run resumed stop at the same trial with the same records.
    let fresh = ok(&run(&["--precision", "0.03"], "fresh"));
    assert!(fresh.contains("trials 0..20480 of 40000"), "{fresh}");
    let further = ok(&run(&["--precision", "0.03", "--resume"], "one"));
    assert!(further.contains("trials 0..20480 of 40000 (8192 run, 12288 resumed)"), "{further}");
    let a = read_frame(&tmp.path().join("fresh").join("trials.parquet"));
    assert!(a.equals_missing(&read_frame(&tmp.path().join("one").join("trials.parquet"))));
    // A cap that comes first is said, and recorded.
    let capped_dir = path("capped");
    let capped = ok(&fdimc(&["run", CI_DECK, "--trials", "4096", "--precision", "0.001", "--out", &capped_dir]));
    assert!(
        capped
            .contains("warning: the cap of 4096 trials came first: 48 of 48 watched rates are still wider than 0.001"),
        "{capped}"
    );
    assert_eq!(manifest("capped")["precision"]["met"], serde_json::Value::Bool(false));
    // Refused, exit 2: a half-width out of range, an unknown rate, shards.
    for (extra, says) in [
        (vec!["--precision", "0.7"], "--precision 0.7: allowed 0 < W < 0.5"),
        (
            vec!["--precision", "0.01", "--precision-rates", "pd,delay"],
            "\"delay\" is not a rate of summary.csv; allowed: pd, pfa, isolation_accuracy",
        ),
        (vec!["--precision", "0.01", "--shard", "0/2"], "--precision stops where the trials before"),
    ] {
        let out = run(&extra, "bad");
        assert_eq!(out.status.code(), Some(2), "{extra:?}");
        assert!(text(&out.stderr).contains(says), "{extra:?}: {}", text(&out.stderr));
    }
}

#[test]
fn bad_run_input_exits_2_and_keeps_what_was_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let d = dir.to_str().unwrap();
    let code = |args: &[&str]| {
        let out = fdimc(args);
        (out.status.code(), text(&out.stderr))
    };
    let (c, e) = code(&["run", CI_DECK, "--shard", "3/2", "--out", d]);
    assert_eq!(c, Some(2), "{e}");
    assert!(e.contains("needs 0 <= I < N"), "{e}");
    assert_eq!(code(&["run", CI_DECK, "--threads", "0", "--out", d]).0, Some(2));
    assert_eq!(code(&["run", CI_DECK, "--trials", "0", "--out", d]).0, Some(2));

    run_deck(CI_DECK, Some(500), Path::new(d));
    let summary_before = std::fs::read(dir.join("summary.csv")).unwrap();
    // Occupied folder without --resume or --force.
    let (c, e) = code(&["run", CI_DECK, "--trials", "500", "--out", d]);
    assert_eq!(c, Some(2), "{e}");
    assert!(e.contains("already holds a run"), "{e}");
    // --resume with another deck (or trial count).
    let (c, e) = code(&["run", DECK, "--resume", "--out", d]);
    assert_eq!(c, Some(2), "{e}");
    assert!(e.contains("holds a run of another deck"), "{e}");
    // A corrupt trials file: named, exit 2, the earlier summary untouched.
    let trials = dir.join("trials.parquet");
    let good = std::fs::read(&trials).unwrap();
    std::fs::write(&trials, &good[..good.len() / 2]).unwrap();
    let (c, e) = code(&["summarize", d]);
    assert_eq!(c, Some(2), "{e}");
    assert!(e.contains("trials.parquet"), "{e}");
    assert_eq!(std::fs::read(dir.join("summary.csv")).unwrap(), summary_before);
    // Not a results folder; a missing baseline.
    let (c, e) = code(&["summarize", tmp.path().to_str().unwrap()]);
    assert_eq!(c, Some(2), "{e}");
    assert!(e.contains("manifest.json"), "{e}");
    std::fs::write(&trials, &good).unwrap();
    let (c, e) = code(&["check", d, "--baseline", "results/baselines/nope.csv"]);
    assert_eq!(c, Some(2), "{e}");
    assert!(e.contains("nope.csv"), "{e}");
}

/// The texts of an SVG's `<text>` elements, trimmed.
/// `scripts/check_report.py` on the report of `dir`: every image loads in headless Chromium and no link
/// points nowhere. Without Chromium the check is skipped, unless FDIMC_REQUIRE_CHROMIUM is set (as
/// `.ci/run` sets it, after installing Chromium).
fn assert_report_loads_in_a_browser(dir: &Path) {
    let has = Command::new("chromium").arg("--version").output().is_ok_and(|o| o.status.success());
    if !has {
        assert!(std::env::var_os("FDIMC_REQUIRE_CHROMIUM").is_none(), "FDIMC_REQUIRE_CHROMIUM set, no chromium");
        eprintln!("chromium not installed: the browser check of {} is skipped", dir.display());
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/check_report.py");
    let out = Command::new("python3").arg(script).arg(dir).output().unwrap();
    assert!(out.status.success(), "{}{}", text(&out.stdout), text(&out.stderr));
    assert!(text(&out.stdout).contains(" 0 failure(s)"), "{}", text(&out.stdout));
    // The answer block was measured, in view of a 1400 x 900 window (a sensitivity page has none).
    let sensitivity = std::fs::read_to_string(dir.join("manifest.json")).is_ok_and(|m| m.contains("\"sensitivity\":"));
    assert!(sensitivity || text(&out.stdout).contains("answer block at x "), "{}", text(&out.stdout));
}

/// `fdimc report DIR --trials N` on a run of a kind: the page, and each of `plots` with the texts it
/// must hold (legend entries, axis titles), and the page loads in a browser.
fn assert_report(dir: &Path, trial: &str, plots: &[(&str, &[&str])]) {
    let d = dir.to_str().unwrap();
    let stdout = ok(&fdimc(&["report", d, "--trials", trial]));
    let report = dir.join("report");
    for (name, texts) in plots {
        let svg = std::fs::read_to_string(report.join(name)).unwrap_or_else(|e| panic!("{name}: {e}\n{stdout}"));
        for t in *texts {
            assert!(svg.contains(t), "{name} lacks {t:?}");
        }
    }
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    for (name, _) in plots {
        assert!(html.contains(&format!("src=\"{name}\"")), "report.html does not show {name}");
    }
    assert_report_loads_in_a_browser(dir);
}

fn svg_texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| Some(t[t.find('>')? + 1..t.find("</text>")?].trim().to_string()))
        .collect()
}

#[test]
fn report_draws_every_plot_with_its_series_and_links_only_existing_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let d = dir.to_str().unwrap();
    run_deck(CI_DECK, Some(1500), Path::new(d));
    let stdout = ok(&fdimc(&["report", d, "--trials", "3,17"]));
    // 13 plots before the false-alarm plots went where something varies: this deck has one noise scale
    // and no parameter error, so a single point per detector, which the table says.
    assert!(stdout.contains("11 plots"), "{stdout}");
    let report = dir.join("report");
    let svg = |name: &str| std::fs::read_to_string(report.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    // Each plot names its series (legend entries) and axis titles with units.
    let pd = svg("pd_size_seed_bias.svg");
    // The legend carries each output's minimum detectable size, as min_detectable.csv gives it.
    let md = csv_frame(&dir.join("min_detectable.csv"));
    let (det, out, size) = (
        md.column("detector").unwrap().str().unwrap().clone(),
        md.column("target").unwrap().str().unwrap().clone(),
        md.column("min_size_pd90").unwrap().f64().unwrap().clone(),
    );
    // Each row says its size's unit (the bias sizes of this deck are in sensor sigmas).
    let (kinds, units) = (md.column("kind").unwrap().str().unwrap(), md.column("size_unit").unwrap().str().unwrap());
    for i in 0..md.height() {
        let want = if kinds.get(i) == Some("bias") { "multiples of the sensor sigma" } else { "none" };
        assert_eq!(units.get(i), Some(want), "row {i} ({:?})", kinds.get(i));
    }
    // Listed sizes are their own bins: both edges are the size.
    let lo = md.column("min_size_pd90_lo").unwrap().f64().unwrap().clone();
    let hi = md.column("min_size_pd90_hi").unwrap().f64().unwrap().clone();
    for i in (0..md.height()).filter(|&i| size.get(i).is_some()) {
        assert_eq!((lo.get(i), hi.get(i)), (size.get(i), size.get(i)), "row {i}");
    }
    let legend = |output: &str| -> String {
        let i = (0..md.height())
            .find(|&i| det.get(i) == Some("seed") && out.get(i) == Some(output))
            .unwrap_or_else(|| panic!("no min_detectable.csv row for seed/{output}"));
        format!("{output} (Pd &gt;= 0.9 from {:.3})", size.get(i).expect("a detectable size"))
    };
    for s in [
        legend("alpha_rad").as_str(),
        legend("q_rad_s").as_str(),
        "Pd = 0.9",
        "fault size (multiples of the sensor sigma)",
        "detection probability Pd",
    ] {
        assert!(pd.contains(s), "pd_size_seed_bias.svg lacks {s:?}");
    }
    assert!(svg("pd_size_fast_bias.svg").contains("fast, bias"));
    let roc = svg("roc.svg");
    for s in ["seed calibrated: Pfa", "fast calibrated: Pfa", "false-alarm probability Pfa per trial"] {
        assert!(roc.contains(s), "roc.svg lacks {s:?}");
    }
    let legend = svg_texts(&roc);
    assert!(legend.iter().any(|t| t == "seed") && legend.iter().any(|t| t == "fast"), "{legend:?}");
    // The tail plot per detector: the observed exceedance fraction, the fit, the per-hour targets.
    for d in ["seed", "fast"] {
        let tail = svg(&format!("tail_{d}.svg"));
        for s in ["observed fraction above", "generalised Pareto fit (shape", "threshold for a target, 95 % interval"] {
            assert!(tail.contains(s), "tail_{d}.svg lacks {s:?}");
        }
    }
    let delay = svg("delay_seed.svg");
    assert!(delay.contains("bias (") && delay.contains("stuck (") && delay.contains("delay after onset (s)"));
    let confusion = svg("confusion_seed.svg");
    let labels = svg_texts(&confusion);
    for s in [
        "true target",
        "isolated (named) target",
        "none",
        "alpha_rad",
        "q_rad_s",
        "h_m",
        "correct isolation",
        "another target, or none",
    ] {
        assert!(labels.iter().any(|t| t == s), "confusion_seed.svg lacks {s:?}: {labels:?}");
    }
    for trial in ["trace_trial3.svg", "trace_trial17.svg"] {
        let t = svg(trial);
        for s in ["r_q_rad_s", "deck threshold", "calibrated threshold", "t (s)"] {
            assert!(t.contains(s), "{trial} lacks {s:?}");
        }
    }
    // The page references only files that exist, all beside it, and loads nothing from the network.
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    assert!(!html.contains("http://") && !html.contains("https://"));
    let mut refs = 0;
    for part in html.split("src=\"").skip(1) {
        let name = &part[..part.find('"').unwrap()];
        assert!(report.join(name).is_file(), "report.html references missing {name}");
        refs += 1;
    }
    assert_eq!(refs, 11);
    assert!(html.contains("ci_seed000") && html.contains("deck SHA-256"));
    assert!(!report.join("false_alarms_seed.svg").exists(), "a plot of one point");
    assert!(html.contains("<th>fault_free_trials</th>"), "the false alarms' table");
    // The tables are for reading: the thresholds' calibration trials an integer, the source said once.
    assert!(html.contains("<code>trials</code>: 441; "), "{html}");
    assert!(
        html.contains(
            "<code>target_pfa</code>: 0.01; <code>confidence</code>: -; <code>source</code>: calibrated at Pfa"
        ),
        "{html}"
    );
    assert!(!html.contains(".00000<"), "numbers padded with zeros");
    assert_report_loads_in_a_browser(&dir);
    // Without --trials the report picks what a reader looks at first, says why, and draws each.
    ok(&fdimc(&["report", d]));
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    let note = html.split("Trials picked for detector seed").nth(1).unwrap_or_else(|| panic!("{html}"));
    let note = &note[..note.find('.').unwrap()];
    assert!(note.contains(" (first detected fault)") && note.contains(" (first missed fault)"), "{note}");
    let drawn = html.matches("src=\"trace_trial").count();
    assert_eq!(drawn, note.matches(" (first ").count(), "one trace per picked trial: {note}");
    // From another folder the run's deck (a relative path) is not there: the report is still written,
    // without picked traces, and says why.
    let elsewhere = Command::new(env!("CARGO_BIN_EXE_fdimc"))
        .args(["report", dir.canonicalize().unwrap().to_str().unwrap()])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    ok(&elsewhere);
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    assert!(html.contains("no traces: the run's deck studies/ci_seed000.toml is missing"), "{html}");
    assert_eq!(html.matches("src=\"trace_trial").count(), 0);
    // A trial outside the run is refused.
    let out = fdimc(&["report", d, "--trials", "1500"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
}

/// `examples/custom_detector.rs` (built by `cargo test`): the user's moving-average test runs next to
/// the deck's detectors on the same trials and gets the same records, summaries and report.
#[test]
fn the_custom_detector_example_runs_a_study_with_its_own_test() {
    // `cargo test` builds examples under a hashed name beside the uplifted one: take the newest.
    let examples = std::env::current_exe().unwrap().parent().unwrap().parent().unwrap().join("examples");
    let example = std::fs::read_dir(&examples)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            name.starts_with("custom_detector") && p.extension().is_none()
        })
        .max_by_key(|p| std::fs::metadata(p).unwrap().modified().unwrap())
        .expect("cargo test builds examples/custom_detector");
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("custom");
    let out = Command::new(&example).args(["--out", dir.to_str().unwrap(), "--trials", "600"]).output().unwrap();
    let stdout = ok(&out);
    assert!(stdout.contains("600 trials x [\"seed\", \"fast\", \"moving_average\"]"), "{stdout}");
    let trials = read_frame(&dir.join("trials.parquet"));
    assert_eq!(trials.height(), 600 * 3, "one row per trial and detector");
    let names = trials.column("detector").unwrap().str().unwrap().clone();
    let own = (0..names.len()).filter(|&i| names.get(i) == Some("moving_average"));
    assert_eq!(own.count(), 600);
    let detectors = csv_frame(&dir.join("detectors.csv"));
    assert_eq!(detectors.height(), 6, "deck and calibrated thresholds for each of the three");
    let comparison = csv_frame(&dir.join("comparison.csv"));
    assert_eq!(comparison.height(), 6, "every pair of three detectors, at both threshold sets");
    assert!(dir.join("report/pd_size_moving_average_bias.svg").is_file());
    assert_report_loads_in_a_browser(&dir);
}

/// `fdimc new <kind> FILE` writes, for every registered kind, a deck that validates and runs as
/// written, its study named after the file; an existing file is kept unless `--force`, an unknown kind
/// refused with the kinds listed.
#[test]
fn new_writes_a_starter_deck_of_every_kind_that_validates_and_runs() {
    let tmp = tempfile::tempdir().unwrap();
    for method in fdimc::methods::REGISTRY {
        let deck = tmp.path().join(format!("my {}.toml", method.kind));
        let d = deck.to_str().unwrap();
        let stdout = ok(&fdimc(&["new", method.kind, d]));
        assert!(stdout.contains(&format!("study \"my_{}\"", method.kind)), "{stdout}");
        let written = std::fs::read_to_string(&deck).unwrap();
        assert!(written.starts_with(&format!("# A deck of kind {} (", method.kind)), "{written}");
        assert!(
            written.contains(&format!("name = \"my_{}\"", method.kind)) && !written.contains("for CI"),
            "{written}"
        );
        ok(&fdimc(&["validate", d]));
        let out_dir = tmp.path().join(method.kind);
        let run = ok(&fdimc(&["run", d, "--trials", "8", "--out", out_dir.to_str().unwrap()]));
        assert!(run.starts_with(&format!("my_{}: trials 0..8 of 8", method.kind)), "{run}");
        // Written once: a second `new` keeps the user's edits.
        let again = fdimc(&["new", method.kind, d]);
        assert_eq!(again.status.code(), Some(2), "{}", text(&again.stderr));
        assert!(text(&again.stderr).contains("exists; name another file, or --force"));
        ok(&fdimc(&["new", method.kind, d, "--force"]));
    }
    let out = fdimc(&["new", "kalman", tmp.path().join("x.toml").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("possible values: detection_filter, thrust_loss"), "{}", text(&out.stderr));
}

/// `fdimc log` lists what a flight log holds and a topic's field spreads; a missing file, a file that is
/// not a log and a topic the log lacks exit 2 naming the file (and the topic).
#[test]
fn log_lists_topics_and_refuses_what_it_cannot_read() {
    let small = "studies/logs/sample_log_small.ulg";
    let out = ok(&fdimc(&["log", small, "--topic", "sensor_combined"]));
    assert!(out.starts_with(&format!("{small}: 70 topic instances, read to its end")), "{out}");
    let row = out.lines().find(|l| l.starts_with("sensor_combined ")).unwrap();
    let cells: Vec<&str> = row.split_whitespace().collect();
    // Seconds from the first sensor_combined sample, as a deck's [log] windows count (the log's own
    // clock said once: 20.326716 s after boot).
    assert_eq!(cells, ["sensor_combined", "0", "1298", "0.000", "6.496", "199.66", "0.1613", "0"], "{out}");
    assert!(out.contains("at 20.326716 s on the log's clock"), "{out}");
    let gyro = out.lines().find(|l| l.starts_with("gyro_rad[0] ")).unwrap();
    assert_eq!(
        gyro.split_whitespace().collect::<Vec<_>>(),
        [
            "gyro_rad[0]",
            "4.457860e-3",
            "2.907517e-3",
            "2.771991e-3",
            "0.092",
            "0.134",
            "0.037",
            "-0.037",
            "1.18",
            // The empirical law's fitted tail shape (bounded; a deck's law raises it to 0).
            "-0.11",
            "student_t(9.1)"
        ]
    );

    let tmp = tempfile::tempdir().unwrap();
    let deck = tmp.path().join("deck.ulg");
    std::fs::write(&deck, "[study]\n").unwrap();
    // One byte of a parameter record's length changed (21 -> 102 at offset 36,809): px4-ulog 0.6.1
    // slices past the record and panics; fdimc says the file is malformed, without the panic's text.
    let mut bytes = std::fs::read(small).unwrap();
    assert_eq!(bytes[36_809], 21);
    bytes[36_809] = 102;
    let corrupt = tmp.path().join("corrupt.ulg");
    std::fs::write(&corrupt, bytes).unwrap();
    for (args, want) in [
        (vec!["log", "studies/logs/none.ulg"], "studies/logs/none.ulg: no such file".to_string()),
        (vec!["log", deck.to_str().unwrap()], format!("{}: not a PX4 ULog: 8 bytes, shorter than", deck.display())),
        (
            vec!["log", corrupt.to_str().unwrap()],
            format!("{}: not a readable ULog file: a malformed record", corrupt.display()),
        ),
        (
            vec!["log", small, "--topic", "airspeed_x"],
            format!("{small}: no topic \"airspeed_x\" instance 0 (the log has: "),
        ),
    ] {
        let out = fdimc(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let stderr = text(&out.stderr);
        assert!(stderr.contains(&want) && !stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

/// The replay deck (method 003 on a real log) runs as any study: identical records for any threads,
/// shards and resume; one row per trial and classifier with the segment's start inside the evaluated
/// half; the fault-free replay's alarms; the report; `simulate --trial`.
#[test]
fn replay_records_are_identical_for_any_threads_shards_and_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let edits = [("trials = 400", "trials = 600"), ("trials_per_class = 300", "trials_per_class = 40")];
    let deck_path = edited_deck(tmp.path(), "replay_px4.toml", &edits, "replay.toml");
    let deck = deck_path.to_str().unwrap();
    let tables = ["confusion.csv", "summary.csv", "detectors.csv", "comparison.csv"];
    let (one, stdout) = assert_identical_runs(deck, tmp.path(), 600, 512, &tables);
    for name in ["tree_sim", "flat_sim", "tree_log", "flat_log"] {
        assert_eq!(stdout.lines().filter(|l| l.starts_with(&format!("    {name}  Pfa "))).count(), 1, "{stdout}");
    }
    let records = read_frame(&one.join("trials.parquet"));
    assert_eq!(records.height(), 600 * 4);
    let starts: Vec<f64> = records.column("log_start_s").unwrap().f64().unwrap().into_no_null_iter().collect();
    let (first, last) = starts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    assert!(first >= 4.8 - 1e-9 && last <= 5.6 + 1e-9, "segments start in [{first}, {last}]");
    assert!(last - first > 0.5, "segments spread over the half: [{first}, {last}]");
    // The fault-free second half at the simulated flights' threshold: one alarm in 3.3 s.
    let replay: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(one.join("fault_free_replay.json")).unwrap()).unwrap();
    assert_eq!(replay["threshold"], 60.0);
    assert_eq!(replay["alarms"], 1);
    assert!((replay["watched_s"].as_f64().unwrap() - 3.3).abs() < 0.011, "{replay}");
    let check = ok(&fdimc(&["check", one.to_str().unwrap(), "--baseline", one.join("summary.csv").to_str().unwrap()]));
    assert!(check.contains(": 0 regression(s)"), "{check}");
    // Classifiers trained on another split of the log (which could have seen the evaluated samples)
    // are refused.
    let split =
        edited_deck(tmp.path(), "replay_px4.toml", &[("train_s = [0.0, 4.8]", "train_s = [0.0, 4.7]")], "split.toml");
    let classifiers = one.join("classifiers.json");
    let out = fdimc(&[
        "run",
        split.to_str().unwrap(),
        "--classifiers",
        classifiers.to_str().unwrap(),
        "--out",
        tmp.path().join("split").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("training part [0.000, 4.800) s at dt 0.01 s, debiased [], but "),
        "{}",
        text(&out.stderr)
    );
    // The report re-flies a trial of the log.
    assert_report(
        &one,
        "2",
        &[("trace_trial2.svg", &["attitude-EKF residual (unit gravity direction, 1)", "detection statistic"])],
    );
    let trace = tmp.path().join("trace.csv");
    let sim = ok(&fdimc(&["simulate", deck, "--trial", "2", "--out", trace.to_str().unwrap()]));
    assert!(csv_frame(&trace).height() == 400, "{sim}");
}

/// `fdimc sensitivity` on the CI deck with two factors added: a listed noise scale (which drives false
/// alarms) and an error on the plant's throttle entry, which no detector can see (the throttle never
/// moves): its indices are exactly 0, intervals included, while the fault size's total index on Pd is
/// clear of 0. Shards and merge, and a stopped run resumed, give the same records and indices to the
/// bit; the report draws the indices; other kinds and bad arguments are refused.
#[test]
fn sensitivity_indices_see_what_the_detector_sees_whatever_the_shards_or_resume() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let deck = edited_deck(
        tmp.path(),
        "ci_seed000.toml",
        &[(
            "onset_s = { range = [2.0, 6.0] }",
            "onset_s = { range = [2.0, 6.0] }\nnoise_scale = { values = [1.0, 2.0] }\n\n\
             [[monte_carlo.parameter_error]]\nname = \"throttle_unused\"\nmodel = \"plant\"\nmatrix = \"b\"\n\
             entries = [[\"v_m_s\", \"throttle\"]]\nabsolute = { range = [-1.0, 1.0] }\n",
        )],
        "sens.toml",
    );
    let deck = deck.to_str().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    let run = |extra: &[&str], out: &str| {
        let out = s(out);
        let mut args = vec!["sensitivity", deck, "--base-samples", "800", "--out", &out];
        args.extend_from_slice(extra);
        fdimc(&args)
    };
    let printed = ok(&run(&[], "whole"));
    // Faulty: kind, output, size, onset, noise scale, throttle, noise = 7 factors, 800 x 9 trials;
    // fault-free: noise scale, throttle, noise, 800 x 5. 22,400 rows: the analysis reads them in two slices.
    assert!(printed.contains("faulty trials: 7 factors (fault_kind, output, size, onset_s, noise_scale, throttle_unused, noise_realisation): 7200 trials"), "{printed}");
    assert!(
        printed.contains("fault-free trials: 3 factors (noise_scale, throttle_unused, noise_realisation): 4000 trials"),
        "{printed}"
    );
    let table = csv_frame(&tmp.path().join("whole/sensitivity.csv"));
    assert_eq!(table.height(), 2 * (7 * 3 + 3), "detectors x (factors x outcomes) per part");
    assert_eq!(read_frame(&tmp.path().join("whole/trials.parquet")).height(), 2 * 11200);
    let rows = |outcome: &str, detector: &str, factor: &str| {
        table
            .clone()
            .lazy()
            .filter(
                col("outcome")
                    .eq(lit(outcome))
                    .and(col("detector").eq(lit(detector)))
                    .and(col("factor").eq(lit(factor))),
            )
            .collect()
            .unwrap()
    };
    let value = |df: &DataFrame, c: &str| df.column(c).unwrap().f64().unwrap().get(0);
    for detector in ["seed", "fast"] {
        for outcome in ["pd", "isolation", "delay_s", "pfa"] {
            let r = rows(outcome, detector, "throttle_unused");
            for c in ["s1", "s1_lo", "s1_hi", "st", "st_lo", "st_hi"] {
                assert_eq!(value(&r, c), Some(0.0), "{outcome} {detector} {c}: the throttle is invisible");
            }
        }
        let size = rows("pd", detector, "size");
        assert!(value(&size, "st_lo").unwrap() > 0.05, "{detector}: the size drives Pd\n{size}");
        let noise = rows("pfa", detector, "noise_scale");
        assert!(value(&noise, "st_lo").unwrap() > 0.05, "{detector}: doubling the noise drives false alarms\n{noise}");
    }

    for i in 0..3 {
        ok(&run(&["--shard", &format!("{i}/3"), "--quiet"], &format!("s{i}")));
    }
    ok(&fdimc(&["merge", &s("s2"), &s("s0"), &s("s1"), "--out", &s("merged")]));
    let stopped = ok(&run(&["--stop-after", "1", "--threads", "1"], "resumed"));
    assert!(stopped.contains("--resume"), "{stopped}");
    ok(&run(&["--resume"], "resumed"));
    let reference = read_frame(&tmp.path().join("whole/trials.parquet"));
    let whole = std::fs::read_to_string(tmp.path().join("whole/sensitivity.csv")).unwrap();
    for other in ["merged", "resumed"] {
        assert!(reference.equals_missing(&read_frame(&tmp.path().join(other).join("trials.parquet"))), "{other}");
        assert_eq!(whole, std::fs::read_to_string(tmp.path().join(other).join("sensitivity.csv")).unwrap(), "{other}");
    }
    // A plain run's shard does not merge with a sensitivity run's.
    ok(&fdimc(&["run", deck, "--trials", "11200", "--shard", "2/3", "--quiet", "--out", &s("plain2")]));
    let out = fdimc(&["merge", &s("s0"), &s("s1"), &s("plain2"), "--out", &s("bad")]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));

    // At another run's calibrated thresholds: the same trials, read again; isolation left out.
    ok(&fdimc(&["run", deck, "--trials", "3000", "--quiet", "--out", &s("plain")]));
    let calibrated = s("plain/thresholds.csv");
    ok(&fdimc(&["summarize", &s("merged"), "--thresholds", &calibrated]));
    let at_calibrated = csv_frame(&tmp.path().join("merged/sensitivity.csv"));
    assert_eq!(at_calibrated.height(), 2 * (7 * 2 + 3), "no isolation rows");
    let source = at_calibrated.column("thresholds").unwrap().str().unwrap().get(0).unwrap().to_string();
    assert_eq!(source, format!("from {calibrated}"));
    let out = fdimc(&["summarize", &s("merged"), "--target-pfa", "0.01"]);
    assert_eq!(out.status.code(), Some(2), "a sensitivity run calibrates nothing");

    let report = ok(&fdimc(&["report", &s("whole")]));
    let page = std::fs::read_to_string(tmp.path().join("whole/report/report.html")).unwrap();
    for name in ["sensitivity_pd_seed.svg", "sensitivity_pfa_fast.svg", "sensitivity_delay_s_fast.svg"] {
        let svg = std::fs::read_to_string(tmp.path().join("whole/report").join(name)).unwrap();
        let texts = svg_texts(&svg);
        assert!(texts.iter().any(|t| t == "throttle_unused"), "{name}: {texts:?}");
        assert!(texts.iter().any(|t| t.starts_with("ST: total")), "{name}: {texts:?}");
        assert!(page.contains(&format!("src=\"{name}\"")), "{report}");
    }
    assert_report_loads_in_a_browser(&tmp.path().join("whole"));

    for (args, want) in [
        (vec!["sensitivity", "studies/ci_seed004.toml"], "not to this surface_bank study"),
        (vec!["sensitivity", deck, "--base-samples", "1"], "--base-samples 1: allowed 2 to"),
        (vec!["sensitivity", deck, "--bootstrap", "5"], "--bootstrap 5: allowed 10 to 100000"),
    ] {
        let out = fdimc(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(text(&out.stderr).contains(want), "{}", text(&out.stderr));
    }
}

/// The launch-vehicle (001) and air-data (002) kinds name their factors for a design too: the factors
/// printed, one row per outcome, detector and factor, and the same indices for 1 and 2 threads.
#[test]
fn launch_and_air_data_decks_take_a_sensitivity_design() {
    let tmp = tempfile::tempdir().unwrap();
    for (deck, faulty, fault_free) in [
        (
            "studies/ci_seed001.toml",
            "faulty trials: 5 factors (engine, loss_percent, onset_s, gust_scale, noise_realisation): 224 trials",
            "fault-free trials: 2 factors (gust_scale, noise_realisation): 128 trials",
        ),
        (
            "studies/ci_seed002.toml",
            "faulty trials: 4 factors (output_set, size, onset_s, noise_realisation): 192 trials",
            "fault-free trials: 1 factors (noise_realisation): 96 trials",
        ),
    ] {
        let out = |threads: &str| tmp.path().join(format!("{}-{threads}", &deck[8..18])).to_str().unwrap().to_string();
        let printed = ok(&fdimc(&["sensitivity", deck, "--base-samples", "32", "--threads", "2", "--out", &out("2")]));
        assert!(printed.contains(faulty) && printed.contains(fault_free), "{deck}: {printed}");
        ok(&fdimc(&["sensitivity", deck, "--base-samples", "32", "--threads", "1", "--quiet", "--out", &out("1")]));
        let table = csv_frame(&Path::new(&out("2")).join("sensitivity.csv"));
        let detectors = table.column("detector").unwrap().n_unique().unwrap();
        let (kf, k0) = if deck.contains("001") { (5, 2) } else { (4, 1) };
        assert_eq!(table.height(), detectors * (3 * kf + k0), "{deck}");
        let read = |o: &str| std::fs::read_to_string(Path::new(&out(o)).join("sensitivity.csv")).unwrap();
        assert_eq!(read("1"), read("2"), "{deck}: the same indices for any thread count");
    }
}

/// One writer per results folder (issue 26): a second run on a folder that another run is writing is
/// refused (exit 2) naming the holder's pid; once the first is killed (SIGKILL), its lock is gone with
/// it, and `--resume` completes the run to the records of an uninterrupted one.
#[test]
fn a_second_writer_is_refused_and_a_killed_runs_lock_is_not_stale() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    // 16,384 CI trials on one thread: four part files, a few seconds of writing, the second run refused
    // within milliseconds of the first part file.
    fn args(out: &str) -> Vec<&str> {
        vec!["run", CI_DECK, "--trials", "16384", "--threads", "1", "--quiet", "--out", out]
    }
    let busy = s("busy");
    let mut first = Command::new(env!("CARGO_BIN_EXE_fdimc"))
        .args(args(&busy))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .spawn()
        .unwrap();
    let parts = tmp.path().join("busy/parts");
    let started = std::time::Instant::now();
    while !std::fs::read_dir(&parts)
        .is_ok_and(|d| d.flatten().any(|e| e.file_name().to_string_lossy().starts_with("part-")))
    {
        assert!(started.elapsed().as_secs() < 60, "the first run wrote no part file");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let second = fdimc(&[args(&busy), vec!["--resume"]].concat());
    assert_eq!(second.status.code(), Some(2), "{}", text(&second.stderr));
    let e = text(&second.stderr);
    assert!(
        e.contains("another fdimc is writing this folder") && e.contains(&format!("pid {} on host", first.id())),
        "{e}"
    );
    first.kill().unwrap();
    first.wait().unwrap();
    assert!(!tmp.path().join("busy/trials.parquet").exists(), "killed before its end");
    let resumed = ok(&fdimc(&["run", CI_DECK, "--trials", "16384", "--resume", "--out", &busy]));
    assert!(resumed.contains(" resumed)") && !resumed.contains(", 0 resumed)"), "{resumed}");
    ok(&fdimc(&args(&s("whole"))));
    let whole = read_frame(&tmp.path().join("whole/trials.parquet"));
    assert!(whole.equals_missing(&read_frame(&tmp.path().join("busy/trials.parquet"))));
}

/// The cluster files the README shows (issue 26): the SLURM job file takes its shard from the array and
/// resumes; the Kubernetes indexed Job's shard count is its completion count, its deck is bundled.
#[test]
fn the_cluster_job_files_take_their_shard_from_the_scheduler() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let sbatch = std::fs::read_to_string(root.join("scripts/cluster/fdimc-array.sbatch")).unwrap();
    let command = sbatch.lines().find(|l| l.starts_with("exec ")).expect("the job's command");
    for word in ["run", "--shard auto", "--out \"$OUT\"", "--resume", "--threads \"${SLURM_CPUS_PER_TASK:-1}\""] {
        assert!(command.contains(word), "{command}: {word}");
    }
    assert!(sbatch.contains("#SBATCH --requeue"));

    let yaml = std::fs::read_to_string(root.join("scripts/cluster/fdimc-indexed-job.yaml")).unwrap();
    let field = |name: &str| -> String {
        let line =
            yaml.lines().find(|l| l.trim_start().starts_with(&format!("{name}:"))).unwrap_or_else(|| panic!("{name}"));
        line.split_once(':').unwrap().1.trim().to_string()
    };
    assert_eq!(field("apiVersion"), "batch/v1");
    assert_eq!(field("kind"), "Job");
    assert_eq!(field("completionMode"), "Indexed");
    assert_eq!(field("restartPolicy"), "Never");
    let completions: u64 = field("completions").parse().unwrap();
    assert_eq!(field("parallelism").parse::<u64>().unwrap(), completions);
    // The command, as a flow list over lines: its quoted words.
    let start = yaml.find("command: [").unwrap();
    let list = &yaml[start + 10..start + yaml[start..].find(']').unwrap()];
    let words: Vec<&str> = list.split(',').map(|w| w.trim().trim_matches('"')).collect();
    let after = |flag: &str| words[words.iter().position(|w| *w == flag).unwrap_or_else(|| panic!("{flag}")) + 1];
    assert_eq!(&words[..2], ["fdimc", "run"]);
    assert!(root.join(words[2]).exists(), "{}", words[2]);
    assert_eq!(after("--shard"), format!("auto/{completions}"));
    assert!(words.contains(&"--resume"));
    assert_eq!(after("--threads"), field("cpu").trim_matches('"'));
    // What a pod would do with it: index 3 of the completions is shard 3, in its own folder.
    let out = tempfile::tempdir().unwrap();
    let o = out.path().to_str().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_fdimc"))
        .args(["run", CI_DECK, "--trials", "64", "--shard", &format!("auto/{completions}"), "--out", o])
        .env("JOB_COMPLETION_INDEX", "3")
        .current_dir(root)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    assert!(out.path().join(format!("shard-3-of-{completions}/manifest.json")).exists());
    // And without a scheduler, `auto` is refused.
    let bare = Command::new(env!("CARGO_BIN_EXE_fdimc"))
        .args(["run", CI_DECK, "--shard", "auto", "--out", o])
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .current_dir(root)
        .output()
        .unwrap();
    assert_eq!(bare.status.code(), Some(2));
    assert!(text(&bare.stderr).contains("no array task in the environment"), "{}", text(&bare.stderr));
}

/// A calibration allows floor(p n) alarms on its trials, and that many alarm, on every seed: the whole
/// detector's thresholds (per-statistic thresholds times a common factor) once rounded one ulp below
/// the value that set the factor, and one trial more alarmed (seed 1003 at 2000 trials: 21 of 20; about
/// one calibration in ten did, so the 48 here (24 seeds, two detectors) would all pass by luck with
/// probability 0.9^48 = 0.006).
#[test]
fn a_calibration_lets_through_exactly_the_alarms_it_allows() {
    let tmp = tempfile::tempdir().unwrap();
    for seed in (1000..1024).map(|s| s.to_string()) {
        let seed = seed.as_str();
        let dir = tmp.path().join(seed);
        let d = dir.to_str().unwrap();
        let deck = "studies/seed000_rare_false_alarms.toml";
        ok(&fdimc(&["run", deck, "--seed", seed, "--trials", "2000", "--quiet", "--out", d]));
        let t = csv_frame(&dir.join("thresholds.csv"));
        let statistic = t.column("statistic").unwrap().str().unwrap();
        let alarms = t.column("detector_false_alarms").unwrap().i64().unwrap();
        let trials = t.column("trials").unwrap().i64().unwrap();
        let whole: Vec<usize> = (0..t.height()).filter(|&i| statistic.get(i) == Some("all")).collect();
        assert!(!whole.is_empty(), "{t}");
        for i in whole {
            let allowed = (0.01 * trials.get(i).unwrap() as f64).floor() as i64;
            assert_eq!(alarms.get(i), Some(allowed), "seed {seed}, row {i}:\n{t}");
        }
    }
    // The deck can ask for the confidence: the run's own thresholds are then Wilks' order statistic,
    // and say so.
    let deck = edited_deck(
        tmp.path(),
        "seed000_rare_false_alarms.toml",
        &[("[monte_carlo]\n", "[monte_carlo]\nconfidence = 0.95\n")],
        "confident.toml",
    );
    let dir = tmp.path().join("confident");
    let d = dir.to_str().unwrap();
    ok(&fdimc(&["run", deck.to_str().unwrap(), "--seed", "1003", "--trials", "2000", "--quiet", "--out", d]));
    let t = csv_frame(&dir.join("thresholds.csv"));
    let statistic = t.column("statistic").unwrap().str().unwrap();
    let (alarms, trials) =
        (t.column("detector_false_alarms").unwrap().i64().unwrap(), t.column("trials").unwrap().i64().unwrap());
    assert_eq!(t.column("confidence").unwrap().f64().unwrap().get(0), Some(0.95), "{t}");
    for i in (0..t.height()).filter(|&i| statistic.get(i) == Some("all")) {
        let n = trials.get(i).unwrap() as u64;
        let allowed = fdimc::engine::results::thresholds::confident_allowed(n, 0.01, 0.95).unwrap() as i64;
        assert!(allowed < (0.01 * n as f64).floor() as i64, "{allowed}");
        assert_eq!(alarms.get(i), Some(allowed), "row {i}:\n{t}");
    }
    // Another target keeps the deck's confidence (each from the command line where given, else the deck).
    let stdout = ok(&fdimc(&["summarize", d, "--target-pfa", "0.05"]));
    assert!(stdout.contains("calibrated at Pfa 0.05 with 0.95 confidence"), "{stdout}");
    assert!(dir.join("calibrations/pfa_0.05_confidence_0.95/thresholds.csv").is_file());
}

/// Every file under `dir` with its bytes, for "nothing already written changed".
fn folder_bytes(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().is_some_and(|n| n != ".fdimc-lock") {
                // (The lock file names its last holder: bookkeeping, rewritten by every command.)
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// A bad deck pointed at a folder that holds a run changes nothing there (issue 49, item 5): for the CI
/// deck of every kind and the log-replay deck, each line with a value, given values of the wrong type,
/// out of range, non-finite, long or non-ASCII, or deleted, runs as `run --out` (refused: the folder
/// holds a run, or the deck is bad), `run --resume` (refused: another deck, or bad) and, where the deck
/// is bad, `run --force`; every one exits 2 with the deck's path in the message where the deck is at
/// fault, and the folder's bytes stay as they were. The replay deck is also pointed at damaged copies
/// of its log (cut short, a zeroed header, a parameter record's length changed, a missing file).
#[test]
fn a_bad_deck_leaves_an_existing_run_untouched() {
    let tmp = tempfile::tempdir().unwrap();
    let replay = edited_deck(
        tmp.path(),
        "replay_px4.toml",
        &[("trials_per_class = 300", "trials_per_class = 20")],
        "replay.toml",
    );
    let mut total = 0;
    for (n, deck) in ["studies/ci_seed000.toml", "studies/ci_seed001.toml", "studies/ci_seed002.toml"]
        .into_iter()
        .map(PathBuf::from)
        .chain(["studies/ci_seed003.toml", "studies/ci_seed004.toml"].into_iter().map(PathBuf::from))
        .chain([replay.clone()])
        .enumerate()
    {
        let dir = tmp.path().join(format!("run{n}"));
        let d = dir.to_str().unwrap();
        ok(&fdimc(&["run", deck.to_str().unwrap(), "--trials", "8", "--quiet", "--out", d]));
        let before = folder_bytes(&dir);
        let original = std::fs::read_to_string(&deck).unwrap();
        let lines: Vec<&str> = original.lines().collect();
        let bad_values = ["nan", "-1", "1e308", "\"ünïcødé ✈\"", "[]", "true"];
        let mut decks: Vec<PathBuf> = Vec::new();
        for (i, line) in lines.iter().enumerate().filter(|(_, l)| l.contains('=') && !l.trim_start().starts_with('#')) {
            let key = &line[..line.find('=').unwrap()];
            let mut variants: Vec<String> = bad_values.iter().map(|v| format!("{key}= {v}")).collect();
            variants.push(String::new());
            for (v, variant) in variants.iter().enumerate() {
                let mut edited = lines.clone();
                edited[i] = variant;
                let bad = tmp.path().join(format!("bad{n}_{i}_{v}.toml"));
                std::fs::write(&bad, edited.join("\n")).unwrap();
                decks.push(bad);
            }
        }
        if deck == replay {
            decks.extend(damaged_logs(tmp.path()).into_iter().enumerate().map(|(i, log)| {
                let text = original.replacen("file = \"", &format!("file = \"{}\" # was \"", log.display()), 1);
                let bad = tmp.path().join(format!("bad_log_{i}.toml"));
                std::fs::write(&bad, text).unwrap();
                bad
            }));
        }
        for bad in &decks {
            let bad = bad.to_str().unwrap();
            let valid = fdimc(&["validate", bad]).status.success();
            let mut modes =
                vec![vec!["run", bad, "--quiet", "--out", d], vec!["run", bad, "--quiet", "--resume", "--out", d]];
            if !valid {
                modes.push(vec!["run", bad, "--quiet", "--force", "--out", d]);
            }
            for args in modes {
                let out = fdimc(&args);
                let err = text(&out.stderr);
                assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
                assert!(valid || err.contains(bad), "{args:?}: the message does not name the deck: {err}");
                assert!(!err.contains("panicked"), "{args:?}: {err}");
            }
        }
        assert!(decks.len() > 50, "{}: {}", deck.display(), decks.len());
        total += decks.len();
        let after = folder_bytes(&dir);
        let changed: Vec<_> = before.keys().chain(after.keys()).filter(|k| before.get(*k) != after.get(*k)).collect();
        assert!(changed.is_empty(), "{}: a bad deck changed {changed:?}", deck.display());
    }
    assert!(total >= 900, "{total} edited decks (900 today)");
}

/// Damaged copies of the replay deck's log in `dir`: cut at a third, its header zeroed, one parameter
/// record's length byte changed (px4-ulog 0.6.1 panics on it, fdimc reports a malformed record), and
/// a path with no file.
fn damaged_logs(dir: &Path) -> Vec<PathBuf> {
    let source =
        std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/logs/sample_appended_multiple.ulg")).unwrap();
    let small = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/logs/sample_log_small.ulg")).unwrap();
    let mut header_zeroed = source.clone();
    header_zeroed[..16].fill(0);
    let mut record = small;
    record[36_809] = 102;
    let mut out: Vec<PathBuf> = [source[..source.len() / 3].to_vec(), header_zeroed, record]
        .into_iter()
        .enumerate()
        .map(|(i, bytes)| {
            let path = dir.join(format!("damaged_{i}.ulg"));
            std::fs::write(&path, bytes).unwrap();
            path
        })
        .collect();
    out.push(dir.join("no_such_log.ulg"));
    out
}

/// ROC (`roc.csv`): per detector, points whose Pfa rises as Pd does; the calibrated point repeats
/// thresholds.csv's false alarms and the calibrated Pd of detectors.csv exactly, and the report draws
/// every detector's curve from it.
#[test]
fn the_roc_passes_through_the_calibrated_point() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    ok(&fdimc(&["run", CI_DECK, "--quiet", "--out", dir.to_str().unwrap()]));
    let roc = csv_frame(&dir.join("roc.csv"));
    let thresholds = csv_frame(&dir.join("thresholds.csv"));
    let detectors = csv_frame(&dir.join("detectors.csv"));
    let s = |df: &polars::prelude::DataFrame, c: &str| df.column(c).unwrap().str().unwrap().clone();
    let n = |df: &polars::prelude::DataFrame, c: &str| {
        df.column(c).unwrap().cast(&polars::prelude::DataType::Float64).unwrap().f64().unwrap().clone()
    };
    let (det, calibrated) = (s(&roc, "detector"), roc.column("calibrated").unwrap().bool().unwrap().clone());
    let (pfa, pd, false_alarms, detected) =
        (n(&roc, "pfa"), n(&roc, "pd"), n(&roc, "false_alarms"), n(&roc, "detected"));
    assert_eq!(s(&roc, "pfa_read_on").get(0), Some("calibration trials"));
    for name in ["seed", "fast"] {
        let rows: Vec<usize> = (0..roc.height()).filter(|&i| det.get(i) == Some(name)).collect();
        assert!(rows.len() > 20, "{name}: {} points", rows.len());
        // Scales descend: Pfa and Pd never fall; the first point lets no calibration trial alarm.
        assert_eq!(false_alarms.get(rows[0]), Some(0.0));
        for w in rows.windows(2) {
            assert!(pfa.get(w[1]) >= pfa.get(w[0]) && pd.get(w[1]) >= pd.get(w[0]), "{roc}");
        }
        let c = *rows.iter().find(|&&i| calibrated.get(i) == Some(true)).unwrap();
        let (td, ts) = (s(&thresholds, "detector"), s(&thresholds, "statistic"));
        let t = (0..thresholds.height()).find(|&i| td.get(i) == Some(name) && ts.get(i) == Some("all")).unwrap();
        assert_eq!(false_alarms.get(c), n(&thresholds, "detector_false_alarms").get(t), "{name}");
        let (dd, dset) = (s(&detectors, "detector"), s(&detectors, "thresholds"));
        let d =
            (0..detectors.height()).find(|&i| dd.get(i) == Some(name) && dset.get(i) == Some("calibrated")).unwrap();
        assert_eq!(detected.get(c), n(&detectors, "detected").get(d), "{name}");
        assert_eq!(pd.get(c), n(&detectors, "pd").get(d), "{name}");
    }
    ok(&fdimc(&["report", dir.to_str().unwrap()]));
    let svg = std::fs::read_to_string(dir.join("report/roc.svg")).unwrap();
    assert!(svg.contains("seed calibrated: Pfa") && svg.contains("fast calibrated: Pfa"), "{svg}");
}

/// An ROC against its closed form: the residual of `tests/data/white_residual.toml` is white N(0, 1)
/// (plus a bias of 1 from the onset), so at threshold c a fault-free flight of 200 samples alarms with
/// probability 1 - (1 - 2 Q(c))^200 and a faulty one detects within its 100 samples after the onset
/// with probability 1 - (Phi(c - 1) - Phi(-c - 1))^100. Every point of roc.csv (about 2,000 trials of
/// each) holds both within its 99.9 % Wilson interval; thresholds 3 % off would put most points outside
/// (32 of 37, measured), as would counting the wrong trials (faulty as fault-free, pre-onset windows).
/// The same law end to end: at the deck's threshold (3.5) the summary's Pfa interval (over every flight
/// once: the 2,000 fault-free ones, 200 samples each, and the faulty ones' 100 samples before the
/// onset) holds 0.5 (1 - (1 - 2 Q(3.5))^200) + 0.5 (1 - (1 - 2 Q(3.5))^100) = 0.0671718 (SciPy's
/// `norm.sf`; 0.0888733 and 0.0454704 the two halves), and the calibration
/// at Pfa 0.05 recovers the threshold that law gives, 3.5 x 1.0444993 (SciPy's brentq on the same
/// law), within 5 of its standard errors (0.68 % each from 2,000 fault-free trials: the order
/// statistic's spread over the law's slope, d ln Pfa / d ln c = -14.4).
#[test]
fn the_roc_of_a_white_residual_meets_its_closed_form() {
    use fdimc::engine::stats::intervals::{normal_sf, wilson};
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    ok(&fdimc(&["run", "tests/data/white_residual.toml", "--quiet", "--out", dir.to_str().unwrap()]));
    let roc = csv_frame(&dir.join("roc.csv"));
    let thresholds = csv_frame(&dir.join("thresholds.csv"));
    let whole = thresholds.column("detector_threshold").unwrap().f64().unwrap().get(0).unwrap();
    assert!((whole / (3.5 * 1.0444993082327543) - 1.0).abs() < 5.0 * 0.0068, "calibrated threshold {whole}");
    let detectors = csv_frame(&dir.join("detectors.csv"));
    let set = detectors.column("thresholds").unwrap().str().unwrap();
    let at_deck = (0..detectors.height()).find(|&i| set.get(i) == Some("deck")).unwrap();
    let bound = |c: &str| detectors.column(c).unwrap().f64().unwrap().get(at_deck).unwrap();
    let (lo, hi) = (bound("pfa_lo"), bound("pfa_hi"));
    assert!(lo <= 0.06717184514005914 && 0.06717184514005914 <= hi, "Pfa at the deck's threshold: [{lo}, {hi}]");
    let n = |c: &str| roc.column(c).unwrap().cast(&polars::prelude::DataType::Float64).unwrap().f64().unwrap().clone();
    let (scale, trials, false_alarms, faulty, detected) =
        (n("scale"), n("trials"), n("false_alarms"), n("faulty"), n("detected"));
    assert!(roc.height() > 30, "{roc}");
    let phi = |x: f64| 1.0 - normal_sf(x);
    for i in 0..roc.height() {
        let c = whole * scale.get(i).unwrap();
        let pfa = 1.0 - (1.0 - 2.0 * normal_sf(c)).powi(200);
        let pd = 1.0 - (phi(c - 1.0) - phi(-c - 1.0)).powi(100);
        let count = |x: &polars::prelude::Float64Chunked| x.get(i).unwrap() as u64;
        let (lo, hi) = wilson(count(&false_alarms), count(&trials), 3.29);
        assert!(lo <= pfa && pfa <= hi, "point {i}, threshold {c}: Pfa {pfa} outside [{lo}, {hi}]");
        let (lo, hi) = wilson(count(&detected), count(&faulty), 3.29);
        assert!(lo <= pd && pd <= hi, "point {i}, threshold {c}: Pd {pd} outside [{lo}, {hi}]");
    }
}

/// Coverage against a known law (issue 82, item 1), over 60 seeds of 400 fault-free flights of
/// `tests/data/white_residual.toml`, whose residual is white N(0, 1): a flight of 200 samples alarms at
/// threshold c with probability 1 - (1 - 2 Q(c))^200 (Q from statrs' erfc here, none of fdimc's code).
/// - The deck row's 95 % Wilson interval holds the law's Pfa at c = 3.5 (0.0888733) in at least 52 of
///   60 seeds (57 expected; 51 or fewer with probability 0.003 if the intervals hold 95 %).
/// - The calibration at Pfa 0.05 with 95 % confidence gives a threshold the law lets through more than
///   0.05 in at most 8 of 60 seeds (3 expected; 9 or more with probability 0.004 at 5 %), and the plain
///   calibration (no confidence) in about half (the order statistic's median: 20 to 40 of 60).
/// - Past Wilks' count: at Pfa 1e-3 with 95 % confidence 400 trials are too few for the order statistic
///   (2,995 needed), and the thresholds are the tail fit's 95 % bound; the law lets them through more
///   than 1e-3 in at most 8 of 60 seeds (the fit's own test finds it conservative on this law: 0 of
///   60 seen).
#[test]
fn wilson_intervals_and_confident_thresholds_cover_a_known_law_over_seeds() {
    let q = |z: f64| 0.5 * statrs::function::erf::erfc(z / std::f64::consts::SQRT_2);
    let law = |c: f64| -((1.0 - 2.0 * q(c)).ln() * 200.0).exp_m1();
    assert!((law(3.5) - 0.0888733).abs() < 1e-6, "{}", law(3.5));
    let deck = std::fs::read_to_string("tests/data/white_residual.toml").unwrap();
    assert!(deck.contains("fault_free_fraction = 0.5") && deck.contains("target_pfa = 0.05"));
    let tmp = tempfile::tempdir().unwrap();
    let mut paths = Vec::new();
    for (name, target) in [
        ("confident.toml", "0.05\nconfidence = 0.95"),
        ("plain.toml", "0.05"),
        ("past_wilks.toml", "0.001\nconfidence = 0.95"),
    ] {
        let path = tmp.path().join(name);
        let text = deck
            .replace("fault_free_fraction = 0.5", "fault_free_fraction = 1.0")
            .replace("target_pfa = 0.05", &format!("target_pfa = {target}"));
        std::fs::write(&path, text).unwrap();
        paths.push(path);
    }
    let dir = tmp.path().join("run");
    let (mut covered, mut confident_over, mut plain_over, mut past_wilks_over) = (0, 0, 0, 0);
    for seed in 1..=60 {
        for (k, path) in paths.iter().enumerate() {
            let args = ["run", path.to_str().unwrap(), "--trials", "400", "--seed", &seed.to_string()];
            ok(&fdimc(&[&args[..], &["--quiet", "--force", "--out", dir.to_str().unwrap()]].concat()));
            let t = csv_frame(&dir.join("thresholds.csv"));
            let stat = t.column("statistic").unwrap().str().unwrap().clone();
            let i = (0..t.height()).find(|&i| stat.get(i) == Some("y")).unwrap();
            let c = t.column("detector_threshold").unwrap().f64().unwrap().get(i).unwrap();
            if k == 0 {
                confident_over += (law(c) > 0.05) as usize;
                let d = csv_frame(&dir.join("detectors.csv"));
                let set = d.column("thresholds").unwrap().str().unwrap().clone();
                let at = (0..d.height()).find(|&i| set.get(i) == Some("deck")).unwrap();
                let f = |name: &str| d.column(name).unwrap().f64().unwrap().get(at).unwrap();
                covered += (f("pfa_lo") <= law(3.5) && law(3.5) <= f("pfa_hi")) as usize;
            } else if k == 1 {
                plain_over += (law(c) > 0.05) as usize;
            } else {
                past_wilks_over += (law(c) > 0.001) as usize;
            }
        }
    }
    println!(
        "of 60 seeds: Wilson covered {covered}, confident over 0.05 {confident_over}, plain {plain_over}, past Wilks over 0.001 {past_wilks_over}"
    );
    assert!(past_wilks_over <= 8, "the tail fit's 95 % bound let through more than 1e-3 in {past_wilks_over} of 60");
    assert!(covered >= 52, "the 95 % Wilson interval held the law in {covered} of 60 seeds");
    assert!(confident_over <= 8, "95 %-confident thresholds let through more than 0.05 in {confident_over} of 60");
    assert!((20..=40).contains(&plain_over), "plain thresholds over 0.05 in {plain_over} of 60");
}

/// The false-alarm row's one-sided 95 % bound against a known law (issue 82, item 1): `safety.csv`'s
/// `value_upper_95` of the plain Monte Carlo row, over 60 seeds of 400 fault-free trials. The deck is
/// `tests/data/white_residual.toml` stretched to trials of 360 samples of 1 s at the threshold 3.7, so
/// a trial alarms with probability p = 1 - (1 - 2 Q(3.7))^360 = 0.0746879 and, its residual being white,
/// an hour of 10 trials with 1 - (1 - p)^10 = 0.539868 exactly (the conversion is exact here; statrs'
/// erfc in the test). Wilson's one-sided bound at 400 trials covers that p with probability 0.94973 (the
/// binomial sum over the counts, computed in the test), so the per-hour bound holds the hour's truth in
/// at least 52 of 60 seeds (51 or fewer with probability 0.003), and lies inside the two-sided
/// interval's upper end (a wider bound would cover more for the wrong reason). The row is read at the
/// deck's threshold (`summarize --thresholds`): the run's answer is at its calibration's.
#[test]
fn the_one_sided_bound_of_false_alarms_per_hour_covers_a_known_law_over_seeds() {
    let q = |z: f64| 0.5 * statrs::function::erf::erfc(z / std::f64::consts::SQRT_2);
    let p = -((1.0 - 2.0 * q(3.7)).ln() * 360.0).exp_m1();
    let hour = -((-p).ln_1p() * 10.0).exp_m1();
    assert!((p - 0.0746879).abs() < 1e-6 && (hour - 0.539868).abs() < 1e-6, "{p} {hour}");
    // Wilson's one-sided upper bound written out (z = 1.6448536), and its coverage at p over Bin(400, p).
    let upper = |k: f64, n: f64| {
        let (z, f) = (1.6448536269514722_f64, k / n);
        let d = 1.0 + z * z / n;
        ((f + z * z / (2.0 * n)) + z * (f * (1.0 - f) / n + z * z / (4.0 * n * n)).sqrt()) / d
    };
    let mut log_pmf = 400.0 * (-p).ln_1p();
    let mut coverage = 0.0;
    for k in 0..=400 {
        if k > 0 {
            log_pmf += ((400 - k + 1) as f64 / k as f64).ln() + (p / (1.0 - p)).ln();
        }
        coverage += if upper(k as f64, 400.0) >= p { log_pmf.exp() } else { 0.0 };
    }
    assert!((coverage - 0.94973).abs() < 5e-5, "coverage {coverage}");
    let deck = std::fs::read_to_string("tests/data/white_residual.toml").unwrap();
    let edits = [
        ("duration_s = 2.0", "duration_s = 360.0"),
        ("dt_s = 0.01", "dt_s = 1.0"),
        ("thresholds = [3.5]", "thresholds = [3.7]"),
        ("fault_free_fraction = 0.5", "fault_free_fraction = 1.0"),
    ];
    let text = edits.iter().fold(deck.clone(), |text, (from, to)| {
        assert!(text.contains(from), "{from}");
        text.replace(from, to)
    });
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("hour.toml");
    std::fs::write(&path, text).unwrap();
    let at_deck = tmp.path().join("deck_thresholds.csv");
    std::fs::write(&at_deck, "detector,statistic,per_statistic_threshold,detector_threshold\nwhite,y,3.7,3.7\n")
        .unwrap();
    let dir = tmp.path().join("run");
    let mut covered = 0;
    for seed in 1..=60 {
        let args = ["run", path.to_str().unwrap(), "--trials", "400", "--seed", &seed.to_string(), "--quiet"];
        ok(&fdimc(&[&args[..], &["--force", "--out", dir.to_str().unwrap()]].concat()));
        ok(&fdimc(&["summarize", dir.to_str().unwrap(), "--thresholds", at_deck.to_str().unwrap()]));
        let s = csv_frame(&dir.join("validation/safety.csv"));
        let set = s.column("thresholds").unwrap().str().unwrap().clone();
        assert!(set.iter().all(|v| v == Some("validation")), "{s}");
        let method = s.column("method").unwrap().str().unwrap().clone();
        let rows: Vec<usize> =
            (0..s.height()).filter(|&i| method.get(i).unwrap().starts_with("plain Monte Carlo: ")).collect();
        assert_eq!(rows.len(), 1, "{s}");
        assert!(method.get(rows[0]).unwrap().ends_with("of 400 fault-free trials of 360 s"), "{s}");
        let f = |name: &str| s.column(name).unwrap().f64().unwrap().get(rows[0]).unwrap();
        let (value, hi, bound) = (f("value"), f("value_hi"), f("value_upper_95"));
        assert!(value <= bound && bound < hi, "seed {seed}: {value} {bound} {hi}");
        covered += (hour <= bound) as usize;
    }
    println!("of 60 seeds the one-sided bound held {hour} per hour in {covered}");
    assert!(covered >= 52, "the one-sided 95 % bound held the hour's truth in {covered} of 60 seeds");
}

/// The miss before the hazard against its exact answer (issue 82, item 1): on
/// `tests/data/white_residual.toml` the residual is white N(0, 1) plus the fault's bias b from the
/// onset, so a fault is missed within a time to hazard of 0.195 s (the 20 samples at delays 0 to 0.19
/// s) with probability (Phi(c - b) - Phi(-c - b))^20 at threshold c = 3.5 (statrs' erfc here): 0.882807
/// for b = 1, by plain trials (`detectors.csv`'s 95 % interval at the deck's threshold) and 6.2e-4 for
/// b = 3, by splitting in time (`rare-event --miss-before-hazard`'s interval).
#[test]
fn the_miss_before_the_hazard_meets_a_white_residuals_exact_answer() {
    let phi = |x: f64| 1.0 - 0.5 * statrs::function::erf::erfc(x / std::f64::consts::SQRT_2);
    let exact = |b: f64| (phi(3.5 - b) - phi(-3.5 - b)).powi(20);
    let deck = std::fs::read_to_string("tests/data/white_residual.toml").unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let with_bias = |b: &str| -> PathBuf {
        let text = deck
            .replace("fault_free_fraction = 0.5", "fault_free_fraction = 0.1")
            .replace("size_sigma = 1.0", &format!("size_sigma = {b}"))
            + "\n[monte_carlo.time_to_hazard_s]\nbias = 0.195\n";
        let path = tmp.path().join(format!("bias{b}.toml"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let one = with_bias("1.0");
    let run = tmp.path().join("run");
    ok(&fdimc(&["run", one.to_str().unwrap(), "--quiet", "--out", run.to_str().unwrap()]));
    let d = csv_frame(&run.join("detectors.csv"));
    let set = d.column("thresholds").unwrap().str().unwrap().clone();
    let at = (0..d.height()).find(|&i| set.get(i) == Some("deck")).unwrap();
    let f = |name: &str| d.column(name).unwrap().f64().unwrap().get(at).unwrap();
    let (p, lo, hi) = (f("p_miss_before_hazard"), f("p_miss_before_hazard_lo"), f("p_miss_before_hazard_hi"));
    assert!((exact(1.0) - 0.882807).abs() < 1e-6, "{}", exact(1.0));
    println!("plain {p} [{lo}, {hi}] vs exact {}", exact(1.0));
    assert!(lo <= exact(1.0) && exact(1.0) <= hi, "plain {p} [{lo}, {hi}] vs exact {}", exact(1.0));
    let three = with_bias("3.0");
    let out = tmp.path().join("split");
    let args = ["rare-event", three.to_str().unwrap(), "--miss-before-hazard", "--estimator", "splitting", "--quiet"];
    ok(&fdimc(&[&args[..], &["--out", out.to_str().unwrap()]].concat()));
    let t = csv_frame(&out.join("miss_before_hazard.csv"));
    let g = |name: &str| t.column(name).unwrap().f64().unwrap().get(0).unwrap();
    let (p, lo, hi) = (g("p_miss_before_hazard"), g("p_miss_before_hazard_lo"), g("p_miss_before_hazard_hi"));
    println!("splitting {p} [{lo}, {hi}] vs exact {}", exact(3.0));
    assert!(lo <= exact(3.0) && exact(3.0) <= hi, "splitting {p} [{lo}, {hi}] vs exact {}", exact(3.0));
    assert!(hi / lo < 3.0, "[{lo}, {hi}]");
}

/// A run's miss before the hazard at the deck's thresholds: `detectors.csv`'s 95 % interval (its
/// units more than 3,400: the miss tests' 4,000 trials, a tenth fault-free).
fn deck_miss_interval(run: &Path) -> (f64, f64) {
    let d = csv_frame(&run.join("detectors.csv"));
    let set = d.column("thresholds").unwrap().str().unwrap().clone();
    let at = (0..d.height()).find(|&i| set.get(i) == Some("deck")).unwrap();
    let f = |name: &str| d.column(name).unwrap().f64().unwrap().get(at).unwrap();
    assert!(d.column("hazard_units").unwrap().i64().unwrap().get(at).unwrap() > 3400);
    (f("p_miss_before_hazard_lo"), f("p_miss_before_hazard_hi"))
}

/// A one-statistic run's calibrated threshold and `safety.csv`'s miss before the hazard there: its
/// interval and one-sided 95 % bound, `(threshold, lo, hi, upper_95)`.
fn calibrated_miss_row(run: &Path) -> (f64, f64, f64, f64) {
    let t = csv_frame(&run.join("thresholds.csv"));
    let threshold = t.column("detector_threshold").unwrap().f64().unwrap().get(0).unwrap();
    let s = csv_frame(&run.join("safety.csv"));
    let figure = s.column("figure").unwrap().str().unwrap().clone();
    let row = (0..s.height()).find(|&i| figure.get(i) == Some("missed detection before the hazard")).unwrap();
    assert_eq!(s.column("thresholds").unwrap().str().unwrap().get(row), Some("calibrated"));
    let g = |name: &str| s.column(name).unwrap().f64().unwrap().get(row).unwrap();
    (threshold, g("value_lo"), g("value_hi"), g("value_upper_95"))
}

/// The miss before the hazard where the residual itself has memory (issue 82, item 1): a one-state
/// plant with a slow mode (a = -1 /s, process noise 0.141067 per step) under a gain-0 filter (its
/// eigenvalue the plant's own), so the residual is an AR(1) state error (time constant 1 s) plus white
/// sensor noise, and a bias fault of `size_sigma` from 1 s (sample 100), missed if no sample of the
/// 20 at delays 0 to 0.19 s exceeds the threshold. The exact answer is `src/exact/slow_mode.rs`
/// (checked against NumPy): 0.53173 at b = 2 and threshold 4, where each sample taken alone would say
/// 0.21975. Over 40 seeds of about 3,600 faulty trials each, `detectors.csv`'s 95 % interval at the
/// deck's threshold holds the exact miss for b = 2 and for faults of random size (b uniform on [1, 3]:
/// 0.52623) and for faults of random onset (b = 2, the onset uniform on [0.5, 1.5] s: 0.53714, below),
/// and `safety.csv`'s interval at the calibrated threshold (Pfa 0.05, new each seed) holds the exact miss
/// there, each in at least 33 of 40 seeds (38 expected; 32 or fewer with probability 7e-4).
///
/// A random onset `u = 0.01 (m + f)` s (`m` whole, `f` in [0, 1)) is faulty from sample `m + 1` (the
/// samples at `t >= u`), and the samples within 0.195 s of it are 19 where `f < 0.5` and 20 where
/// `f >= 0.5`: the exact miss is the average over `m` from 50 to 149 of the two windows' misses from
/// onset sample `m + 1`, each weighing half.
#[test]
fn the_miss_before_the_hazard_of_a_slow_mode_residual_meets_its_exact_law() {
    let window = exact_slow_mode::slow_mode_window();
    let (fixed, random) = (window.miss(2.0, 801), window.miss_uniform(1.0, 3.0, 401));
    let onsets: f64 = (50..150)
        .flat_map(|m| {
            [19, 20].map(|samples| exact_slow_mode::SlowModeWindow { onset: m + 1, window: samples, ..window })
        })
        .map(|w| w.miss(2.0, 401))
        .sum::<f64>()
        / 200.0;
    assert!((onsets - 0.5371403224).abs() < 1e-9, "{onsets}");
    let tmp = tempfile::tempdir().unwrap();
    let write = |name: &str, size: &str, onset: &str| -> PathBuf {
        let text = slow_mode_deck(4.0, "0.1", size).replace("onset_s = 1.0", &format!("onset_s = {onset}"))
            + "\n[monte_carlo.time_to_hazard_s]\nbias = 0.195\n";
        assert!(text.contains(&format!("onset_s = {onset}")));
        let path = tmp.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let decks = [
        (write("fixed.toml", "2.0", "1.0"), fixed),
        (write("random.toml", "{ range = [1.0, 3.0] }", "1.0"), random),
        (write("onsets.toml", "2.0", "{ range = [0.5, 1.5] }"), onsets),
    ];
    let run = tmp.path().join("run");
    let (mut covered, mut calibrated_covered) = ([0; 3], 0);
    for seed in 1..=40 {
        for (k, (path, exact)) in decks.iter().enumerate() {
            let args = ["run", path.to_str().unwrap(), "--seed", &seed.to_string(), "--quiet", "--force", "--out"];
            ok(&fdimc(&[&args[..], &[run.to_str().unwrap()]].concat()));
            let (lo, hi) = deck_miss_interval(&run);
            covered[k] += (lo <= *exact && *exact <= hi) as usize;
            if k == 0 {
                let (threshold, lo, hi, _) = calibrated_miss_row(&run);
                let exact =
                    exact_slow_mode::SlowModeWindow { threshold, ..exact_slow_mode::slow_mode_window() }.miss(2.0, 401);
                calibrated_covered += (lo <= exact && exact <= hi) as usize;
            }
        }
    }
    println!(
        "of 40 seeds: b = 2 covered {}, b uniform on [1, 3] {}, onsets uniform on [0.5, 1.5] s {}, at the \
         calibrated threshold {calibrated_covered}",
        covered[0], covered[1], covered[2]
    );
    for (what, n) in [
        ("b = 2", covered[0]),
        ("b uniform on [1, 3]", covered[1]),
        ("onsets uniform on [0.5, 1.5] s", covered[2]),
        ("calibrated", calibrated_covered),
    ] {
        assert!(n >= 33, "{what}: the interval held the exact miss in {n} of 40 seeds");
    }
}

/// The miss before the hazard where the statistic has memory (issue 82, item 1): a CUSUM (`kind =
/// "cusum"`, drift 1) on `tests/data/white_residual.toml`'s residual, white N(0, 1) with the fault's bias
/// b from the onset at 1 s (sample 100). The exact answer is Brook and Evans' Markov chain
/// (`src/exact/cusum.rs`, checked against NumPy by its own test): the CUSUM runs 100 fault-free
/// samples from 0, then the window's 20 (delays 0 to 0.19 s).
/// - Over 40 seeds, b = 1, about 3,600 faulty trials each: `detectors.csv`'s 95 % interval at the deck's
///   threshold 4 holds the chain's answer (0.31075), and at the calibrated threshold (Pfa 0.05, a new one each
///   seed) `safety.csv`'s interval and its one-sided 95 % bound (`value_upper_95`) hold the chain's
///   answer there, each in at least 33 of 40 seeds (38 expected; 32 or fewer with probability 7e-4 at
///   95 %). The deck keeps the profiles' default 5 % grid: their exact point at the time to hazard
///   makes the replay exact (without it the figure was high, held in 15 of 40 seeds, 2026-12-06). On
///   one seed the full profiles (`profile_resolution = 0`) give the same misses and, with a detection
///   window of 0.1 s, the same detections at the calibrated threshold.
/// - b = 3, threshold 25: splitting in time's interval (`rare-event --miss-before-hazard`, 3,000
///   particles by 32 replicas) holds 2.4409e-4 and is an answer.
#[test]
fn the_miss_before_the_hazard_of_a_cusum_meets_brook_and_evans_chain() {
    use exact_cusum::CusumWindow;
    let window = |threshold: f64, bias: f64| CusumWindow { drift: 1.0, threshold, bias, before: 100, window: 20 };
    let at_four = window(4.0, 1.0).miss(0.04, 30.0);
    let tmp = tempfile::tempdir().unwrap();
    let write = |name: &str, threshold: &str, bias: &str| -> PathBuf {
        let text = fdimc::cli::verify::cusum_deck(threshold, bias) + "\n[monte_carlo.time_to_hazard_s]\nbias = 0.195\n";
        let path = tmp.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let plain = write("plain.toml", "4.0", "1.0");
    let run = tmp.path().join("run");
    let (mut deck_covered, mut covered, mut bounded) = (0, 0, 0);
    for seed in 1..=40 {
        let args = ["run", plain.to_str().unwrap(), "--seed", &seed.to_string(), "--quiet", "--force", "--out"];
        ok(&fdimc(&[&args[..], &[run.to_str().unwrap()]].concat()));
        let (lo, hi) = deck_miss_interval(&run);
        deck_covered += (lo <= at_four && at_four <= hi) as usize;
        let (calibrated, lo, hi, upper_95) = calibrated_miss_row(&run);
        let exact = window(calibrated, 1.0).miss(0.04, 30.0);
        assert!(upper_95 < hi, "the one-sided bound is below the two-sided interval's end");
        covered += (lo <= exact && exact <= hi) as usize;
        bounded += (exact <= upper_95) as usize;
    }
    println!("of 40 seeds: deck threshold covered {deck_covered}, calibrated covered {covered}, one-sided {bounded}");
    for (what, n) in [
        ("the deck threshold's interval", deck_covered),
        ("the calibrated one's", covered),
        ("the one-sided bound", bounded),
    ] {
        assert!(n >= 33, "{what} held the chain's answer in {n} of 40 seeds");
    }
    // The full profiles on the same trials: the same calibrated threshold, misses and detections (with
    // a detection window, whose end the profiles also keep exactly), and no caveat in the statement.
    let figures = |deck: &Path, out: &str| {
        let dir = tmp.path().join(out);
        let args = ["run", deck.to_str().unwrap(), "--seed", "40", "--quiet", "--force", "--out"];
        ok(&fdimc(&[&args[..], &[dir.to_str().unwrap()]].concat()));
        let s = csv_frame(&dir.join("safety.csv"));
        let figure = s.column("figure").unwrap().str().unwrap().clone();
        let row = (0..s.height()).find(|&i| figure.get(i) == Some("missed detection before the hazard")).unwrap();
        let said = s.column("assumptions").unwrap().str().unwrap().get(row).unwrap().to_string();
        assert!(!said.contains("replayed") && !said.contains("may be high"), "{said}");
        let d = csv_frame(&dir.join("detectors.csv"));
        let set = d.column("thresholds").unwrap().str().unwrap().clone();
        let at = (0..d.height()).find(|&i| set.get(i) == Some("calibrated")).unwrap();
        let count = |name: &str| {
            d.column(name).unwrap().cast(&polars::prelude::DataType::Int64).unwrap().i64().unwrap().get(at)
        };
        let threshold =
            csv_frame(&dir.join("thresholds.csv")).column("detector_threshold").unwrap().f64().unwrap().get(0);
        (threshold, count("missed_before_hazard"), count("hazard_units"), count("detected"))
    };
    let with = |name: &str, extra: &str| {
        let text =
            std::fs::read_to_string(&plain).unwrap().replace("onset_s = 1.0", &format!("onset_s = 1.0\n{extra}"));
        let path = tmp.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let grid = figures(&plain, "grid");
    let full = figures(&with("full.toml", "profile_resolution = 0.0"), "full");
    let in_window = "detection_window_s = 0.1";
    let grid_window = figures(&with("grid_window.toml", in_window), "grid_window");
    let full_window =
        figures(&with("full_window.toml", &format!("{in_window}\nprofile_resolution = 0.0")), "full_window");
    println!("5 % grid {grid:?} and full profiles {full:?}; with the window {grid_window:?} and {full_window:?}");
    assert_eq!(grid, full);
    assert_eq!(grid_window, full_window);
    assert!(grid_window.3 < grid.3 && grid_window.1 > grid.1, "the window cuts detections");
    let rare = write("rare.toml", "25.0", "3.0");
    let exact = window(25.0, 3.0).miss(0.025, 30.0);
    assert!((exact / 2.440938e-4 - 1.0).abs() < 1e-5, "{exact}");
    let out = tmp.path().join("split");
    // The CUSUM's misses are decided in the window's last samples, where most particles die at once:
    // 3,000 particles a replica give an answer (fewer: an interval the table marks as no answer).
    let args = ["rare-event", rare.to_str().unwrap(), "--miss-before-hazard", "--estimator", "splitting", "--quiet"];
    let more = ["--particles", "3000", "--replicas", "32", "--out", out.to_str().unwrap()];
    ok(&fdimc(&[&args[..], &more[..]].concat()));
    let t = csv_frame(&out.join("miss_before_hazard.csv"));
    let g = |name: &str| t.column(name).unwrap().f64().unwrap().get(0).unwrap();
    let (p, lo, hi) = (g("p_miss_before_hazard"), g("p_miss_before_hazard_lo"), g("p_miss_before_hazard_hi"));
    println!("splitting {p} [{lo}, {hi}] vs the chain's {exact}");
    assert_eq!(t.column("answer").unwrap().bool().unwrap().get(0), Some(true));
    assert!(lo <= exact && exact <= hi && hi / lo < 3.0, "splitting {p} [{lo}, {hi}] vs the chain's {exact}");
}

/// P(an alarm within `samples`) of that deck's CUSUM at threshold `h`, from g = 0: Brook and Evans' chain.
fn fault_free_cusum_alarm(h: f64, samples: usize) -> f64 {
    let chain = exact_cusum::CusumWindow { drift: 1.0, threshold: h, bias: 0.0, before: 0, window: samples };
    1.0 - chain.miss(0.04, 0.0)
}

/// `tests/data/white_residual.toml` as a fault-free CUSUM deck (drift 1, threshold `h`) in `dir`: Page's
/// CUSUM on |r| with r white N(0, 1), whose alarm probability over any window Brook and Evans' chain
/// gives exactly (`src/exact/cusum.rs`).
fn fault_free_cusum_deck(dir: &Path, h: f64) -> PathBuf {
    let deck = std::fs::read_to_string("tests/data/white_residual.toml").unwrap();
    let path = dir.join("cusum.toml");
    let text = deck
        .replace("kind = \"detection_filter\"", "kind = \"cusum\"\ndrift = [1.0]")
        .replace("thresholds = [3.5]", &format!("thresholds = [{h:?}]"))
        .replace("fault_free_fraction = 0.5", "fault_free_fraction = 1.0");
    std::fs::write(&path, text).unwrap();
    path
}

/// Splitting over flights against an exact law where the statistic has memory (issue 82, item 1): the
/// CUSUM (drift 1, threshold 10) on `tests/data/white_residual.toml`'s fault-free residual, flights of
/// 20 s in segments of the deck's 2 s trials, every one starting at g = 0. Brook and Evans' chain
/// (`src/exact/cusum.rs`) gives P(an alarm in 200 samples) and in 2,000; `rare-event
/// --estimator splitting --flight-s 20` (500 particles by 32 replicas) answers, and its intervals per
/// segment and per flight hold them.
#[test]
fn splitting_over_flights_meets_a_cusums_exact_law() {
    let (segment, flight) = (fault_free_cusum_alarm(10.0, 200), fault_free_cusum_alarm(10.0, 2000));
    let tmp = tempfile::tempdir().unwrap();
    let path = fault_free_cusum_deck(tmp.path(), 10.0);
    let out = tmp.path().join("flights");
    let args = ["rare-event", path.to_str().unwrap(), "--estimator", "splitting", "--flight-s", "20"];
    let more = ["--particles", "500", "--replicas", "32", "--quiet", "--out", out.to_str().unwrap()];
    ok(&fdimc(&[&args[..], &more[..]].concat()));
    let t = csv_frame(&out.join("per_hour.csv"));
    let f = |name: &str| t.column(name).unwrap().f64().unwrap().get(0).unwrap();
    println!(
        "segment {} [{}, {}] vs {segment}; flight {} [{}, {}] vs {flight}",
        f("pfa_per_segment"),
        f("pfa_per_segment_lo"),
        f("pfa_per_segment_hi"),
        f("pfa_per_flight"),
        f("pfa_per_flight_lo"),
        f("pfa_per_flight_hi")
    );
    assert_eq!(t.column("answer").unwrap().bool().unwrap().get(0), Some(true), "{t}");
    assert!(f("pfa_per_segment_lo") <= segment && segment <= f("pfa_per_segment_hi"), "{t} vs {segment}");
    assert!(f("pfa_per_flight_lo") <= flight && flight <= f("pfa_per_flight_hi"), "{t} vs {flight}");
}

/// The extremal index's 95 % interval over seeds against a CUSUM's exact index (issue 82, item 1). The
/// CUSUM (drift 1, threshold 7) on the white residual: Brook and Evans' chain gives P(an alarm in a 2 s
/// segment of 200 samples) = 0.025632 and in a 20 s flight of 2,000 = 0.24647, so the exact index
/// `ln(1 - p_flight) / (10 ln(1 - p_segment))` is 1.0898 (segments restart at g = 0, a flight does
/// not). `rare-event --estimator splitting --flight-s 20` (300 particles by 24 replicas) on seeds 1 to
/// 40: the index's interval (the delta method, `src/engine/rare_event/flights.rs`) and the segment's
/// hold their exact values in at least 34 of 40 seeds (33 or fewer at 95 % coverage with probability
/// 0.003; `FDIMC_COVERAGE_SEEDS` more seeds, the least the same binomial rule allows), and the index's
/// and the flight's estimates average within 1.5 % and 1 % of theirs (4 and 4.5 standard errors on the
/// 260-seed spread). On 260 seeds the index covered in 254, the segment in
/// 248 and the flight in 244 (93.8 %); seeds 1 to 40 happen to miss the flight 8 times, so its
/// coverage is the script's (docs/verification.md (d)), not asserted here. About 35 s.
#[test]
fn the_extremal_index_interval_covers_a_cusums_exact_index_over_seeds() {
    let (segment, flight) = (fault_free_cusum_alarm(7.0, 200), fault_free_cusum_alarm(7.0, 2000));
    let index = (-flight).ln_1p() / (10.0 * (-segment).ln_1p());
    assert!((index - 1.08984).abs() < 2e-4, "the chain's index {index}");
    let tmp = tempfile::tempdir().unwrap();
    let path = fault_free_cusum_deck(tmp.path(), 7.0);
    // FDIMC_COVERAGE_SEEDS raises the seeds (260 gives docs/verification.md's figures), never below 40.
    let seeds: u64 =
        std::env::var("FDIMC_COVERAGE_SEEDS").ok().and_then(|s| s.parse().ok()).map_or(40, |n: u64| n.max(40));
    let least = fewest_covered(seeds);
    let (mut covered, mut sums) = ([0u64; 3], [0.0; 3]);
    for seed in 1..=seeds {
        let t = splitting_over_20_s_flights(&path, seed, &tmp.path().join(format!("seed{seed}")));
        assert_eq!(t.column("answer").unwrap().bool().unwrap().get(0), Some(true), "seed {seed}: {t}");
        let f = |name: &str| t.column(name).unwrap().f64().unwrap().get(0).unwrap();
        for (k, (name, exact)) in [("extremal_index", index), ("pfa_per_segment", segment), ("pfa_per_flight", flight)]
            .into_iter()
            .enumerate()
        {
            covered[k] += (f(&format!("{name}_lo")) <= exact && exact <= f(&format!("{name}_hi"))) as u64;
            sums[k] += f(name) / exact;
        }
    }
    let mean = sums.map(|s| s / seeds as f64);
    println!(
        "of {seeds} seeds, covered: index {}, segment {}, flight {}; mean over exact {mean:?}",
        covered[0], covered[1], covered[2]
    );
    assert!(seeds > 40 || least == 34, "{least}");
    assert!(covered[0] >= least && covered[1] >= least, "covered {covered:?} of {seeds}, at least {least} asked");
    assert!((mean[0] - 1.0).abs() < 0.015 && (mean[2] - 1.0).abs() < 0.01, "mean over exact {mean:?}");
}

/// `rare-event DECK --estimator splitting --flight-s 20` (300 particles by 24 replicas) at `seed` into
/// `out`: its `per_hour.csv`.
fn splitting_over_20_s_flights(deck: &Path, seed: u64, out: &Path) -> polars::prelude::DataFrame {
    let args = ["rare-event", deck.to_str().unwrap(), "--estimator", "splitting", "--flight-s", "20"];
    let seed = seed.to_string();
    let more = ["--particles", "300", "--replicas", "24", "--seed", &seed, "--quiet", "--out", out.to_str().unwrap()];
    ok(&fdimc(&[&args[..], &more[..]].concat()));
    csv_frame(&out.join("per_hour.csv"))
}

/// The extremal index where the residual itself has memory (issue 82, item 1): the slow-mode deck
/// (`slow_mode_deck`, a 1 s mode) fault-free at threshold 6, flights of 20 s in segments of the deck's
/// 2 s trials, each begun from e = 0. The exact law (`src/exact/slow_mode.rs`, checked against
/// NumPy) gives P(an alarm in a trial) = 1.9085e-3 and in a flight 3.6157e-2: an index of 1.9278, the
/// trials' conversion undercounting the flight by half. `rare-event --estimator splitting --flight-s 20`
/// (300 particles by 24 replicas, about 5 s a seed):
/// - over the seeds (8 in CI, `FDIMC_COVERAGE_SEEDS` more), the splitting's intervals per flight and
///   per segment each hold the exact value in at least `fewest_covered` (5 of 8: 95 % coverage falls
///   below with probability 0.004; 40 and 37 of 40 seen). Its own index needs the segment within
///   +-25 %, which a trial's 1.9e-3 from e = 0 often misses at this size (an answer on 11 of 40 seeds;
///   where it answers its index held the exact one on all 11); printed, not asserted;
/// - the conditional estimate on the exact law: its intervals of the index, the flight and the segment
///   each hold the exact value on at least as many seeds (its draws follow `--seed`).
#[test]
fn the_extremal_index_intervals_cover_a_slow_mode_residuals_exact_index_over_seeds() {
    let law = exact_slow_mode::SlowModeWindow { threshold: 6.0, ..exact_slow_mode::slow_mode_window() };
    let (segment, flight) = (law.fault_free_alarm(200, 801), law.fault_free_alarm(2000, 801));
    let index = (-flight).ln_1p() / (10.0 * (-segment).ln_1p());
    assert!((index - 1.92779).abs() < 1e-4, "the exact index {index}");
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("slow.toml");
    std::fs::write(&path, slow_mode_deck(6.0, "1.0", "1.0")).unwrap();
    let seeds: u64 =
        std::env::var("FDIMC_COVERAGE_SEEDS").ok().and_then(|s| s.parse().ok()).map_or(8, |n: u64| n.max(8));
    let least = fewest_covered(seeds);
    let holds = |t: &polars::prelude::DataFrame, name: &str, exact: f64| {
        let f = |name: &str| t.column(name).unwrap().f64().unwrap().get(0).unwrap();
        f(&format!("{name}_lo")) <= exact && exact <= f(&format!("{name}_hi"))
    };
    // The splitting's flight and segment, then the conditional estimate's index, flight and segment.
    let figures = [
        ("pfa_per_flight", flight),
        ("pfa_per_segment", segment),
        ("extremal_index_conditional", index),
        ("conditional_per_flight", flight),
        ("conditional_per_segment", segment),
    ];
    let (mut covered, mut answered, mut index_covered) = ([0u64; 5], 0, 0);
    for seed in 1..=seeds {
        let t = splitting_over_20_s_flights(&path, seed, &tmp.path().join(format!("seed{seed}")));
        for (c, (name, exact)) in covered.iter_mut().zip(figures) {
            *c += holds(&t, name, exact) as u64;
        }
        if t.column("answer").unwrap().bool().unwrap().get(0) == Some(true) {
            answered += 1;
            index_covered += holds(&t, "extremal_index", index) as u64;
        }
    }
    println!(
        "of {seeds} seeds, held the exact value ({}): {covered:?}; the splitting answered on {answered}, its \
         index covered on {index_covered}",
        figures.map(|f| f.0).join(", ")
    );
    assert!(seeds > 8 || least == 5, "{least}");
    assert!(covered.iter().all(|&c| c >= least), "covered {covered:?} of {seeds}, at least {least} asked");
}

/// The tail fit's per-hour row where the trials do not convert to hours (issue 82, item 1): the
/// slow-mode deck (`slow_mode_deck`, a 1 s mode in 2 s trials) fault-free, 20,000 trials a seed,
/// evaluated at threshold 8 (`summarize --thresholds`). The exact law (`src/exact/slow_mode.rs`,
/// checked against NumPy): a trial alarms with probability 1.1141e-6, the hour's 1,800 trials taken as
/// independent (the row's own definition) 2.0034e-3, an hour flown through 5.7084e-3: an index of
/// 2.8547. Per seed:
/// - `safety.csv`'s tail-fit row at those thresholds: its 95 % interval holds 2.0034e-3 on at least
///   `fewest_covered(seeds)` seeds (5 of 8), and a miss carries the fit's doubts in its statement.
///   The fit extrapolates 200 times past 1/trials here: with the free shape's upper end the interval
///   held on only 16 of 20 seeds, every miss too low; its upper end now trusts no shape below 0
///   (`TailFit::survival_interval_conservative`) and held on 20 of 20 (FDIMC_COVERAGE_SEEDS=20, 110 s);
/// - its role is "a lower bound" naming the index of fdimc's own conversion check (`hour_conversion`:
///   Sidak's bound over the hour and over a trial), 2.867, within [1, 1.01] of the exact index;
/// - `tail.csv`'s thresholds for 1e-5, 1e-7 and 1e-9 per hour (7.3 to 12.2 over seeds): their
///   `hour_over_conversion` within [0.999, 1.03] of the exact index at each (Sidak's ratio is a little
///   high where alarms cluster most: 1.8 % at threshold 7), and where the exact law puts a trial's Pfa
///   above twice the fit's target, `trust` says the fit may be far too low.
#[test]
fn the_tail_fits_per_hour_row_meets_an_hour_flown_through_on_a_slow_mode() {
    let (trials_per_hour, trial_samples, hour_samples) = (1800.0, 200, 360_000);
    // A trial's alarm probability and the index of an hour flown through over its conversion, exact.
    let exact = |threshold: f64, points: usize| -> (f64, f64) {
        let law = exact_slow_mode::SlowModeWindow { threshold, ..exact_slow_mode::slow_mode_window() };
        let (trial, hour) =
            (law.fault_free_log_no_alarm(trial_samples, points), law.fault_free_log_no_alarm(hour_samples, points));
        (-trial.exp_m1(), hour / (trials_per_hour * trial))
    };
    let (trial, index) = exact(8.0, 801);
    let conversion = -(trials_per_hour * (-trial).ln_1p()).exp_m1();
    assert!((conversion / 2.003367982961e-3 - 1.0).abs() < 1e-9 && (index / 2.8547150868 - 1.0).abs() < 1e-9);
    let tmp = tempfile::tempdir().unwrap();
    let deck = tmp.path().join("slow.toml");
    let text = slow_mode_deck(8.0, "1.0", "1.0").replace("trials = 4000", "trials = 20000");
    std::fs::write(&deck, text.replace("target_pfa = 0.05\n", "")).unwrap();
    let at_8 = tmp.path().join("thresholds_8.csv");
    std::fs::write(&at_8, "detector,statistic,per_statistic_threshold,detector_threshold\nwhite,y,8.0,8.0\n").unwrap();
    let seeds: u64 =
        std::env::var("FDIMC_COVERAGE_SEEDS").ok().and_then(|s| s.parse().ok()).map_or(8, |n: u64| n.max(8));
    let mut covered = 0;
    for seed in 1..=seeds {
        let out = tmp.path().join(format!("seed{seed}"));
        let (out_s, seed_s) = (out.to_str().unwrap(), seed.to_string());
        ok(&fdimc(&["run", deck.to_str().unwrap(), "--seed", &seed_s, "--quiet", "--out", out_s]));
        ok(&fdimc(&["summarize", out_s, "--thresholds", at_8.to_str().unwrap()]));
        let safety = csv_frame(&out.join("validation/safety.csv"));
        let column = |name: &str| safety.column(name).unwrap().clone();
        let words = |name: &str, i: usize| column(name).str().unwrap().get(i).unwrap().to_string();
        let row = (0..safety.height())
            .find(|&i| words("method", i).contains("generalised Pareto"))
            .expect("the tail fit's row");
        let value = |name: &str| column(name).f64().unwrap().get(row).unwrap();
        let (statement, role) = (words("statement", row), words("role", row));
        if value("value_lo") <= conversion && conversion <= value("value_hi") {
            covered += 1;
        } else {
            assert!(statement.contains("the fit's doubts: "), "seed {seed}: a miss said nothing: {statement}");
        }
        let named: f64 =
            role.split("extremal index ").nth(1).and_then(|r| r.split(' ').next()).unwrap().parse().unwrap();
        assert!(role.starts_with("a lower bound") && (1.0..1.01).contains(&(named / index)), "{role}");
        let tail = csv_frame(&out.join("validation/tail.csv"));
        let strs = |name: &str| tail.column(name).unwrap().str().unwrap().clone();
        let f64s = |name: &str| tail.column(name).unwrap().f64().unwrap().clone();
        let mut targets = 0;
        for i in 0..tail.height() {
            if strs("query").get(i) != Some("threshold_for_pfa") {
                continue;
            }
            targets += 1;
            let threshold = f64s("threshold").get(i).unwrap();
            let (at_trial, at_index) = exact(threshold, 401);
            let ratio = f64s("hour_over_conversion").get(i).unwrap() / at_index;
            assert!((0.999..1.03).contains(&ratio), "seed {seed}, threshold {threshold}: {ratio} of the exact index");
            if at_trial > 2.0 * f64s("pfa").get(i).unwrap() {
                let trust = strs("trust").get(i).unwrap().to_string();
                assert!(trust.contains("the residual's exact law puts"), "seed {seed}, {threshold}: {trust}");
            }
        }
        assert_eq!(targets, 3, "{tail}");
    }
    println!("the tail fit's per-hour interval held the exact {conversion:.4e} on {covered} of {seeds} seeds");
    assert!(covered >= fewest_covered(seeds), "held on {covered} of {seeds} seeds");
}

/// `fdimc verify` (issue 86, item 2): its eight known-answer cases, their coverage over 8 seeds
/// (`--seeds 8`: each run case's intervals hold the answer on at least 5) and, where `FDIMC_PYTHON`
/// names a Python with NumPy, SciPy and polars (`.ci/run` sets it), the second implementation's
/// agreement pass on this build; `verification.csv` has one row each with the expected value's source,
/// and the CSV and the page name this build's commit (`git rev-parse`, independent of the build
/// script's reading) and the lane path's vector form. Without that Python the case is left out and
/// the console and the page say so.
#[test]
fn verify_passes_its_known_answer_cases_and_names_the_build() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("verify");
    let python = std::env::var("FDIMC_PYTHON").ok();
    let mut args = vec!["verify", "--out", out.to_str().unwrap(), "--seeds", "8"];
    // Without FDIMC_PYTHON, a Python that is not there: the case must be left out, not fail.
    args.extend(["--python", python.as_deref().unwrap_or("/nonexistent/python3")]);
    let printed = ok(&fdimc(&args));
    let cases = if python.is_some() { 12 } else { 11 };
    assert!(printed.contains(&format!("{cases} of {cases} cases passed")), "{printed}");
    let t = csv_frame(&out.join("verification.csv"));
    assert_eq!(t.height(), cases, "{t}");
    let strs = |name: &str| -> Vec<String> {
        let c = t.column(name).unwrap().str().unwrap().clone();
        (0..t.height()).map(|i| c.get(i).unwrap().to_string()).collect()
    };
    let pass = t.column("pass").unwrap().bool().unwrap().clone();
    assert!((0..t.height()).all(|i| pass.get(i) == Some(true)), "{t}");
    let mut names = vec![
        "exact_slow_mode_law",
        "exact_cusum_chain",
        "white_residual_pfa",
        "slow_mode_miss_before_hazard",
        "cusum_miss_before_hazard",
        "records_identical_across_threads_and_shards",
        "records_identical_after_a_resume",
        "lane_path_equals_one_trial_path",
        "white_residual_pfa_coverage",
        "slow_mode_miss_before_hazard_coverage",
        "cusum_miss_before_hazard_coverage",
    ];
    if python.is_some() {
        names.push("second_implementation_agrees");
        let compared = csv_frame(&out.join("second_implementation.csv"));
        assert!(compared.height() >= 44, "{compared}");
    } else {
        assert!(printed.contains("the second implementation was not run"), "{printed}");
    }
    assert_eq!(strs("case"), names);
    // The coverage rows: 8 seeds, at least 5 asked.
    let (expected, measured) =
        (t.column("expected").unwrap().f64().unwrap(), t.column("measured").unwrap().f64().unwrap());
    for i in 8..11 {
        assert_eq!(expected.get(i), Some(5.0));
        assert!((5.0..=8.0).contains(&measured.get(i).unwrap()), "{t}");
    }
    assert!(strs("expected_from").iter().all(|s| !s.is_empty()));
    let head = Command::new("git").args(["rev-parse", "--short=12", "HEAD"]).output().unwrap();
    let commit = String::from_utf8_lossy(&head.stdout).trim().to_string();
    assert!(strs("commit").iter().all(|c| *c == commit), "{commit} vs {t}");
    let page = std::fs::read_to_string(out.join("verification.html")).unwrap();
    assert!(page.contains(&format!("<td>{commit}</td>")) && page.contains("vector form"), "{page}");
    assert_eq!(page.matches("<td>pass</td>").count(), cases, "{page}");
    let few = fdimc(&["verify", "--out", out.to_str().unwrap(), "--seeds", "3"]);
    assert_eq!(few.status.code(), Some(2));
    assert!(text(&few.stderr).contains("--seeds 3: at least 8"), "{}", text(&few.stderr));
}

#[test]
fn fmu_prints_what_a_deck_needs_and_refuses_a_file_that_is_not_an_fmu() {
    let dir = tempfile::tempdir().unwrap();
    let built = build_fmus::build_all(Path::new(env!("CARGO_MANIFEST_DIR")), dir.path()).unwrap();
    let aircraft = built.iter().find(|p| p.ends_with("aircraft.fmu")).unwrap();
    let out = fdimc(&["fmu", aircraft.to_str().unwrap()]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    for line in [
        "FMI 2.0",
        "continuous states 5, event indicators 0",
        "model_exchange  library aircraft",
        "instances per process many: runs here",
        "inputs (commands, actuators, the model's own fault inputs): 3",
        "parameters (set before initialisation; a deck's parameter errors act on these): 28",
    ] {
        assert!(stdout.contains(line), "{line:?} not in\n{stdout}");
    }
    let throttle = stdout.lines().find(|l| l.trim_start().starts_with("throttle ")).unwrap();
    assert_eq!(throttle.split_whitespace().take(6).collect::<Vec<_>>(), ["throttle", "14", "real", "0.0", "1", "0"]);
    // The states in the order the deck's [plant] follows, each with its derivative.
    let states = stdout.split("continuous states (in the FMU's state order").nth(1).unwrap();
    let listed: Vec<String> = states
        .lines()
        .skip(2)
        .take_while(|l| !l.trim().is_empty())
        .map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            format!("{} {}", w[0], w[7])
        })
        .collect();
    let expected = ["V_m_s", "alpha_rad", "q_rad_s", "theta_rad", "h_m"].map(|n| format!("{n} der({n})"));
    assert_eq!(listed, expected, "{stdout}");
    let fmi3 = built.iter().find(|p| p.ends_with("aircraft_fmi3.fmu")).unwrap();
    let stdout = text(&fdimc(&["fmu", fmi3.to_str().unwrap()]).stdout);
    // FMI 3.0 model exchange runs through fdimc's own binding of the standard's calls.
    assert!(stdout.contains("model_exchange  library aircraft") && !stdout.contains("does not run here"), "{stdout}");
    assert_eq!(stdout.matches("instances per process many: runs here").count(), 2, "{stdout}");
    let out = fdimc(&["fmu", "studies/ci_seed000.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("studies/ci_seed000.toml: not an FMU: an FMU is a zip archive"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn an_fmu_truth_flies_closed_loop_with_identical_records_and_a_failing_fmu_fails_its_trials() {
    bundled_fmus();
    let dir = tempfile::tempdir().unwrap();
    let deck = std::fs::read_to_string("studies/fmu_aircraft.toml")
        .unwrap()
        .replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {:?}", bundled_fmus().join("aircraft.fmu")));
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let good = write("fmu.toml", &deck);
    let run = |deck: &str, out: &str, threads: &str| {
        let out = dir.path().join(out);
        let o =
            fdimc(&["run", deck, "--trials", "120", "--threads", threads, "--out", out.to_str().unwrap(), "--quiet"]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        out
    };
    let one = run(&good, "one", "1");
    let two = run(&good, "two", "2");
    let (a, b) = (read_frame(&one.join("trials.parquet")), read_frame(&two.join("trials.parquet")));
    assert_eq!(a.height(), 3 * 120, "three detectors");
    assert!(a.equals_missing(&b), "records differ between 1 and 2 threads");
    assert_eq!(a.column("failure").unwrap().null_count(), 3 * 120, "no trial failed");
    let manifest = std::fs::read_to_string(one.join("manifest.json")).unwrap();
    assert!(manifest.contains("\"file\": \"aircraft.fmu\"") && manifest.contains("\"sha256\""), "{manifest}");
    // Through the loop the seed filter finds the faults of the nominal airframe (pitch-stiffness error 0)
    // and false-alarms on every airframe whose stiffness is off (docs/findings-fmu.md).
    let f64s = |name: &str| {
        let c = a.column(name).unwrap().f64().unwrap().clone();
        (0..a.height()).map(|i| c.get(i)).collect::<Vec<_>>()
    };
    let names = a.column("detector").unwrap().str().unwrap().clone();
    let detector: Vec<_> = (0..a.height()).map(|i| names.get(i).map(str::to_string)).collect();
    let flags = a.column("fault_free").unwrap().bool().unwrap().clone();
    let fault_free: Vec<_> = (0..a.height()).map(|i| flags.get(i)).collect();
    let (error, delay, false_alarm) = (f64s("perr_pitch_stiffness"), f64s("delay_s"), f64s("false_alarm_s"));
    let (mut nominal, mut found, mut off, mut alarmed) = (0, 0, 0, 0);
    for i in (0..a.height()).filter(|&i| detector[i].as_deref() == Some("seed")) {
        let e = error[i].unwrap();
        if fault_free[i] == Some(false) && e == 0.0 {
            nominal += 1;
            found += usize::from(delay[i].is_some());
        }
        if e.abs() >= 0.1 {
            off += 1;
            alarmed += usize::from(false_alarm[i].is_some());
        }
    }
    assert!(nominal > 10 && found * 10 >= nominal * 9, "{found} of {nominal} nominal faulty trials detected");
    assert!(off > 40 && alarmed * 10 >= off * 9, "{alarmed} of {off} off-stiffness trials false-alarmed");

    // The aircraft told to fail at 12 s: trials fail with the FMU's message, and the run goes on to
    // its tables, then exits 2 saying how many failed and why (every one did).
    let failing = write("failing.toml", &deck.replace("h0_m = 1000.0 }", "h0_m = 1000.0, fail_at_s = 12.0 }"));
    let out = dir.path().join("failing");
    let o = fdimc(&["run", &failing, "--trials", "120", "--threads", "2", "--out", out.to_str().unwrap(), "--quiet"]);
    let said = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{said}");
    assert!(
        said.contains("360 of 360 trial x detector units failed")
            && said
                .contains("the first failure: the FMU truth failed: aircraft.fmu: fmi2GetDerivatives returned Error"),
        "{said}"
    );
    assert!(out.join("summary.csv").exists(), "the tables are written before the refusal");
    let df = read_frame(&out.join("trials.parquet"));
    assert_eq!(df.height(), 3 * 120);
    let failure = df.column("failure").unwrap().str().unwrap().clone();
    assert_eq!(failure.null_count(), 0);
    let first = failure.get(0).unwrap();
    assert!(
        first.contains("the FMU truth failed: aircraft.fmu: fmi2GetDerivatives returned Error at t = 12 s")
            && first.contains("failing at t=12 as asked by fail_at_s"),
        "{first}"
    );

    // Bad mappings: exit 2 naming the deck, the field and what the FMU has.
    for (edit, field, says) in [
        (
            "\"gamma_rad\", \"h_m\"]",
            "truth.outputs[4]",
            "aircraft.fmu has no variable \"gamma\"; an output must be one of: V_m_s, der(V_m_s), alpha_rad",
        ),
        (
            "theta0_rad = 0.0443566119725",
            "truth.parameters.theta0_rad",
            "\"elevator_rad\" of aircraft.fmu has causality input and type Real; a parameter must be one of: m_kg",
        ),
        ("trim_inputs = [0.459166130340,", "truth.trim_inputs[0]", "throttle: 1.5 is above its declared max 1"),
        ("interface = \"model_exchange\"", "truth.interface", "model_exchange"),
    ] {
        let bad = match field {
            "truth.outputs[4]" => deck.replace(edit, "\"gamma\", \"h_m\"]"),
            "truth.parameters.theta0_rad" => deck.replace(edit, "theta0_rad = 0.0443566119725, elevator_rad = 0.1"),
            "truth.trim_inputs[0]" => deck.replace(edit, "trim_inputs = [1.5,"),
            _ => deck.replace(edit, "interface = \"cosim\""),
        };
        let path = write("bad.toml", &bad);
        let o = fdimc(&["validate", &path]);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{field}: {err}");
        let field_shown = if field == "truth.parameters.theta0_rad" { "truth.parameters.elevator_rad" } else { field };
        assert!(err.contains(&format!("bad.toml: {field_shown}")) && err.contains(says), "{field}: {err}");
    }
}

#[test]
fn a_controller_fmu_closes_the_loop_as_the_decks_gain_matrix_does() {
    let fmus = bundled_fmus();
    let dir = tempfile::tempdir().unwrap();
    let deck = std::fs::read_to_string("studies/fmu_aircraft.toml")
        .unwrap()
        .replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {:?}", fmus.join("aircraft.fmu")));
    let gain =
        "[controller]\noutput_feedback = [\n  [0.0, 0.0, 0.0,  0.0, 0.0, 0.0],\n  [0.0, 0.0, -0.5, -2.0, 0.0, 0.0],\n]";
    assert!(deck.contains(gain));
    // fmus/pitch_controller with its speed loop off and its trims at the aircraft's trim: elevator =
    // trim + command + 0.5 q + 2 (theta - theta_trim), throttle = trim, the gain matrix's law.
    let controller = format!(
        "[controller]\nfmu = {:?}\n\
         measured = {{ q_meas_rad_s = \"q_rad_s\", theta_meas_rad = \"theta_rad\", V_meas_m_s = \"v_m_s\" }}\n\
         commands = {{ elevator_cmd_rad = \"elevator_rad\" }}\n\
         drives = {{ elevator_rad = \"elevator_rad\", throttle = \"throttle\" }}\n\
         parameters = {{ kq = -0.5, ktheta = -2.0, theta_ref_rad = 0.0443566119725, elevator_trim_rad = 0.0211591440454, \
         kv = 0.0, ki_v = 0.0, V_ref_m_s = 53.6, throttle_trim = 0.459166130340 }}",
        fmus.join("pitch_controller.fmu")
    );
    let with_fmu = deck.replace(gain, &controller);
    let (a, b) = (dir.path().join("gain.toml"), dir.path().join("fmu.toml"));
    std::fs::write(&a, &deck).unwrap();
    std::fs::write(&b, &with_fmu).unwrap();
    let out = fdimc(&["validate", b.to_str().unwrap()]);
    let stdout = ok(&out);
    assert!(
        stdout.contains("controller  FMU pitch_controller.fmu (co-simulation")
            && stdout.contains("sees the measured [v_m_s, q_rad_s, theta_rad] and the commands on [elevator_rad], drives [elevator_rad, throttle]"),
        "{stdout}"
    );
    let trace = |deck: &Path, name: &str| {
        let file = dir.path().join(name);
        ok(&fdimc(&["simulate", deck.to_str().unwrap(), "--trial", "7", "--out", file.to_str().unwrap()]));
        read_frame(&file)
    };
    let (ta, tb) = (trace(&a, "gain.parquet"), trace(&b, "fmu.parquet"));
    assert_eq!(ta.height(), 2000);
    for (column, tolerance) in
        [("u_elevator_rad", 1e-12), ("u_throttle", 0.0), ("y_q_rad_s", 1e-12), ("r_q_rad_s", 1e-12)]
    {
        let (x, y) =
            (ta.column(column).unwrap().f64().unwrap().clone(), tb.column(column).unwrap().f64().unwrap().clone());
        let worst = (0..ta.height()).map(|i| (x.get(i).unwrap() - y.get(i).unwrap()).abs()).fold(0.0, f64::max);
        assert!(worst <= tolerance, "{column}: the two loops differ by {worst}");
    }
    // The loop acts: the elevator moves with the measured pitch, not only with the square wave.
    let u = tb.column("u_elevator_rad").unwrap().f64().unwrap().clone();
    let moved = (0..tb.height()).filter(|&i| (u.get(i).unwrap().abs() - 0.02).abs() > 1e-3).count();
    assert!(moved > 1000, "{moved}");
    // A fixed-step controller at another step is refused by name.
    let other = with_fmu.replace("dt_s = 0.01", "dt_s = 0.02");
    std::fs::write(&b, other).unwrap();
    let out = fdimc(&["validate", b.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("controller.fmu: ")
            && text(&out.stderr).contains("steps only at a fixed communication step (0.01 s, its default experiment) and the study's dt_s is 0.02 s"),
        "{}",
        text(&out.stderr)
    );
}

/// EWMA of `|(y_i - mean_i) / scale_i|` per channel as fmus/ewma_detector computes it (same operations,
/// same order): the statistic (the largest) and the channel (1-based, first on ties, 0 while all are 0).
fn native_ewma(y: [&[f64]; 3], mean: [f64; 3], lambda: f64, scale: [f64; 3]) -> (Vec<f64>, Vec<usize>) {
    let mut e = [0.0f64; 3];
    let (mut statistic, mut channel) = (Vec::new(), Vec::new());
    for k in 0..y[0].len() {
        for i in 0..3 {
            e[i] = (1.0 - lambda) * e[i] + lambda * ((y[i][k] - mean[i]) / scale[i]).abs();
        }
        let (mut s, mut c) = (e[0], 1);
        if e[1] > s {
            (s, c) = (e[1], 2);
        }
        if e[2] > s {
            (s, c) = (e[2], 3);
        }
        statistic.push(s);
        channel.push(if e == [0.0; 3] { 0 } else { c });
    }
    (statistic, channel)
}

#[test]
fn a_detector_fmu_alarms_as_the_same_test_written_natively() {
    let fmus = bundled_fmus();
    let dir = tempfile::tempdir().unwrap();
    // The LTI twin of the FMU study without its excitation: the measured outputs are noise and faults,
    // which an EWMA of |y / sigma| can test; the trims are zero, so the FMU sees what fdimc measures.
    let detector = format!(
        "[[detector]]\nname = \"ewma\"\nkind = \"fmu\"\nfmu = {:?}\n\
         measured = {{ in_1 = \"alpha_rad\", in_2 = \"q_rad_s\", in_3 = \"theta_rad\" }}\n\
         statistic = \"statistic\"\nisolated_channel = \"isolated_channel\"\n\
         channels = [\"alpha_rad\", \"q_rad_s\", \"theta_rad\"]\n\
         parameters = {{ lambda = 0.05, scale_1 = 0.002, scale_2 = 0.005, scale_3 = 0.002 }}\n\
         thresholds = [1.6]\n\n[monte_carlo]\n",
        fmus.join("ewma_detector.fmu")
    );
    let deck = std::fs::read_to_string("studies/fmu_aircraft_lti.toml")
        .unwrap()
        .replace("amplitude = 0.02", "amplitude = 0.0")
        .replacen("[monte_carlo]\n", &detector, 1);
    let path = dir.path().join("ewma.toml");
    std::fs::write(&path, &deck).unwrap();
    let deck_path = path.to_str().unwrap();
    let stdout = ok(&fdimc(&["validate", deck_path]));
    assert!(
        stdout.contains("alarm when the output \"statistic\" of the detector FMU ewma_detector.fmu (co-simulation")
            && stdout.contains("isolation: the channel the detector names by the end of the window, 0 s to 1 s"),
        "{stdout}"
    );

    let run = |out: &str, threads: &str| {
        let out = dir.path().join(out);
        ok(&fdimc(&[
            "run",
            deck_path,
            "--trials",
            "40",
            "--threads",
            threads,
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ]));
        read_frame(&out.join("trials.parquet"))
    };
    let (a, b) = (run("one", "1"), run("two", "2"));
    assert_eq!(a.height(), 4 * 40);
    assert!(a.equals_missing(&b), "records differ between 1 and 2 threads");
    let manifest = std::fs::read_to_string(dir.path().join("one").join("manifest.json")).unwrap();
    assert!(manifest.contains("\"file\": \"ewma_detector.fmu\""), "{manifest}");

    let column = |name: &str| a.column(name).unwrap().clone();
    let detectors = column("detector");
    let rows: Vec<usize> = (0..a.height()).filter(|&i| detectors.str().unwrap().get(i) == Some("ewma")).collect();
    assert_eq!(rows.len(), 40);
    let f64_at = |name: &str, i: usize| column(name).f64().unwrap().get(i);
    let (mut alarms, mut false_alarms, mut isolated) = (0, 0, 0);
    for (trial, &row) in rows.iter().enumerate().take(12) {
        let file = dir.path().join(format!("trace{trial}.parquet"));
        let trial_s = trial.to_string();
        ok(&fdimc(&[
            "simulate",
            deck_path,
            "--trial",
            &trial_s,
            "--detector",
            "ewma",
            "--out",
            file.to_str().unwrap(),
        ]));
        let trace = read_frame(&file);
        let series = |name: &str| -> Vec<f64> {
            let c = trace.column(name).unwrap().f64().unwrap().clone();
            (0..trace.height()).map(|i| c.get(i).unwrap()).collect()
        };
        let (alpha, q, theta, t) = (series("y_alpha_rad"), series("y_q_rad_s"), series("y_theta_rad"), series("t_s"));
        let (statistic, channel) = native_ewma([&alpha, &q, &theta], [0.0; 3], 0.05, [0.002, 0.005, 0.002]);
        // The FMU's statistic, sample by sample, is the native one to the bit.
        assert_eq!(series("stat_q_rad_s"), statistic, "trial {trial}");
        // The alarms the run recorded are where the native statistic first exceeds 1.6.
        let onset = f64_at("onset_s", row).unwrap_or(f64::INFINITY);
        let first = |from: f64, to: f64| (0..t.len()).find(|&k| t[k] >= from && t[k] < to && statistic[k] > 1.6);
        let false_alarm = first(f64::NEG_INFINITY, onset).map(|k| t[k]);
        let alarm = first(onset, f64::INFINITY);
        assert_eq!(f64_at("false_alarm_s", row), false_alarm, "trial {trial}");
        assert_eq!(f64_at("alarm_s", row), alarm.map(|k| t[k]), "trial {trial}");
        // Isolation: the channel the FMU names at the last sample of [alarm, alarm + 1 s).
        let named = alarm.map(|k| {
            let last = (0..t.len()).rev().find(|&m| t[m] >= t[k] && t[m] < t[k] + 1.0).unwrap();
            ["", "alpha_rad", "q_rad_s", "theta_rad"][channel[last]]
        });
        let recorded = column("isolated").str().unwrap().get(row).map(str::to_string);
        assert_eq!(recorded.as_deref(), named.filter(|n| !n.is_empty()), "trial {trial}");
        alarms += usize::from(alarm.is_some());
        false_alarms += usize::from(false_alarm.is_some());
        isolated += usize::from(named.is_some_and(|n| !n.is_empty()));
    }
    assert!(alarms >= 3 && isolated >= 3, "{alarms} alarms, {isolated} isolated of 12 trials");
    assert!(false_alarms < 12, "{false_alarms} false alarms of 12 trials");

    // A detector FMU field on another kind, and a statistic the FMU lacks: exit 2 naming the field.
    for (from, to, field, says) in [
        (
            "name = \"seed\"\nkind = \"detection_filter\"",
            "name = \"seed\"\nkind = \"detection_filter\"\nstatistic = \"s\"",
            "detector[0].statistic",
            "applies to kind = \"fmu\" only",
        ),
        (
            "statistic = \"statistic\"",
            "statistic = \"stat\"",
            "detector[3].statistic",
            "ewma_detector.fmu has no variable \"stat\"",
        ),
        ("thresholds = [1.6]", "thresholds = [1.6, 2.0]", "detector[3].thresholds", "one number for kind = \"fmu\""),
        ("in_3 = \"theta_rad\"", "in_3 = \"theta\"", "detector[3].measured.in_3", "\"theta\""),
    ] {
        assert!(deck.contains(from), "{from}");
        std::fs::write(&path, deck.replacen(from, to, 1)).unwrap();
        let out = fdimc(&["validate", deck_path]);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(&format!("{field}: ")) && err.contains(says), "{field}: {err}");
    }
}

/// `from` repacked as `to` with its modelDescription.xml edited by `edit` (a user's FMU that declares
/// other capabilities).
fn repacked_fmu(from: &Path, to: &Path, edit: impl Fn(&str) -> String) {
    use std::io::{Read, Write};
    let mut archive = zip::ZipArchive::new(std::fs::File::open(from).unwrap()).unwrap();
    let mut out = zip::ZipWriter::new(std::fs::File::create(to).unwrap());
    for k in 0..archive.len() {
        let mut entry = archive.by_index(k).unwrap();
        let name = entry.name().to_string();
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).unwrap();
        if name == "modelDescription.xml" {
            bytes = edit(std::str::from_utf8(&bytes).unwrap()).into_bytes();
        }
        out.start_file(name, zip::write::SimpleFileOptions::default()).unwrap();
        out.write_all(&bytes).unwrap();
    }
    out.finish().unwrap();
}

#[test]
fn an_fmu_allowed_one_instance_per_process_runs_on_one_thread_with_the_same_records() {
    let fmus = bundled_fmus();
    let dir = tempfile::tempdir().unwrap();
    let once = dir.path().join("aircraft_once.fmu");
    repacked_fmu(&fmus.join("aircraft.fmu"), &once, |xml| {
        let flag = " canBeInstantiatedOnlyOncePerProcess=\"true\"";
        xml.replace("<ModelExchange", &format!("<ModelExchange{flag}"))
            .replace("<CoSimulation", &format!("<CoSimulation{flag}"))
    });
    let shown = ok(&fdimc(&["fmu", once.to_str().unwrap()]));
    assert!(
        shown.contains(
            "instances per process one thread in process (it may be instantiated only once per process \
             (canBeInstantiatedOnlyOncePerProcess))"
        ),
        "{shown}"
    );
    let deck = std::fs::read_to_string("studies/fmu_aircraft.toml").unwrap();
    let write = |name: &str, fmu: &Path| {
        let p = dir.path().join(name);
        std::fs::write(&p, deck.replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {fmu:?}"))).unwrap();
        p
    };
    let (many, one) = (write("many.toml", &fmus.join("aircraft.fmu")), write("once.toml", &once));
    let run = |deck: &Path, out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args =
            vec!["run", deck.to_str().unwrap(), "--trials", "30", "--threads", "2", "--out", out.to_str().unwrap()];
        args.extend(extra);
        let o = fdimc(&args);
        assert!(o.status.success(), "{}", text(&o.stderr));
        (read_frame(&out.join("trials.parquet")), text(&o.stderr))
    };
    let ((a, quiet), (b, said)) = (run(&many, "many", &[]), run(&one, "once", &["--fmu-in-process"]));
    assert!(!quiet.contains("once per process"), "{quiet}");
    assert!(
        said.contains(
            "note: aircraft_once.fmu: it may be instantiated only once per process \
             (canBeInstantiatedOnlyOncePerProcess): the run in process uses one thread"
        ),
        "{said}"
    );
    assert!(a.equals_missing(&b), "the one-thread run's records differ");
    // In worker processes (the default for a deck with FMUs) each process holds its one instance: both
    // threads fly, with no note, and the records are the same.
    let (c, workers) = run(&one, "once_workers", &[]);
    assert!(!workers.contains("once per process"), "{workers}");
    assert!(a.equals_missing(&c), "the worker processes' records differ");
}

/// A run exits 0 when at most half its rows failed, else 2 saying how many (its tables written).
fn mostly_failed_exits_2(o: &std::process::Output, records: &polars::prelude::DataFrame) {
    let failed = records.height() - records.column("failure").unwrap().null_count();
    if failed * 2 > records.height() {
        let said = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{failed} of {} failed: {said}", records.height());
        assert!(said.contains(&format!("{failed} of {} trial x detector units failed", records.height())), "{said}");
    } else {
        assert!(o.status.success(), "{failed} of {} failed: {}", records.height(), text(&o.stderr));
    }
}

#[test]
fn an_fmu_that_crashes_its_process_fails_only_its_trials_in_worker_processes() {
    let fmus = bundled_fmus();
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string("studies/fmu_aircraft.toml")
        .unwrap()
        .replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {:?}", fmus.join("aircraft.fmu")));
    // Half the trials tell the aircraft to abort() the process at 12 s (abort_at_s 30 - 18); the twin
    // deck has the same draws make it return an error there instead (fail_at_s), in process.
    let deck = |hook: &str| {
        // The pitch-stiffness error held at 0: listed values are drawn as a grid in trial order, and
        // 24 trials would not reach the crash error's second value behind its five.
        let mut text = base
            .replace("h0_m = 1000.0 }", &format!("h0_m = 1000.0, {hook} = 30.0 }}"))
            .replace("relative = { values = [-0.2, -0.1, 0.0, 0.1, 0.2] }", "relative = { values = [0.0] }");
        text.push_str(&format!(
            "\n[[monte_carlo.parameter_error]]\nname = \"crash\"\nmodel = \"plant\"\nfmu_parameters = [\"{hook}\"]\n\
             absolute = {{ values = [0.0, -18.0] }}\n"
        ));
        let path = dir.path().join(format!("{hook}.toml"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let (aborting, failing) = (deck("abort_at_s"), deck("fail_at_s"));
    let run = |deck: &Path, out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args = vec!["run", deck.to_str().unwrap(), "--trials", "24", "--threads", "2", "--quiet", "--out"];
        args.push(out.to_str().unwrap());
        args.extend_from_slice(extra);
        let o = fdimc(&args);
        let df = read_frame(&out.join("trials.parquet"));
        mostly_failed_exits_2(&o, &df);
        df
    };
    // The crashing run in a temporary folder of its own: the workers' unpacked FMUs (killed and
    // crashed children cannot remove them) are gone with the run.
    let temporary = dir.path().join("tmp");
    std::fs::create_dir(&temporary).unwrap();
    let crashed_out = dir.path().join("crashed");
    let o = Command::new(env!("CARGO_BIN_EXE_fdimc"))
        .args(["run", aborting.to_str().unwrap(), "--trials", "24", "--threads", "2", "--quiet", "--fmu-processes"])
        .arg("--out")
        .arg(&crashed_out)
        .env("TMPDIR", &temporary)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let left: Vec<_> = std::fs::read_dir(&temporary).unwrap().map(|e| e.unwrap().path()).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    let crashed = read_frame(&crashed_out.join("trials.parquet"));
    mostly_failed_exits_2(&o, &crashed);
    let errored = run(&failing, "errored", &[]);
    assert_eq!(crashed.height(), 3 * 24);
    let failure = crashed.column("failure").unwrap().str().unwrap().clone();
    let failed: Vec<usize> = (0..crashed.height()).filter(|&i| failure.get(i).is_some()).collect();
    assert!(failed.len() >= 3 * 6 && failed.len() <= 3 * 18, "{} of {} rows failed", failed.len(), crashed.height());
    for &i in &failed {
        let why = failure.get(i).unwrap();
        assert!(why.contains("the worker process died while flying trial") && why.contains("SIGABRT"), "{why}");
    }
    // Exactly the trials whose FMU was told to stop failed, and every other record is the one the
    // in-process run of the twin deck wrote.
    let other = errored.column("failure").unwrap().str().unwrap().clone();
    let failed_twin: Vec<usize> = (0..errored.height()).filter(|&i| other.get(i).is_some()).collect();
    assert_eq!(failed, failed_twin);
    let flown = |df: &polars::prelude::DataFrame| df.drop("failure").unwrap();
    assert!(flown(&crashed).equals_missing(&flown(&errored)), "the records of the trials that flew differ");

    // Without an FMU there is nothing to isolate.
    let out = fdimc(
        &["run", "studies/fmu_aircraft_lti.toml", "--trials", "8", "--fmu-processes", "--out"]
            .iter()
            .copied()
            .chain([dir.path().join("lti").to_str().unwrap()])
            .collect::<Vec<_>>(),
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("--fmu-processes: studies/fmu_aircraft_lti.toml runs no FMU"),
        "{}",
        text(&out.stderr)
    );
}

/// `studies/fmu_aircraft.toml` with the aircraft's test hook `hook` (fmus/README.md) at 30 s less a
/// parameter error of 0 or -18 s: half the trials reach it at 12 s.
fn hooked_aircraft_deck(dir: &Path, hook: &str) -> PathBuf {
    let text = std::fs::read_to_string("studies/fmu_aircraft.toml")
        .unwrap()
        .replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {:?}", bundled_fmus().join("aircraft.fmu")))
        .replace("h0_m = 1000.0 }", &format!("h0_m = 1000.0, {hook} = 30.0 }}"))
        // The pitch-stiffness error held at 0: listed values are drawn as a grid in trial order.
        .replace("relative = { values = [-0.2, -0.1, 0.0, 0.1, 0.2] }", "relative = { values = [0.0] }");
    assert!(text.contains(&format!("{hook} = 30.0")) && text.contains("values = [0.0] }"));
    let text = format!(
        "{text}\n[[monte_carlo.parameter_error]]\nname = \"hook\"\nmodel = \"plant\"\nfmu_parameters = [\"{hook}\"]\n\
         absolute = {{ values = [0.0, -18.0] }}\n"
    );
    let path = dir.join(format!("{hook}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The project's own FMU made to write through a null pointer (SIGSEGV inside a step) and made to
/// diverge (an unstable pitch mode of 10/s from 12 s), in runs at default settings: the run survives
/// the first, each of those trials failed with the signal; the second's trials are marked
/// `truth_diverged` with where the truth left the linear plant's prediction, counted apart from a
/// filter's `diverged`, and no threshold is calibrated on them.
#[test]
fn an_fmu_that_segfaults_or_diverges_fails_only_its_trials_and_calibrates_nothing_on_them() {
    let dir = tempfile::tempdir().unwrap();
    let run = |deck: &Path, out: &str| {
        let out = dir.path().join(out);
        let o = fdimc(&["run", deck.to_str().unwrap(), "--trials", "24", "--out", out.to_str().unwrap()]);
        let df = read_frame(&out.join("trials.parquet"));
        mostly_failed_exits_2(&o, &df);
        (df, format!("{}{}", text(&o.stdout), text(&o.stderr)), out)
    };
    let failed_rows = |df: &polars::prelude::DataFrame| -> Vec<usize> {
        let failure = df.column("failure").unwrap().str().unwrap().clone();
        (0..df.height()).filter(|&i| failure.get(i).is_some()).collect()
    };
    let hooked = |df: &polars::prelude::DataFrame| -> Vec<usize> {
        let hook = df.column("perr_hook").unwrap().f64().unwrap().clone();
        (0..df.height()).filter(|&i| hook.get(i) == Some(-18.0)).collect()
    };

    let (crashed, _, _) = run(&hooked_aircraft_deck(dir.path(), "segfault_at_s"), "segfault");
    assert_eq!(crashed.height(), 3 * 24);
    assert_eq!(failed_rows(&crashed), hooked(&crashed), "exactly the hooked trials failed");
    assert!((3..3 * 24).contains(&hooked(&crashed).len()), "some trials hooked, not all");
    let failure = crashed.column("failure").unwrap().str().unwrap().clone();
    for i in hooked(&crashed) {
        let why = failure.get(i).unwrap();
        assert!(why.contains("the worker process died while flying trial") && why.contains("SIGSEGV"), "{why}");
    }
    let truth_diverged = |df: &polars::prelude::DataFrame| -> Vec<usize> {
        let c = df.column("truth_diverged").unwrap().bool().unwrap().clone();
        (0..df.height()).filter(|&i| c.get(i) == Some(true)).collect()
    };
    assert!(truth_diverged(&crashed).is_empty(), "a crash is no divergence");

    let (diverged, said, out) = run(&hooked_aircraft_deck(dir.path(), "diverge_at_s"), "diverge");
    assert_eq!(failed_rows(&diverged), hooked(&diverged));
    assert_eq!(truth_diverged(&diverged), hooked(&diverged), "every hooked trial's truth diverged, no other");
    let filter_diverged = diverged.column("diverged").unwrap().bool().unwrap().clone();
    assert_eq!(filter_diverged.sum(), Some(0), "no filter went non-finite");
    let failure = diverged.column("failure").unwrap().str().unwrap().clone();
    let at = diverged.column("diverged_at_s").unwrap().f64().unwrap().clone();
    for i in hooked(&diverged) {
        let why = failure.get(i).unwrap();
        // The pitch loop turns the 10/s mode into a growing oscillation; the nonlinear aerodynamics
        // then blow up within a sample or two (a pitch rate of tens of rad/s, under the default stray
        // limit of 100 x (prediction + 1 rad/s), to 1e5 or 1e8 m/s): by either rule.
        let t = at.get(i).unwrap();
        assert!(why.starts_with("the FMU truth failed: diverged at t = "), "{why}");
        assert!((15.0..19.0).contains(&t), "diverged at {t} s: {why}");
    }
    // With [truth] stray_factor = 1 the linear plant catches them earlier, when the pitch rate first
    // strays from its prediction by more than that prediction's peak + 1 rad/s (about 14.7 s), and
    // nothing else: the other trials stay within it.
    let strict = dir.path().join("strict.toml");
    let deck = std::fs::read_to_string(dir.path().join("diverge_at_s.toml")).unwrap();
    std::fs::write(&strict, deck.replace("linearise = true\n", "linearise = true\nstray_factor = 1.0\n")).unwrap();
    let (strayed, _, _) = run(&strict, "strict");
    assert_eq!(truth_diverged(&strayed), hooked(&strayed));
    let failure_strict = strayed.column("failure").unwrap().str().unwrap().clone();
    let at_strict = strayed.column("diverged_at_s").unwrap().f64().unwrap().clone();
    for i in hooked(&strayed) {
        let why = failure_strict.get(i).unwrap();
        assert!(why.contains("where the deck's linear plant predicts") && why.contains("stray_factor"), "{why}");
        assert!(at_strict.get(i).unwrap() < at.get(i).unwrap() - 1.0, "{why}");
    }
    let n = hooked(&diverged).len() / 3;
    assert!(said.contains(&format!("{n} trials' truth diverged or left its physical range")), "{said}");
    assert!(said.contains("calibration trial x detector units left out of the calibration"), "{said}");
    // summary.csv counts them apart; the fault-free ones are not among the calibration trials.
    let summary = csv_frame(&out.join("detectors.csv"));
    let flights = summary.column("flights_truth_diverged").unwrap().cast(&polars::prelude::DataType::Int64).unwrap();
    assert!(flights.i64().unwrap().iter().all(|v| v == Some(n as i64)), "{flights:?}");
    let fault_free = diverged.column("fault_free").unwrap().bool().unwrap().clone();
    let calibrating =
        (0..diverged.height()).filter(|&i| fault_free.get(i) == Some(true) && failure.get(i).is_none()).count() as i64
            / 3;
    let thresholds = csv_frame(&out.join("thresholds.csv"));
    let trials = thresholds.column("trials").unwrap().cast(&polars::prelude::DataType::Int64).unwrap();
    assert!(trials.i64().unwrap().iter().all(|v| v == Some(calibrating)), "{trials:?} against {calibrating}");
    assert!(calibrating > 0, "some fault-free trials flew to the end");
}

/// A sensitivity design flies its FMUs in worker processes by default too: an FMU that writes
/// through a null pointer fails only the design's trials that reach it, and every other record is
/// the one the in-process design of the twin deck (an FMU error instead of the crash) wrote.
#[test]
fn a_sensitivity_design_survives_an_fmu_that_segfaults() {
    let dir = tempfile::tempdir().unwrap();
    let run = |hook: &str, extra: &[&str]| {
        let deck = hooked_aircraft_deck(dir.path(), hook);
        let out = dir.path().join(format!("{hook}-out"));
        let mut args = vec!["sensitivity", deck.to_str().unwrap(), "--base-samples", "4", "--quiet", "--out"];
        args.push(out.to_str().unwrap());
        args.extend_from_slice(extra);
        let o = fdimc(&args);
        assert!(o.status.code().is_some(), "{hook}: died: {:?}\n{}", o.status, text(&o.stderr));
        read_frame(&out.join("trials.parquet"))
    };
    let crashed = run("segfault_at_s", &[]);
    let errored = run("fail_at_s", &["--fmu-in-process"]);
    let failed = |df: &polars::prelude::DataFrame| -> Vec<usize> {
        let failure = df.column("failure").unwrap().str().unwrap().clone();
        (0..df.height()).filter(|&i| failure.get(i).is_some()).collect()
    };
    let hook = crashed.column("perr_hook").unwrap().f64().unwrap().clone();
    let hooked: Vec<usize> = (0..crashed.height()).filter(|&i| hook.get(i) == Some(-18.0)).collect();
    assert!(!hooked.is_empty() && hooked.len() < crashed.height(), "the design varies the hook");
    assert_eq!(failed(&crashed), hooked);
    assert_eq!(failed(&errored), hooked);
    let failure = crashed.column("failure").unwrap().str().unwrap().clone();
    for &i in &hooked {
        let why = failure.get(i).unwrap();
        assert!(why.contains("the worker process died while flying trial") && why.contains("SIGSEGV"), "{why}");
    }
    let flown = |df: &polars::prelude::DataFrame| df.drop("failure").unwrap();
    assert!(flown(&crashed).equals_missing(&flown(&errored)), "the records of the trials that flew differ");
}

#[test]
fn the_engine_solves_the_trim_on_the_fmu_and_prints_its_residual() {
    let fmus = bundled_fmus();
    let dir = tempfile::tempdir().unwrap();
    // Start the trim away from level flight; the engine finds fmus/README.md's trim (Newton in Python).
    let deck = std::fs::read_to_string("studies/fmu_aircraft.toml")
        .unwrap()
        .replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {:?}", fmus.join("aircraft.fmu")))
        .replace("trim_inputs = [0.459166130340, 0.0211591440454]", "trim_inputs = [0.6, 0.0]")
        .replace("alpha0_rad = 0.0443566119725", "alpha0_rad = 0.02")
        .replace("theta0_rad = 0.0443566119725", "theta0_rad = 0.1")
        .replace(
            "linearise = true\n",
            "linearise = true\n\n[truth.trim]\nfree = [\"throttle\", \"elevator_rad\", \"alpha0_rad\", \"theta0_rad\"]\n\
             zero = [\"der(V_m_s)\", \"der(alpha_rad)\", \"der(q_rad_s)\", \"der(h_m)\"]\n",
        );
    assert!(deck.contains("[truth.trim]") && deck.contains("[0.6, 0.0]"));
    let path = dir.path().join("trim.toml");
    std::fs::write(&path, &deck).unwrap();
    let out = ok(&fdimc(&["validate", path.to_str().unwrap()]));
    let line = out.lines().find(|l| l.contains("trim solved in")).unwrap_or_else(|| panic!("{out}"));
    let value = |name: &str| -> f64 {
        let at = line.find(&format!("{name} ")).unwrap_or_else(|| panic!("{name}: {line}")) + name.len() + 1;
        line[at..].split([',', ';']).next().unwrap().trim().parse().unwrap()
    };
    for (name, want) in [
        ("throttle", 0.459166130340),
        ("elevator_rad", 0.0211591440454),
        ("alpha0_rad", 0.0443566119725),
        ("theta0_rad", 0.0443566119725),
    ] {
        assert!((value(name) - want).abs() < 1e-10, "{name}: {} vs {want}\n{line}", value(name));
    }
    // The linear model is then the one at the true trim: the trim's derivatives vanish.
    let design = ok(&fdimc(&["design", path.to_str().unwrap()]));
    let largest = design.lines().find(|l| l.contains("the trim's state derivatives")).unwrap();
    let worst: f64 = largest.rsplit("largest ").next().unwrap().trim().parse().unwrap();
    assert!(worst < 1e-9, "{largest}");

    for (from, to, field, says) in [
        ("\"der(h_m)\"]", "]", "truth.trim.zero", "3 variables for 4 free values"),
        (
            "free = [\"throttle\"",
            "free = [\"thrust\"",
            "truth.trim.free[0]",
            "aircraft.fmu has no such scalar Real variable \"thrust\"",
        ),
        ("\"der(h_m)\"]", "\"h_m\"]", "truth.trim", "the trim's Jacobian is singular"),
        ("trim_inputs = [0.6, 0.0]", "trim_inputs = []", "truth.trim_inputs", "0 values for 2 inputs"),
    ] {
        std::fs::write(&path, deck.replace(from, to)).unwrap();
        let out = fdimc(&["validate", path.to_str().unwrap()]);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(&format!("{field}: ")) && err.contains(says), "{field}: {err}");
    }
}

/// The fmu_aircraft decks (FMU truth and its LTI twin) without their sampled fault population, every
/// trial faulty, the nominal airframe.
fn actuator_decks() -> [(&'static str, String); 2] {
    let population = "[[monte_carlo.fault]]\nkind = \"bias\"\nsize_sigma = { values = [3.0, 6.0, 10.0] }\n";
    let stiffness = "relative = { values = [-0.2, -0.1, 0.0, 0.1, 0.2] }";
    let edit = |deck: String| {
        assert!(deck.contains(population) && deck.contains("fault_free_fraction = 0.3") && deck.contains(stiffness));
        (deck.replace(population, "").replace("fault_free_fraction = 0.3", "fault_free_fraction = 0.0"))
            .replace(stiffness, "relative = 0.0")
    };
    let fmu = std::fs::read_to_string("studies/fmu_aircraft.toml")
        .unwrap()
        .replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {:?}", bundled_fmus().join("aircraft.fmu")));
    [("fmu", edit(fmu)), ("lti", edit(std::fs::read_to_string("studies/fmu_aircraft_lti.toml").unwrap()))]
}

fn f64_column(df: &polars::prelude::DataFrame, name: &str) -> Vec<f64> {
    let c = df.column(name).unwrap().f64().unwrap().clone();
    (0..df.height()).map(|i| c.get(i).unwrap_or(f64::NAN)).collect()
}

#[test]
fn an_actuator_fault_reaches_the_plant_while_the_detectors_see_the_command() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let trace = |deck: &str, name: &str| {
        let file = dir.path().join(name);
        let out = fdimc(&["simulate", deck, "--trial", "3", "--out", file.to_str().unwrap()]);
        (ok(&out), read_frame(&file))
    };
    // A 0.01 rad elevator bias from 6 s through the pitch loop, against the same command added to the
    // reference (a step in the excitation): the plant gets the same input either way, so it flies the
    // same trajectory; the detectors of the faulty deck see the command without the bias.
    let bias = "\n[[faults]]\ninput = \"elevator_rad\"\nkind = \"bias\"\nsize = 0.01\nonset_s = 6.0\n";
    let step = "[[excitation]]\ninput = \"elevator_rad\"\nshape = \"step\"\namplitude = 0.01\nstart_s = 6.0\n\n[noise]";
    for (truth, deck) in actuator_decks() {
        let faulty = write(&format!("{truth}_bias.toml"), &(deck.clone() + bias));
        let twin = write(&format!("{truth}_twin.toml"), &deck.replace("[noise]", step));
        let validated = ok(&fdimc(&["validate", &faulty]));
        assert!(validated.contains("fault       elevator_rad actuator_bias 0.01 from 6 s"), "{validated}");
        let (said, f) = trace(&faulty, &format!("{truth}_bias.parquet"));
        assert!(said.contains("fault               elevator_rad actuator_bias 0.01 (input units) from 6 s"), "{said}");
        let (_, t) = trace(&twin, &format!("{truth}_twin.parquet"));
        let time = f64_column(&f, "t_s");
        for y in ["y_v_m_s", "y_alpha_rad", "y_q_rad_s", "y_theta_rad", "y_gamma_rad", "y_h_m"] {
            let (a, b) = (f64_column(&f, y), f64_column(&t, y));
            let worst = a.iter().zip(&b).map(|(a, b)| (a - b).abs() / (1.0 + b.abs())).fold(0.0, f64::max);
            assert!(worst < 1e-9, "{truth} {y}: the plant flew differently ({worst})");
        }
        let (command, reference) = (f64_column(&f, "u_elevator_rad"), f64_column(&t, "u_elevator_rad"));
        for k in 0..time.len() {
            let seen = reference[k] - command[k];
            let want = if time[k] >= 6.0 { 0.01 } else { 0.0 };
            assert!((seen - want).abs() < 1e-9, "{truth} at {} s: the detectors saw {seen} of the bias", time[k]);
        }
        // The faulty deck's residual shows the fault; the twin's (whose filter knows the input) does not.
        let after = |df: &polars::prelude::DataFrame| {
            let r = f64_column(df, "r_q_rad_s");
            (0..time.len()).filter(|&k| time[k] >= 6.0).map(|k| r[k].abs()).fold(0.0, f64::max)
        };
        let (seen, quiet) = (after(&f), after(&t));
        assert!(seen > 3.0 * quiet, "{truth}: residual after the onset {seen} against {quiet} without the fault");
    }
}

#[test]
fn a_models_own_fault_input_is_a_fault_kind_and_actuator_populations_are_sampled_and_summarized() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let run = |deck: &str, out: &str, trials: &str| {
        let out = dir.path().join(out);
        let o = fdimc(&["run", deck, "--trials", trials, "--out", out.to_str().unwrap(), "--quiet"]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        out
    };
    let [(_, deck), _] = actuator_decks();
    let deck =
        deck.replace("\nlinearise = true\n", "\nlinearise = true\nfault_inputs = [\"elevator_effectiveness\"]\n");
    assert!(deck.contains("fault_inputs"));
    // The aircraft's elevator effectiveness dropped to 0 (the model's own fault: the deflection times
    // 0) and the elevator jammed at 0 rad absolute (its deviation -trim): the same airframe, the same
    // commands, so the same records to the bit, but for the fault's labels.
    let own = "\n[[faults]]\ninput = \"elevator_effectiveness\"\nkind = \"stuck\"\nsize = 0.0\nonset_s = 6.0\n";
    let jam = "\n[[faults]]\ninput = \"elevator_rad\"\nkind = \"stuck\"\nsize = -0.0211591440454\nonset_s = 6.0\n";
    let (a, b) = (
        run(&write("own.toml", &(deck.clone() + own)), "own", "24"),
        run(&write("jam.toml", &(deck.clone() + jam)), "jam", "24"),
    );
    let (a, b) = (read_frame(&a.join("trials.parquet")), read_frame(&b.join("trials.parquet")));
    assert_eq!(a.height(), 3 * 24);
    let labels = ["kind", "target", "size", "size_bin", "size_unit"];
    let rest = |df: &polars::prelude::DataFrame| df.drop_many(labels);
    assert!(rest(&a).equals_missing(&rest(&b)), "the two faults flew differently");
    let target = a.column("target").unwrap().str().unwrap().clone();
    assert_eq!(target.get(0), Some("elevator_effectiveness"));
    assert_eq!(a.column("kind").unwrap().str().unwrap().get(0), Some("actuator_stuck"));
    assert_eq!(a.column("size_unit").unwrap().str().unwrap().get(0), Some("input units"));
    // The fault matters: with no elevator the pitch loop is open and the seed filter sees it.
    let detected = a.column("detected").unwrap().bool().unwrap().clone();
    assert!(detected.sum().unwrap_or(0) >= 12, "{} of 72 rows detected", detected.sum().unwrap_or(0));
    // Nothing a detector names is an input: no isolation decision counts.
    assert_eq!(a.column("isolated_correctly").unwrap().null_count(), a.height());

    // Sampled: a sensor bias, an actuator bias on either input, a stuck effectiveness; every group in
    // the summary with its own unit, and no isolation decided on the actuator groups.
    let populations = "[[monte_carlo.fault]]\nkind = \"bias\"\nsize_sigma = 6.0\n\n\
        [[monte_carlo.fault]]\nkind = \"bias\"\ninputs = [\"elevator_rad\", \"throttle\"]\nsize = 0.01\n\n\
        [[monte_carlo.fault]]\nkind = \"stuck\"\ninputs = [\"elevator_effectiveness\"]\nsize = { range = [0.0, 0.5] }\n";
    let sampled = write("sampled.toml", &(deck.clone() + "\n" + populations));
    let out = run(&sampled, "sampled", "36");
    let df = read_frame(&out.join("trials.parquet"));
    assert_eq!(df.height(), 3 * 36);
    let str_column = |name: &str| {
        let c = df.column(name).unwrap().str().unwrap().clone();
        (0..df.height()).map(|i| c.get(i).map(str::to_string)).collect::<Vec<_>>()
    };
    let (detector, kind, target) = (str_column("detector"), str_column("kind"), str_column("target"));
    let count = |k: &str, t: Option<&str>| {
        (0..df.height())
            .filter(|&i| detector[i].as_deref() == Some("seed") && kind[i].as_deref() == Some(k))
            .filter(|&i| t.is_none_or(|t| target[i].as_deref() == Some(t)))
            .count()
    };
    // Every trial faulty; the kind is the fastest grid digit, so the three populations take turns.
    assert_eq!((count("bias", None), count("actuator_bias", None), count("actuator_stuck", None)), (12, 12, 12));
    assert!(count("actuator_bias", Some("elevator_rad")) >= 4 && count("actuator_bias", Some("throttle")) >= 4);
    assert_eq!(count("actuator_stuck", Some("elevator_effectiveness")), 12);
    let manifest = std::fs::read_to_string(out.join("manifest.json")).unwrap();
    assert!(
        manifest.contains("\"actuator_bias\": \"input units\"")
            && manifest.contains("\"bias\": \"multiples of the sensor sigma\""),
        "{manifest}"
    );
    ok(&fdimc(&["summarize", out.to_str().unwrap()]));
    let summary = csv_frame(&out.join("summary.csv"));
    let (skind, decided) = (
        summary.column("kind").unwrap().str().unwrap().clone(),
        summary.column("isolation_decided").unwrap().i64().unwrap().clone(),
    );
    let actuator_rows: Vec<usize> =
        (0..summary.height()).filter(|&i| skind.get(i).is_some_and(|k| k.starts_with("actuator_"))).collect();
    assert!(!actuator_rows.is_empty());
    assert!(
        actuator_rows.iter().all(|&i| decided.get(i) == Some(0)),
        "an actuator group counted an isolation decision"
    );

    // Bad actuator faults: exit 2 naming the field and what is allowed.
    let bad_fixed = |f: &str| deck.clone() + "\n[[faults]]\n" + f + "\nonset_s = 6.0\n";
    for (bad, field, says) in [
        (
            bad_fixed("input = \"elevator_rad\"\nkind = \"total_failure\""),
            "faults[0].kind",
            "allowed \"stuck\", \"gain\", \"bias\", \"float\"",
        ),
        (
            bad_fixed("output = \"q_rad_s\"\nkind = \"float\""),
            "faults[0].kind",
            "allowed \"stuck\", \"gain\", \"bias\", \"total_failure\"",
        ),
        (
            bad_fixed("output = \"q_rad_s\"\ninput = \"elevator_rad\"\nkind = \"bias\"\nsize = 1.0"),
            "faults[0].input",
            "not both",
        ),
        (bad_fixed("input = \"rudder\"\nkind = \"float\""), "faults[0].input", "plant.inputs or truth.fault_inputs"),
        (
            deck.clone() + "\n[[monte_carlo.fault]]\nkind = \"bias\"\ninputs = [\"throttle\"]\nsize_sigma = 2.0\n",
            "monte_carlo.fault[0].size_sigma",
            "an actuator has no sensor sigma",
        ),
        (
            deck.replace("fault_inputs = [\"elevator_effectiveness\"]", "fault_inputs = [\"elevator_rad\"]"),
            "truth.fault_inputs[0]",
            "is mapped to a model input",
        ),
        (
            deck.replace("fault_inputs = [\"elevator_effectiveness\"]", "fault_inputs = [\"V0_m_s\"]"),
            "truth.fault_inputs[0]",
            "a fault input must be one of: elevator_rad, throttle, elevator_effectiveness",
        ),
    ] {
        let path = write("bad.toml", &bad);
        let o = fdimc(&["validate", &path]);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{field}: {err}");
        assert!(err.contains(&format!("bad.toml: {field}")) && err.contains(says), "{field}: {err}");
    }
}

/// Beside the identifier's own fit, an answer from outside fdimc: FMPy's central differences of the same
/// aircraft (its model-exchange FMU) at the deck's trim, which the model-exchange deck's linearisation
/// meets to 1e-6 of each matrix's largest entry. The deck's trim is one (FMPy's derivatives
/// there below 1e-9), the identified model's poles are FMPy's Jacobian's to 0.5 % (short period -2.05
/// +- 2.95i, phugoid -0.022 +- 0.214i, the altitude integrator 0; 0.2 % seen), and its frequency
/// response from the two inputs to the six outputs is FMPy's to 1 % of its largest entry at 0.1, 0.3, 1
/// and 3 rad/s (0.3 % seen, 2026-12-06).
fn identified_model_meets_fmpys_jacobian(deck: &str) {
    use nalgebra::{Complex, DMatrix};
    let design: serde_json::Value = serde_json::from_str(&ok(&fdimc(&["design", deck, "--json"]))).unwrap();
    let model = &design["linear_model"];
    let (a, b, c) = (fmpy::matrix(&model["a"]), fmpy::matrix(&model["b"]), fmpy::matrix(&model["c"]));
    let aircraft = bundled_fmus().join("aircraft.fmu");
    let trim = [
        "alpha0_rad=0.0443566119725",
        "theta0_rad=0.0443566119725",
        "throttle=0.459166130340",
        "elevator_rad=0.0211591440454",
    ];
    let mut args = vec!["jacobian", aircraft.to_str().unwrap()];
    trim.iter().for_each(|t| args.extend(["--set", t]));
    let Some(j) = fmpy::fmpy(&args) else { return };
    assert!(j["error"].is_null(), "{j}");
    let dx0: Vec<f64> = j["dx0"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!(dx0.iter().all(|d| d.abs() < 1e-9), "not a trim: {dx0:?}");
    let names = |key: &str| -> Vec<String> {
        j[key].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect()
    };
    let at = |list: &[String], name: &str| list.iter().position(|n| n == name).unwrap_or_else(|| panic!("{name}"));
    let (inputs, outputs) = (names("inputs"), names("outputs"));
    // The deck's [truth] inputs and outputs, in the order of the identified model's columns and rows.
    let deck_inputs = ["throttle", "elevator_rad"].map(|n| at(&inputs, n));
    let deck_outputs = ["V_m_s", "alpha_rad", "q_rad_s", "theta_rad", "gamma_rad", "h_m"].map(|n| at(&outputs, n));
    let a_ref = fmpy::matrix(&j["A"]);
    let b_ref = fmpy::matrix(&j["B"]).select_columns(&deck_inputs);
    let c_ref = fmpy::matrix(&j["C"]).select_rows(&deck_outputs);
    let poles = a.complex_eigenvalues();
    let poles_ref = a_ref.complex_eigenvalues();
    for p in poles_ref.iter() {
        let nearest = poles.iter().map(|q| (q - p).norm()).fold(f64::INFINITY, f64::min);
        assert!(nearest <= 0.005 * p.norm() + 1e-3, "FMPy's pole {p} is {nearest} from the identified {poles}");
    }
    let response = |a: &DMatrix<f64>, b: &DMatrix<f64>, c: &DMatrix<f64>, w: f64| {
        let n = a.nrows();
        let s_minus_a =
            DMatrix::<Complex<f64>>::from_fn(n, n, |i, k| Complex::new(-a[(i, k)], if i == k { w } else { 0.0 }));
        let x = s_minus_a.lu().solve(&b.map(|v| Complex::new(v, 0.0))).unwrap();
        c.map(|v| Complex::new(v, 0.0)) * x
    };
    for w in [0.1, 0.3, 1.0, 3.0] {
        let (g, g_ref) = (response(&a, &b, &c, w), response(&a_ref, &b_ref, &c_ref, w));
        let largest = g_ref.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let off = (&g - &g_ref).iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert!(off <= 0.01 * largest, "at {w} rad/s the identified response is {off} off FMPy's, largest {largest}");
    }
    // The model-exchange deck's linearisation (the aircraft's own directional derivatives, held against
    // fdimc's central differences) is FMPy's central differences entry by entry, in the same coordinates.
    let design: serde_json::Value =
        serde_json::from_str(&ok(&fdimc(&["design", "studies/fmu_aircraft.toml", "--json"]))).unwrap();
    let model = &design["linear_model"];
    assert!(model["method"].as_str().unwrap().contains("directional derivatives"), "{model}");
    for (what, ours, theirs) in [
        ("A", fmpy::matrix(&model["a"]), a_ref),
        ("B", fmpy::matrix(&model["b"]), b_ref),
        ("C", fmpy::matrix(&model["c"]), c_ref),
    ] {
        let off = (&ours - &theirs).amax();
        assert!(off <= 1e-6 * theirs.amax(), "{what}: {off} off FMPy's\n{ours}{theirs}");
    }
}

#[test]
fn a_co_simulation_only_fmu_gets_its_linear_model_identified_and_flies() {
    let dir = tempfile::tempdir().unwrap();
    let deck = std::fs::read_to_string("studies/fmu_aircraft.toml")
        .unwrap()
        .replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {:?}", bundled_fmus().join("aircraft_cs.fmu")))
        .replace("interface = \"model_exchange\"", "interface = \"co_simulation\"")
        .replace("\nlinearise = true\n", "\nidentify = true\n");
    assert!(deck.contains("identify = true") && deck.contains("aircraft_cs.fmu"));
    let path = dir.path().join("identified.toml");
    std::fs::write(&path, &deck).unwrap();
    let path = path.to_str().unwrap();
    let validated = ok(&fdimc(&["validate", path]));
    assert!(validated.contains("[plant] is identified from the FMU's responses at the trim"), "{validated}");
    let design = ok(&fdimc(&["design", path]));
    assert!(
        design.contains("from aircraft_cs.fmu's pulse responses about the trim by ERA: 5 states")
            && design.contains("fit on 5 s of square waves: v_m_s "),
        "{design}"
    );
    // Every output fits to better than 99 %.
    let fits: Vec<f64> = design
        .split("fit on 5 s of square waves: ")
        .nth(1)
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .split(", ")
        .map(|f| f.split(' ').nth(1).unwrap().parse().unwrap())
        .collect();
    assert!(fits.len() == 6 && fits.iter().all(|&f| f > 99.0), "{fits:?}");
    identified_model_meets_fmpys_jacobian(path);
    let out = dir.path().join("run");
    ok(&fdimc(&["run", path, "--trials", "30", "--out", out.to_str().unwrap(), "--quiet"]));
    let df = read_frame(&out.join("trials.parquet"));
    assert_eq!((df.height(), df.column("failure").unwrap().null_count()), (3 * 30, 3 * 30));
    // Both at once is refused by name.
    let both = deck.replace("\nidentify = true\n", "\nidentify = true\nlinearise = true\n");
    std::fs::write(dir.path().join("both.toml"), both).unwrap();
    let o = fdimc(&["validate", dir.path().join("both.toml").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o.stderr).contains("truth.identify: give linearise (model exchange) or identify, not both"));
}

#[test]
fn a_detector_fmu_on_an_fmu_truth_sees_the_measured_outputs_with_their_trims_added_back() {
    let dir = tempfile::tempdir().unwrap();
    // The FMU aircraft's trim: alpha = theta = 0.0443566119725 rad, q = 0. The detector FMU sees absolute
    // outputs, so its means are the trims: it then tests the deviations, as fdimc's detectors do.
    let trim = 0.0443566119725;
    let detector = format!(
        "[[detector]]\nname = \"ewma\"\nkind = \"fmu\"\nfmu = {:?}\n\
         measured = {{ in_1 = \"alpha_rad\", in_2 = \"q_rad_s\", in_3 = \"theta_rad\" }}\n\
         statistic = \"statistic\"\n\
         parameters = {{ lambda = 0.05, mean_1 = {trim}, mean_3 = {trim}, scale_1 = 0.002, scale_2 = 0.005, scale_3 = 0.002 }}\n\
         thresholds = [1.6]\n\n[monte_carlo]\n",
        bundled_fmus().join("ewma_detector.fmu")
    );
    let deck = std::fs::read_to_string("studies/fmu_aircraft.toml")
        .unwrap()
        .replace("fmu = \"fmus/aircraft.fmu\"", &format!("fmu = {:?}", bundled_fmus().join("aircraft.fmu")))
        .replacen("[monte_carlo]\n", &detector, 1);
    let path = dir.path().join("ewma.toml");
    std::fs::write(&path, &deck).unwrap();
    let file = dir.path().join("trace.parquet");
    let said = ok(&fdimc(&[
        "simulate",
        path.to_str().unwrap(),
        "--trial",
        "5",
        "--detector",
        "ewma",
        "--out",
        file.to_str().unwrap(),
    ]));
    let trace = read_frame(&file);
    let (alpha, q, theta) =
        (f64_column(&trace, "y_alpha_rad"), f64_column(&trace, "y_q_rad_s"), f64_column(&trace, "y_theta_rad"));
    // What the FMU was given: each measured deviation plus its output trim, added as fdimc adds it.
    let absolute = |y: &[f64], t: f64| y.iter().map(|v| v + t).collect::<Vec<f64>>();
    let (alpha, q, theta) = (absolute(&alpha, trim), absolute(&q, 0.0), absolute(&theta, trim));
    let (statistic, _) = native_ewma([&alpha, &q, &theta], [trim, 0.0, trim], 0.05, [0.002, 0.005, 0.002]);
    assert_eq!(f64_column(&trace, "stat_q_rad_s"), statistic, "{said}");
    // The trims matter: without them the statistic would start near |alpha_trim| / 0.002 / 20 = 1.1.
    assert!(statistic[0] < 0.2, "{}", statistic[0]);
}

/// The default profile grid (5 %) against the full profiles (`--profile-resolution 0`, every rise) on
/// the CI deck: the same rows, the same calibrated thresholds to the byte, every count and rate equal;
/// only the calibrated sets' delays differ, never earlier (a replayed alarm is at or after the
/// statistic's first sample above the threshold); and the records several times smaller.
#[test]
fn the_profile_grid_keeps_every_count_and_threshold_of_the_full_profiles() {
    let tmp = tempfile::tempdir().unwrap();
    let (grid, full) = (tmp.path().join("grid"), tmp.path().join("full"));
    ok(&fdimc(&["run", CI_DECK, "--quiet", "--out", grid.to_str().unwrap()]));
    ok(&fdimc(&["run", CI_DECK, "--quiet", "--profile-resolution", "0", "--out", full.to_str().unwrap()]));
    let manifest = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("manifest.json")).unwrap()).unwrap()
    };
    assert_eq!(manifest(&grid)["profile_resolution"].as_f64(), Some(0.05));
    assert_eq!(manifest(&full)["profile_resolution"].as_f64(), Some(0.0));
    assert_eq!(
        std::fs::read(grid.join("thresholds.csv")).unwrap(),
        std::fs::read(full.join("thresholds.csv")).unwrap()
    );
    let (g, f) = (csv_frame(&grid.join("summary.csv")), csv_frame(&full.join("summary.csv")));
    assert_eq!(g.height(), f.height());
    let calibrated: Vec<bool> =
        g.column("thresholds").unwrap().str().unwrap().iter().map(|s| s == Some("calibrated")).collect();
    let (mut later, mut delays) = (0, 0);
    for name in g.get_column_names() {
        let (a, b) = (g.column(name).unwrap(), f.column(name).unwrap());
        if name.starts_with("delay_") {
            let (a, b) = (a.f64().unwrap(), b.f64().unwrap());
            for i in 0..g.height() {
                if calibrated[i] {
                    if let (Some(x), Some(y)) = (a.get(i), b.get(i)) {
                        assert!(x >= y, "{name} row {i}: {x} s on the grid, {y} s exact");
                        later += usize::from(x > y);
                        delays += 1;
                    }
                } else {
                    assert_eq!(a.get(i), b.get(i), "{name} row {i}: the deck's thresholds read the trials' own alarms");
                }
            }
        } else {
            assert!(a.equals_missing(b), "{name}");
        }
    }
    assert!(delays >= 48 && later > 0, "{later} of {delays} calibrated delays later on the grid");
    let rows = |d: &Path| read_frame(&d.join("trials.parquet")).height();
    assert_eq!(rows(&grid), rows(&full));
    let bytes = |d: &Path| std::fs::metadata(d.join("trials.parquet")).unwrap().len();
    assert!(bytes(&grid) * 3 < bytes(&full), "{} B on the grid, {} B full", bytes(&grid), bytes(&full));
    assert_replay_repeats_the_trials(&grid);
}

/// The newcomer's path of issue 51: a deck from `fdimc new` (with parameter errors), calibrated at
/// 0.001 with 0.95 confidence, that calibration's summary copied as the baseline, and a check of a
/// fresh run of the same deck: no false regression (the check calibrates at the baseline's target, not
/// the deck's 0.01, which gave three "REGRESSION"s). On the way: the answer block ends the console
/// output with the fault-free Pfa to its significant digits, the tail fits' figures only behind
/// --verbose, and parameter_errors.csv groups by each parameter's own bins.
#[test]
fn the_newcomers_path_calibrates_copies_a_baseline_and_checks_without_false_regressions() {
    let tmp = tempfile::tempdir().unwrap();
    let (deck, out) = (tmp.path().join("own.toml"), tmp.path().join("own"));
    let (deck_s, out_s) = (deck.to_str().unwrap(), out.to_str().unwrap());
    let ok = |o: &Output| {
        assert!(o.status.success(), "{}{}", text(&o.stdout), text(&o.stderr));
        text(&o.stdout)
    };
    ok(&fdimc(&["new", "detection_filter", deck_s]));
    let run = ok(&fdimc(&["run", deck_s, "--out", out_s]));
    let answer = run.split("  answer, at the calibrated thresholds").nth(1).expect("the answer block ends the output");
    // The printed Pfa is the calibration's count over the flights with Wilson's interval, each worked out
    // here: at 0.01 the calibration lets through floor(0.01 n) of n (8 of 869: 9.2e-3 [4.7e-3, 1.8e-2]).
    let a = csv_frame(&out.join("answer.csv"));
    let count = |c: &str| {
        a.column(c).unwrap().cast(&polars::prelude::DataType::Float64).unwrap().f64().unwrap().get(0).unwrap()
    };
    let (n, k) = (count("fault_free_flights"), count("fault_free_false_alarms"));
    assert_eq!(k, (0.01 * n).floor(), "{n} flights, {k} alarms");
    let z = 1.959_963_984_540_054_f64;
    let (p, centre, denom) = (k / n, k / n + z * z / (2.0 * n), 1.0 + z * z / n);
    let half = z * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    let said = format!(
        "Pfa {:.1e} [{:.1e}, {:.1e}] on {n} fault-free flights",
        p,
        (centre - half) / denom,
        (centre + half) / denom
    );
    assert!(answer.contains(&said), "{said} in {run}");
    assert!(answer.contains("Pd by fault: bias "), "{run}");
    assert!(!run.contains("do not trust: shape"), "tail details only with --verbose: {run}");
    let verbose = ok(&fdimc(&["summarize", out_s, "--verbose"]));
    assert!(verbose.contains("rare false alarms (generalised Pareto fit"), "{verbose}");

    // Each parameter error by its own bins: 5 of pitch_moment's -0.2..0.2, 3 of elevator's -0.1..0.1,
    // per threshold set (2), detector (2) and fault-free or faulty (2).
    let by_parameter = csv_frame(&out.join("parameter_errors.csv"));
    assert_eq!(by_parameter.height(), (5 + 3) * 2 * 2 * 2);
    let bins = |name: &str| -> Vec<f64> {
        let p = by_parameter.column("parameter").unwrap().str().unwrap().clone();
        let b = by_parameter.column("error_bin").unwrap().f64().unwrap().clone();
        let mut v: Vec<f64> = (0..p.len()).filter(|&i| p.get(i) == Some(name)).filter_map(|i| b.get(i)).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    assert_eq!(bins("pitch_moment"), [-0.16, -0.08, 0.0, 0.08, 0.16]);
    assert_eq!(bins("elevator"), [-0.066666666667, 0.0, 0.066666666667]);
    // The largest-|error| bin of summary.csv without last-bit noise: 0 is 0, +-1/15 one group.
    let summary = csv_frame(&out.join("summary.csv"));
    let mut largest: Vec<f64> = summary.column("param_error_bin").unwrap().f64().unwrap().into_no_null_iter().collect();
    largest.sort_by(f64::total_cmp);
    largest.dedup();
    assert_eq!(largest, [0.0, 0.066666666667, 0.08, 0.16]);
    // The report: false alarms against the parameter error (one noise scale), each parameter's table.
    ok(&fdimc(&["report", out_s]));
    let report = out.join("report");
    let fa = std::fs::read_to_string(report.join("false_alarms_seed.svg")).unwrap();
    assert!(fa.contains("parameter error (bin: the largest |error| of the trial") && fa.contains("noise scale 1"));
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    assert!(
        html.contains("<h2>Parameter errors, one at a time</h2>")
            && html.contains("parameter_errors.csv</code>: 64 rows")
    );

    ok(&fdimc(&["summarize", out_s, "--target-pfa", "0.001", "--confidence", "0.95"]));
    let baseline = tmp.path().join("baseline.csv");
    std::fs::copy(out.join("calibrations/pfa_1e-3_confidence_0.95/summary.csv"), &baseline).unwrap();
    let check = fdimc(&["check", deck_s, "--baseline", baseline.to_str().unwrap()]);
    let said = text(&check.stdout);
    assert_eq!(check.status.code(), Some(0), "{said}{}", text(&check.stderr));
    assert!(said.contains("the baseline's thresholds are calibrated at Pfa 0.001 with 0.95 confidence"), "{said}");
    assert!(!said.contains("REGRESSION") && said.contains(": 0 regression(s)"), "{said}");
}

/// Missed detection before the hazard (issue 52, item 3): with `[monte_carlo.time_to_hazard_s]` the
/// summary gives, per group, the faulty flights not detected within their fault's time to hazard, and
/// the answer prints it per fault kind. Recounted here from the records at the deck's thresholds: a
/// bias within 0.5 s, a stuck alpha sensor within 0.05 s and a stuck pitch-rate sensor within 1 s.
/// Times the deck cannot use are refused by field.
#[test]
fn time_to_hazard_gives_the_probability_of_missing_the_hazard() {
    use polars::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let table = "\n[monte_carlo.time_to_hazard_s]\nbias = 0.5\nstuck = { alpha_rad = 0.05, q_rad_s = 1.0 }\n";
    let edit = |name: &str, extra: &str| {
        let source = std::fs::read_to_string(CI_DECK).unwrap();
        let path = tmp.path().join(name);
        std::fs::write(&path, format!("{source}{extra}")).unwrap();
        path
    };
    let deck = edit("hazard.toml", table);
    let out = tmp.path().join("run");
    let stdout = ok(&fdimc(&["run", deck.to_str().unwrap(), "--trials", "1500", "--out", out.to_str().unwrap()]));

    let records = read_frame(&out.join("trials.parquet"));
    let col = |n: &str| records.column(n).unwrap().clone();
    let (det, kind, target) = (col("detector"), col("kind"), col("target"));
    let (det, kind, target) = (det.str().unwrap(), kind.str().unwrap(), target.str().unwrap());
    let (fault_free, detected, delay, failure) = (col("fault_free"), col("detected"), col("delay_s"), col("failure"));
    let (fault_free, detected, delay) = (fault_free.bool().unwrap(), detected.bool().unwrap(), delay.f64().unwrap());
    let failure = failure.str().unwrap();
    // Per (kind, target) of the seed detector: (units, missed before the hazard).
    let mut want: std::collections::BTreeMap<(String, String), (u64, u64)> = Default::default();
    for i in 0..records.height() {
        if det.get(i) != Some("seed") || fault_free.get(i) == Some(true) || failure.get(i).is_some() {
            continue;
        }
        let (k, t) = (kind.get(i).unwrap(), target.get(i).unwrap());
        let limit = match (k, t) {
            ("bias", _) => 0.5,
            ("stuck", "alpha_rad") => 0.05,
            ("stuck", "q_rad_s") => 1.0,
            other => panic!("a fault this deck does not fly: {other:?}"),
        };
        let in_time = detected.get(i) == Some(true) && delay.get(i).is_some_and(|d| d <= limit);
        let e = want.entry((k.to_string(), t.to_string())).or_default();
        *e = (e.0 + 1, e.1 + (!in_time) as u64);
    }
    let summary = csv_frame(&out.join("summary.csv"));
    let s = |n: &str| summary.column(n).unwrap().clone();
    let (sets, sdet, skind, starget) = (s("thresholds"), s("detector"), s("kind"), s("target"));
    let (units, missed, time) = (
        s("hazard_units").cast(&DataType::UInt64).unwrap(),
        s("missed_before_hazard").cast(&DataType::UInt64).unwrap(),
        s("time_to_hazard_s").cast(&DataType::Float64).unwrap(),
    );
    let mut got: std::collections::BTreeMap<(String, String), (u64, u64)> = Default::default();
    for i in 0..summary.height() {
        if sets.str().unwrap().get(i) != Some("deck") || sdet.str().unwrap().get(i) != Some("seed") {
            continue;
        }
        let Some(n) = units.u64().unwrap().get(i) else { continue };
        let key =
            (skind.str().unwrap().get(i).unwrap().to_string(), starget.str().unwrap().get(i).unwrap().to_string());
        let t = time.f64().unwrap().get(i).unwrap();
        assert_eq!(
            t,
            if key.0 == "bias" {
                0.5
            } else if key.1 == "alpha_rad" {
                0.05
            } else {
                1.0
            },
            "{key:?}"
        );
        let e = got.entry(key).or_default();
        *e = (e.0 + n, e.1 + missed.u64().unwrap().get(i).unwrap());
    }
    assert_eq!(got, want);
    assert_eq!(got.len(), 4, "bias and stuck on two outputs");
    // Some miss the hazard and some do not, so the counts can tell the times apart.
    assert!(got.values().any(|&(n, m)| m > 0 && m < n), "{got:?}");

    // detectors.csv over every fault, and the answer per kind.
    let detectors = csv_frame(&out.join("detectors.csv"));
    let row = (0..detectors.height())
        .find(|&i| {
            detectors.column("thresholds").unwrap().str().unwrap().get(i) == Some("deck")
                && detectors.column("detector").unwrap().str().unwrap().get(i) == Some("seed")
        })
        .unwrap();
    let (n, m) = want.values().fold((0, 0), |a, &(n, m)| (a.0 + n, a.1 + m));
    let p = detectors.column("p_miss_before_hazard").unwrap().f64().unwrap().get(row).unwrap();
    assert_eq!(p, m as f64 / n as f64);
    let answer = stdout.split("  answer, at the").nth(1).unwrap();
    assert!(answer.contains("P(not detected before the hazard): bias within 0.5 s "), "{stdout}");
    assert!(answer.contains("; stuck within its target's time "), "{stdout}");

    // safety.csv (issue 52, item 4): the plain Monte Carlo rate per flight hour is the fault-free
    // flights' rate over an hour of 360 independent 10 s flights; the miss before the hazard is
    // detectors.csv's at the same thresholds; each says its method and assumptions.
    let safety = csv_frame(&out.join("safety.csv"));
    let text_of = |c: &str, i: usize| safety.column(c).unwrap().str().unwrap().get(i).unwrap().to_string();
    let value = |i: usize| safety.column("value").unwrap().f64().unwrap().get(i).unwrap();
    let answers = csv_frame(&out.join("answer.csv"));
    let a = (0..answers.height())
        .find(|&i| answers.column("detector").unwrap().str().unwrap().get(i) == Some("seed"))
        .unwrap();
    let cell = |c: &str| answers.column(c).unwrap().cast(&DataType::Float64).unwrap().f64().unwrap().get(a).unwrap();
    let p = cell("fault_free_false_alarms") / cell("fault_free_flights");
    let plain = (0..safety.height())
        .find(|&i| {
            text_of("detector", i) == "seed"
                && text_of("method", i).starts_with("plain Monte Carlo")
                && text_of("figure", i) == "false alarms per flight hour"
        })
        .unwrap();
    assert!((value(plain) - (1.0 - (1.0 - p).powf(360.0))).abs() < 1e-12, "{}", value(plain));
    assert!(text_of("assumptions", plain).starts_with(
        "per flight hour: at least one false alarm in an hour of flight, the hour's 360 trials of 10 s taken as \
         independent, each begun with the filter on the truth; sensor noise Gaussian"
    ));
    // The sentence to paste (issue 81, item 3): its thresholds, the one-sided 95 % upper bound (Wilson
    // at z = 1.645, computed here), what it leaves out, the deck's hash and fdimc's version; 10 s
    // trials are trials, not flights.
    let (k, n) = (cell("fault_free_false_alarms"), cell("fault_free_flights"));
    let z = 1.6448536269514722f64;
    let one_sided =
        (p + z * z / (2.0 * n) + z * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt()) / (1.0 + z * z / n);
    let upper = safety.column("value_upper_95").unwrap().f64().unwrap().get(plain).unwrap();
    assert!((upper / (1.0 - (1.0 - one_sided).powf(360.0)) - 1.0).abs() < 1e-9, "{upper} ({k} of {n})");
    let statement = text_of("statement", plain);
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    let sha = manifest["deck_sha256"].as_str().unwrap()[..16].to_string();
    for part in [
        "seed at the calibrated thresholds (".to_string(),
        "one-sided 95 % upper bound ".to_string(),
        "fault-free trials of 10 s; assuming per flight hour".to_string(),
        "not covered: model error beyond the deck's parameter errors".to_string(),
        format!("deck sha256 {sha}, fdimc {}", env!("CARGO_PKG_VERSION")),
    ] {
        assert!(statement.contains(&part), "{part:?} not in {statement}");
    }
    assert!(!statement.contains("fault-free flights"), "{statement}");
    let missed = (0..safety.height())
        .find(|&i| text_of("detector", i) == "seed" && text_of("figure", i) == "missed detection before the hazard")
        .unwrap();
    let calibrated = (0..detectors.height())
        .find(|&i| {
            detectors.column("thresholds").unwrap().str().unwrap().get(i) == Some("calibrated")
                && detectors.column("detector").unwrap().str().unwrap().get(i) == Some("seed")
        })
        .unwrap();
    assert_eq!(Some(value(missed)), detectors.column("p_miss_before_hazard").unwrap().f64().unwrap().get(calibrated));
    let said = text_of("statement", missed);
    assert!(said.starts_with("seed at the calibrated thresholds (v_m_s "), "{said}");
    assert!(
        said.contains("): missed detection before the hazard ") && said.contains("not covered: fault kinds"),
        "{said}"
    );
    // The answer says it; the safety sentences are safety.csv's (and --verbose's).
    assert!(
        stdout.contains("P(not detected before the hazard): ") && stdout.contains("safety.csv (the figures to quote"),
        "{stdout}"
    );

    for (name, extra, field, allowed) in [
        ("negative", "\n[monte_carlo.time_to_hazard_s]\nbias = -1.0\n", "bias", "must be a finite number > 0, got -1"),
        (
            "kind",
            "\n[monte_carlo.time_to_hazard_s]\ndrift = 1.0\n",
            "drift",
            "no drift faults in this deck; its fault kinds: bias, stuck",
        ),
        (
            "target",
            "\n[monte_carlo.time_to_hazard_s]\nstuck = { h_m = 1.0 }\n",
            "stuck.h_m",
            "stuck faults of this deck hit alpha_rad, q_rad_s, not h_m",
        ),
        (
            "text",
            "\n[monte_carlo.time_to_hazard_s]\nbias = \"soon\"\n",
            "bias",
            "a time in seconds, or a table of targets to times (s), got string",
        ),
    ] {
        let bad = edit(&format!("{name}.toml"), extra);
        let out = fdimc(&["validate", bad.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{name}");
        let want = format!("{}: monte_carlo.time_to_hazard_s.{field}: {allowed}", bad.display());
        assert!(text(&out.stderr).contains(&want), "{name}: {}", text(&out.stderr));
    }
    // A kind that does not take it says so.
    let source = std::fs::read_to_string("studies/ci_seed002.toml").unwrap();
    let air = tmp.path().join("air.toml");
    std::fs::write(&air, format!("{source}\n[monte_carlo.time_to_hazard_s]\nbias = 1.0\n")).unwrap();
    let out = fdimc(&["validate", air.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("monte_carlo.time_to_hazard_s: not used by"), "{}", text(&out.stderr));
}

/// Heavy-tailed sensor noise (issue 52, item 2): `noise.sensor_law` takes "gaussian" or
/// "student_t(N)", for every output or one per output; anything else is refused by field, and the
/// rare-event command, whose importance sampling tilts Gaussian draws, refuses a heavy-tailed deck.
#[test]
fn sensor_noise_laws_are_checked_and_rare_event_refuses_heavy_tails() {
    let tmp = tempfile::tempdir().unwrap();
    let source = std::fs::read_to_string(CI_DECK).unwrap();
    let with = |name: &str, law: &str| {
        let path = tmp.path().join(name);
        std::fs::write(&path, source.replacen("[noise]\n", &format!("[noise]\nsensor_law = {law}\n"), 1)).unwrap();
        path
    };
    let log_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/logs/sample_log_small.ulg");
    let recorded = with("recorded.toml", &format!("{{ log = \"{}\", field = \"gyro_rad[0]\" }}", log_path.display()));
    let said = ok(&fdimc(&["validate", recorded.to_str().unwrap()]));
    assert!(said.contains("empirical(") && said.contains("sensor_combined gyro_rad[0])"), "{said}");
    let good = with("good.toml", "\"student_t(4)\"");
    let said = ok(&fdimc(&["validate", good.to_str().unwrap()]));
    assert!(
        said.contains(
            "sensor law [student_t(4), student_t(4), student_t(4), student_t(4), student_t(4), student_t(4)]"
        ),
        "{said}"
    );
    for (name, law, field, allowed) in [
        (
            "dof",
            "\"student_t(2)\"",
            "noise.sensor_law",
            "\"student_t(2)\": 2 degrees of freedom; allowed \"gaussian\", \"student_t(N)\" with N > 2",
        ),
        (
            "word",
            "[\"gaussian\", \"laplace\", \"gaussian\", \"gaussian\", \"gaussian\", \"gaussian\"]",
            "noise.sensor_law[1]",
            "\"laplace\": allowed",
        ),
        (
            "count",
            "[\"gaussian\", \"gaussian\"]",
            "noise.sensor_law",
            "one law for every output, or a list of 6 (one per output), got 2",
        ),
        ("type", "4", "noise.sensor_law", "got integer; allowed \"gaussian\""),
        (
            "key",
            "{ log = \"x.ulg\", field = \"gyro_rad[0]\", colour = 1 }",
            "noise.sensor_law.colour",
            "unknown key; allowed log, field, topic, instance",
        ),
        ("field", "{ log = \"x.ulg\" }", "noise.sensor_law.field", "missing: the topic's field"),
        (
            "file",
            "{ log = \"nope.ulg\", field = \"gyro_rad[0]\" }",
            "noise.sensor_law.log",
            &format!("{}: no such file", tmp.path().join("nope.ulg").display()),
        ),
        (
            "channel",
            &format!("{{ log = \"{}\", field = \"gyro_rad[7]\" }}", log_path.display()),
            "noise.sensor_law.log",
            &format!("{}: topic \"sensor_combined\" has no number field \"gyro_rad[7]\"", log_path.display()),
        ),
    ] {
        let bad = with(&format!("{name}.toml"), law);
        let out = fdimc(&["validate", bad.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{name}");
        let want = format!("{}: {field}: {allowed}", bad.display());
        assert!(text(&out.stderr).contains(&want), "{name}: {}", text(&out.stderr));
    }
    let out = fdimc(&["rare-event", good.to_str().unwrap(), "--out", tmp.path().join("rare").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("noise.sensor_law: importance sampling and splitting here tilt Gaussian"),
        "{}",
        text(&out.stderr)
    );
}
