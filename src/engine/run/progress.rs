//! A run's progress on stderr: on a terminal a bar with the rate and the time left; elsewhere (a
//! cluster job's log, a pipe) one plain line every [`PLAIN_EVERY_S`] seconds, so a long run's log is
//! never silent; nothing with `--quiet`. Shared by the pool's workers.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressState, ProgressStyle};

/// Seconds between plain progress lines; `FDIMC_PROGRESS_EVERY_S` sets another (0: every chunk of
/// trials a worker finishes, as the tests use).
pub const PLAIN_EVERY_S: f64 = 10.0;

pub struct Progress {
    bar: ProgressBar,
    /// Not a terminal: when the last plain line was written.
    plain: Option<Mutex<Instant>>,
    every: Duration,
    label: String,
    total: u64,
    done: AtomicU64,
    start: Instant,
}

impl Progress {
    /// Progress of `total` trials named `label`; `shown`: false for `--quiet`.
    pub fn new(label: &str, total: u64, shown: bool) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let bar = if shown && terminal { ProgressBar::new(total) } else { ProgressBar::hidden() };
        bar.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} trials, {rate}, {eta} left")
                .expect("static template")
                .with_key("rate", |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = write!(w, "{:.0} trials/s", s.per_sec());
                }),
        );
        let every = std::env::var("FDIMC_PROGRESS_EVERY_S")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(PLAIN_EVERY_S);
        let start = Instant::now();
        Progress {
            bar,
            plain: (shown && !terminal).then(|| Mutex::new(start)),
            every: Duration::from_secs_f64(every),
            label: label.to_string(),
            total,
            done: AtomicU64::new(0),
            start,
        }
    }

    /// `n` more trials done.
    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        let Some(last) = &self.plain else { return };
        // A worker that finds another writing skips its line: the next one comes soon enough, and
        // `finish` writes the last.
        let Ok(mut last) = last.try_lock() else { return };
        let now = Instant::now();
        if now.duration_since(*last) >= self.every && done < self.total {
            *last = now;
            self.line(done, now);
        }
    }

    /// Ends the bar; without a terminal, writes the final line.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
        if self.plain.is_some() {
            self.line(self.done.load(Ordering::Relaxed), Instant::now());
        }
    }

    fn line(&self, done: u64, now: Instant) {
        let seconds = now.duration_since(self.start).as_secs_f64();
        let rate = done as f64 / seconds.max(1e-9);
        let left = (self.total - done.min(self.total)) as f64 / rate.max(1e-9);
        eprintln!(
            "{}: {done}/{} trials ({:.0} %), {rate:.0} trials/s, about {left:.0} s left",
            self.label,
            self.total,
            100.0 * done as f64 / self.total.max(1) as f64
        );
    }
}
