//! Method 003 on a recorded flight (issue 22): the log's gyro and accelerometer are the healthy truth,
//! the deck's faults are injected into the recorded accelerometer, and the attitude EKF runs on the
//! result. The log is read once per study by the engine's [`crate::engine::logs::log_source`]; a trial is a
//! segment of it (its start drawn inside the evaluation part, or the training part for classifiers that
//! learn from the log) with one fault drawn as a simulated trial draws it, onset from the segment's
//! start. Nothing is added to the recorded noise.
//!
//! Also here, what only a log can tell: the residual detector over the fault-free log
//! ([`FaultFreeReplay`]: alarms per flight hour) and a threshold calibrated on the training part.

use nalgebra::Vector3;
use rand::{Rng, RngExt};
use serde::Serialize;

use crate::engine::logs::log_source::{Needs, Part, ReplayLog, Signal};
use crate::fault::{ActiveFaults, ChannelFault};
use crate::methods::accelerometer::attitude::AttitudeEkfParams;
use crate::methods::accelerometer::ekf_svm::{
    DetectionParams, FaultClass, ResidualTrace, TrialError, detection_statistics, filter_trial, window_start,
};
use crate::methods::accelerometer::imu::AccelFaultRanges;

/// What the method reads from a log: PX4's `sensor_combined` (body FRD axes, as the filter's x forward,
/// y right, z down), gyro then accelerometer.
pub const NEEDS: Needs = Needs {
    topic: "sensor_combined",
    signals: &[
        Signal { name: "gyro_x_rad_s", ulog_field: "gyro_rad[0]" },
        Signal { name: "gyro_y_rad_s", ulog_field: "gyro_rad[1]" },
        Signal { name: "gyro_z_rad_s", ulog_field: "gyro_rad[2]" },
        Signal { name: "accel_x_mps2", ulog_field: "accelerometer_m_s2[0]" },
        Signal { name: "accel_y_mps2", ulog_field: "accelerometer_m_s2[1]" },
        Signal { name: "accel_z_mps2", ulog_field: "accelerometer_m_s2[2]" },
    ],
};

/// A replayed trial's segment and fault.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayDraw {
    pub fault: Option<ChannelFault>,
    /// Onset from the segment's start (nominal for the normal class).
    pub onset_s: f64,
    /// The segment's first grid sample in the log.
    pub start: usize,
}

/// Draws a trial of `class` on a segment of `samples` samples inside `part`: the fault as
/// [`AccelFaultRanges::draw`] draws it (4 uniforms), then one uniform for the segment's start.
pub fn draw<R: Rng + ?Sized>(
    ranges: &AccelFaultRanges,
    part: Part,
    samples: usize,
    class: FaultClass,
    rng: &mut R,
) -> ReplayDraw {
    let (fault, onset_s) = ranges.draw(class.fault_kind(), rng);
    let start = part.segment_start(samples, rng.random::<f64>());
    ReplayDraw { fault, onset_s, start }
}

/// The filter over `samples` samples of the log from `start`, with `faults` (onsets from `start`)
/// applied to the recorded accelerometer.
pub fn replay_trace(
    log: &ReplayLog,
    start: usize,
    samples: usize,
    faults: &[ChannelFault],
    ekf: &AttitudeEkfParams,
) -> Result<ResidualTrace, TrialError> {
    let s = &log.signals;
    let mut active = ActiveFaults::new(faults.to_vec());
    let dt_s = log.dt_s;
    let end = (start + samples).min(log.samples());
    let rows = (start..end).map(|k| {
        let mut accel = [s[3][k], s[4][k], s[5][k]];
        active.apply((k - start) as f64 * dt_s, &mut accel);
        (Vector3::new(s[0][k], s[1][k], s[2][k]), Vector3::from(accel), None)
    });
    filter_trial(dt_s, end.saturating_sub(start), rows, ekf)
}

/// The residual detector over a fault-free stretch of the log, filtered from its start: what a user
/// flying this aircraft with this threshold would see.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultFreeReplay {
    /// The stretch, log seconds from its first sample.
    pub part_s: [f64; 2],
    /// Seconds watched: the stretch after `settle_s`.
    pub watched_s: f64,
    pub threshold: f64,
    /// Largest `T` watched.
    pub largest_statistic: f64,
    /// Separate alarms (each run of samples at or over the threshold counts once).
    pub alarms: u64,
    /// `alarms` per hour watched, and its exact one-sided 95 % Poisson upper bound.
    pub alarms_per_flight_hour: f64,
    pub alarms_per_flight_hour_upper95: f64,
}

/// [`FaultFreeReplay`] of `part` under `detection` (threshold included), alarms counted from
/// `settle_s` after the part's start.
pub fn fault_free_replay(
    log: &ReplayLog,
    part: Part,
    ekf: &AttitudeEkfParams,
    detection: &DetectionParams,
    settle_s: f64,
) -> Result<FaultFreeReplay, TrialError> {
    let trace = replay_trace(log, part.first, part.len(), &[], ekf)?;
    let statistics = detection_statistics(&trace.samples, detection);
    let settle = window_start(settle_s, 0.0, log.dt_s).min(statistics.len());
    let watched = &statistics[settle..];
    let over = |t: f64| t >= detection.threshold;
    let alarms = (0..watched.len()).filter(|&k| over(watched[k]) && (k == 0 || !over(watched[k - 1]))).count() as u64;
    let hours = watched.len() as f64 * log.dt_s / 3600.0;
    let upper = crate::engine::stats::intervals::poisson_upper95(alarms);
    Ok(FaultFreeReplay {
        part_s: log.seconds(part),
        watched_s: hours * 3600.0,
        threshold: detection.threshold,
        // NaN (no decision) is passed over by max; an infinite T counts, as it alarms.
        largest_statistic: watched.iter().copied().fold(f64::NAN, f64::max),
        alarms,
        alarms_per_flight_hour: alarms as f64 / hours,
        alarms_per_flight_hour_upper95: upper / hours,
    })
}

