//! Method 001: launch-vehicle thrust-loss detection by an EKF residual on the pitch rate and a
//! moving-horizon generalised-least-squares (GLS) fault estimator, with the loss converted to a
//! percentage by a linear fit and the faulty engine named by the signs of the lateral-overload jumps
//! (Ye, Chen, Xiong, Beijing Institute of Aerospace Automatic Control; `docs/findings-seed001.md`).
//!
//! # Residual
//! An EKF ([`Stekf`](crate::estimation::Stekf)`<13, 12>`, no fading, Joseph-form update) on the 13-state model of
//! [`crate::methods::thrust_loss::vehicle`] (`[P, vx, vy, vz, wx, wy, wz, x, y, z, phi, psi, gamma]`), measuring
//! the 12 states other than the thrust (`H = [0 I]`). Its model ([`FilterModel`]): all four engines at
//! `P / 4`, the nominal mass schedule, the thrust's nominal altitude law, and the measured gimbal
//! positions as input; one RK4 step per sample. The transition Jacobian is
//! `I + A dt + (A dt)^2 / 2` with `A` the exact Jacobian of the continuous dynamics at `x(k|k)`, from one
//! evaluation on dual numbers, which also gives the first RK4 stage (exact to second order in `dt`). The
//! residual is the innovation of the pitch rate, `r(k) = wz_measured(k) - wz(k|k-1)` (rad/s).
//!
//! That filter has no state for a loss's moment (its model holds the four engines equal), so a loss
//! leaves a lasting step in the residual. The seed's residual recovers ("after the detection the jump
//! returns to normal"): [`EkfParams::moment_bias_sigma_rad_s2_per_sqrt_s`] adds an angular-acceleration
//! bias per body axis ([`AUGMENTED`] states, random walks), which follows the moment, so the jump
//! clears within a time set by the walk's rate (about 0.05 s at 0.1 rad/s^2/sqrt(s), 0.15 s at 0.01).
//!
//! # Moving-horizon GLS
//! The window `Y(k) = [r(k - N D), r(k - (N-1) D), ..., r(k)]'` (N + 1 samples at interval D). The
//! seed linearises `Y(f) = Y(0) + S f` with the sensitivity `S` obtained by finite difference with a
//! unit fault `e` of 1 % thrust loss, and with `e_w ~ N(0, V)`, `f ~ N(0, R)` estimates
//! `fhat = (S' V^-1 S + R^-1)^-1 S' V^-1 (Y - Y0)`, `V = I`, `R = F^2` ([`gls_fault_estimate`]). `f` and
//! `F` are counted in unit faults, so `fhat = 30` reads "thirty 1 % losses".
//!
//! Where the seed is silent, and how it is done here ([`DetectorParams::design`]):
//! - Time alignment. A fault's residual signature depends on the time since its onset, and an online
//!   estimator does not know the onset. Each window is read as "a fault began just before this
//!   window": `S_j` is the residual response `j D` samples after the first sample that feels a 1 %
//!   loss (the sample after the onset). So `fhat(k)` is a matched filter for a fault starting at
//!   sample `k - N D`.
//! - Finite difference, offline, on the nominal model. One noise-free nominal flight (truth, controller
//!   and this EKF) is flown; at each onset of a grid ([`CalibrationGrid`], default every 5 s) it is
//!   branched with a 1 % loss on the reference engine, and
//!   `S_j(t_c) = r_branch(k_c + 1 + j D) - r_nominal(k_c + 1 + j D)` (per unit fault). Online, `S` is
//!   interpolated linearly in the hypothesised onset time (clamped at the grid ends, counted).
//! - `Y0` is the nominal flight's residual at the window's samples (numerically zero when the filter's
//!   model is the truth's, but kept so that a design model that differs from the nominal truth is
//!   handled as the seed writes it).
//! - Engine sign. A loss on engines {1, 4} (`y1 > 0`) pitches the nose up, on {2, 3} down: the pitch-rate
//!   residual of one pair is the mirror image of the other's. `S` is computed for the reference engine
//!   (engine 1), so `fhat` is negative for engines 2 and 3; detection and the loss conversion use
//!   `|fhat|`.
//! - `V = v I` with `v` a parameter: the seed's `V = I` is `v = 1` with the residual in rad/s. The
//!   residual's own variance is about `8.7e-8 (rad/s)^2`, so with `V = I` the prior term `1/R`
//!   dominates `S'S` (`~2e-10` per unit fault squared) for every `R` up to `500^2`, and
//!   `fhat ~ R S'(Y - Y0)`: a correlation scaled by `R`. Setting `v` to the residual variance makes the
//!   estimate a proper MAP estimate, in which `R` trades prior and data as the seed describes.
//!
//! # What comes out of the seed's findings here
//! (measured; tests `window_length_and_fault_intensity_as_they_come_out_here`,
//! `fhat_peak_grows_linearly_with_the_loss`)
//! - With the plain filter the residual of a permanent loss is a step that ramps up over ~0.3 s and
//!   stays: `fhat` plateaus near its peak instead of recovering, for every `N`, and the peak-to-noise
//!   ratio grows with `N` (11.9, 19.8, 27.3 for 1, 5, 10).
//! - With the recovering filter (`the_recovering_residual_clears_and_shows_the_seeds_window_trade`) the
//!   jump clears, and the seed's "a smaller N loses amplitude" appears (peak-to-noise 0.59, 1.16, 1.17
//!   at 0.1 rad/s^2/sqrt(s)); its "a larger N recovers in fewer beats" does not; and a jump that clears
//!   carries a twentieth of the step's peak-to-noise.
//! - `R`: with `V = I` it only scales `fhat` (same peak-to-noise); with `V` the residual variance, the
//!   peak grows with `R` and saturates, with no second rise.
//! - The peak of `fhat` is linear in the loss (R^2 = 0.9995 over 10-60 %), as the seed reports.
//!
//! # Detection, loss, localisation
//! An alarm is `|fhat| >= threshold` ([`DetectorParams::threshold_fhat`]). From the first alarm on, the
//! running peak of `|fhat|` is converted to a loss percentage by the linear fit `loss = a + b fhat_peak`
//! ([`LossFit`], fitted from calibration runs by [`MheDesign::calibrate_loss_fit`], the seed's eq. 27; the
//! seed's table over onset time is `trial.rs`'s `LossTable`, one fit per onset). At the first alarm the
//! onset is located as the largest
//! step of the overloads within the last second, the jumps are
//! `mean(n over post samples after the onset) - mean(n over pre samples up to it)`
//! ([`LocalisationParams`]), and their signs name the engine ([`localise`]): `n_y` alike for {1, 4} and
//! for {2, 3}, `n_z` alike for {1, 2} and for {3, 4}, as the seed's table.
//!
//! Numerical trouble is counted ([`DetectorHealth`]), never a panic.
#![allow(non_snake_case)]

