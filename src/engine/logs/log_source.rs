//! A recorded flight as a scenario source any method can replay (issue 22). A method names the signals
//! it needs ([`Needs`]: a deck name with its unit, and the ULog field it is read from by default); the
//! deck's `[log]` section names the file and may map each signal to another field or, for a table, a
//! column. The log is read once per study ([`crate::engine::logs::flight_log`]: checked, streamed), resampled
//! onto the study's step (each step the mean of the samples within half a step of it, a step without one
//! the linear interpolation across the gap: the documented repair for a log's own jittery rate and for
//! gaps up to `max_gap_s`), and split into parts: trials are drawn from the evaluation part, and
//! whatever learns from the log (a classifier, a threshold) only from the training part, which may not
//! overlap it.
//!
//! ```toml
//! [log]
//! file = "logs/sample_appended_multiple.ulg"  # relative to the deck; .ulg, or .csv / .parquet (a table)
//! topic = "sensor_combined"                   # ULog: the topic (default: the method's) and its instance (0)
//! time_column = "t_us"                        # tables: the time column and seconds per unit (1)
//! time_unit_s = 1e-6
//! max_gap_s = 0.05                            # longest gap bridged by interpolation (s)
//! evaluate_s = [4.8, 9.6]                     # log seconds from its first sample (default: all)
//! train_s = [0.0, 4.8]                        # where classifiers and thresholds may learn (optional)
//! debias = ["gyro_x_rad_s"]                   # signals less their train_s mean (a bias calibration)
//! [log.signals]                               # a signal's field or column (ULog: the method's default)
//! accel_x_mps2 = "accelerometer_m_s2[0]"
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;

use crate::engine::logs::flight_log::{LogError, TableRequest, TopicRequest, TopicSeries, read_table, read_ulog};
use crate::engine::scenario::deck::{DeckError, Validator};

/// The deck's `[log]` section (module docs).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogSection {
    pub file: String,
    pub topic: Option<String>,
    pub instance: Option<u8>,
    pub time_column: Option<String>,
    pub time_unit_s: Option<f64>,
    pub max_gap_s: Option<f64>,
    pub evaluate_s: Option<[f64; 2]>,
    pub train_s: Option<[f64; 2]>,
    #[serde(default)]
    pub signals: BTreeMap<String, String>,
    /// Signals whose mean over `train_s` is subtracted from the whole log: a bias calibration (such as a
    /// gyro's at power-up) that sees only the training part.
    #[serde(default)]
    pub debias: Vec<String>,
}

/// Gaps up to this are bridged unless the deck says otherwise (s): 12 samples at 250 Hz (a choice).
pub const DEFAULT_MAX_GAP_S: f64 = 0.05;

/// One signal a method replays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Signal {
    /// Its name in `[log.signals]`, with the unit the method expects.
    pub name: &'static str,
    /// The ULog field it is read from unless the deck maps it.
    pub ulog_field: &'static str,
}

/// What a method reads from a log: the default topic and the signals, in the order the method uses them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Needs {
    pub topic: &'static str,
    pub signals: &'static [Signal],
}

impl Needs {
    /// The signals' names, for messages.
    pub fn names(&self) -> String {
        self.signals.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
    }
}

/// Grid samples `[first, end)` of a resampled log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Part {
    pub first: usize,
    pub end: usize,
}

impl Part {
    pub fn len(&self) -> usize {
        self.end.saturating_sub(self.first)
    }

    pub fn is_empty(&self) -> bool {
        self.end == self.first
    }

    /// The first sample of a segment of `samples` samples inside the part, from a uniform `u` in [0, 1):
    /// every start that keeps the segment inside is equally likely.
    pub fn segment_start(&self, samples: usize, u: f64) -> usize {
        let starts = self.len() + 1 - samples.min(self.len());
        self.first + ((u * starts as f64) as usize).min(starts - 1)
    }
}