/// A threshold calibrated on the fault-free training part: `margin` times the largest `T` after
/// `settle_s` there (the margin is the deck's choice; the part is never the evaluated one).
pub fn calibrated_threshold(
    log: &ReplayLog,
    part: Part,
    ekf: &AttitudeEkfParams,
    detection: &DetectionParams,
    settle_s: f64,
    margin: f64,
) -> Result<f64, TrialError> {
    Ok(margin * fault_free_replay(log, part, ekf, detection, settle_s)?.largest_statistic)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scenario::deck::FromDeck;
    use crate::fault::FaultMode;
    use crate::methods::accelerometer::study::AccelerometerStudy;

    /// Method 003 on the bench log (at rest; its 161 ms dropout bridged): 6 s trials, the seed's filter
    /// and detector at 100 Hz.
    fn bench_study() -> AccelerometerStudy {
        let deck = r#"
            [study]
            name = "replay_bench"
            seed = 1
            duration_s = 6.0
            dt_s = 0.01
            [imu]
            [log]
            file = "logs/sample_log_small.ulg"
            max_gap_s = 0.2
            [faults]
            onset_s = [2.0, 3.0]
            [detection]
            settle_s = 1.5
        "#;
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/replay_bench.toml");
        AccelerometerStudy::from_toml(deck, &path).unwrap()
    }

    /// The bench log replayed from sample `start` for the study's length with `faults`, by the study's
    /// filter at the nominal noise.
    fn replayed(study: &AccelerometerStudy, start: usize, faults: &[ChannelFault]) -> ResidualTrace {
        let (log, ekf) = (study.log.as_ref().unwrap(), study.design.ekf_for(1.0));
        replay_trace(log, start, study.header.steps, faults, &ekf).unwrap()
    }

    /// A zero-size fault (a bias of 0, a gain of 1) leaves every residual exactly as the clean replay's.
    #[test]
    fn a_zero_size_fault_leaves_the_replay_identical() {
        let study = bench_study();
        let clean = replayed(&study, 7, &[]);
        assert_eq!(clean.samples.len(), 600);
        for mode in [FaultMode::Bias { bias: 0.0 }, FaultMode::Gain { factor: 1.0 }] {
            for channel in 0..3 {
                let zero = ChannelFault { channel, onset_s: 2.5, mode };
                let faulty = replayed(&study, 7, &[zero]);
                // Equal residuals: equal statistics, alarms and features, which are functions of them.
                assert_eq!(faulty.samples, clean.samples, "{mode:?} on axis {channel}");
            }
        }
        // A real fault does move it (the comparison above can fail).
        let bias = ChannelFault { channel: 0, onset_s: 2.5, mode: FaultMode::Bias { bias: 0.05 } };
        assert_ne!(replayed(&study, 7, &[bias]).samples, clean.samples);
    }

    /// A 0.1 m/s^2 bias on x at 3 s of the bench log (at rest, gravity on z): at the onset sample the
    /// residual moves by exactly the bias's turn of the measured gravity direction (the prediction has
    /// not seen it); after that the filter absorbs it as its steady state predicts, the shift decaying
    /// as `(1 - k)^n` with `k` the steady-state gain of the scalar tilt channel (process variance
    /// `(dt sigma_w)^2`, measurement variance `(sigma_a / g)^2`: k = 0.0085, a 1.17 s time constant),
    /// within 2 % of the first shift over 2 s.
    #[test]
    fn a_known_bias_moves_the_residual_as_the_steady_state_filter_predicts() {
        let study = bench_study();
        let (log, ekf) = (study.log.as_ref().unwrap(), study.design.ekf_for(1.0));
        let clean = replayed(&study, 0, &[]);
        let (onset_s, b) = (3.0, 0.1);
        let k0 = window_start(onset_s, 0.0, log.dt_s);
        let fault = ChannelFault { channel: 0, onset_s, mode: FaultMode::Bias { bias: b } };
        let faulty = replayed(&study, 0, &[fault]);
        // The measured direction's shift at the onset, from the recorded sample.
        let a = Vector3::new(log.signals[3][k0], log.signals[4][k0], log.signals[5][k0]);
        let shifted = a + Vector3::new(b, 0.0, 0.0);
        let dz = shifted[0] / shifted.norm() - a[0] / a.norm();
        let shift = |m: usize| faulty.samples[k0 + m].residual[0] - clean.samples[k0 + m].residual[0];
        assert!((shift(0) - dz).abs() < 1e-12 * dz.abs().max(1.0), "{} vs {dz}", shift(0));
        assert!((dz - b / a.norm()).abs() < 0.01 * dz, "at rest the turn is b / |a|");
        let (q, r) = ((ekf.dt_s * ekf.gyro_noise_std_rad_s).powi(2), ekf.residual_noise_std().powi(2));
        let mut p = q;
        for _ in 0..10_000 {
            let predicted = p + q;
            p = predicted * r / (predicted + r);
        }
        let k = (p + q) / (p + q + r);
        assert!((k - 0.008521).abs() < 1e-5, "k = {k}");
        for m in [1, 5, 10, 20, 50, 100, 200] {
            let expected = dz * (1.0 - k).powi(m as i32);
            assert!((shift(m) - expected).abs() < 0.02 * dz, "after {m} samples: {} vs {expected}", shift(m));
        }
        // Before the onset nothing differs.
        assert!((0..k0).all(|m| faulty.samples[m] == clean.samples[m]));
    }
}
