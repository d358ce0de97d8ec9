//! Recorded flights as a source of sensor signals (issue 22): the topics and fields a method needs, read
//! from a PX4 ULog file with `px4-ulog` (the one reader that read both bundled logs, appended sections
//! included, value for value as pyulog does; README "Dependencies").
//!
//! The file is streamed: only the requested topic's fields are kept, as `f64` per sample, so memory
//! follows the signals used, not the log's other topics. What a replay needs of a log is checked here
//! and refused with the file, topic and field named: a missing topic or field, timestamps that do not
//! increase, a value that is not finite, a gap longer than the deck allows. A log that ends mid-record
//! (a cut-off recording) keeps its valid prefix, and [`TopicSeries::ending`] says so for the run to
//! report. Logs of other autopilots, converted to CSV or Parquet by their own tools, are read with a
//! column map ([`TableRequest`], [`read_table`]) and checked the same way.

use std::collections::hash_map::Entry;
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use px4_ulog::stream_parser::model::{Completeness, FlattenedFieldType};
use px4_ulog::stream_parser::{FieldParser, Message, SimpleCallbackResult, read_file_with_simple_callback};

/// PX4's fused IMU topic (gyro and accelerometer in body FRD axes): what `fdimc log --plot` draws
/// without `--topic` or a deck, and what the accelerometer kind replays.
pub const PX4_IMU_TOPIC: &str = "sensor_combined";

/// Which topic instance and fields to read.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicRequest {
    pub topic: String,
    /// The topic's `multi_id` (0 for the first or only instance).
    pub instance: u8,
    /// Flattened field names as the log writes them: `gyro_rad[0]`, `accelerometer_m_s2[2]`, `x`, ..
    pub fields: Vec<String>,
    /// The longest gap between consecutive samples the caller accepts (s).
    pub max_gap_s: f64,
}

/// One topic instance's samples: times and the requested fields, in request order.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicSeries {
    /// Sample times (s) on the log's boot clock (`timestamp` / 1e6).
    pub t_s: Vec<f64>,
    /// `values[field][sample]`.
    pub values: Vec<Vec<f64>>,
    /// How the file ended: `None` when cleanly; otherwise what was lost (the valid prefix is kept).
    pub ending: Option<String>,
}

/// Why a log cannot be replayed; every message names the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LogError {
    #[error("{file}: {message}")]
    Unreadable { file: PathBuf, message: String },
    #[error("{file}: no topic {topic:?} instance {instance} (the log has: {available})")]
    MissingTopic { file: PathBuf, topic: String, instance: u8, available: String },
    #[error("{file}: topic {topic:?} has no number field {field:?} (its number fields: {available})")]
    MissingField { file: PathBuf, topic: String, field: String, available: String },
    #[error("{file}: table has no column {column:?} (its columns: {available})")]
    MissingColumn { file: PathBuf, column: String, available: String },
    /// Times here and below are seconds from the series' first sample, the time base decks use.
    #[error(
        "{file}: {origin}: time {t_s} s (sample {index}) does not follow {previous_s} s (s from its first sample); times must increase"
    )]
    NotIncreasing { file: PathBuf, origin: String, index: usize, t_s: f64, previous_s: f64 },
    #[error(
        "{file}: {origin}: field {field:?} is {value} at {t_s} s from its first sample (sample {index}); allowed: finite values"
    )]
    NotFinite { file: PathBuf, origin: String, field: String, index: usize, t_s: f64, value: f64 },
    #[error(
        "{file}: {origin}: a gap of {gap_s:.3} s after {t_s:.3} s from its first sample; the deck allows {max_gap_s} s \
         (max_gap_s). The log's largest gap is {largest_gap_s:.3} s: max_gap_s = {suggested_s} bridges every gap \
         (by interpolation across it), if a sensor silent that long is acceptable for the study"
    )]
    Gap { file: PathBuf, origin: String, t_s: f64, gap_s: f64, max_gap_s: f64, largest_gap_s: f64, suggested_s: f64 },
}

/// The first bytes of every ULog file: "ULog", then 0x01 0x12 0x35 (the format's magic number).
const ULOG_MAGIC: [u8; 7] = *b"ULog\x01\x12\x35";

/// A field's decoder: the number types PX4 writes sensor values in.
enum NumberField {
    F32(FieldParser<f32>),
    F64(FieldParser<f64>),
}

impl NumberField {
    fn parse(&self, data: &[u8]) -> f64 {
        match self {
            NumberField::F32(p) => f64::from(p.parse(data)),
            NumberField::F64(p) => p.parse(data),
        }
    }
}