/// A log read, checked and resampled (module docs): `signals[s][k]` is signal `s` (the [`Needs`] order)
/// at `k dt_s` after the log's first sample.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayLog {
    pub file: PathBuf,
    /// Where in the file: `topic "sensor_combined" instance 0`, or `table`.
    pub origin: String,
    pub dt_s: f64,
    pub signals: Vec<Vec<f64>>,
    /// The log's own samples, their mean rate and largest gap.
    pub log_samples: usize,
    pub log_rate_hz: f64,
    pub largest_gap_s: f64,
    /// How the file ended when not cleanly (a cut-off recording keeps its valid prefix).
    pub ending: Option<String>,
    /// Where trials are drawn from.
    pub evaluate: Part,
    /// Where classifiers and thresholds may learn; never overlaps `evaluate`.
    pub train: Option<Part>,
    /// The signals `debias` named and the mean over `train` subtracted from each.
    pub removed_means: Vec<(String, f64)>,
    /// The log file's SHA-256 (hex), for the run's provenance.
    pub sha256: String,
    /// The first sample's time on the log's own clock (s; a ULog's boot time): deck and messages count
    /// seconds from it.
    pub first_sample_s: f64,
    /// What the run should warn of: a `debias` window that is not at rest ([`motion_in_window`]).
    pub warnings: Vec<String>,
}

impl ReplayLog {
    /// Grid samples in the log.
    pub fn samples(&self) -> usize {
        self.signals.first().map_or(0, Vec::len)
    }

    /// The seconds `[from, to)` of a part, from the log's first sample.
    pub fn seconds(&self, part: Part) -> [f64; 2] {
        [part.first as f64 * self.dt_s, part.end as f64 * self.dt_s]
    }

