//! `fdimc log`: what a flight log holds, and a plot of chosen signals with a deck's parts marked.
//!
//! One time base for the user: seconds from the first sample. The table counts from the log's first
//! sample of any topic and says once where that is on the log's own clock (a ULog's boot time); a
//! topic's fields, its plot and a deck's `[log]` windows count from that topic's first sample, as a
//! replay does.

use std::path::Path;

use crate::cli::CliError;
use crate::engine::logs::flight_log::{AUTOCORRELATION_LAGS, LogError, TopicRequest, field_spreads, read_ulog, survey};

/// What `fdimc log` was asked.
pub struct LogArgs<'a> {
    pub file: &'a Path,
    pub topic: Option<&'a str>,
    pub instance: u8,
    /// `--plot OUT.svg`, `--signals`, `--deck`.
    pub plot: Option<&'a Path>,
    pub signals: &'a [String],
    pub deck: Option<&'a Path>,
}

fn invalid(e: LogError) -> CliError {
    CliError::Invalid(e.to_string())
}

/// `fdimc log` (module docs). Every refusal comes before anything is printed.
pub fn exec_log(a: &LogArgs) -> Result<(), CliError> {
    if a.plot.is_none() && (!a.signals.is_empty() || a.deck.is_some()) {
        return Err(CliError::Invalid("--signals and --deck draw a plot: give --plot OUT.svg".into()));
    }
    let (topics, ending) = survey(a.file).map_err(invalid)?;
    // With a deck, the topic is the deck's unless --topic names one.
    let section = match a.deck {
        Some(deck) => Some(deck_log(deck, a.file)?),
        None => None,
    };
    let topic = a.topic.map(str::to_string).or_else(|| section.as_ref().and_then(|s| s.topic.clone()));
    let instance = section.as_ref().and_then(|s| s.instance).filter(|_| a.topic.is_none()).unwrap_or(a.instance);
    if let Some(name) = &topic
        && !topics.iter().any(|t| t.topic == *name && t.instance == instance)
    {
        let mut names: Vec<&str> = topics.iter().map(|t| t.topic.as_str()).collect();
        names.dedup();
        return Err(invalid(LogError::MissingTopic {
            file: a.file.to_path_buf(),
            topic: name.clone(),
            instance,
            available: names.join(", "),
        }));
    }
    if let Some(out) = a.plot {
        let topic = topic.as_deref().unwrap_or(crate::engine::logs::flight_log::PX4_IMU_TOPIC);
        return plot(a, out, topic, instance, section.as_ref());
    }
    // Zero: the first sample of the topic a replay would read (--topic, the deck's, else the method's),
    // so the table's times are the deck's; a log without it counts from its first non-zero timestamp
    // (a zero timestamp is a topic that never set its clock).
    let reference = topic.as_deref().unwrap_or(crate::engine::logs::flight_log::PX4_IMU_TOPIC);
    let (t0, zero) = match topics.iter().find(|t| t.topic == reference && t.instance == instance) {
        Some(t) => (
            t.first_s,
            format!(
                "the first {reference} sample (instance {instance}), where a deck's [log] evaluate_s and train_s count from"
            ),
        ),
        None => (
            topics.iter().map(|t| t.first_s).filter(|t| *t > 0.0).fold(f64::INFINITY, f64::min),
            "the log's first non-zero timestamp".to_string(),
        ),
    };
    let t0 = if t0.is_finite() { t0 } else { 0.0 };
    println!(
        "{}: {} topic instances, {}; times in s from {zero}, at {t0:.6} s on the log's clock (boot time; earlier samples are negative)",
        a.file.display(),
        topics.len(),
        ending.as_deref().unwrap_or("read to its end")
    );
    println!(
        "{:<32} {:>8} {:>8} {:>10} {:>10} {:>9} {:>14} {:>10}",
        "topic", "instance", "samples", "first_s", "last_s", "rate_hz", "largest_gap_s", "bad_times"
    );
    for t in topics.iter().filter(|t| topic.as_ref().is_none_or(|name| t.topic == *name)) {
        // One sample has no rate (nor a gap).
        let rate = if t.samples < 2 { "-".to_string() } else { format!("{:.2}", t.mean_rate_hz()) };
        let gap = if t.samples < 2 { "-".to_string() } else { format!("{:.4}", t.largest_gap_s) };
        println!(
            "{:<32} {:>8} {:>8} {:>10.3} {:>10.3} {:>9} {:>14} {:>10}",
            t.topic,
            t.instance,
            t.samples,
            t.first_s - t0,
            t.last_s - t0,
            rate,
            gap,
            t.not_increasing
        );
    }
    println!(
        "(rate_hz: mean over the span, '-' for a single sample; bad_times: samples whose timestamp repeats or goes back, which a replay refuses)"
    );
    if let Some(name) = topic {
        let spreads = field_spreads(a.file, &name, instance).map_err(invalid)?;
        // Each field's residual tail as an empirical noise law would fit it (the whole topic read again).
        let request = crate::engine::logs::flight_log::TopicRequest {
            topic: name.clone(),
            instance,
            fields: spreads.iter().map(|f| f.field.clone()).collect(),
            max_gap_s: f64::INFINITY,
        };
        let series = crate::engine::logs::flight_log::read_ulog(a.file, &request).map_err(invalid)?;
        let tail_shape = |i: usize| {
            crate::engine::scenario::noise::EmpiricalLaw::from_samples("", &series.values[i])
                .map_or("-".to_string(), |law| format!("{:.2}", law.tail_shape().1))
        };
        let samples = topics.iter().find(|t| t.topic == name && t.instance == instance).map_or(0, |t| t.samples);
        println!("\n{name} instance {instance}");
        println!(
            "number fields (difference sd = sd of sample-to-sample differences / sqrt 2, the white noise when the signal moves slowly; r(l) = autocorrelation at l samples, 0 for white noise; kurtosis = the noise's excess kurtosis from the differences, 0 for Gaussian; tail_shape = the generalised Pareto shape of the largest tenth of the residuals about each sample's four neighbours, as a deck's empirical law {{ log, field }} fits it: 0 exponential, above 0 a power law (Student-t N: 1/N), below 0 bounded (the law then takes 0), '-' under 500 samples; noise_law = a deck's noise.sensor_law of that kurtosis, Student-t by moments, gaussian within 3 standard errors)"
        );
        let lags = AUTOCORRELATION_LAGS.map(|l| format!("r({l})"));
        println!(
            "{:<32} {:>14} {:>14} {:>14} {:>7} {:>7} {:>7} {:>7} {:>9} {:>10}  noise_law",
            "field", "mean", "sd", "difference_sd", lags[0], lags[1], lags[2], lags[3], "kurtosis", "tail_shape"
        );
        for (i, f) in spreads.into_iter().enumerate() {
            let r = f.autocorrelation;
            println!(
                "{:<32} {:>14.6e} {:>14.6e} {:>14.6e} {:>7.3} {:>7.3} {:>7.3} {:>7.3} {:>9.2} {:>10}  {}",
                f.field,
                f.mean,
                f.sd,
                f.difference_sd,
                r[0],
                r[1],
                r[2],
                r[3],
                f.excess_kurtosis,
                tail_shape(i),
                f.fitted_law(samples as usize).describe()
            );
        }
    }
    Ok(())
}