/// Reads `request`'s topic instance from the ULog file at `path` and checks it (module docs).
pub fn read_ulog(path: &Path, request: &TopicRequest) -> Result<TopicSeries, LogError> {
    let file = path.to_path_buf();
    let mut topics: BTreeSet<String> = BTreeSet::new();
    let mut parsers: Option<Result<(FieldParser<u64>, Vec<NumberField>), LogError>> = None;
    let mut times_us: Vec<u64> = Vec::new();
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); request.fields.len()];
    let ending = stream(path, |data| {
        let format = data.flattened_format;
        let name = format.message_name();
        if name != request.topic || data.multi_id.value() != request.instance {
            if !topics.contains(name) {
                topics.insert(name.to_string());
            }
            return SimpleCallbackResult::KeepReading;
        }
        let built = parsers.get_or_insert_with(|| field_parsers(&file, request, format));
        let Ok((timestamp, fields)) = built else { return SimpleCallbackResult::Stop };
        times_us.push(timestamp.parse(data.data));
        for (column, field) in values.iter_mut().zip(fields.iter()) {
            column.push(field.parse(data.data));
        }
        SimpleCallbackResult::KeepReading
    })?;
    match parsers {
        None => return Err(missing_topic(path, &request.topic, request.instance, topics)),
        Some(Err(e)) => return Err(e),
        Some(Ok(_)) => {}
    }
    let series = TopicSeries { t_s: times_us.iter().map(|&t| t as f64 * 1e-6).collect(), values, ending };
    check(&file, &format!("topic {:?}", request.topic), &request.fields, request.max_gap_s, &series)?;
    Ok(series)
}