    /// Reads, checks and resamples the log of `section` for a method that `needs` these signals, at the
    /// study's step `dt_s`, for trials of `trial_samples` samples. Every refusal names the deck, the
    /// field, and (for what the log lacks) the log file, topic and field.
    pub(crate) fn load(
        v: &Validator,
        section: &LogSection,
        needs: &Needs,
        dt_s: f64,
        trial_samples: usize,
    ) -> Result<Arc<ReplayLog>, DeckError> {
        let file = v.file.parent().unwrap_or(Path::new("")).join(&section.file);
        let max_gap_s = v.positive("log.max_gap_s", section.max_gap_s.unwrap_or(DEFAULT_MAX_GAP_S))?;
        for name in section.signals.keys() {
            if !needs.signals.iter().any(|s| s.name == name) {
                return Err(v.err(format!("log.signals.{name}"), format!("not a signal; allowed: {}", needs.names())));
            }
        }
        let mapped = |s: &Signal| section.signals.get(s.name).cloned();
        let extension = file.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        // Each refusal against the deck field that would mend it: a missing topic is `log.topic`'s, a
        // missing field the signal's mapping, a long gap `log.max_gap_s`; the rest is the file's.
        let log_error = |e: LogError| {
            let field = match &e {
                LogError::MissingTopic { .. } if section.instance.is_some_and(|i| i != 0) => "log.instance".to_string(),
                LogError::MissingTopic { .. } => "log.topic".to_string(),
                LogError::MissingField { field, .. } | LogError::MissingColumn { column: field, .. } => {
                    match needs.signals.iter().find(|s| mapped(s).unwrap_or_else(|| s.ulog_field.to_string()) == *field)
                    {
                        Some(s) => format!("log.signals.{}", s.name),
                        None if section.time_column.as_deref() == Some(field.as_str()) => "log.time_column".into(),
                        None => "log.file".into(),
                    }
                }
                LogError::Gap { .. } => "log.max_gap_s".to_string(),
                _ => "log.file".to_string(),
            };
            v.err(field, e.to_string())
        };
        let (series, origin) = match extension.as_str() {
            "ulg" => {
                for (field, given) in
                    [("time_column", section.time_column.is_some()), ("time_unit_s", section.time_unit_s.is_some())]
                {
                    if given {
                        return Err(v.err(
                            format!("log.{field}"),
                            "only for table logs (.csv, .parquet); a ULog file's time is its timestamp",
                        ));
                    }
                }
                let topic = section.topic.clone().unwrap_or_else(|| needs.topic.to_string());
                let instance = section.instance.unwrap_or(0);
                let fields =
                    needs.signals.iter().map(|s| mapped(s).unwrap_or_else(|| s.ulog_field.to_string())).collect();
                let request = TopicRequest { topic: topic.clone(), instance, fields, max_gap_s };
                (read_ulog(&file, &request).map_err(log_error)?, format!("topic {topic:?} instance {instance}"))
            }
            "csv" | "parquet" => {
                for (field, given) in [("topic", section.topic.is_some()), ("instance", section.instance.is_some())] {
                    if given {
                        return Err(v.err(
                            format!("log.{field}"),
                            "only for ULog files (.ulg); a table names its columns in [log.signals]",
                        ));
                    }
                }
                let time_column = section.time_column.clone().ok_or_else(|| {
                    v.err("log.time_column", "a table log needs its time column (and time_unit_s, seconds per unit)")
                })?;
                let seconds_per_time_unit = v.positive("log.time_unit_s", section.time_unit_s.unwrap_or(1.0))?;
                let columns = needs
                    .signals
                    .iter()
                    .map(|s| {
                        mapped(s).ok_or_else(|| {
                            v.err(format!("log.signals.{}", s.name), "a table log maps every signal to a column")
                        })
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                let request = TableRequest { time_column, seconds_per_time_unit, columns, max_gap_s };
                (read_table(&file, &request).map_err(log_error)?, "table".to_string())
            }
            _ => {
                return Err(v.err(
                    "log.file",
                    format!("{}: allowed a PX4 ULog file (.ulg) or a table (.csv, .parquet)", file.display()),
                ));
            }
        };
        if let Some((&t0, &t_last)) = series.t_s.first().zip(series.t_s.last()) {
            let samples = (t_last - t0) / dt_s;
            if !(samples < MAX_LOG_SAMPLES) {
                return Err(v.err(
                    "study.dt_s",
                    format!(
                        "{dt_s} s over the log's {:.3} s makes {samples:.3e} samples; allowed at most {MAX_LOG_SAMPLES:e}",
                        t_last - t0
                    ),
                ));
            }
        }
        let mut signals = resample(&series, dt_s);
        let samples = signals.first().map_or(0, Vec::len);
        let span_s = samples as f64 * dt_s;
        let part = |field: &str, range: Option<[f64; 2]>| -> Result<Part, DeckError> {
            let [lo, hi] = range.unwrap_or([0.0, span_s]);
            if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi && hi <= span_s + 1e-9) {
                return Err(v.err(
                    field,
                    format!("[{lo}, {hi}]: allowed [from, to] with 0 <= from < to <= {span_s:.3} s, the log's length at dt {dt_s} s"),
                ));
            }
            let p = Part {
                first: (lo / dt_s - 1e-9).ceil() as usize,
                end: ((hi / dt_s + 1e-9).floor() as usize).min(samples),
            };
            if p.end <= p.first || p.len() < trial_samples {
                return Err(v.err(
                    field,
                    format!(
                        "[{lo}, {hi}] holds {} samples; a trial needs {trial_samples} (study.duration_s / study.dt_s)",
                        p.end.saturating_sub(p.first)
                    ),
                ));
            }
            Ok(p)
        };
        let evaluate = part("log.evaluate_s", section.evaluate_s)?;
        let train = section.train_s.map(|r| part("log.train_s", Some(r))).transpose()?;
        if let Some(t) = train
            && t.first < evaluate.end
            && evaluate.first < t.end
        {
            return Err(v.err(
                "log.train_s",
                format!(
                    "{:?} overlaps evaluate_s {:?}: what learns from the log may not see the samples it is evaluated on",
                    section.train_s.unwrap_or_default(),
                    section.evaluate_s.unwrap_or([0.0, span_s])
                ),
            ));
        }
        let mut removed_means = Vec::new();
        let mut warnings = Vec::new();
        for (i, name) in section.debias.iter().enumerate() {
            let field = format!("log.debias[{i}]");
            let Some(index) = needs.signals.iter().position(|s| s.name == name) else {
                return Err(v.err(field, format!("{name:?} is not a signal; allowed: {}", needs.names())));
            };
            if removed_means.iter().any(|(n, _)| n == name) {
                return Err(v.err(field, format!("{name:?} appears twice")));
            }
            let Some(t) = train else {
                return Err(v.err(field, "the mean is taken over the training part: give train_s"));
            };
            let signal = &mut signals[index];
            let [from, to] = [t.first as f64 * dt_s, t.end as f64 * dt_s];
            // The log's own samples of the window: grid step k holds those within half a step of k dt.
            let t0 = series.t_s.first().copied().unwrap_or(0.0);
            let within = |t: &f64| (from - 0.5 * dt_s..to - 0.5 * dt_s).contains(&(t - t0));
            let raw: Vec<f64> =
                series.t_s.iter().zip(&series.values[index]).filter(|(t, _)| within(t)).map(|(_, x)| *x).collect();
            if let Some(m) = motion_in_window(&signal[t.first..t.end], dt_s, &raw) {
                warnings.push(format!(
                    "log.debias: {name} is not at rest over train_s [{from:.2}, {to:.2}) s: {}; the {:.4e} removed is then partly motion, not the sensor's bias: choose a train_s where the vehicle stands still, motors off if it can (`fdimc log FILE --plot OUT.svg --signals ... --deck DECK` shows the signals)",
                    m.why, m.mean
                ));
            }
            let mean = signal[t.first..t.end].iter().sum::<f64>() / t.len() as f64;
            signal.iter_mut().for_each(|x| *x -= mean);
            removed_means.push((name.clone(), mean));
        }
        let gaps = series.t_s.windows(2).map(|w| w[1] - w[0]);
        let n = series.t_s.len();
        let sha256 = file_sha256(&file).map_err(|e| v.err("log.file", format!("{}: {e}", file.display())))?;
        Ok(Arc::new(ReplayLog {
            file,
            origin,
            dt_s,
            signals,
            log_samples: n,
            log_rate_hz: if n > 1 { (n - 1) as f64 / (series.t_s[n - 1] - series.t_s[0]) } else { f64::NAN },
            largest_gap_s: gaps.fold(0.0, f64::max),
            ending: series.ending.clone(),
            evaluate,
            train,
            removed_means,
            sha256,
            first_sample_s: series.t_s.first().copied().unwrap_or(0.0),
            warnings,
        }))
    }
}

/// SHA-256 of a file's bytes, hex.
pub fn file_sha256(path: &Path) -> std::io::Result<String> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(path)?;
    Ok(Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect())
}

