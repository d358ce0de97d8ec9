//! The online detector of method 001: the residual filter, the moving window and its GLS estimate
//! `fhat`, the alarm, the loss and the engine named by the overload jumps (module docs of [`super`]).
#![allow(non_snake_case)]

use std::collections::VecDeque;
use std::sync::Arc;

use super::design::*;
use super::residual::*;
use crate::estimation::FilterHealth;
use crate::methods::thrust_loss::vehicle::{ENGINES, Measurement, expected_jump_signs};

/// The GLS estimate `fhat = (S' V^-1 S + R^-1)^-1 S' V^-1 (Y - Y0)` for `V = v I` and scalar `R`; `None`
/// when it is not finite.
pub fn gls_fault_estimate(S: &[f64], Y: &[f64], Y0: &[f64], v: f64, R: f64) -> Option<f64> {
    assert!(S.len() == Y.len() && Y.len() == Y0.len(), "window lengths differ");
    let (mut StS, mut StY) = (0.0, 0.0);
    for ((s, y), y0) in S.iter().zip(Y).zip(Y0) {
        StS += s * s;
        StY += s * (y - y0);
    }
    let fhat = (StY / v) / (StS / v + 1.0 / R);
    fhat.is_finite().then_some(fhat)
}

/// The engine (index) whose loss produces jumps of these signs (module docs of the plant); `None` when
/// either jump is exactly zero or not finite.
pub fn localise(jump_n_y_g: f64, jump_n_z_g: f64) -> Option<usize> {
    if !(jump_n_y_g.is_finite() && jump_n_z_g.is_finite()) || jump_n_y_g == 0.0 || jump_n_z_g == 0.0 {
        return None;
    }
    (0..ENGINES).find(|&i| expected_jump_signs(i) == (jump_n_y_g.signum(), jump_n_z_g.signum()))
}

/// The first alarm of a run and the engine it names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    pub k: usize,
    pub t_s: f64,
    /// The estimated onset: the sample after which the overloads step ([`LocalisationParams`]).
    pub onset_estimate_s: f64,
    pub jump_n_y_g: f64,
    pub jump_n_z_g: f64,
    /// Engine index (the seed's engine `index + 1`); `None` if a jump is zero or not finite.
    pub engine: Option<usize>,
}

/// What the detector reports at a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MheStep {
    /// `wz_measured - wz(k|k-1)` (rad/s).
    pub residual_rad_s: f64,
    /// The GLS estimate (unit faults; negative for engines 2 and 3); 0 until the window is full or when
    /// the estimate is not finite.
    pub fhat: f64,
    pub window_full: bool,
    /// `|fhat| >= threshold` at this sample.
    pub alarm: bool,
    /// The first alarm so far, if any.
    pub detection: Option<Detection>,
    /// The loss (%) from the running peak of `|fhat|` since the first alarm (needs a [`LossFit`]).
    pub loss_percent: Option<f64>,
}

/// Numerical-health counters of a run (columns of the trial records).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DetectorHealth {
    pub filter: FilterHealth,
    /// Samples whose hypothesised onset lay outside the sensitivity grid (the nearest end was used).
    pub sensitivity_clamped: u32,
    /// Samples past the end of the nominal residual (`Y0 = 0` was used).
    pub nominal_residual_missing: u32,
    /// Samples whose GLS estimate was not finite (reported as 0).
    pub gls_failed: u32,
}

/// One sample of the detector's memory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Past {
    pub(super) k: usize,
    pub(super) residual: f64,
    pub(super) n_y_g: f64,
    pub(super) n_z_g: f64,
    pub(super) fhat: f64,
}

/// Indices, in a history of `len` samples (at least `N D + 1`), of the window
/// `[x(k - N D), x(k - (N-1) D), ..., x(k)]` of the newest samples.
pub(super) fn window_indices(len: usize, mhe: &MheParams) -> impl Iterator<Item = usize> + use<> {
    let (first, n, d) = (len - mhe.span_samples(), mhe.window_n, mhe.interval_samples);
    (0..=n).map(move |j| first + j * d)
}

/// The online detector of one trial.
#[derive(Debug, Clone)]
pub struct EkfMhe {
    design: Arc<MheDesign>,
    loss_fit: Option<LossFit>,
    ekf: ResidualFilter,
    /// The latest samples, oldest first: the window, the look-back and the pre-onset average.
    history: VecDeque<Past>,
    capacity: usize,
    detection: Option<Detection>,
    peak_abs_fhat: f64,
    health: DetectorHealth,
    /// Per-sample buffers of the window's `Y`, `Y0` and `S`, kept to spare an allocation each sample.
    window_y: Vec<f64>,
    window_y0: Vec<f64>,
    window_s: Vec<f64>,
}