/// The timestamp's and the requested fields' decoders for `format`, or the missing field named.
fn field_parsers(
    file: &Path,
    request: &TopicRequest,
    format: &px4_ulog::stream_parser::model::FlattenedFormat,
) -> Result<(FieldParser<u64>, Vec<NumberField>), LogError> {
    let missing = |field: &str| {
        let numbers: Vec<&str> = (format.field_iter())
            .filter(|f| matches!(f.field_type, FlattenedFieldType::Float | FlattenedFieldType::Double))
            .map(|f| f.flattened_field_name.as_str())
            .collect();
        LogError::MissingField {
            file: file.to_path_buf(),
            topic: request.topic.clone(),
            field: field.to_string(),
            available: numbers.join(", "),
        }
    };
    let timestamp = format.get_field_parser::<u64>("timestamp").map_err(|_| missing("timestamp"))?;
    let fields = (request.fields.iter())
        .map(|name| {
            (format.get_field_parser::<f32>(name).map(NumberField::F32))
                .or_else(|_| format.get_field_parser::<f64>(name).map(NumberField::F64))
                .map_err(|_| missing(name))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((timestamp, fields))
}

/// Increasing times, finite values, no gap above `max_gap_s`; `origin` names where the series came from
/// in messages (`topic "sensor_combined"`, `table`).
fn check(file: &Path, origin: &str, fields: &[String], max_gap_s: f64, series: &TopicSeries) -> Result<(), LogError> {
    let (file, origin) = (file.to_path_buf(), origin.to_string());
    // Messages give times from the first sample, as decks do (`evaluate_s`, `train_s`).
    let t0 = series.t_s.first().copied().unwrap_or(0.0);
    let mut first_gap: Option<(f64, f64)> = None;
    let mut largest_gap_s: f64 = 0.0;
    for (index, pair) in series.t_s.windows(2).enumerate() {
        if !(pair[1] > pair[0]) {
            let (t_s, previous_s) = (pair[1] - t0, pair[0] - t0);
            return Err(LogError::NotIncreasing { file, origin, index: index + 1, t_s, previous_s });
        }
        let gap_s = pair[1] - pair[0];
        largest_gap_s = largest_gap_s.max(gap_s);
        if gap_s > max_gap_s && first_gap.is_none() {
            first_gap = Some((pair[0] - t0, gap_s));
        }
    }
    if let Some((t_s, gap_s)) = first_gap {
        // The next millisecond up: a limit that the largest gap itself passes.
        let suggested_s = (largest_gap_s * 1e3).floor() / 1e3 + 1e-3;
        return Err(LogError::Gap { file, origin, t_s, gap_s, max_gap_s, largest_gap_s, suggested_s });
    }
    for (field, column) in fields.iter().zip(&series.values) {
        if let Some(index) = column.iter().position(|v| !v.is_finite()) {
            let (field, t_s, value) = (field.clone(), series.t_s[index] - t0, column[index]);
            return Err(LogError::NotFinite { file, origin, field, index, t_s, value });
        }
    }
    Ok(())
}

/// A log another autopilot's tools converted to a table (CSV, or Parquet by the `.parquet` extension):
/// the column holding time, its unit, and the signal columns.
#[derive(Debug, Clone, PartialEq)]
pub struct TableRequest {
    pub time_column: String,
    /// Seconds per unit of the time column: 1 for seconds, 1e-6 for microseconds.
    pub seconds_per_time_unit: f64,
    pub columns: Vec<String>,
    pub max_gap_s: f64,
}

/// Reads `request`'s columns of the table at `path` and checks them as a ULog topic is checked (a
/// null reads as a non-finite value). The table is read whole, once per study.
pub fn read_table(path: &Path, request: &TableRequest) -> Result<TopicSeries, LogError> {
    use polars::prelude::DataType;
    let unreadable = |message: String| LogError::Unreadable { file: path.to_path_buf(), message };
    if !path.is_file() {
        return Err(unreadable("no such file".into()));
    }
    let frame = crate::engine::results::tables::read_summary(path).map_err(|e| unreadable(e.to_string()))?;
    let names: Vec<String> = frame.get_column_names().iter().map(|n| n.to_string()).collect();
    let column = |name: &str| -> Result<Vec<f64>, LogError> {
        let missing = || LogError::MissingColumn {
            file: path.to_path_buf(),
            column: name.to_string(),
            available: names.join(", "),
        };
        let c = frame.column(name).map_err(|_| missing())?;
        let c = c.cast(&DataType::Float64).map_err(|_| missing())?;
        let values = c.f64().map_err(|_| missing())?;
        Ok((0..values.len()).map(|i| values.get(i).unwrap_or(f64::NAN)).collect())
    };
    let time = column(&request.time_column)?;
    let series = TopicSeries {
        t_s: time.iter().map(|t| t * request.seconds_per_time_unit).collect(),
        values: request.columns.iter().map(|c| column(c)).collect::<Result<_, _>>()?,
        ending: None,
    };
    if let Some(index) = series.t_s.iter().position(|t| !t.is_finite()) {
        let (file, origin, field) = (path.to_path_buf(), "table".to_string(), request.time_column.clone());
        return Err(LogError::NotFinite { file, origin, field, index, t_s: f64::NAN, value: time[index] });
    }
    check(path, "table", &request.columns, request.max_gap_s, &series)?;
    Ok(series)
}

/// One topic instance of a log at a glance (`fdimc log`).
#[derive(Debug, Clone, PartialEq)]
pub struct TopicSurvey {
    pub topic: String,
    pub instance: u8,
    pub samples: u64,
    pub first_s: f64,
    pub last_s: f64,
    /// The longest interval between consecutive samples (s); 0 with fewer than two.
    pub largest_gap_s: f64,
    /// Intervals that do not move forward (repeated or decreasing timestamps).
    pub not_increasing: u64,
}

impl TopicSurvey {
    /// Mean sample rate (Hz) over the topic's span; 0 with fewer than two samples.
    pub fn mean_rate_hz(&self) -> f64 {
        if self.samples < 2 || self.last_s <= self.first_s {
            0.0
        } else {
            (self.samples - 1) as f64 / (self.last_s - self.first_s)
        }
    }
}

/// A number field's spread over a topic instance: mean, standard deviation, and the standard deviation
/// of its sample-to-sample differences over the square root of 2, which is the white-noise standard
/// deviation when the signal moves slowly against the sample rate (motion inflates the first two).
#[derive(Debug, Clone, PartialEq)]
pub struct FieldSpread {
    pub field: String,
    pub mean: f64,
    pub sd: f64,
    pub difference_sd: f64,
    /// The white noise's excess kurtosis, read off the sample-to-sample differences (twice theirs: a
    /// difference of two independent draws halves it); 0 for Gaussian noise.
    pub excess_kurtosis: f64,
    /// The values' autocorrelation at [`AUTOCORRELATION_LAGS`] samples (0 at every lag for white noise
    /// about a constant, such as the simulator's sensors at rest; near 1 for motion or filtered noise).
    pub autocorrelation: [f64; AUTOCORRELATION_LAGS.len()],
}

/// The lags (samples) of [`FieldSpread::autocorrelation`], ascending.
pub const AUTOCORRELATION_LAGS: [usize; 4] = [1, 2, 5, 10];
const MAX_LAG: usize = AUTOCORRELATION_LAGS[AUTOCORRELATION_LAGS.len() - 1];

impl FieldSpread {
    /// The noise law a deck's `noise.sensor_law` can take from this field: a Student-t of the same
    /// excess kurtosis (`6 / (dof - 4)`, by moments), or Gaussian where the kurtosis is within three
    /// standard errors (`sqrt(24 / n)`, doubled with the differences) of 0 or below it.
    pub fn fitted_law(&self, samples: usize) -> crate::engine::scenario::noise::SensorLaw {
        use crate::engine::scenario::noise::SensorLaw;
        let noise = 3.0 * 2.0 * (24.0 / samples.max(1) as f64).sqrt();
        if !(self.excess_kurtosis > noise) {
            return SensorLaw::Gaussian;
        }
        // To a tenth (dof > 4 here): the moment estimate is not finer; a division keeps 5.6 as written.
        let dof = 4.0 + 6.0 / self.excess_kurtosis;
        SensorLaw::StudentT { dof: (dof * 10.0).round() / 10.0 }
    }
}

/// Running central moments to the fourth (Terriberry's update of Welford's): the spread and the excess
/// kurtosis of a stream.
#[derive(Default, Clone, Copy)]
struct Moments {
    n: f64,
    mean: f64,
    m2: f64,
    m3: f64,
    m4: f64,
}

impl Moments {
    fn add(&mut self, x: f64) {
        let n1 = self.n;
        self.n += 1.0;
        let n = self.n;
        let delta = x - self.mean;
        let delta_n = delta / n;
        let delta_n2 = delta_n * delta_n;
        let term1 = delta * delta_n * n1;
        self.mean += delta_n;
        self.m4 += term1 * delta_n2 * (n * n - 3.0 * n + 3.0) + 6.0 * delta_n2 * self.m2 - 4.0 * delta_n * self.m3;
        self.m3 += term1 * delta_n * (n - 2.0) - 3.0 * delta_n * self.m2;
        self.m2 += term1;
    }

    fn sd(&self) -> f64 {
        if self.n > 1.0 { (self.m2 / (self.n - 1.0)).sqrt() } else { f64::NAN }
    }

    fn excess_kurtosis(&self) -> f64 {
        if self.n > 3.0 && self.m2 > 0.0 { self.n * self.m4 / (self.m2 * self.m2) - 3.0 } else { f64::NAN }
    }
}

/// Welford's running mean and variance.
#[derive(Default, Clone, Copy)]
struct Running {
    n: f64,
    mean: f64,
    m2: f64,
}

impl Running {
    fn add(&mut self, x: f64) {
        self.n += 1.0;
        let d = x - self.mean;
        self.mean += d / self.n;
        self.m2 += d * (x - self.mean);
    }

    fn sd(&self) -> f64 {
        if self.n > 1.0 { (self.m2 / (self.n - 1.0)).sqrt() } else { f64::NAN }
    }
}

/// A field's mean and spread, and the sums for its autocorrelation at fixed lags, one sample at a time: the values are shifted by the first
/// (so an offset such as gravity does not cancel digits), the last lags kept in a ring.
#[derive(Clone)]
struct FieldStats {
    shift: Option<f64>,
    ring: [f64; MAX_LAG],
    /// The first values (as many as the longest lag).
    first: [f64; MAX_LAG],
    n: usize,
    /// Mean and spread of the shifted values.
    values: Running,
    /// Per lag: the sum of products `x_t x_(t-l)`, and the sums of the first and the last `n - l` values.
    products: [f64; AUTOCORRELATION_LAGS.len()],
    heads: [f64; AUTOCORRELATION_LAGS.len()],
}

impl FieldStats {
    fn new() -> Self {
        let z = [0.0; AUTOCORRELATION_LAGS.len()];
        FieldStats {
            shift: None,
            ring: [0.0; MAX_LAG],
            first: [0.0; MAX_LAG],
            n: 0,
            values: Running::default(),
            products: z,
            heads: z,
        }
    }

    fn add(&mut self, x: f64) {
        let x = x - *self.shift.get_or_insert(x);
        for (i, &lag) in AUTOCORRELATION_LAGS.iter().enumerate() {
            if self.n >= lag {
                let earlier = self.ring[(self.n - lag) % self.ring.len()];
                self.products[i] += x * earlier;
                self.heads[i] += earlier;
            }
        }
        self.ring[self.n % self.ring.len()] = x;
        if self.n < self.first.len() {
            self.first[self.n] = x;
        }
        self.n += 1;
        self.values.add(x);
    }

    fn mean(&self) -> f64 {
        self.shift.unwrap_or(f64::NAN) + self.values.mean
    }

    /// `sum_t (x_t - m)(x_(t-l) - m) / sum_t (x_t - m)^2`, `m` the mean of all values.
    fn autocorrelation(&self) -> [f64; AUTOCORRELATION_LAGS.len()] {
        let (m, variance_sum) = (self.values.mean, self.values.m2);
        let sum = m * self.n as f64;
        std::array::from_fn(|i| {
            let lag = AUTOCORRELATION_LAGS[i];
            if self.n <= lag {
                return f64::NAN;
            }
            // The later partner of each pair runs over all values but the first l.
            let tails = sum - self.first[..lag].iter().sum::<f64>();
            let pairs = (self.n - lag) as f64;
            (self.products[i] - m * (tails + self.heads[i]) + pairs * m * m) / variance_sum
        })
    }
}

/// The error for a topic instance the log lacks, listing the topics it has (`seen`).
fn missing_topic(path: &Path, topic: &str, instance: u8, seen: BTreeSet<String>) -> LogError {
    let seen: Vec<String> = seen.into_iter().collect();
    LogError::MissingTopic {
        file: path.to_path_buf(),
        topic: topic.to_string(),
        instance,
        available: if seen.is_empty() { "no data".into() } else { seen.join(", ") },
    }
}

/// Streams a ULog file through `on_data` (every data message), with the reader's panics and errors
/// turned into [`LogError::Unreadable`] naming `path`; returns how the file ended.
fn stream(
    path: &Path,
    mut on_data: impl FnMut(&px4_ulog::stream_parser::DataMessage) -> SimpleCallbackResult,
) -> Result<Option<String>, LogError> {
    let unreadable = |message: String| LogError::Unreadable { file: path.to_path_buf(), message };
    let path_text = path.to_str().ok_or_else(|| unreadable("the path is not UTF-8".into()))?;
    if !path.is_file() {
        return Err(unreadable("no such file".into()));
    }
    // The reader's own refusal of a foreign file is an `io::Error` around its parse error, printed as
    // Rust's debug text: the header is checked here first, in words.
    let mut head = Vec::with_capacity(ULOG_MAGIC.len());
    std::io::Read::read_to_end(
        &mut std::io::Read::take(std::fs::File::open(path).map_err(|e| unreadable(e.to_string()))?, 16),
        &mut head,
    )
    .map_err(|e| unreadable(e.to_string()))?;
    if head.len() < 16 || head[..ULOG_MAGIC.len()] != ULOG_MAGIC {
        let why = if head.len() < 16 {
            format!("{} bytes, shorter than a ULog file's 16-byte header", head.len())
        } else {
            "it does not begin with the ULog header (\"ULog\" then bytes 01 12 35); fdimc reads PX4 ULog files (.ulg), \
             or a CSV or Parquet table"
                .to_string()
        };
        return Err(unreadable(format!("not a PX4 ULog: {why}")));
    }
    let mut on_message = |message: &Message| match message {
        Message::Data(data) => on_data(data),
        _ => SimpleCallbackResult::KeepReading,
    };
    // The reader slices a corrupt parameter record without a bounds check (px4-ulog 0.6.1): a panic
    // there is a malformed file, not a bug of ours, and is reported as one, without the panic's own
    // message and backtrace on standard error.
    let read = quietly(|| {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            read_file_with_simple_callback(path_text, &mut on_message)
        }))
    });
    match read {
        Ok(Ok(Completeness::Complete)) => Ok(None),
        Ok(Ok(Completeness::Truncated)) => Ok(Some("the file ends partway through a record (kept up to it)".into())),
        Ok(Ok(Completeness::MalformedRecord(why))) => Ok(Some(format!("a malformed record ({why}); kept up to it"))),
        Ok(Err(e)) => {
            // The parse error's own description, not the `io::Error`'s debug text around it.
            let parse =
                e.get_ref().and_then(|inner| inner.downcast_ref::<px4_ulog::stream_parser::model::UlogParseError>());
            let why = parse.map_or_else(|| e.to_string(), |p| p.description.clone());
            Err(unreadable(format!("not a readable ULog file: {why}")))
        }
        Err(_) => Err(unreadable("not a readable ULog file: a malformed record".into())),
    }
}