/// Why a window is not at rest ([`motion_in_window`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Motion {
    /// The resampled signal's mean over the window (what `debias` removes).
    pub mean: f64,
    /// What shows the motion, with its numbers.
    pub why: String,
}

/// Seconds per batch of [`motion_in_window`]'s first test: longer than the correlation of a
/// multirotor's vibration and of PX4's sensor filters (the moving bundled log's r(10) at 250 Hz is
/// still 0.2), short enough for ten batches in a few seconds.
pub const REST_BATCH_S: f64 = 0.25;

/// Halves' means this many standard errors apart mean motion: with [`REST_MIN_BATCHES`] batches or more
/// (6 degrees of freedom or more), the halves of a window at rest are that far apart in under 1 % of
/// windows (Student's t).
pub const REST_Z: f64 = 4.0;

/// Fewer batches tell nothing ([`REST_Z`]): 2 s at [`REST_BATCH_S`].
pub const REST_MIN_BATCHES: usize = 8;

/// The most a signal at rest spreads, in units of its sample-to-sample noise ([`motion_in_window`]'s
/// second test): 1 for white noise, 1.3 for the bench log's filtered gyro (r(1) up to 0.4 gives
/// 1 / sqrt(1 - r(1))); the moving bundled log's gyro is at 2.8.
pub const REST_SPREAD_RATIO: f64 = 2.0;

