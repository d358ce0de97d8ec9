//! `fdimc new accelerometer FILE --replay LOG`: a commented starter deck that replays a PX4 log. The
//! log is surveyed first, so the deck names a topic it has, a gap limit it passes and parts that fit:
//! the first half trains (classifiers `trained_on = "log"`), the second half is evaluated.

use std::path::{Component, Path, PathBuf};

use crate::engine::logs::flight_log::survey;
use crate::methods::accelerometer::replay::NEEDS;

/// A trial's segment in the starter (s); each half of the log must hold one.
const TRIAL_S: f64 = 4.0;
/// The step the log is resampled to (s): the rate the method's filter and features are tuned for.
const DT_S: f64 = 0.01;

/// The starter deck for study `study`, written to `deck`, replaying `log`; or why `log` cannot be
/// replayed as the starter has it (naming the log and what to do).
pub fn replay_deck(study: &str, log: &Path, deck: &Path) -> Result<String, String> {
    let name = log.display();
    if !log.is_file() {
        return Err(format!("--replay {name}: no such file"));
    }
    let (topics, _) = survey(log).map_err(|e| format!("--replay {e}"))?;
    let Some(imu) = topics.iter().find(|t| t.topic == NEEDS.topic && t.instance == 0) else {
        let mut names: Vec<&str> = topics.iter().map(|t| t.topic.as_str()).collect();
        names.dedup();
        return Err(format!(
            "--replay {name}: no topic {:?} (the log has: {}); write [log] topic and [log.signals] by hand (docs/deck.md)",
            NEEDS.topic,
            names.join(", ")
        ));
    };
    let span_s = imu.last_s - imu.first_s;
    if !(span_s >= 2.0 * TRIAL_S) {
        return Err(format!(
            "--replay {name}: {} spans {span_s:.2} s; the starter's {TRIAL_S} s trials need {} s (a half to train, a half to evaluate): write the deck by hand with a shorter study.duration_s",
            NEEDS.topic,
            2.0 * TRIAL_S
        ));
    }
    // Parts on the resampled grid, at 0.1 s and 0.01 s: inside the log's span at DT_S.
    let half_s = (span_s / 2.0 * 10.0).floor() / 10.0;
    let end_s = (span_s / DT_S).floor() * DT_S;
    // The next millisecond above the largest gap, at least 20 ms (5 samples at 250 Hz).
    let max_gap_s = ((imu.largest_gap_s * 1e3).floor() / 1e3 + 1e-3).max(0.02);
    let file = relative_to(deck, log);
    Ok(format!(
        r#"# A deck of kind accelerometer (method 003) that replays a recorded flight, written by
# `fdimc new accelerometer --replay`: the log's gyro and accelerometer replace the simulator; each trial
# is a {TRIAL_S} s segment of the evaluated part with one accelerometer fault (bias, gain or stuck, on a
# drawn axis, size and onset) injected into the recorded accelerometer, or none.
# `fdimc validate` shows what it resolves to, `fdimc run` writes results/{study}/ (fault_free_replay.json:
# the fault-free log's alarms per flight hour), `fdimc report results/{study}` adds "Replay of a flight
# log". Look at the log and the parts first:
#   fdimc log {name} --plot log.svg --signals gyro_rad[2],accelerometer_m_s2[2] --deck {deck_name}
# Every field: docs/deck.md and docs/flight-logs.md in fdimc's repository.

[study]
name = "{study}"
seed = 1
duration_s = {TRIAL_S:.1}                # a trial's segment; each part must hold one
dt_s = {DT_S}                   # the log resampled to 100 Hz, the rate the filter and features are tuned for

[imu]                           # the kind's marker; the motion is the log's

[log]
file = "{file}"
topic = "{topic}"       # gyro_rad[0..2], accelerometer_m_s2[0..2] ([log.signals] maps others)
max_gap_s = {max_gap_s:.3}                # s; this log's largest gap is {gap:.3} s (longer gaps are refused)
train_s = [0.0, {half_s:.1}]            # s from the first sample: classifiers trained_on = "log" (and a calibrated threshold) learn here
evaluate_s = [{half_s:.1}, {end_s:.2}]         # s: trials start here; never overlaps train_s
# debias = ["gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s"]  # remove the gyro's train_s mean (a bias
#                               # calibration): only where train_s is at rest, which validate checks

[faults]
bias_mps2 = [0.05, 0.5]         # |bias|, the seed deck's range
gain_deviation = [0.05, 0.3]    # |factor - 1|
onset_s = [2.0, 2.8]            # from the segment's start: after settle_s, the features' window inside

[training]
trials_per_class = 100          # more make steadier classifiers (the bundled replay decks train 300)
seed = 2
c = 10.0

[detection]
window_samples = 20
threshold = 60.0                # measured on simulated flights; or, instead of it:
# log_threshold_margin = 1.5    # 1.5 x the largest fault-free T of train_s (warned of when train_s holds a transient)
settle_s = 1.5                  # the filter aligns on the segment's first sample

[[classifier]]
name = "tree_sim"               # the patent's SVM tree, trained on simulated flights
scheme = "tree"

[[classifier]]
name = "tree_log"               # the same tree, trained on faults injected into train_s
scheme = "tree"
trained_on = "log"

[monte_carlo]
trials = 400                    # 100 of each class: the fault-free 100 calibrate at Pfa 0.01
classes = ["normal", "bias", "gain", "stuck"]
"#,
        topic = NEEDS.topic,
        gap = imu.largest_gap_s,
        deck_name = deck.display(),
    ))
}

/// `target` as the deck at `deck` names it: relative to the deck's folder (the way `[log] file` is
/// read), through `..` where needed; absolute where the two share no root.
fn relative_to(deck: &Path, target: &Path) -> String {
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let folder = absolute(deck.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")));
    let target = absolute(target);
    fn normal(p: &Path) -> Vec<Component<'_>> {
        let mut out: Vec<Component> = Vec::new();
        for c in p.components() {
            match c {
                Component::CurDir => {}
                Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                    out.pop();
                }
                c => out.push(c),
            }
        }
        out
    }
    let (from, to) = (normal(&folder), normal(&target));
    let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return target.display().to_string();
    }
    let mut rel = PathBuf::new();
    for _ in common..from.len() {
        rel.push("..");
    }
    for c in &to[common..] {
        rel.push(c.as_os_str());
    }
    rel.display().to_string().replace('\\', "/")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The log is named from the deck's folder, as `[log] file` is read.
    #[test]
    fn the_log_is_named_relative_to_the_deck() {
        assert_eq!(relative_to(Path::new("/a/b/deck.toml"), Path::new("/a/logs/x.ulg")), "../logs/x.ulg");
        assert_eq!(relative_to(Path::new("/a/deck.toml"), Path::new("/a/logs/./x.ulg")), "logs/x.ulg");
        assert_eq!(relative_to(Path::new("/a/b/c/deck.toml"), Path::new("/a/b/c/x.ulg")), "x.ulg");
    }
}
