//! A recorded flight as a scenario source any method can replay (issue 22). A method names the signals
//! it needs ([`Needs`]: a deck name with its unit, and the ULog field it is read from by default); the
//! deck's `[log]` section names the file and may map each signal to another field or, for a table, a
//! column. The log is read once per study ([`crate::engine::logs::flight_log`]: checked, streamed), resampled
//! onto the study's step by linear interpolation (the documented repair for a log's own jittery rate and
//! for gaps up to `max_gap_s`), and split into parts: trials are drawn from the evaluation part, and
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

use crate::engine::logs::flight_log::{TableRequest, TopicRequest, TopicSeries, read_table, read_ulog};
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
        let log_error = |e: crate::engine::logs::flight_log::LogError| v.err("log.file", e.to_string());
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
            let mean = signal[t.first..t.end].iter().sum::<f64>() / t.len() as f64;
            signal.iter_mut().for_each(|x| *x -= mean);
            removed_means.push((name.clone(), mean));
        }
        let gaps = series.t_s.windows(2).map(|w| w[1] - w[0]);
        let n = series.t_s.len();
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
        }))
    }
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
    }
}