thread_local! {
    /// Set while this thread runs the ULog reader, whose panics are caught and reported as input errors.
    static IN_ULOG_READER: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` with the panic hook silent for this thread: the hook installed once here passes every
/// other panic (other threads, or this one outside `f`) to the hook that was there before.
fn quietly<T>(f: impl FnOnce() -> T) -> T {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !IN_ULOG_READER.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    IN_ULOG_READER.with(|q| q.set(true));
    let out = f();
    IN_ULOG_READER.with(|q| q.set(false));
    out
}

/// Every topic instance of the log at `path`, sorted by topic and instance, and how the file ended.
pub fn survey(path: &Path) -> Result<(Vec<TopicSurvey>, Option<String>), LogError> {
    // Per subscription (msg_id): its entry, its timestamp's decoder and its last timestamp, looked up once.
    let mut topics: Vec<TopicSurvey> = Vec::new();
    let mut by_id: HashMap<u16, (usize, FieldParser<u64>, u64)> = HashMap::new();
    let ending = stream(path, |data| {
        let entry = match by_id.entry(data.msg_id) {
            Entry::Occupied(e) => e.into_mut(),
            Entry::Vacant(e) => {
                let format = data.flattened_format;
                let Ok(timestamp) = format.get_field_parser::<u64>("timestamp") else {
                    return SimpleCallbackResult::KeepReading;
                };
                topics.push(TopicSurvey {
                    topic: format.message_name().to_string(),
                    instance: data.multi_id.value(),
                    samples: 0,
                    first_s: f64::INFINITY,
                    last_s: f64::NEG_INFINITY,
                    largest_gap_s: 0.0,
                    not_increasing: 0,
                });
                e.insert((topics.len() - 1, timestamp, u64::MAX))
            }
        };
        let (index, timestamp, last_us) = entry;
        let (s, t_us) = (&mut topics[*index], timestamp.parse(data.data));
        let t_s = t_us as f64 * 1e-6;
        if *last_us != u64::MAX {
            if t_us <= *last_us {
                s.not_increasing += 1;
            } else {
                s.largest_gap_s = s.largest_gap_s.max((t_us - *last_us) as f64 * 1e-6);
            }
        }
        *last_us = t_us;
        s.samples += 1;
        s.first_s = s.first_s.min(t_s);
        s.last_s = s.last_s.max(t_s);
        SimpleCallbackResult::KeepReading
    })?;
    if topics.is_empty() {
        let message = "not a readable ULog file: no data messages (not a log, or cut before its data)".into();
        return Err(LogError::Unreadable { file: path.to_path_buf(), message });
    }
    topics.sort_by(|a, b| (a.topic.as_str(), a.instance).cmp(&(b.topic.as_str(), b.instance)));
    Ok((topics, ending))
}

/// The spread of every `f32`/`f64` field of one topic instance ([`FieldSpread`]), in the log's field
/// order; a topic instance the log lacks is [`LogError::MissingTopic`].
pub fn field_spreads(path: &Path, topic: &str, instance: u8) -> Result<Vec<FieldSpread>, LogError> {
    let mut fields: Option<Vec<(String, NumberField, FieldStats, Moments, f64)>> = None;
    let mut seen: BTreeSet<String> = BTreeSet::new();
    stream(path, |data| {
        let format = data.flattened_format;
        if format.message_name() != topic || data.multi_id.value() != instance {
            if !seen.contains(format.message_name()) {
                seen.insert(format.message_name().to_string());
            }
            return SimpleCallbackResult::KeepReading;
        }
        let fields = fields.get_or_insert_with(|| {
            (format.field_iter())
                .filter_map(|f| {
                    let name = f.flattened_field_name.as_str();
                    let parser = match f.field_type {
                        FlattenedFieldType::Float => NumberField::F32(format.get_field_parser::<f32>(name).ok()?),
                        FlattenedFieldType::Double => NumberField::F64(format.get_field_parser::<f64>(name).ok()?),
                        _ => return None,
                    };
                    Some((name.to_string(), parser, FieldStats::new(), Moments::default(), f64::NAN))
                })
                .collect()
        });
        for (_, parser, values, differences, last) in fields.iter_mut() {
            let x = parser.parse(data.data);
            values.add(x);
            if last.is_finite() {
                differences.add(x - *last);
            }
            *last = x;
        }
        SimpleCallbackResult::KeepReading
    })?;
    let Some(fields) = fields else { return Err(missing_topic(path, topic, instance, seen)) };
    Ok(fields
        .into_iter()
        .map(|(field, _, values, differences, _)| FieldSpread {
            field,
            mean: values.mean(),
            sd: values.values.sd(),
            difference_sd: differences.sd() / std::f64::consts::SQRT_2,
            excess_kurtosis: 2.0 * differences.excess_kurtosis(),
            autocorrelation: values.autocorrelation(),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The streaming fourth moment against the two-pass formula, and the law fitted to Student-t(10)
    /// noise (excess kurtosis 6 / (10 - 4) = 1) drawn as a deck draws it: 10 within the estimate's
    /// spread at 400,000 samples; Gaussian noise fits Gaussian.
    #[test]
    fn the_noise_kurtosis_streams_and_fits_the_student_t_it_came_from() {
        use crate::engine::scenario::noise::SensorLaw;
        use crate::engine::scenario::streams::{Substream, noise_rng};
        use rand::RngExt;
        let x = [1.0, 2.0, 3.5, -4.0, 100.0, 0.25, 7.0];
        let mut m = Moments::default();
        x.iter().for_each(|&v| m.add(v));
        let n = x.len() as f64;
        let mean = x.iter().sum::<f64>() / n;
        let (m2, m4) =
            (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>(), x.iter().map(|v| (v - mean).powi(4)).sum::<f64>());
        assert!((m.excess_kurtosis() - (n * m4 / (m2 * m2) - 3.0)).abs() < 1e-12);

        let spread = |law: SensorLaw| {
            let mut normals = noise_rng(5, 1, Substream::SensorNoise);
            let mut scales = crate::engine::scenario::streams::tail_scales(&[law], 5, 1);
            let mut d = Moments::default();
            let mut last = f64::NAN;
            for _ in 0..400_000 {
                let z: f64 = normals.sample(rand_distr::StandardNormal);
                let v = z * scales.as_mut().map_or(1.0, |s| s.scale(0));
                if last.is_finite() {
                    d.add(v - last);
                }
                last = v;
            }
            FieldSpread {
                field: "x".into(),
                mean: 0.0,
                sd: 1.0,
                difference_sd: d.sd() / std::f64::consts::SQRT_2,
                excess_kurtosis: 2.0 * d.excess_kurtosis(),
                autocorrelation: [0.0; AUTOCORRELATION_LAGS.len()],
            }
        };
        let t10 = spread(SensorLaw::StudentT { dof: 10.0 });
        assert!((t10.excess_kurtosis - 1.0).abs() < 0.3, "{}", t10.excess_kurtosis);
        let SensorLaw::StudentT { dof } = t10.fitted_law(400_000) else { panic!("a heavy tail fits Student-t") };
        assert!((8.0..13.0).contains(&dof), "{dof}");
        assert_eq!(spread(SensorLaw::Gaussian).fitted_law(400_000), SensorLaw::Gaussian);
    }

    fn log(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/logs").join(name)
    }

    fn imu_request(max_gap_s: f64) -> TopicRequest {
        let mut fields: Vec<String> = (0..3).map(|i| format!("gyro_rad[{i}]")).collect();
        fields.extend((0..3).map(|i| format!("accelerometer_m_s2[{i}]")));
        TopicRequest { topic: "sensor_combined".into(), instance: 0, fields, max_gap_s }
    }

    /// Both bundled logs read as pyulog 1.3.0 reads them (its numbers written in): sample count, first
    /// and last timestamps, and the first, second and last values of every IMU field, to f32 precision
    /// (the log stores f32; pyulog prints them widened to f64, as here).
    #[test]
    fn the_bundled_logs_read_as_pyulog_reads_them() {
        type Case = (&'static str, usize, f64, f64, [[f64; 3]; 6]);
        let cases: [Case; 2] = [
            (
                "sample_log_small.ulg",
                1298,
                20.326716,
                26.822868,
                [
                    [0.002968383487313986, 0.0015724377008154988, 0.0038848412223160267],
                    [0.003646239871159196, 0.0012462260201573372, -0.0030337886419147253],
                    [0.0009424961172044277, 0.002898464212194085, 0.0007792016840539873],
                    [0.0012458056444302201, 0.011952392756938934, -0.010053723119199276],
                    [-0.15434497594833374, -0.18632270395755768, -0.1637258678674698],
                    [-9.63424301147461, -9.631083488464355, -9.566828727722168],
                ],
            ),
            (
                "sample_appended_multiple.ulg",
                2373,
                12.262822,
                21.880422,
                [
                    [0.0032860368955880404, 0.004764501471072435, 0.05898718535900116],
                    [0.009327229112386703, 0.010173491202294827, 0.03172055631875992],
                    [0.0039487420581281185, 0.005221804603934288, 0.012260101735591888],
                    [0.5401454567909241, 0.5732278823852539, 0.5413755178451538],
                    [0.32172298431396484, 0.293390691280365, 0.30004557967185974],
                    [-9.93630313873291, -9.894732475280762, -9.923652648925781],
                ],
            ),
        ];
        for (name, count, first_s, last_s, fields) in cases {
            let s = read_ulog(&log(name), &imu_request(0.5)).unwrap();
            assert_eq!((s.t_s.len(), s.ending.clone()), (count, None), "{name}");
            assert!((s.t_s[0] - first_s).abs() < 1e-9 && (s.t_s[count - 1] - last_s).abs() < 1e-9, "{name}");
            for (column, want) in s.values.iter().zip(fields) {
                assert_eq!([column[0], column[1], column[count - 1]], want, "{name}");
            }
        }
    }

    /// The survey and the field spreads equal pyulog 1.3.0 with numpy on the same files: topic instances,
    /// counts, mean rates, largest gaps; means, standard deviations (n - 1) and difference standard
    /// deviations over sqrt 2 of two fields. On the bench log (small) the two deviations agree (white noise
    /// dominates); in the moving log the gyro's standard deviation is 2.8 times its difference one.
    #[test]
    fn the_survey_and_spreads_match_pyulog() {
        let (small, ending) = survey(&log("sample_log_small.ulg")).unwrap();
        assert_eq!((small.len(), ending), (70, None));
        let find = |s: &[TopicSurvey], topic: &str, instance: u8| {
            s.iter().find(|t| t.topic == topic && t.instance == instance).unwrap().clone()
        };
        let combined = find(&small, "sensor_combined", 0);
        assert_eq!((combined.samples, combined.not_increasing), (1298, 0));
        assert!((combined.mean_rate_hz() - 199.6566582801634).abs() < 1e-9);
        assert!((combined.largest_gap_s - 0.161303).abs() < 1e-12);
        assert_eq!(find(&small, "sensor_accel", 2).samples, 6);
        let (appended, _) = survey(&log("sample_appended_multiple.ulg")).unwrap();
        let combined = find(&appended, "sensor_combined", 0);
        assert_eq!((appended.len(), combined.samples), (20, 2373));
        assert!((combined.mean_rate_hz() - 246.63117617700883).abs() < 1e-9);
        assert!((combined.largest_gap_s - 0.016001).abs() < 1e-12);

        let close = |got: f64, want: f64| (got - want).abs() <= 1e-9 * want.abs();
        // (log, field, [mean, sd, difference sd], autocorrelation at 1, 2, 5, 10 samples): numpy on
        // pyulog 1.3.0's arrays.
        type Spread = (&'static str, &'static str, [f64; 3], [f64; 4]);
        let cases: [Spread; 4] = [
            (
                "sample_log_small.ulg",
                "gyro_rad[0]",
                [0.004457859755187899, 0.002907516816116944, 0.002771990926852554],
                [0.091636425578, 0.134122097017, 0.037050748954, -0.037459154906],
            ),
            (
                "sample_log_small.ulg",
                "accelerometer_m_s2[2]",
                [-9.621494837644839, 0.04057122740455669, 0.032006920636332745],
                [0.377367010349, 0.004019435193, 0.096473519054, -0.201629606474],
            ),
            (
                "sample_appended_multiple.ulg",
                "gyro_rad[0]",
                [-0.0038622410727393326, 0.05745443389194065, 0.02026831066852839],
                [0.875348856757, 0.541029541975, -0.754826713695, 0.203774375604],
            ),
            (
                "sample_appended_multiple.ulg",
                "accelerometer_m_s2[2]",
                [-9.921208001871024, 0.1092127010681122, 0.04445650501381795],
                [0.834365025084, 0.535114783792, -0.673618024560, 0.138535886425],
            ),
        ];
        for (name, field, [mean, sd, difference_sd], autocorrelation) in cases {
            let spreads = field_spreads(&log(name), "sensor_combined", 0).unwrap();
            let f = spreads.iter().find(|f| f.field == field).unwrap();
            assert!(close(f.mean, mean) && close(f.sd, sd) && close(f.difference_sd, difference_sd), "{name} {f:?}");
            for (got, want) in f.autocorrelation.iter().zip(autocorrelation) {
                assert!((got - want).abs() < 1e-9, "{name} {field}: {:?} vs {autocorrelation:?}", f.autocorrelation);
            }
        }
        let err = field_spreads(&log("sample_appended_multiple.ulg"), "airspeed", 0).unwrap_err().to_string();
        assert!(err.contains("no topic \"airspeed\" instance 0 (the log has: "), "{err}");
    }

    /// A log converted to a table reads back to the same series: the small log's gyro written as CSV
    /// (time in microseconds) and as Parquet (seconds) gives its times and values exactly; a missing column,
    /// an empty cell and rows out of order are refused naming the file and column.
    #[test]
    fn a_table_log_reads_as_the_ulog_it_came_from() {
        use polars::prelude::*;
        let fields: Vec<String> = (0..3).map(|i| format!("gyro_rad[{i}]")).collect();
        let request = TopicRequest { fields: fields.clone(), ..imu_request(0.5) };
        let ulog = read_ulog(&log("sample_log_small.ulg"), &request).unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let mut csv = String::from("time_us,gx,gy,gz\n");
        for (k, t) in ulog.t_s.iter().enumerate() {
            let t_us = (t * 1e6).round();
            csv += &format!("{t_us},{},{},{}\n", ulog.values[0][k], ulog.values[1][k], ulog.values[2][k]);
        }
        let csv_path = tmp.path().join("imu.csv");
        std::fs::write(&csv_path, &csv).unwrap();
        let columns: Vec<String> = ["gx", "gy", "gz"].map(String::from).to_vec();
        let table =
            TableRequest { time_column: "time_us".into(), seconds_per_time_unit: 1e-6, columns, max_gap_s: 0.5 };
        let from_csv = read_table(&csv_path, &table).unwrap();
        assert_eq!(from_csv.values, ulog.values);
        assert!(from_csv.t_s.iter().zip(&ulog.t_s).all(|(a, b)| (a - b).abs() < 1e-12));

        let mut frame =
            df!("t_s" => &ulog.t_s, "gx" => &ulog.values[0], "gy" => &ulog.values[1], "gz" => &ulog.values[2]).unwrap();
        let parquet_path = tmp.path().join("imu.parquet");
        ParquetWriter::new(std::fs::File::create(&parquet_path).unwrap()).finish(&mut frame).unwrap();
        let seconds = TableRequest { time_column: "t_s".into(), seconds_per_time_unit: 1.0, ..table.clone() };
        assert_eq!(read_table(&parquet_path, &seconds).unwrap(), TopicSeries { ending: None, ..ulog.clone() });

        let wrong = TableRequest { columns: vec!["gx".into(), "gyro_y".into()], ..table.clone() };
        let err = read_table(&csv_path, &wrong).unwrap_err().to_string();
        assert!(err.ends_with("imu.csv: table has no column \"gyro_y\" (its columns: time_us, gx, gy, gz)"), "{err}");
        let mut lines: Vec<&str> = csv.lines().collect();
        let holed = lines[11].rsplit_once(',').unwrap().0.to_string() + ",";
        lines[11] = &holed;
        std::fs::write(&csv_path, lines.join("\n")).unwrap();
        let err = read_table(&csv_path, &table).unwrap_err().to_string();
        assert!(err.contains("imu.csv: table: field \"gz\" is NaN at ") && err.contains("(sample 10)"), "{err}");
        lines.swap(20, 21);
        lines[11] = csv.lines().nth(11).unwrap();
        std::fs::write(&csv_path, lines.join("\n")).unwrap();
        let err = read_table(&csv_path, &table).unwrap_err().to_string();
        assert!(err.contains("imu.csv: table: time ") && err.contains("(sample 20) does not follow"), "{err}");
    }

    /// What a replay cannot use is refused naming the file, topic and field: the small log's 161 ms
    /// dropout against a 0.1 s limit, a topic or a field it lacks, a file that is not a log, a missing
    /// file; a log cut mid-record keeps its valid prefix and says so.
    #[test]
    fn unusable_logs_are_refused_by_name() {
        let small = log("sample_log_small.ulg");
        let err = read_ulog(&small, &imu_request(0.1)).unwrap_err().to_string();
        assert!(err.contains("sample_log_small.ulg: topic \"sensor_combined\": a gap of 0.161 s after"), "{err}");
        // From the first sample (the log's boot clock starts 20.3 s earlier), with the way out.
        let after: f64 = err.split(" s after ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
        assert!(
            (0.0..6.5).contains(&after) && err.contains(&format!("after {after:.3} s from its first sample")),
            "{err}"
        );
        assert!(err.contains("The log's largest gap is 0.161 s: max_gap_s = 0.162 bridges every gap"), "{err}");
        let mut wrong_topic = imu_request(0.5);
        wrong_topic.topic = "sensor_combined_x".into();
        let err = read_ulog(&small, &wrong_topic).unwrap_err().to_string();
        assert!(
            err.contains("no topic \"sensor_combined_x\" instance 0 (the log has: ") && err.contains("sensor_accel"),
            "{err}"
        );
        let mut wrong_field = imu_request(0.5);
        wrong_field.fields[1] = "gyro_rad[3]".into();
        let err = read_ulog(&small, &wrong_field).unwrap_err().to_string();
        assert!(err.contains("has no number field \"gyro_rad[3]\" (its number fields: gyro_rad[0], "), "{err}");
        let mut instance = imu_request(2.0); // logged at about 1 Hz
        instance.topic = "sensor_accel".into();
        instance.instance = 2;
        instance.fields = vec!["x".into(), "y".into(), "z".into()];
        assert_eq!(read_ulog(&small, &instance).unwrap().t_s.len(), 6, "the third accelerometer (pyulog: 6)");

        let tmp = tempfile::tempdir().unwrap();
        let bytes = std::fs::read(&small).unwrap();
        let cut = tmp.path().join("cut.ulg");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        let s = read_ulog(&cut, &imu_request(0.5)).unwrap();
        assert_eq!(s.t_s.len(), 595, "pyulog 1.3.0 reads 595 samples of the first half of the file");
        assert!(s.ending.unwrap().contains("partway through a record"));
        let not_a_log = tmp.path().join("deck.ulg");
        std::fs::write(&not_a_log, "[study]\nname = \"x\"\n").unwrap();
        let err = read_ulog(&not_a_log, &imu_request(0.5)).unwrap_err().to_string();
        assert!(err.starts_with(&format!("{}: not a PX4 ULog: ", not_a_log.display())), "{err}");
        // A file of 16 bytes or more with another start: the header named, not the reader's debug text.
        std::fs::write(&not_a_log, [7u8; 64]).unwrap();
        let err = read_ulog(&not_a_log, &imu_request(0.5)).unwrap_err().to_string();
        assert_eq!(
            err,
            format!(
                "{}: not a PX4 ULog: it does not begin with the ULog header (\"ULog\" then bytes 01 12 35); fdimc reads PX4 ULog files (.ulg), or a CSV or Parquet table",
                not_a_log.display()
            )
        );
        let err = read_ulog(&tmp.path().join("none.ulg"), &imu_request(0.5)).unwrap_err().to_string();
        assert!(err.ends_with("none.ulg: no such file"), "{err}");
    }
}