/// Whether a `debias` window is at rest: `None` when it is, else what shows motion. A sensor at rest
/// reads its bias plus nearly white noise, so two tests, each with its reason:
/// - the level stays put: the means of the window's halves (of the resampled `signal`, at `dt_s`)
///   agree within [`REST_Z`] standard errors, estimated by batch means ([`REST_BATCH_S`] batches: the
///   noise is not white, so the samples' own spread would understate it); a vehicle that turns, tilts
///   or drifts moves the level, and its mean then mixes motion into the bias (windows of fewer than
///   [`REST_MIN_BATCHES`] batches skip this test);
/// - nothing but noise: on the log's own samples in the window (`raw`), the spread is at most
///   [`REST_SPREAD_RATIO`] times the sample-to-sample noise (the differences' sd over sqrt 2, which
///   equals the spread for white noise); content slower than the sample rate that is not noise is
///   motion or vibration (motors running), whose mean need not be the bias (coning, rectification).
pub fn motion_in_window(signal: &[f64], dt_s: f64, raw: &[f64]) -> Option<Motion> {
    let mean = signal.iter().sum::<f64>() / signal.len().max(1) as f64;
    let per_batch = ((REST_BATCH_S / dt_s).round() as usize).max(1);
    let batches = signal.len() / per_batch / 2 * 2;
    if batches >= REST_MIN_BATCHES {
        let means: Vec<f64> = (0..batches)
            .map(|b| signal[b * per_batch..(b + 1) * per_batch].iter().sum::<f64>() / per_batch as f64)
            .collect();
        let half = batches / 2;
        let avg = |m: &[f64]| m.iter().sum::<f64>() / m.len() as f64;
        let (first, second) = (avg(&means[..half]), avg(&means[half..]));
        // Pooled variance of the batch means within each half (the step between halves is not noise).
        let ss = means[..half].iter().map(|m| (m - first).powi(2)).sum::<f64>()
            + means[half..].iter().map(|m| (m - second).powi(2)).sum::<f64>();
        let se = (ss / (batches - 2) as f64 * 2.0 / half as f64).sqrt();
        let z = (first - second).abs() / se;
        if z > REST_Z {
            let why = format!(
                "its mean moves from {first:.4e} over the first half to {second:.4e} over the second ({z:.1} standard errors; a bias stays put)"
            );
            return Some(Motion { mean, why });
        }
    }
    if raw.len() >= 3 {
        let sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        let spread = sd(raw);
        let differences: Vec<f64> = raw.windows(2).map(|w| w[1] - w[0]).collect();
        let noise = sd(&differences) / std::f64::consts::SQRT_2;
        let ratio = spread / noise;
        if ratio > REST_SPREAD_RATIO {
            let why = format!(
                "its spread ({spread:.2e}) is {ratio:.1} times its sample-to-sample noise ({noise:.2e}; at most {REST_SPREAD_RATIO} for a sensor at rest): the vehicle moves or vibrates"
            );
            return Some(Motion { mean, why });
        }
    }
    None
}

/// `series` on the grid `t_0 + k dt_s` up to its last sample (times increase:
/// [`crate::engine::logs::flight_log`] checked them). Grid sample k is the mean of the log's samples in
/// `[t_k - dt_s / 2, t_k + dt_s / 2)`: what a sensor read at `1 / dt_s` reports (the mean over its
/// interval), which keeps the noise density (interpolating between independent samples would shrink
/// the noise by up to half its variance and fold more of what lies above `1 / (2 dt_s)` in). A bin without
/// a sample (a log slower than the grid, or a gap) takes the linear interpolation at `t_k`.
pub fn resample(series: &TopicSeries, dt_s: f64) -> Vec<Vec<f64>> {
    let t = &series.t_s;
    let n = t.len();
    let Some((&t0, &t_last)) = t.first().zip(t.last()) else { return vec![Vec::new(); series.values.len()] };
    let samples = grid_samples(t0, t_last, dt_s);
    let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(samples); series.values.len()];
    let (mut first, mut bracket) = (0, 0);
    for k in 0..samples {
        let tk = t0 + k as f64 * dt_s;
        let (from, to) = (tk - 0.5 * dt_s, tk + 0.5 * dt_s);
        while first < n && t[first] < from {
            first += 1;
        }
        let end = first + t[first..].iter().take_while(|&&ti| ti < to).count();
        if end > first {
            for (column, values) in out.iter_mut().zip(&series.values) {
                column.push(values[first..end].iter().sum::<f64>() / (end - first) as f64);
            }
            continue;
        }
        while bracket + 2 < n && t[bracket + 1] <= tk {
            bracket += 1;
        }
        let (a, b) = if n > 1 { (bracket, bracket + 1) } else { (0, 0) };
        let w = if b > a { ((tk - t[a]) / (t[b] - t[a])).clamp(0.0, 1.0) } else { 0.0 };
        for (column, values) in out.iter_mut().zip(&series.values) {
            column.push(values[a] + w * (values[b] - values[a]));
        }
    }
    out
}

/// Grid samples from `t0` to `t_last` every `dt_s`, both ends included.
fn grid_samples(t0: f64, t_last: f64, dt_s: f64) -> usize {
    ((t_last - t0) / dt_s + 1e-9).floor() as usize + 1
}

/// The most grid samples a replayed log may have (as a trial's steps): 1e8, some 5 GB for six signals.
pub const MAX_LOG_SAMPLES: f64 = 1e8;

#[cfg(test)]
mod tests {
    use super::*;