/// The `[log]` section of `deck`, which must replay `file`.
fn deck_log(deck: &Path, file: &Path) -> Result<crate::engine::logs::log_source::LogSection, CliError> {
    use serde::Deserialize;
    let text = crate::engine::scenario::deck::read_deck(deck)?;
    let bad = |field: &str, message: String| CliError::Invalid(format!("{}: {field}: {message}", deck.display()));
    let table: toml::Table = toml::from_str(&text).map_err(|e| bad("(top level)", e.to_string()))?;
    let log = table.get("log").ok_or_else(|| bad("log", "--deck: a deck with a [log] table (a replay)".into()))?;
    let section = crate::engine::logs::log_source::LogSection::deserialize(log.clone())
        .map_err(|e| bad("log", e.to_string().trim_end().to_string()))?;
    let named = deck.parent().unwrap_or(Path::new("")).join(&section.file);
    let same = named.canonicalize().ok().zip(file.canonicalize().ok()).is_some_and(|(a, b)| a == b);
    if !same {
        return Err(bad(
            "log.file",
            format!("{} is not {}: --deck marks the parts of the log it replays", named.display(), file.display()),
        ));
    }
    Ok(section)
}

/// `--plot`: the `--signals` fields of `topic` against seconds from its first sample, one panel each,
/// with the deck's `train_s` and `evaluate_s` shaded.
fn plot(
    a: &LogArgs,
    out: &Path,
    topic: &str,
    instance: u8,
    section: Option<&crate::engine::logs::log_source::LogSection>,
) -> Result<(), CliError> {
    use crate::engine::report::plots::{FONT, color, e, legend, register_font};
    use plotters::prelude::*;
    if a.signals.is_empty() {
        return Err(CliError::Invalid(format!(
            "--plot: name the fields to draw with --signals, e.g. --signals gyro_rad[0],gyro_rad[2] (`fdimc log {} --topic {topic}` lists them)",
            a.file.display()
        )));
    }
    if !out.extension().is_some_and(|x| x.eq_ignore_ascii_case("svg")) {
        return Err(CliError::Invalid(format!("--plot {}: allowed an .svg file", out.display())));
    }
    // Every gap is drawn as it is: the plot shows the log, not what a deck accepts of it.
    let request = TopicRequest { topic: topic.into(), instance, fields: a.signals.to_vec(), max_gap_s: f64::INFINITY };
    let series = read_ulog(a.file, &request).map_err(invalid)?;
    let t0 = series.t_s.first().copied().unwrap_or(0.0);
    let t_s: Vec<f64> = series.t_s.iter().map(|t| t - t0).collect();
    let span_s = t_s.last().copied().unwrap_or(0.0).max(1e-9);
    // The parts as the deck gives them (its own validation says whether they fit a study).
    let windows: Vec<(&str, [f64; 2], RGBColor)> = match section {
        None => Vec::new(),
        Some(s) => {
            [("train_s", s.train_s, color(2)), ("evaluate_s", Some(s.evaluate_s.unwrap_or([0.0, span_s])), color(0))]
                .into_iter()
                .filter_map(|(name, w, c)| w.map(|w| (name, w, c)))
                .collect()
        }
    };
    register_font();
    let panels = a.signals.len() as u32;
    let root = SVGBackend::new(out, (1100, 80 + 220 * panels)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| CliError::Internal(e(x)))?;
    let title = format!("{} {topic} instance {instance}", a.file.file_name().unwrap_or_default().to_string_lossy());
    let root = root.titled(&title, (FONT, 20)).map_err(|x| CliError::Internal(e(x)))?;
    let draw = || -> Result<(), String> {
        for ((name, v), area) in a.signals.iter().zip(&series.values).zip(root.split_evenly((a.signals.len(), 1))) {
            let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
            let pad = ((hi - lo) * 0.08).max(1e-9);
            let (lo, hi) = (lo - pad, hi + pad);
            let mut chart = ChartBuilder::on(&area)
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(75)
                .build_cartesian_2d(0.0..span_s, lo..hi)
                .map_err(e)?;
            chart
                .configure_mesh()
                .x_desc(format!("t (s from the first {topic} sample)"))
                .y_desc(name.as_str())
                .label_style((FONT, 12))
                .draw()
                .map_err(e)?;
            for (label, [from, to], c) in &windows {
                let c = *c;
                chart
                    .draw_series([Rectangle::new([(*from, lo), (*to, hi)], c.mix(0.15).filled())])
                    .map_err(e)?
                    .label(format!("{label} [{from:.2}, {to:.2}) s"))
                    .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], c.mix(0.3).filled()));
            }
            chart
                .draw_series(LineSeries::new(t_s.iter().copied().zip(v.iter().copied()), color(1)))
                .map_err(e)?
                .label(name.as_str())
                .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], color(1)));
            legend(&mut chart, SeriesLabelPosition::UpperRight, 11)?;
        }
        root.present().map_err(e)
    };
    draw().map_err(|m| CliError::Internal(format!("{}: {m}", out.display())))?;
    println!(
        "{}: {} of {topic} instance {instance} over {span_s:.3} s from its first sample (at {t0:.6} s on the log's clock){} -> {}",
        a.file.display(),
        a.signals.join(", "),
        if windows.is_empty() {
            String::new()
        } else {
            format!(
                ", the deck's {} shaded",
                windows
                    .iter()
                    .map(|(n, w, _)| format!("{n} [{:.2}, {:.2})", w[0], w[1]))
                    .collect::<Vec<_>>()
                    .join(" and ")
            )
        },
        out.display()
    );
    Ok(())
}