mod calibration;
mod design;
mod detector;
mod residual;

pub use calibration::*;
pub use design::*;
pub use detector::*;
pub use residual::*;

#[cfg(test)]
mod tests {
    use super::detector::{Past, window_indices};
    use super::residual::WithMomentStates;
    use super::*;
    use std::collections::VecDeque;
    use std::sync::Arc;

    use nalgebra::SVector;

    use crate::dual::value_and_jacobian;

    use crate::estimation::{DiscreteModel, FilterHealth};
    use crate::methods::thrust_loss::vehicle::{
        ENGINES, LaunchVehicleConfig, Measurement, STATES, SensorNoise, ThrustFault, Vehicle, expected_jump_signs,
        filter_derivatives, idx,
    };
    use nalgebra::{DMatrix, DVector};
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::StandardNormal;
    use std::sync::OnceLock;

    fn seed_design() -> Arc<MheDesign> {
        static DESIGN: OnceLock<Arc<MheDesign>> = OnceLock::new();
        DESIGN.get_or_init(|| Arc::new(DetectorParams::seed().design(&LaunchVehicleConfig::default()).unwrap())).clone()
    }

    /// The loss fit of the seed design: noise-free losses of 10, 15, .. 60 % at 20 s, peaks over 3 s.
    fn seed_fit() -> &'static (LossFit, Vec<(f64, f64)>) {
        static FIT: OnceLock<(LossFit, Vec<(f64, f64)>)> = OnceLock::new();
        FIT.get_or_init(|| {
            let losses: Vec<f64> = (0..11).map(|i| 10.0 + 5.0 * i as f64).collect();
            seed_design().calibrate_loss_fit(&LaunchVehicleConfig::default(), 20.0, &losses, 3.0, None).unwrap()
        })
    }

    /// Flies a trial to `until_s` with sensor noise from ChaCha8 `seed` (noise-free when `None`).
    fn run(
        design: &Arc<MheDesign>,
        fault: Option<ThrustFault>,
        until_s: f64,
        seed: Option<u64>,
        fit: Option<LossFit>,
    ) -> Vec<(Measurement, MheStep)> {
        let mut config = LaunchVehicleConfig::default();
        if seed.is_none() {
            config.noise = SensorNoise::none();
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed.unwrap_or(0));
        let mut vehicle = Vehicle::new(&config, fault).unwrap();
        let mut detector = EkfMhe::new(Arc::clone(design), fit);
        let mut out = Vec::new();
        while vehicle.time_s() < until_s - 1e-9 {
            let m = if seed.is_some() { vehicle.step(&mut rng) } else { vehicle.step_exact() }.unwrap();
            out.push((m, detector.step(&m)));
        }
        assert_eq!(detector.health().filter, FilterHealth::default());
        assert_eq!(detector.health().gls_failed, 0);
        out
    }

    /// The filters' exact Jacobians (dual numbers) against central differences of the continuous
    /// dynamics at flown states (the pad, max-q, a gust, late in the burn, with a loss): equal to the
    /// differences' own error, 1e-6 of each column's scale; the first RK4 stage is the plain
    /// evaluation's to the bit, so the transition does not move.
    #[test]
    fn exact_jacobians_match_central_differences() {
        use crate::estimation::stekf::central_difference;
        let config = LaunchVehicleConfig::default();
        let model = FilterModel { params: config.params.clone(), dt_s: config.dt_s };
        let flown = run(
            &seed_design(),
            Some(ThrustFault { engine: 2, onset_s: 60.0, loss_fraction: 0.3 }),
            80.0,
            Some(3),
            None,
        );
        for t_s in [0.0, 40.5, 50.5, 62.0, 79.0] {
            let (m, _) = flown.iter().find(|(m, _)| m.t_s >= t_s).unwrap();
            let u = FilterInput::new(m.t_s, m.gimbal_rad);
            let (k1, exact) = value_and_jacobian(&m.truth, |x| filter_derivatives(&model.params, x, u.t_s, &u.gimbals));
            let numeric = central_difference(&m.truth, |x| filter_derivatives(&model.params, x, u.t_s, &u.gimbals));
            assert_eq!(k1, filter_derivatives(&model.params, &m.truth, u.t_s, &u.gimbals));
            // A central difference's own error: its truncation (relative, below 1e-6 of the column here)
            // and its rounding, about 1e-16 |f_r| / h_c with the step h_c = 1e-6 max(1, |x_c|); allowed
            // 100x that.
            for c in 0..STATES {
                let scale = exact.column(c).amax();
                for r in 0..STATES {
                    let rounding = 1e-8 * k1[r].abs().max(1.0) / m.truth[c].abs().max(1.0);
                    let error = (exact[(r, c)] - numeric[(r, c)]).abs();
                    assert!(error <= 1e-6 * scale + rounding, "t = {t_s} s, ({r}, {c}): {error:e} of {scale:e}");
                }
            }
            // Thrust lifts, and climbing raises the thrust: the thrust state is coupled both ways.
            assert!(exact[(idx::VY, idx::THRUST)] > 0.0 && exact[(idx::THRUST, idx::VY)] > 0.0);
            assert_eq!(model.transition_with_jacobian(&m.truth, &u).0, model.transition(&m.truth, &u));
            let augmented = WithMomentStates(&model);
            let x16 = SVector::<f64, AUGMENTED>::from_fn(|i, _| if i < STATES { m.truth[i] } else { 0.01 * i as f64 });
            let (_, exact16) = value_and_jacobian(&x16, |x| augmented.derivatives(x, u.t_s, &u.gimbals));
            let numeric16 = central_difference(&x16, |x| augmented.derivatives(x, u.t_s, &u.gimbals));
            assert!((exact16 - numeric16).amax() <= 1e-6 * exact16.amax().max(1.0), "t = {t_s} s, augmented");
            assert_eq!(exact16[(idx::WX, STATES)], 1.0);
            assert_eq!(augmented.transition_with_jacobian(&x16, &u).0, augmented.transition(&x16, &u));
        }
    }

    /// `(S' V^-1 S + R^-1)^-1 S' V^-1 (Y - Y0)` written out with general matrices.
    fn closed_form(S: &[f64], Y: &[f64], Y0: &[f64], V: &DMatrix<f64>, R: f64) -> f64 {
        let S = DMatrix::from_column_slice(S.len(), 1, S);
        let Vi = V.clone().try_inverse().unwrap();
        let A = S.transpose() * &Vi * &S + DMatrix::from_element(1, 1, 1.0 / R);
        let b = S.transpose() * &Vi * (DVector::from_column_slice(Y) - DVector::from_column_slice(Y0));
        (A.try_inverse().unwrap() * b)[(0, 0)]
    }

    /// The estimator on synthetic windows (random `S`, `Y`, `Y0` of the real scales, `V = v I`, the seed's
    /// `R` range) equals the closed form to 1e-12 relative (measured worst 5.2e-15), and the window takes
    /// the samples `k - (N - j) D`.
    #[test]
    fn gls_equals_the_closed_form_on_a_synthetic_window() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut normal = || rng.sample::<f64, _>(StandardNormal);
        let mut worst = 0.0f64;
        for case in 0..200 {
            let n = 2 + case % 10;
            let S: Vec<f64> = (0..n).map(|_| 1e-5 * normal()).collect();
            let Y: Vec<f64> = (0..n).map(|_| 1e-3 * normal()).collect();
            let Y0: Vec<f64> = (0..n).map(|_| 1e-4 * normal()).collect();
            let v = [1.0, 8.7e-8, 1e-10][case % 3];
            let R = [0.01f64, 1.0, 20.0, 500.0, 5000.0, 1e4][case % 6].powi(2);
            let ours = gls_fault_estimate(&S, &Y, &Y0, v, R).unwrap();
            let reference = closed_form(&S, &Y, &Y0, &(DMatrix::identity(n, n) * v), R);
            worst = worst.max((ours - reference).abs() / reference.abs());
        }
        assert!(worst < 1e-12, "{worst:e}");

        let mhe = MheParams { window_n: 3, interval_samples: 2, ..MheParams::seed() };
        let history: VecDeque<Past> =
            (0..20).map(|k| Past { k, residual: k as f64, n_y_g: 0.0, n_z_g: 0.0, fhat: 0.0 }).collect();
        let ks: Vec<usize> = window_indices(history.len(), &mhe).map(|i| history[i].k).collect();
        assert_eq!(ks, [13, 15, 17, 19]);
    }

    /// How much the data weigh against the prior in the seed's estimator (issue 21.2): `R S'S / v` for
    /// the window's `S` (per unit fault) at a 20 s onset. Measured `S'S` = 2.62e-10 (rad/s)^2, 8.59e-7
    /// (deg/s)^2; it grows with the onset (1e-10 at lift-off, 1.8e-9 at 130 s) as the inertia falls. So for
    /// the seed's F of 1 to 100 the prior dominates in either unit (`R S'S / v` at most 2.6e-6 in rad/s,
    /// 8.6e-3 in deg/s), and `fhat` is `R` times a correlation of the window with `S`: its shape cannot
    /// change with `R` there. The data weigh as much as the prior only from F = 1,100 in deg/s (62,000
    /// in rad/s).
    #[test]
    fn the_prior_dominates_in_rad_s_and_not_in_deg_s() {
        let design = seed_design();
        let (onsets, table) = design.sensitivity_table();
        let at = onsets.iter().position(|t| *t == 20.0).unwrap();
        let sts: f64 = table[at].iter().map(|s| s * s).sum();
        assert!((2.55e-10..2.7e-10).contains(&sts), "{sts:e}");
        let deg2 = (180.0 / std::f64::consts::PI).powi(2);
        let weight = |f: f64, v: f64| f * f * sts / v;
        assert!(weight(100.0, 1.0) < 3e-6 && weight(100.0, 1.0 / deg2) < 0.01);
        assert!(weight(1100.0, 1.0 / deg2) > 1.0 && weight(1000.0, 1.0 / deg2) < 1.0);
        let first_onset = table[0].iter().map(|s| s * s).sum::<f64>();
        let last_onset = table[table.len() - 1].iter().map(|s| s * s).sum::<f64>();
        assert!(first_onset < sts && sts < last_onset);
    }

    /// On a real noisy run with a 30 % loss, every `fhat` the detector reports from 0.5 s before to 1 s
    /// after the onset is the closed-form GLS of its own residual window, with `S` and `Y0` from the
    /// design, to 1e-12 relative (measured worst 2.1e-16).
    #[test]
    fn the_detector_fhat_is_the_closed_form_of_its_window() {
        let design = seed_design();
        let p = design.params().mhe;
        let fault = ThrustFault { engine: 0, loss_fraction: 0.3, onset_s: 25.0 };
        let trace = run(&design, Some(fault), 26.0, Some(3), None);
        let n = p.window_n + 1;
        let mut worst = 0.0f64;
        for k in 2450..trace.len() {
            let ks: Vec<usize> = (0..n).map(|j| k - p.window_n + j).collect();
            let Y: Vec<f64> = ks.iter().map(|&i| trace[i].1.residual_rad_s).collect();
            let Y0: Vec<f64> = ks.iter().map(|&i| design.nominal_residual()[i]).collect();
            let (S, clamped) = design.sensitivity_at((ks[0] - 1) as f64 * 0.01);
            assert!(!clamped);
            let reference = closed_form(&S, &Y, &Y0, &DMatrix::identity(n, n), p.R());
            worst = worst.max((trace[k].1.fhat - reference).abs() / reference.abs());
        }
        assert!(worst < 1e-12, "{worst:e}");
    }

    /// The noise-free filter model is the truth: the nominal residual is numerically zero (measured
    /// 1.7e-15 rad/s against a 1 % loss's 1.7e-6), and a unit loss's residual grows over the window.
    #[test]
    fn the_filter_model_reproduces_the_nominal_truth() {
        let design = seed_design();
        let worst = design.nominal_residual().iter().fold(0.0f64, |a, r| a.max(r.abs()));
        assert!(worst < 1e-12, "{worst:e}");
        let (onsets, S) = design.sensitivity_table();
        assert_eq!(onsets.len(), 27);
        for s in S {
            assert!(s.windows(2).all(|w| w[1] > w[0] && w[0] > 0.0), "{s:?}");
        }
    }

    /// The peak of `|fhat|` (noise-free, engine 1 at 20 s, peak over 3 s) is linear in the loss over
    /// 10-60 % in 5 % steps: R^2 > 0.99 (measured 0.99948; 5.87e-6 at 10 %, 3.23e-5 at 60 %, slightly
    /// concave: the slope falls from 5.7e-7 to 4.9e-7 per percent; fit `loss = -1.72 + 1.892e6 fhat`),
    /// and the fit gives every calibration loss back within 2 points (measured 0.62). A fault-free
    /// flight's `fhat` is numerically zero.
    #[test]
    fn fhat_peak_grows_linearly_with_the_loss() {
        let (fit, pairs) = seed_fit();
        assert!(fit.r_squared > 0.99, "{fit:?}");
        assert!(fit.slope_percent_per_fhat > 0.0);
        for (loss, peak) in pairs {
            assert!((fit.loss_percent(*peak) - loss).abs() < 2.0, "{loss}: {}", fit.loss_percent(*peak));
        }
        assert!(pairs.windows(2).all(|w| w[1].1 > w[0].1), "{pairs:?}");
        let design = seed_design();
        let none = design.peak_fhat(&LaunchVehicleConfig::default(), None, 20.0, 3.0).unwrap();
        assert!(none < 1e-15, "{none:e}");
        // Losses the fit never saw, between its points and on the other engines: within 1.5 points (measured
        // -0.41, -0.32, -1.05 on engine 2, -0.42).
        for (engine, loss) in [(0, 12.5), (2, 27.5), (1, 42.5), (3, 57.5)] {
            let fault = ThrustFault { engine, loss_fraction: loss / 100.0, onset_s: 20.0 };
            let peak = design.peak_fhat(&LaunchVehicleConfig::default(), Some(fault), 20.0, 3.0).unwrap();
            assert!(
                (fit.loss_percent(peak) - loss).abs() < 1.5,
                "{loss} % on engine {engine}: {}",
                fit.loss_percent(peak)
            );
        }
    }

    /// Each engine, on noisy flights (the seed's 30 % at 25 s, and 50 % at 50 s): no alarm before the
    /// onset; the alarm within 0.5 s (measured 0.21-0.27 s at 30 %, 0.08-0.10 s at 50 %); the onset
    /// located within 0.1 s (measured: on the onset sample in all eight); the engine named correctly
    /// (jumps measured 8.8e-3 to 1.0e-2 g at 30 %, 1.8e-2 to 2.1e-2 g at 50 %). Outside the tests, 160
    /// noisy flights per size with onsets spread over 15-75 s localised 160/160 at 20, 30 and 50 %.
    #[test]
    fn each_engine_is_localised_on_a_noisy_run() {
        let design = seed_design();
        for engine in 0..ENGINES {
            for (loss_fraction, onset_s) in [(0.3, 25.0), (0.5, 50.0)] {
                let fault = ThrustFault { engine, loss_fraction, onset_s };
                let trace = run(&design, Some(fault), onset_s + 1.0, Some(100 + engine as u64), None);
                let early = trace.iter().filter(|(m, _)| m.t_s < onset_s).any(|(_, s)| s.alarm);
                assert!(!early, "engine {engine}: alarm before the onset");
                let d = trace.last().unwrap().1.detection.expect("detected");
                assert!(d.t_s - onset_s < 0.5, "engine {engine} {loss_fraction}: {d:?}");
                assert!((d.onset_estimate_s - onset_s).abs() < 0.1, "engine {engine} {loss_fraction}: {d:?}");
                assert_eq!(d.engine, Some(engine), "{loss_fraction}: {d:?}");
            }
        }
    }

    /// Fresh fault-free noisy flights (ChaCha8 seeds 200-205, not those the threshold came from) raise no
    /// alarm in 60 s: the largest `|fhat|` is 0.66 of the threshold (measured).
    #[test]
    fn a_fault_free_noisy_flight_raises_no_alarm() {
        let design = seed_design();
        let mut worst = 0.0f64;
        for seed in 200..206 {
            let trace = run(&design, None, 60.0, Some(seed), None);
            assert!(trace.iter().all(|(_, s)| !s.alarm && s.detection.is_none()), "seed {seed}");
            worst = trace.iter().fold(worst, |a, (_, s)| a.max(s.fhat.abs()));
        }
        assert!(worst < design.params().threshold_fhat, "{worst:e}");
    }

    /// The fit from the noise-free calibration, applied to noisy flights with losses of 30, 40 and 50 % at
    /// 20 s on each engine, estimates the loss 2 s after the onset within 12 points, always too high
    /// (measured +3.95 to +9.29 points): the peak of a noisy `|fhat|` is the noise-free peak plus the
    /// largest noise excursion over the plateau (about 2.5 standard deviations of 2e-6, i.e. ~9 points at
    /// the fit's slope). A fit calibrated on noisy flights would absorb this bias.
    #[test]
    fn the_estimated_loss_follows_the_injected_one() {
        let design = seed_design();
        let (fit, _) = seed_fit();
        let (mut lowest, mut highest) = (f64::INFINITY, f64::NEG_INFINITY);
        for engine in 0..ENGINES {
            for loss in [30.0, 40.0, 50.0] {
                let fault = ThrustFault { engine, loss_fraction: loss / 100.0, onset_s: 20.0 };
                let trace = run(&design, Some(fault), 22.0, Some(300 + engine as u64), Some(*fit));
                let estimate = trace.last().unwrap().1.loss_percent.expect("detected");
                lowest = lowest.min(estimate - loss);
                highest = highest.max(estimate - loss);
            }
        }
        assert!(lowest > 0.0 && highest < 12.0, "{lowest} {highest}");
    }

    /// The same noisy flights read through a fit calibrated on noisy flights (the seed's 5 % steps, 4
    /// flights per loss with the default sensor noise, streams of seed 1): the bias is gone, the errors
    /// fall on both sides of zero and within 5 points (measured -1.8 to +3.0, mean +0.8; the noise-free
    /// fit reads the same flights +3.95 to +9.29 points high).
    #[test]
    fn a_fit_on_noisy_flights_reads_the_loss_without_the_bias() {
        let design = seed_design();
        let losses: Vec<f64> = (0..11).map(|i| 10.0 + 5.0 * i as f64).collect();
        let noise = NoisyCalibration { flights_per_loss: 4, seed: 1, first_stream: 0 };
        let (fit, pairs) =
            design.calibrate_loss_fit(&LaunchVehicleConfig::default(), 20.0, &losses, 3.0, Some(noise)).unwrap();
        assert_eq!(pairs.len(), 44);
        let (noise_free, _) = seed_fit();
        assert!(fit.loss_percent(2e-5) < noise_free.loss_percent(2e-5) - 3.0, "{fit:?} {noise_free:?}");
        let mut errors = Vec::new();
        for engine in 0..ENGINES {
            for loss in [30.0, 40.0, 50.0] {
                let fault = ThrustFault { engine, loss_fraction: loss / 100.0, onset_s: 20.0 };
                let trace = run(&design, Some(fault), 22.0, Some(300 + engine as u64), Some(fit));
                errors.push(trace.last().unwrap().1.loss_percent.expect("detected") - loss);
            }
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        assert!(errors.iter().all(|e| e.abs() < 5.0) && errors.iter().any(|e| *e < 0.0), "{errors:?}");
        assert!(mean.abs() < 2.0, "{mean}");
    }

    /// Runs the seed's N and R comparisons (50 % at 50 s, noise-free peak of `|fhat|`; fault-free `fhat`
    /// standard deviation over 5-60 s of one noisy flight) and returns (peak, fhat 5 s after the onset,
    /// noise standard deviation).
    fn compare(window_n: usize, fault_intensity: f64, window_variance: f64) -> (f64, f64, f64) {
        let (peak, late, sd, _) = compare_filters(window_n, fault_intensity, window_variance, None);
        (peak, late, sd)
    }

    /// [`compare`] with the filter's angular-acceleration biases at `moment_bias_sigma` (the plain filter
    /// when `None`); also returns the samples at which `|fhat|` is at least half its peak.
    fn compare_filters(
        window_n: usize,
        fault_intensity: f64,
        window_variance: f64,
        moment_bias_sigma: Option<f64>,
    ) -> (f64, f64, f64, usize) {
        let mut params = DetectorParams {
            mhe: MheParams { window_n, fault_intensity, window_variance, ..MheParams::seed() },
            ..DetectorParams::seed()
        };
        params.ekf.moment_bias_sigma_rad_s2_per_sqrt_s = moment_bias_sigma;
        let design = Arc::new(params.design(&LaunchVehicleConfig::default()).unwrap());
        let fault = ThrustFault { engine: 0, loss_fraction: 0.5, onset_s: 50.0 };
        let trace = run(&design, Some(fault), 55.0, None, None);
        let peak = trace.iter().filter(|(m, _)| m.t_s >= 50.0).fold(0.0f64, |a, (_, s)| a.max(s.fhat.abs()));
        let late = trace.last().unwrap().1.fhat;
        let quiet: Vec<f64> =
            run(&design, None, 60.0, Some(3), None).iter().filter(|(m, _)| m.t_s > 5.0).map(|(_, s)| s.fhat).collect();
        let sd = (quiet.iter().map(|f| f * f).sum::<f64>() / quiet.len() as f64).sqrt();
        let half = trace.iter().filter(|(m, s)| m.t_s >= 50.0 && s.fhat.abs() >= 0.5 * peak).count();
        (peak, late, sd, half)
    }

    /// The seed's N and R findings, as they come out on this model (measured numbers; the seed's do not
    /// reproduce, see the module docs):
    /// - N = 1, 5, 10 (D = 0.01 s, R = 20^2, V = I): peak-to-noise 11.9, 19.8, 27.3, i.e. a longer window
    ///   is better, not worse; and `fhat` does not "recover" for any N: 5 s after the onset it is still
    ///   0.89-0.90 of its peak, because the loss is permanent and the plain EKF has no state for its
    ///   moment, so the pitch-rate residual is a step (ramping over ~0.3 s), not a spike;
    /// - with `V = I` (residual in rad/s), `R` only scales `fhat`: `F = 50` gives exactly `(50/20)^2` the
    ///   peak of `F = 20`, with the same peak-to-noise; with `V` the residual variance (8.7e-8, a MAP
    ///   estimate), the peak grows with `R` and saturates (168 at 20^2, 241 at 50^2, 263 at 500^2 unit
    ///   faults for a 50-unit loss) while the peak-to-noise falls slightly (17.2, 15.7, 15.3); there is
    ///   no second rise.
    #[test]
    fn window_length_and_fault_intensity_as_they_come_out_here() {
        let (p1, l1, s1) = compare(1, 20.0, 1.0);
        let (p5, l5, s5) = compare(5, 20.0, 1.0);
        let (p10, l10, s10) = compare(10, 20.0, 1.0);
        assert!(p1 / s1 < p5 / s5 && p5 / s5 < p10 / s10, "{} {} {}", p1 / s1, p5 / s5, p10 / s10);
        for (late, peak) in [(l1, p1), (l5, p5), (l10, p10)] {
            assert!(late / peak > 0.8, "{late:e} {peak:e}");
        }
        let (p50, _, s50) = compare(5, 50.0, 1.0);
        assert!((p50 / p5 / 6.25 - 1.0).abs() < 1e-3, "{}", p50 / p5);
        assert!(((p50 / s50) / (p5 / s5) - 1.0).abs() < 0.02);
        let map = [20.0, 50.0, 500.0].map(|f| compare(5, f, 8.7e-8));
        assert!(map[0].0 < map[1].0 && map[1].0 < map[2].0, "{map:?}");
        assert!(map[2].0 / map[1].0 < 1.15, "{map:?}");
        assert!(map[2].0 / map[2].2 < map[0].0 / map[0].2, "{map:?}");
    }

    /// The recovering residual (issue 21.1) on the seed's N experiment (50 % at 50 s, noise-free, R = 20^2,
    /// V = I; noise from one fault-free noisy flight), with angular-acceleration biases walking at 0.1
    /// rad/s^2/sqrt(s) (this project's choice: the jump then clears within about 0.05 s, the seed's
    /// "controlled within about 10 ms" scale) and at 0.01 (clears within about 0.15 s). Measured:
    /// - the jump recovers: `fhat` 5 s after the onset is at most 1e-3 of its peak (0.9 with the plain filter);
    /// - the seed's "a smaller N loses amplitude" holds: at 0.1, peak-to-noise 0.59, 1.16, 1.17 for N = 1, 5,
    ///   10; its "a larger N recovers in fewer beats" does not: `|fhat|` stays above half its peak for
    ///   4, 5, 5 samples; at 0.01 N = 10 is best (1.60, 2.98, 4.73);
    /// - a jump that clears costs the detector most of its signal: peak-to-noise 1.16 against the plain
    ///   filter's 21.2 at N = 5;
    /// - the prior still dominates: the recovering `S` is smaller than the plain one's, so `R S'S / v`
    ///   is below 0.01 even at F = 100 in deg/s and `R` only scales `fhat`.
    #[test]
    fn the_recovering_residual_clears_and_shows_the_seeds_window_trade() {
        let fast = [1, 5, 10].map(|n| compare_filters(n, 20.0, 1.0, Some(0.1)));
        let slow = [1, 5, 10].map(|n| compare_filters(n, 20.0, 1.0, Some(0.01)));
        let plain = compare_filters(5, 20.0, 1.0, None);
        let ratio = |r: &(f64, f64, f64, usize)| r.0 / r.2;
        for r in fast.iter().chain(&slow) {
            assert!(r.1.abs() < 2e-3 * r.0, "{r:?}");
        }
        assert!(ratio(&fast[0]) < 0.6 * ratio(&fast[1]), "{fast:?}");
        assert!((ratio(&fast[2]) / ratio(&fast[1]) - 1.0).abs() < 0.05, "{fast:?}");
        assert!(fast.iter().all(|r| (3..=6).contains(&r.3)) && fast[2].3 >= fast[1].3, "{fast:?}");
        assert!(ratio(&slow[0]) < ratio(&slow[1]) && ratio(&slow[1]) < ratio(&slow[2]), "{slow:?}");
        assert!(ratio(&fast[1]) < 0.1 * ratio(&plain), "{plain:?}");

        let mut params = DetectorParams::seed();
        params.ekf.moment_bias_sigma_rad_s2_per_sqrt_s = Some(0.1);
        let design = params.design(&LaunchVehicleConfig::default()).unwrap();
        let (onsets, table) = design.sensitivity_table();
        let sts = |onset_s: f64| {
            let at = onsets.iter().position(|t| *t == onset_s).unwrap();
            table[at].iter().map(|s| s * s).sum::<f64>()
        };
        let deg2 = (180.0 / std::f64::consts::PI).powi(2);
        assert!((1.3e-11..1.42e-11).contains(&sts(20.0)) && (1.9e-11..2.07e-11).contains(&sts(50.0)));
        assert!(100.0f64.powi(2) * sts(50.0) * deg2 < 0.01, "{:e}", sts(50.0));
    }

    /// The seed's table: `n_y` alike for engines {1, 4} and {2, 3}, `n_z` for {1, 2} and {3, 4}.
    #[test]
    fn localise_follows_the_seed_table() {
        assert_eq!(localise(0.01, 0.02), Some(0));
        assert_eq!(localise(-0.01, 0.02), Some(1));
        assert_eq!(localise(-0.01, -0.02), Some(2));
        assert_eq!(localise(0.01, -0.02), Some(3));
        assert_eq!(localise(0.0, 0.02), None);
        assert_eq!(localise(f64::NAN, 0.02), None);
        let sign = |i: usize, f: fn(usize) -> f64| f(i);
        let ny = |i| expected_jump_signs(i).0;
        let nz = |i| expected_jump_signs(i).1;
        assert!(sign(1, ny) == sign(2, ny) && sign(0, ny) == sign(3, ny) && sign(0, ny) != sign(1, ny));
        assert!(sign(0, nz) == sign(1, nz) && sign(2, nz) == sign(3, nz) && sign(0, nz) != sign(2, nz));
    }

    /// Same RNG state, same outputs, bit for bit.
    #[test]
    fn same_rng_state_gives_bit_identical_outputs() {
        let design = seed_design();
        let fault = Some(ThrustFault { engine: 3, loss_fraction: 0.4, onset_s: 2.0 });
        let steps = |seed| run(&design, fault, 3.0, Some(seed), None).into_iter().map(|(_, s)| s).collect::<Vec<_>>();
        assert_eq!(steps(9), steps(9));
        assert_ne!(steps(9), steps(10));
    }

    #[test]
    fn loss_fit_recovers_an_exact_line_and_rejects_degenerate_input() {
        let pairs: Vec<(f64, f64)> = [1e-6, 2e-6, 5e-6].iter().map(|f| (3.0 + 2e6 * f, *f)).collect();
        let fit = LossFit::fit(&pairs).unwrap();
        assert!((fit.intercept_percent - 3.0).abs() < 1e-9 && (fit.slope_percent_per_fhat - 2e6).abs() < 1e-3);
        assert!((fit.r_squared - 1.0).abs() < 1e-12);
        assert_eq!(LossFit::fit(&pairs[..1]), Err(FitError::TooFewPoints(1)));
        assert_eq!(LossFit::fit(&[(10.0, 1e-6), (20.0, 1e-6)]), Err(FitError::NoSpread));
        assert_eq!(LossFit::fit(&[(10.0, f64::NAN), (20.0, 1e-6)]), Err(FitError::NonFinite));
    }

    #[test]
    fn invalid_parameters_are_design_errors() {
        let config = LaunchVehicleConfig::default();
        type Breaks = fn(&mut DetectorParams);
        let cases: [(Breaks, &str); 6] = [
            (|p| p.mhe.window_n = 0, "window_n"),
            (|p| p.mhe.fault_intensity = 0.0, "fault_intensity"),
            (|p| p.mhe.window_variance = f64::NAN, "window_variance"),
            (|p| p.mhe.reference_engine = 4, "reference_engine"),
            (|p| p.threshold_fhat = -1.0, "threshold_fhat"),
            (|p| p.localisation.pre_samples = 0, "localisation pre/post samples"),
        ];
        for (break_it, field) in cases {
            let mut p = DetectorParams::seed();
            break_it(&mut p);
            match p.design(&config) {
                Err(DesignError::Invalid { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {:?}", other.map(|_| ())),
            }
        }
    }

    /// `S` is interpolated linearly between grid onsets and clamped (and flagged) outside.
    #[test]
    fn sensitivity_interpolates_between_grid_onsets() {
        let design = seed_design();
        let (onsets, table) = design.sensitivity_table();
        let (mid, clamped) = design.sensitivity_at(0.5 * (onsets[3] + onsets[4]));
        assert!(!clamped);
        for j in 0..mid.len() {
            assert!((mid[j] - 0.5 * (table[3][j] + table[4][j])).abs() < 1e-20);
        }
        assert_eq!(design.sensitivity_at(1000.0), (table[table.len() - 1].clone(), true));
        assert_eq!(design.sensitivity_at(onsets[0]), (table[0].clone(), false));
    }
}