    /// A log faster than the grid: each grid sample is the mean of the log's samples within half a step
    /// of it, so a straight line stays on itself and alternating noise of +-1 averages to +-1/5 over five
    /// samples; a bin the log skips (a gap) takes the line through the samples either side; the grid
    /// ends at the last sample.
    #[test]
    fn resampling_averages_each_step_and_interpolates_across_gaps() {
        // 1 ms samples from 10 s, with the ones from 10.0105 to 10.0195 s missing.
        let t_s: Vec<f64> =
            (0..=30).map(|i| 10.0 + i as f64 * 1e-3).filter(|t| !(10.0105..10.0195).contains(t)).collect();
        let line: Vec<f64> = t_s.iter().map(|t| 1000.0 * (t - 10.0)).collect();
        let alternating: Vec<f64> = (0..t_s.len()).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
        let series = TopicSeries { t_s, values: vec![line, alternating], ending: None };
        let out = resample(&series, 0.005);
        assert_eq!(out[0].len(), 7, "10.000 .. 10.030 every 5 ms");
        // Bin 0 holds 10.000-10.002 (its first half precedes the log): mean 1.
        assert!((out[0][0] - 1.0).abs() < 1e-9, "{}", out[0][0]);
        for k in [1, 5, 6] {
            let expected = if k == 6 { 29.0 } else { 5.0 * k as f64 };
            assert!((out[0][k] - expected).abs() < 1e-9, "bin {k}: {} vs {expected}", out[0][k]);
        }
        assert!((out[1][1].abs() - 0.2).abs() < 1e-12, "five alternating samples: {}", out[1][1]);
        // Bins 2 (10.0075-10.0125) holds 10.008-10.010 only; 3 (10.0125-10.0175) none: the line at 10.015.
        assert!((out[0][2] - 9.0).abs() < 1e-9 && (out[0][3] - 15.0).abs() < 1e-9, "{:?}", out[0]);
    }

    /// A part's segment starts cover every start that keeps the segment inside, and only those.
    #[test]
    fn segment_starts_stay_inside_their_part() {
        let p = Part { first: 100, end: 110 };
        let starts: Vec<usize> = (0..1000).map(|i| p.segment_start(4, i as f64 / 1000.0)).collect();
        assert_eq!(starts.iter().min(), Some(&100));
        assert_eq!(starts.iter().max(), Some(&106), "a 4-sample segment from 106 ends at 110");
        assert_eq!(p.segment_start(10, 0.999), 100, "a segment as long as the part has one start");
    }