impl EkfMhe {
    /// A detector at lift-off (filter at the lift-off state).
    pub fn new(design: Arc<MheDesign>, loss_fit: Option<LossFit>) -> Self {
        let ekf = design.params.ekf.filter(design.x0, design.model.dt_s);
        let p = &design.params;
        let capacity = p.mhe.span_samples().max(p.localisation.max_lookback_samples + 1) + p.localisation.pre_samples;
        EkfMhe {
            design,
            loss_fit,
            ekf,
            history: VecDeque::with_capacity(capacity),
            capacity,
            detection: None,
            peak_abs_fhat: 0.0,
            health: DetectorHealth::default(),
            window_y: Vec::new(),
            window_y0: Vec::new(),
            window_s: Vec::new(),
        }
    }

    pub fn health(&self) -> DetectorHealth {
        DetectorHealth { filter: self.ekf.health(), ..self.health }
    }

    /// One sample (the plant's step k, at the design's `dt`).
    pub fn step(&mut self, m: &Measurement) -> MheStep {
        let residual_rad_s = self.ekf.pitch_rate_residual(&self.design.model, m);
        self.step_residual(m, residual_rad_s)
    }

    /// [`EkfMhe::step`] with the residual of another detector whose design has the same filter
    /// ([`MheDesign::same_residual`]): one filter serves a sweep of windows and intensities. This
    /// detector's own filter is not stepped, so its health is the other's.
    pub fn step_residual(&mut self, m: &Measurement, residual_rad_s: f64) -> MheStep {
        let design = Arc::clone(&self.design);
        let p = &design.params;
        if self.history.len() == self.capacity {
            self.history.pop_front();
        }
        self.history.push_back(Past { k: m.k, residual: residual_rad_s, n_y_g: m.n_y_g, n_z_g: m.n_z_g, fhat: 0.0 });

        let window_full = self.history.len() >= p.mhe.span_samples();
        let mut fhat = 0.0;
        if window_full {
            self.window_y.clear();
            self.window_y0.clear();
            let mut oldest_k = None;
            for i in window_indices(self.history.len(), &p.mhe) {
                let k = self.history[i].k;
                oldest_k.get_or_insert(k);
                self.window_y.push(self.history[i].residual);
                self.window_y0.push(design.nominal_residual.get(k).copied().unwrap_or_else(|| {
                    self.health.nominal_residual_missing += 1;
                    0.0
                }));
            }
            // A fault cannot begin before lift-off: the first windows hypothesise an onset at sample 0.
            let onset_s = oldest_k.unwrap_or(0).saturating_sub(1) as f64 * design.model.dt_s;
            let clamped = design.sensitivity_into(onset_s, &mut self.window_s);
            self.health.sensitivity_clamped += u32::from(clamped);
            match gls_fault_estimate(&self.window_s, &self.window_y, &self.window_y0, p.mhe.window_variance, p.mhe.R())
            {
                Some(f) => fhat = f,
                None => self.health.gls_failed += 1,
            }
        }
        if let Some(last) = self.history.back_mut() {
            last.fhat = fhat;
        }
        let alarm = window_full && fhat.abs() >= p.threshold_fhat;
        if alarm && self.detection.is_none() {
            self.detection = Some(self.localise_now(m));
        }
        if self.detection.is_some() {
            self.peak_abs_fhat = self.peak_abs_fhat.max(fhat.abs());
        }
        let loss_percent = match (&self.detection, &self.loss_fit) {
            (Some(_), Some(fit)) => Some(fit.loss_percent(self.peak_abs_fhat)),
            _ => None,
        };
        MheStep { residual_rad_s, fhat, window_full, alarm, detection: self.detection, loss_percent }
    }

    /// Onset estimate and overload jumps at the first alarm ([`LocalisationParams`]): the largest
    /// overload step among the look-back's samples that have at least one sample before and after them
    /// (fewer are averaged near the ends); NaN jumps (no engine) when the history is too short.
    fn localise_now(&self, m: &Measurement) -> Detection {
        let l = &self.design.params.localisation;
        let newest = self.history.len() - 1;
        let mean = |range: std::ops::Range<usize>, pick: fn(&Past) -> f64| {
            let len = range.len() as f64;
            range.map(|i| pick(&self.history[i])).sum::<f64>() / len
        };
        let step_after = |i: usize| {
            let pre = i.saturating_sub(l.pre_samples - 1)..i + 1;
            let post = i + 1..(i + 1 + l.post_samples).min(newest + 1);
            (
                mean(post.clone(), |s| s.n_y_g) - mean(pre.clone(), |s| s.n_y_g),
                mean(post, |s| s.n_z_g) - mean(pre, |s| s.n_z_g),
            )
        };
        let candidates = newest.saturating_sub(l.max_lookback_samples)..newest;
        let best = candidates
            .map(|i| (i, step_after(i)))
            .filter(|(_, (y, z))| y.is_finite() && z.is_finite())
            .max_by(|a, b| (a.1.0.hypot(a.1.1)).total_cmp(&b.1.0.hypot(b.1.1)));
        let (onset, (jump_n_y_g, jump_n_z_g)) = best.unwrap_or((newest, (f64::NAN, f64::NAN)));
        Detection {
            k: m.k,
            t_s: m.t_s,
            onset_estimate_s: self.history[onset].k as f64 * self.design.model.dt_s,
            jump_n_y_g,
            jump_n_z_g,
            engine: localise(jump_n_y_g, jump_n_z_g),
        }
    }
}
