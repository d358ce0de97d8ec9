//! Your own detector, run as an fdimc study through the library.
//!
//! The detector: the seed's detection filter (method 000) with a moving-average test of our own on its
//! residual. Each output's statistic is |mean of the last N residual samples|, which averages the sensor
//! noise down by sqrt(N) while a bias stays whole. It runs next to the deck's own detectors on the same
//! trials, and fdimc writes the same trials.parquet, summaries and report as for a built-in detector.
//!
//!     cargo run --release --example custom_detector [-- --out DIR --trials N]
//!
//! Default: studies/ci_seed000.toml, 3,000 trials, results in results/custom_detector/.

use std::collections::VecDeque;
use std::path::PathBuf;

use fdimc::engine::run::runner::{FmuProcesses, RunOptions, Shard};
use fdimc::engine::scenario::deck::FromDeck;
use fdimc::methods::detection_filter::decision::{Decision, ResidualTest, TestState};
use fdimc::methods::detection_filter::study::{DetectorConfig, LtiStudy};

/// The test: |mean of the last `window` residuals| per output.
struct MovingAverage {
    window: usize,
}

impl ResidualTest for MovingAverage {
    fn describe(&self) -> String {
        format!("|moving average of {} residual samples|", self.window)
    }

    // Called once per trial and detector: the state starts empty.
    fn start(&self, outputs: usize, _dt_s: f64) -> Box<dyn TestState> {
        Box::new(MovingAverageState {
            window: self.window,
            recent: vec![VecDeque::new(); outputs],
            sum: vec![0.0; outputs],
        })
    }
}

struct MovingAverageState {
    window: usize,
    recent: Vec<VecDeque<f64>>,
    sum: Vec<f64>,
}

impl TestState for MovingAverageState {
    fn step(&mut self, residual: &[f64], statistic: &mut [f64]) {
        for j in 0..residual.len() {
            let recent = &mut self.recent[j];
            recent.push_back(residual[j]);
            self.sum[j] += residual[j];
            if recent.len() > self.window {
                self.sum[j] -= recent.pop_front().unwrap_or(0.0);
            }
            statistic[j] = (self.sum[j] / recent.len() as f64).abs();
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let (mut out_dir, mut trials) = (PathBuf::from("results/custom_detector"), None);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out_dir = args.next().ok_or("--out needs a folder")?.into(),
            "--trials" => trials = Some(args.next().ok_or("--trials needs a number")?.parse::<u64>()?),
            other => return Err(format!("unknown argument {other:?}; allowed --out DIR, --trials N").into()),
        }
    }

    // 1. A deck as fdimc reads it: plant, noise, faults, Monte Carlo design, the deck's detectors.
    let deck = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/studies/ci_seed000.toml"));
    let mut study = LtiStudy::load(&deck)?;
    if let Some(n) = trials {
        study.monte_carlo.common.trials = n;
    }

    // 2. Our detector: the first deck detector's filter (gains, isolation), our test, our thresholds.
    //    25 samples (0.25 s) average white noise down by 5; the residual is coloured, so half the
    //    one-sample thresholds (calibration to the deck's Pfa then sets the fair ones).
    let mut params = study.detectors[0].params.clone();
    params.decision = Some(Decision::new(MovingAverage { window: 25 }));
    params.thresholds = params.thresholds.map(|t| t / 2.0);
    study.detectors.push(DetectorConfig { name: "moving_average".into(), params });

    // 3. Run it: every trial flies every detector on the same samples; trials.parquet as for any study.
    let opts = RunOptions {
        deck: deck.clone(),
        out_dir: out_dir.clone(),
        threads: None,
        shard: Shard::WHOLE,
        resume: false,
        force: true,
        progress: false,
        stop_after_chunks: None,
        stop: None,
        sensitivity: None,
        command_line: std::env::args().collect(),
        fmu_processes: FmuProcesses::InProcess,
        low_disk: false,
    };
    let run = fdimc::methods::detection_filter::run_study(&study, &opts)?;
    println!("{} trials x {:?} -> {}", run.manifest.trials, run.manifest.detectors, out_dir.display());

    // 4. The same summaries (thresholds calibrated to the deck's Pfa, paired comparison) and report.
    let method = &fdimc::methods::detection_filter::METHOD;
    let summary = fdimc::engine::results::summary::summarize(&out_dir, &method.summary, None, None)?;
    fdimc::engine::results::summary::print(&method.summary, &summary);
    let report = method.write_report(&out_dir, &[])?;
    println!("report: {}", report.files.last().map(|p| p.display().to_string()).unwrap_or_default());
    Ok(())
}