    /// The deck's column map: the bench log's IMU written as a CSV table (time in microseconds, columns
    /// renamed) and replayed through `[log]` gives the same resampled signals as the ULog file itself;
    /// a table without its time column or a signal's column is refused by field.
    #[test]
    fn a_table_log_with_a_column_map_replays_as_its_ulog() {
        use std::io::Write;
        const NEEDS: Needs = Needs {
            topic: "sensor_combined",
            signals: &[
                Signal { name: "gyro_x_rad_s", ulog_field: "gyro_rad[0]" },
                Signal { name: "accel_z_mps2", ulog_field: "accelerometer_m_s2[2]" },
            ],
        };
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
        let ulog = root.join("logs/sample_appended_multiple.ulg");
        let request = TopicRequest {
            topic: "sensor_combined".into(),
            instance: 0,
            fields: vec!["gyro_rad[0]".into(), "accelerometer_m_s2[2]".into()],
            max_gap_s: 0.02,
        };
        let series = read_ulog(&ulog, &request).unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let mut csv = std::fs::File::create(tmp.path().join("imu.csv")).unwrap();
        writeln!(csv, "t_us,wx,az").unwrap();
        for k in 0..series.t_s.len() {
            // Times as the log's integer microseconds; values in full precision.
            let t_us = (series.t_s[k] * 1e6).round();
            writeln!(csv, "{t_us},{:?},{:?}", series.values[0][k], series.values[1][k]).unwrap();
        }
        drop(csv);
        let deck = tmp.path().join("deck.toml");
        let v = Validator { file: &deck };
        let section = |text: &str| -> LogSection { toml::from_str(text).unwrap() };
        let from_table = ReplayLog::load(
            &v,
            &section("file = \"imu.csv\"\ntime_column = \"t_us\"\ntime_unit_s = 1e-6\nmax_gap_s = 0.02\nsignals = { gyro_x_rad_s = \"wx\", accel_z_mps2 = \"az\" }"),
            &NEEDS,
            0.01,
            400,
        )
        .unwrap();
        let path = ulog.display().to_string();
        let from_ulog =
            ReplayLog::load(&v, &section(&format!("file = {path:?}\nmax_gap_s = 0.02")), &NEEDS, 0.01, 400).unwrap();
        assert_eq!(from_table.samples(), 962, "9.62 s at 100 Hz");
        assert_eq!(from_ulog.samples(), from_table.samples());
        for (a, b) in from_table.signals.iter().zip(&from_ulog.signals) {
            assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9), "the same signals");
        }
        assert_eq!((from_table.log_samples, from_table.origin.as_str()), (2373, "table"));
        assert!((from_table.log_rate_hz - 246.63).abs() < 0.01);
        // `debias`: the gyro less its mean over the training part only; the other signal untouched.
        let text = format!(
            "file = {path:?}\nmax_gap_s = 0.02\nevaluate_s = [4.8, 9.6]\ntrain_s = [0.0, 4.8]\ndebias = [\"gyro_x_rad_s\"]"
        );
        let debiased = ReplayLog::load(&v, &section(&text), &NEEDS, 0.01, 400).unwrap();
        let t = debiased.train.unwrap();
        assert_eq!((t.first, t.end), (0, 480));
        let mean = from_ulog.signals[0][..480].iter().sum::<f64>() / 480.0;
        // The mean of the steps' means is the mean of the log's own samples there, to their weighting.
        let t0 = series.t_s[0];
        let raw: Vec<f64> =
            (0..series.t_s.len()).filter(|&k| series.t_s[k] - t0 < 4.795).map(|k| series.values[0][k]).collect();
        let raw_mean = raw.iter().sum::<f64>() / raw.len() as f64;
        assert!((mean - raw_mean).abs() < 1e-4, "{mean} vs {raw_mean} (the gyro sd is 5.7e-2)");
        assert_eq!(debiased.removed_means, vec![("gyro_x_rad_s".to_string(), mean)]);
        assert!(debiased.signals[0].iter().zip(&from_ulog.signals[0]).all(|(d, x)| (d - (x - mean)).abs() < 1e-15));
        assert_eq!(debiased.signals[1], from_ulog.signals[1]);
        let err = |text: &str| ReplayLog::load(&v, &section(text), &NEEDS, 0.01, 400).unwrap_err().to_string();
        let e = err("file = \"imu.csv\"\nsignals = { gyro_x_rad_s = \"wx\", accel_z_mps2 = \"az\" }");
        assert!(e.contains("log.time_column: a table log needs its time column"), "{e}");
        let e = err("file = \"imu.csv\"\ntime_column = \"t_us\"\nsignals = { gyro_x_rad_s = \"wx\" }");
        assert!(e.contains("log.signals.accel_z_mps2: a table log maps every signal to a column"), "{e}");
        let e = err(
            "file = \"imu.csv\"\ntime_column = \"t_us\"\ntime_unit_s = 1e-6\nsignals = { gyro_x_rad_s = \"wx\", accel_z_mps2 = \"a_z\" }",
        );
        assert!(e.contains("table has no column \"a_z\" (its columns: t_us, wx, az)"), "{e}");
        assert!(e.contains("deck.toml: log.signals.accel_z_mps2: "), "the mapping to mend: {e}");
        // What the log lacks is refused against the field that mends it (issue 51, item 11).
        let e = err(&format!("file = {path:?}\ntopic = \"nosuch\""));
        assert!(
            e.contains("deck.toml: log.topic: ") && e.contains("no topic \"nosuch\" instance 0 (the log has: "),
            "{e}"
        );
        let e = err(&format!("file = {path:?}\nmax_gap_s = 0.01"));
        assert!(
            e.contains("deck.toml: log.max_gap_s: ")
                && e.contains("The log's largest gap is 0.016 s: max_gap_s = 0.017 bridges every gap"),
            "{e}"
        );
    }

    /// `debias` over a window that is not at rest is warned of (issue 51, item 9). The bundled moving
    /// log (PX4FMU v4 Pro, vibrating and turning) over the replay decks' train_s [0, 4.8] s: every gyro
    /// axis's halves differ by many standard errors, and the warning names the signal, both halves'
    /// means and the way out. A synthetic still log (250 Hz, a constant bias under white noise, through
    /// the table path) is not warned of, and its bias is removed to within the noise; the same log with a
    /// slow turn of 0.02 rad/s per s added is.
    #[test]
    fn a_debias_window_that_is_not_at_rest_is_warned_of() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        use std::io::Write;
        const GYRO: Needs = Needs {
            topic: "sensor_combined",
            signals: &[
                Signal { name: "gyro_x_rad_s", ulog_field: "gyro_rad[0]" },
                Signal { name: "gyro_y_rad_s", ulog_field: "gyro_rad[1]" },
                Signal { name: "gyro_z_rad_s", ulog_field: "gyro_rad[2]" },
            ],
        };
        let tmp = tempfile::tempdir().unwrap();
        let deck = tmp.path().join("deck.toml");
        let v = Validator { file: &deck };
        let section = |text: &str| -> LogSection { toml::from_str(text).unwrap() };
        let ulog = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/logs/sample_appended_multiple.ulg");
        let moving = format!(
            "file = {:?}\nevaluate_s = [4.8, 9.6]\ntrain_s = [0.0, 4.8]\ndebias = [\"gyro_x_rad_s\", \"gyro_y_rad_s\", \"gyro_z_rad_s\"]",
            ulog.display().to_string()
        );
        let log = ReplayLog::load(&v, &section(&moving), &GYRO, 0.01, 200).unwrap();
        assert_eq!(log.warnings.len(), 3, "{:#?}", log.warnings);
        for (w, name) in log.warnings.iter().zip(["gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s"]) {
            assert!(
                w.starts_with(&format!("log.debias: {name} is not at rest over train_s [0.00, 4.80) s: its spread ("))
            );
            assert!(
                w.contains("times its sample-to-sample noise") && w.contains("the vehicle moves or vibrates"),
                "{w}"
            );
            assert!(w.contains("choose a train_s where the vehicle stands still"), "{w}");
        }

        let (bias, sd) = (0.004, 0.003);
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(51);
        let write = |name: &str, turn_per_s: f64, rng: &mut rand::rngs::ChaCha8Rng| {
            let path = tmp.path().join(name);
            let mut csv = std::fs::File::create(&path).unwrap();
            writeln!(csv, "t_s,gx,gy,gz").unwrap();
            for k in 0..1500 {
                let t = k as f64 / 250.0;
                let mut noise = || sd * <StandardNormal as Distribution<f64>>::sample(&StandardNormal, rng);
                writeln!(csv, "{t},{},{},{}", bias + turn_per_s * t + noise(), bias + noise(), bias + noise()).unwrap();
            }
            path
        };
        let still = write("still.csv", 0.0, &mut rng);
        let turning = write("turning.csv", 0.02, &mut rng);
        let table = |path: &Path| {
            format!(
                "file = {:?}\ntime_column = \"t_s\"\nevaluate_s = [3.0, 5.99]\ntrain_s = [0.0, 3.0]\ndebias = [\"gyro_x_rad_s\"]\nsignals = {{ gyro_x_rad_s = \"gx\", gyro_y_rad_s = \"gy\", gyro_z_rad_s = \"gz\" }}",
                path.display().to_string()
            )
        };
        let log = ReplayLog::load(&v, &section(&table(&still)), &GYRO, 0.01, 200).unwrap();
        assert_eq!(log.warnings, Vec::<String>::new());
        // 300 steps of means of 2.5 samples: the mean's sd is 0.003 / sqrt(750) = 1.1e-4.
        assert!((log.removed_means[0].1 - bias).abs() < 4.0 * sd / 750f64.sqrt(), "{:?}", log.removed_means);
        let log = ReplayLog::load(&v, &section(&table(&turning)), &GYRO, 0.01, 200).unwrap();
        assert_eq!(log.warnings.len(), 1, "{:?}", log.warnings);
        assert!(log.warnings[0].starts_with("log.debias: gyro_x_rad_s is not at rest over train_s [0.00, 3.00) s"));
        // The level test alone (no raw samples): a window too short to tell is passed; a step of 1e-3
        // between the halves over noise of 1e-4 is caught.
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(7);
        let step: Vec<f64> = (0..400)
            .map(|k| {
                let noise: f64 = StandardNormal.sample(&mut rng);
                (if k < 200 { 0.0 } else { 1e-3 }) + 1e-4 * noise
            })
            .collect();
        assert_eq!(motion_in_window(&step[200..], 0.01, &[]), None, "2 s, all after the step");
        assert_eq!(motion_in_window(&step[..150], 0.01, &[]), None, "1.5 s: 6 batches, too few");
        let m = motion_in_window(&step, 0.01, &[]).unwrap();
        assert!(m.why.starts_with("its mean moves from ") && m.why.contains("standard errors"), "{m:?}");
    }
}
