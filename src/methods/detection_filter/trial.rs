//! One trial: true plant + sensor noise + faults + output-feedback loop + detectors, and the alarm logic.
//!
//! Per sample k at `t = k dt`:
//! 1. `y = C x + D r(t) + v` (healthy sensors, `v ~ N(0, diag((noise_scale sensor_sigma)^2))`), then the
//!    trial's faults;
//! 2. `u = r(t) - G y` (the excitation `r` through the output-feedback loop; validation forbids
//!    `D != 0` together with `G != 0`, which would be an algebraic loop, so `y = C x + D u` holds);
//! 3. every detector consumes the same `(u, y)`; output j of a detector alarms when `|gamma_j| > thr_j`;
//! 4. `x <- Ad x + Bd u_a + w` (`w ~ N(0, diag(process_sigma_per_step^2))`), `u_a` the inputs after
//!    the trial's actuator faults (`u` itself without any): the detectors see the command `u`, the
//!    plant gets what the faulty actuators do with it. An FMU truth gets `u_a` plus its trim, and its
//!    own fault inputs (`[truth] fault_inputs`) their healthy values or what the faults make of them.
//!
//! Detection is the first alarm at or after the fault onset; any alarm before it (or in a fault-free
//! trial) is a false alarm. Isolation averages the residual over
//! `[t_detect + isolation_delay_s, + isolation_window_s)` and names an output two ways (see
//! `DetectionFilter::isolate_by_max` and `isolate_by_direction`).
//!
//! So that any threshold can be evaluated afterwards without re-simulating, each detector also keeps,
//! per output, the largest statistic before the onset and the first-passage profile after it
//! ([`FirstPassage`]: the first post-onset sample, a point each time the running maximum passes a level
//! of the deck's profile grid, and the final maximum). For a threshold `thr`, the alarm time is the
//! first kept point with `v > thr`: exact whether an alarm happens, and at most as late as the running
//! maximum takes to pass the grid level above `thr`.

use nalgebra::DVector;
use rand::RngExt;
use rand_distr::StandardNormal;

use crate::engine::rare_event::estimators::Condition;
use crate::engine::scenario::noise::{NoiseRng, TailScales};
use crate::engine::scenario::streams::{Substream, noise_rng, tail_scales};
use crate::fault::ActiveFaults;
use crate::fmu::FmuError;
use crate::methods::detection_filter::filter::DetectionFilter;
use crate::methods::detection_filter::scenario::TrialSpec;
use crate::methods::detection_filter::study::{LtiStudy, Perturbs};

use super::decision::TestState;
use super::kernel::{FilterState, FilterStep, PlantState, PlantStep};
use crate::engine::run::output::Trace;

use crate::engine::results::schema::{ExactDelays, FirstPassage, ProfileGrid};

/// What one detector made of one trial, in compact form.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DetectorOutcome {
    /// Largest |residual| per output before the onset (over the whole trial when fault-free).
    pub pre_onset_max_abs_residual: Vec<f64>,
    /// Per output: the post-onset first-passage profile, times (s) and running-maximum values.
    pub profile_t_s: Vec<Vec<f64>>,
    pub profile_value: Vec<Vec<f64>>,
    /// First alarm before the onset, and the output that raised it (deck thresholds).
    pub false_alarm: Option<(f64, usize)>,
    /// First alarm at or after the onset, and the output that raised it (deck thresholds).
    pub detection: Option<(f64, usize)>,
    pub isolated_by_max: Option<usize>,
    pub isolated_by_direction: Option<usize>,
    /// A residual became non-finite: the filter diverged; statistics stop at that sample.
    pub diverged_at_s: Option<f64>,
}

/// Per-detector bookkeeping during a trial.
struct Tracker {
    out: DetectorOutcome,
    thresholds: DVector<f64>,
    first_passage: Vec<FirstPassage>,
    iso_sum: DVector<f64>,
    iso_count: usize,
    iso_window: Option<(f64, f64)>,
    isolation: (f64, f64),
    /// The residual test's memory and this sample's statistics.
    test: Box<dyn TestState>,
    statistic: Vec<f64>,
    /// The test names the output itself (a detector FMU): what it named last in the isolation window.
    isolates: bool,
    named: Option<usize>,
}

impl Tracker {
    fn new(filter: &DetectionFilter, ny: usize, dt_s: f64, grid: ProfileGrid, exact: ExactDelays) -> Self {
        Tracker {
            out: DetectorOutcome {
                pre_onset_max_abs_residual: vec![0.0; ny],
                profile_t_s: vec![Vec::new(); ny],
                profile_value: vec![Vec::new(); ny],
                ..Default::default()
            },
            thresholds: filter.thresholds.clone(),
            first_passage: vec![FirstPassage::with_exact_delays(grid, exact); ny],
            iso_sum: DVector::zeros(ny),
            iso_count: 0,
            iso_window: None,
            isolation: (filter.isolation_delay_s, filter.isolation_window_s),
            test: filter.decision.start(ny, dt_s),
            statistic: vec![0.0; ny],
            isolates: filter.decision.isolates(),
            named: None,
        }
    }

    fn observe(&mut self, t: f64, after_onset: bool, u: &[f64], residual: &[f64]) {
        if self.out.diverged_at_s.is_some() {
            return;
        }
        if residual.iter().any(|r| !r.is_finite()) {
            self.out.diverged_at_s = Some(t);
            return;
        }
        self.test.inputs(u);
        self.test.step(residual, &mut self.statistic);
        // A statistic that overflows from a finite residual (the Kalman test's r' S^-1 r) has diverged
        // as the filter has.
        if self.statistic.iter().any(|a| !a.is_finite()) {
            self.out.diverged_at_s = Some(t);
            return;
        }
        let mut alarm_channel = None;
        for j in 0..residual.len() {
            let a = self.statistic[j];
            if after_onset {
                self.first_passage[j].observe(t, a, &mut self.out.profile_t_s[j], &mut self.out.profile_value[j]);
            } else if a > self.out.pre_onset_max_abs_residual[j] {
                self.out.pre_onset_max_abs_residual[j] = a;
            }
            if a > self.thresholds[j] && alarm_channel.is_none() {
                alarm_channel = Some(j);
            }
        }
        if let Some(j) = alarm_channel {
            if !after_onset {
                self.out.false_alarm.get_or_insert((t, j));
            } else if self.out.detection.is_none() {
                self.out.detection = Some((t, j));
                let start = t + self.isolation.0;
                self.iso_window = Some((start, start + self.isolation.1));
            }
        }
        if let Some((start, end)) = self.iso_window
            && t >= start
            && t < end
        {
            for (sum, r) in self.iso_sum.iter_mut().zip(residual) {
                *sum += r;
            }
            self.iso_count += 1;
            if self.isolates {
                self.named = self.test.isolated();
            }
        }
    }

    fn finish(mut self, filter: &DetectionFilter) -> DetectorOutcome {
        for (j, fp) in self.first_passage.iter().enumerate() {
            fp.close(&mut self.out.profile_t_s[j], &mut self.out.profile_value[j]);
        }
        if self.iso_count > 0 && self.isolates {
            (self.out.isolated_by_max, self.out.isolated_by_direction) = (self.named, self.named);
        } else if self.iso_count > 0 {
            let mean = &self.iso_sum / self.iso_count as f64;
            self.out.isolated_by_max = Some(filter.isolate_by_max(&mean));
            self.out.isolated_by_direction = Some(filter.isolate_by_direction(&mean));
        }
        self.out
    }
}

/// Runs trial `spec` on the sampled true plant `plant` with every filter in `filters` (a design and
/// its products, started at the study's initial state): the general, one-trial path. `trace`, if
/// given, receives every sample of `filters[0]`. [`super::lanes`] computes the same numbers for several
/// trials at once.
pub fn run_trial(
    study: &LtiStudy,
    plant: &PlantStep,
    spec: &TrialSpec,
    filters: &[(&DetectionFilter, FilterStep)],
    trace: Option<&mut Trace>,
) -> Result<Vec<DetectorOutcome>, FmuFailure> {
    let s = study;
    let (n, nu, ny) = (s.plant.n_states(), s.plant.n_inputs(), s.plant.n_outputs());
    let mut sensor_rng = noise_rng(s.header.seed, spec.noise_trial, Substream::SensorNoise);
    let mut process_rng = noise_rng(s.header.seed, spec.noise_trial, Substream::ProcessNoise);
    let mut tails = tail_scales(&s.sensor_law, s.header.seed, spec.noise_trial);
    let has_process_noise = s.has_process_noise();
    let sensor_sigma = &s.sensor_sigma * spec.noise_scale;

    let mut faults = ActiveFaults::new(spec.fault.faults.clone());
    let onset_s = (spec.fault.onset_s.is_finite()).then_some(spec.fault.onset_s);
    // The failing inputs' values as applied: the plant's inputs, then the FMU's own fault inputs.
    let mut actuators = (!spec.fault.actuators.is_empty()).then(|| {
        let mut applied = vec![0.0; nu];
        applied.extend(s.truth.iter().flat_map(|t| t.fault_inputs.iter().map(|f| f.1)));
        (ActiveFaults::new(spec.fault.actuators.clone()), applied)
    });
    let x0 = s.initial_state.as_slice();
    let mut plant_state = PlantState::new(x0, nu);
    let mut y = vec![0.0; ny];
    let mut states: Vec<FilterState<f64>> = filters.iter().map(|_| FilterState::new(x0, nu, ny)).collect();
    let mut trackers: Vec<Tracker> = filters
        .iter()
        .map(|(design, _)| Tracker::new(design, ny, s.header.dt_s, s.monte_carlo.common.profile, spec.exact_delays(s)))
        .collect();
    let mut rec = trace.map(|t| TraceWriter::new(t, s, n));
    // An FMU truth flies instead of the LTI plant, which then only closes the loop (`u = r - G y`).
    let mut flight = match &s.truth {
        Some(truth) => Some(truth.start(&fmu_parameter_errors(s, spec)).map_err(FmuFailure::truth)?),
        None => None,
    };
    let mut controller = match &s.controller_fmu {
        Some(c) => Some((
            c,
            c.fmu.start(&[]).map_err(FmuFailure::controller)?,
            vec![0.0; c.fmu.input_vrs.len()],
            vec![0.0; c.drives.len()],
        )),
        None => None,
    };

    // What the deck's linear plant predicts for the FMU truth's inputs, and its largest magnitude per
    // output so far: a truth that strays far from it is no trajectory (`FmuPlant::strays`). Not in a
    // trial that fails an FMU fault input, which the linear plant does not have.
    let mut linear = match &s.truth {
        Some(t) if t.stray_factor.is_finite() && spec.fault.actuators.iter().all(|f| f.channel < nu) => {
            Some((PlantState::new(x0, nu), vec![0.0; ny], vec![0.0f64; ny]))
        }
        _ => None,
    };
    let diverged = |t: f64, why: String| FmuFailure {
        role: "truth".into(),
        error: FmuError::Failed(format!("diverged at t = {t} s: {why}")),
        diverged_at_s: Some(t),
    };

    // The samples flown, in a closure so that a failing trial's trace keeps what it flew.
    let flown = (|| -> Result<(), FmuFailure> {
        for k in 0..s.header.steps {
            let t = k as f64 * s.header.dt_s;
            match flight.as_mut() {
                None => measure(
                    s,
                    plant,
                    &mut plant_state,
                    t,
                    sensor_sigma.as_slice(),
                    &mut sensor_rng,
                    tails.as_mut(),
                    &mut y,
                    None,
                ),
                Some(f) => {
                    // The outputs at sample k see the inputs at k, as the linear truth's `D r` does: the
                    // loop's reference (the feedback and actuator faults act on the step, which avoids
                    // an algebraic loop). Read before setting them, a feedthrough would lag a sample.
                    reference(s, &mut plant_state, t);
                    f.set_inputs(plant_state.reference()).map_err(FmuFailure::truth)?;
                    f.outputs(&mut y).map_err(FmuFailure::truth)?;
                    if let Some(why) = f.plant().beyond(&y) {
                        return Err(diverged(t, why));
                    }
                    if let Some((state, y_lin, peak)) = linear.as_mut() {
                        reference(s, state, t);
                        plant.measure(state, y_lin);
                        peak.iter_mut().zip(y_lin.iter()).for_each(|(p, v)| *p = p.max(v.abs()));
                        if let Some(why) = f.plant().strays(&y, y_lin, peak) {
                            return Err(diverged(t, why));
                        }
                    }
                    add_sensor_noise(&mut y, sensor_sigma.as_slice(), &mut sensor_rng, tails.as_mut(), None);
                }
            }
            faults.apply(t, &mut y);
            match controller.as_mut() {
                None => plant.close_loop(&mut plant_state, &y),
                Some((c, ctrl, inputs, outputs)) => {
                    // Its inputs: the measured outputs (the FMU gets them plus the output trims), then the
                    // commands (the excitation, no trim). Its outputs (absolute) drive their plant inputs,
                    // the others take their excitation.
                    let (r, u) = plant_state.reference_and_inputs_mut();
                    for (k, &j) in c.measured.iter().enumerate() {
                        inputs[k] = y[j];
                    }
                    for (k, &j) in c.commands.iter().enumerate() {
                        inputs[c.measured.len() + k] = r[j];
                    }
                    ctrl.set_inputs(inputs).map_err(FmuFailure::controller)?;
                    ctrl.outputs(outputs).map_err(FmuFailure::controller)?;
                    u.copy_from_slice(r);
                    for (&j, v) in c.drives.iter().zip(outputs.iter()) {
                        u[j] = v - c.plant_input_trim[j];
                    }
                }
            }
            let u = plant_state.inputs();

            let after_onset = onset_s.is_some_and(|t0| t >= t0);
            for (i, ((_, filter), (state, tracker))) in
                filters.iter().zip(states.iter_mut().zip(trackers.iter_mut())).enumerate()
            {
                if i == 0
                    && let Some(rec) = rec.as_mut()
                {
                    rec.before_step(t, u, &y, state.estimate());
                }
                filter.step(state, u, &y);
                tracker.observe(t, after_onset, u, state.residual());
                if let Some(why) = tracker.test.failure() {
                    return Err(FmuFailure {
                        role: "detector".into(),
                        error: FmuError::Failed(why),
                        diverged_at_s: None,
                    });
                }
                if i == 0
                    && let Some(rec) = rec.as_mut()
                {
                    rec.after_step(state.residual(), &tracker.statistic, &tracker.thresholds);
                }
            }

            if let Some((faults, applied)) = actuators.as_mut() {
                let (_, u) = plant_state.reference_and_inputs_mut();
                applied[..nu].copy_from_slice(u);
                faults.apply(t, applied);
                u.copy_from_slice(&applied[..nu]);
                if let Some(f) = flight.as_mut() {
                    f.set_fault_inputs(&applied[nu..]).map_err(FmuFailure::truth)?;
                }
            }
            match flight.as_mut() {
                None => advance(s, plant, &mut plant_state, &mut process_rng, has_process_noise),
                Some(f) => {
                    if let Some((state, _, _)) = linear.as_mut() {
                        state.reference_and_inputs_mut().1.copy_from_slice(plant_state.inputs());
                        plant.advance(state, |_| {});
                    }
                    f.step(t, s.header.dt_s, plant_state.inputs()).map_err(FmuFailure::truth)?
                }
            }
            if let Some((_, ctrl, _, _)) = controller.as_mut() {
                ctrl.advance(t, s.header.dt_s).map_err(FmuFailure::controller)?;
            }
        }
        Ok(())
    })();
    if let Some(rec) = rec {
        rec.finish();
    }
    flown?;
    Ok(trackers.into_iter().zip(filters).map(|(tr, (design, _))| tr.finish(design)).collect())
}

/// An FMU of the trial returned an error: which one (`truth`, `controller`, `detector`; the message
/// names the FMU's file) and what it said. The trial fails, every detector with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the FMU {role} failed: {error}")]
pub struct FmuFailure {
    pub role: String,
    pub error: FmuError,
    /// The truth's trajectory diverged or left its physical range at this time: the trial is not data.
    pub diverged_at_s: Option<f64>,
}

impl FmuFailure {
    fn truth(error: FmuError) -> Self {
        FmuFailure { role: "truth".into(), error, diverged_at_s: None }
    }

    fn controller(error: FmuError) -> Self {
        FmuFailure { role: "controller".into(), error, diverged_at_s: None }
    }
}

/// The trial's parameter errors on the FMU truth's parameters: (value reference, perturbed value).
fn fmu_parameter_errors(s: &LtiStudy, spec: &TrialSpec) -> Vec<(u32, f64)> {
    let mut out = Vec::new();
    for (pe, &value) in s.monte_carlo.parameter_errors.iter().zip(&spec.parameter_errors) {
        if let Perturbs::FmuParameters(list) = &pe.what {
            out.extend(
                list.iter()
                    .map(|&(vr, nominal)| (vr, if pe.absolute { nominal + value } else { nominal * (1.0 + value) })),
            );
        }
    }
    out
}

/// Sample `k`'s measurement at `t = k dt`: the excitation into the reference, `y = C x + D r`, then
/// each output's sensor noise `sigma_j z_j`, `z_j` standard normal. Under importance sampling (`rare`:
/// the sample's condition if it has one, and where to write the `z_j`) the draws go through the
/// condition first.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn measure(
    s: &LtiStudy,
    plant: &PlantStep,
    state: &mut PlantState<f64>,
    t: f64,
    sensor_sigma: &[f64],
    rng: &mut NoiseRng,
    tails: Option<&mut TailScales>,
    y: &mut [f64],
    rare: Option<(Option<&Condition>, &mut [f64])>,
) {
    reference(s, state, t);
    plant.measure(state, y);
    add_sensor_noise(y, sensor_sigma, rng, tails, rare);
}

/// The excitation at `t` into the loop's reference `r`.
#[inline]
fn reference(s: &LtiStudy, state: &mut PlantState<f64>, t: f64) {
    let r = state.reference_mut();
    r.fill(0.0);
    for e in &s.excitations {
        r[e.input] += e.value(t);
    }
}

/// Each output's sensor noise `sigma_j z_j`, `z_j` standard normal (times its channel's scale draw
/// where `tails` makes it Student-t), added to `y`.
#[inline]
fn add_sensor_noise(
    y: &mut [f64],
    sensor_sigma: &[f64],
    rng: &mut NoiseRng,
    tails: Option<&mut TailScales>,
    rare: Option<(Option<&Condition>, &mut [f64])>,
) {
    match (rare, tails) {
        (None, None) => {
            for (yj, sigma) in y.iter_mut().zip(sensor_sigma) {
                *yj += sigma * rng.sample::<f64, _>(StandardNormal);
            }
        }
        (None, Some(tails)) => {
            for (j, (yj, sigma)) in y.iter_mut().zip(sensor_sigma).enumerate() {
                let z = rng.sample::<f64, _>(StandardNormal);
                *yj += sigma * tails.shape(j, z);
            }
        }
        // Importance sampling tilts Gaussian draws: the rare-event command refuses other laws.
        (Some(_), Some(_)) => unreachable!("rare-event runs refuse non-Gaussian sensor noise"),
        (Some((condition, draws)), None) => {
            draws.iter_mut().for_each(|z| *z = rng.sample::<f64, _>(StandardNormal));
            if let Some(c) = condition {
                c.apply(draws);
            }
            for ((yj, sigma), z) in y.iter_mut().zip(sensor_sigma).zip(draws.iter()) {
                *yj += sigma * z;
            }
        }
    }
}

/// The plant's step to the next sample, with process noise when the deck has any.
#[inline]
pub(super) fn advance(
    s: &LtiStudy,
    plant: &PlantStep,
    state: &mut PlantState<f64>,
    rng: &mut NoiseRng,
    process_noise: bool,
) {
    plant.advance(state, |x_next| {
        if process_noise {
            for (xi, sigma) in x_next.iter_mut().zip(s.process_sigma_per_step.as_slice()) {
                *xi += sigma * rng.sample::<f64, _>(StandardNormal);
            }
        }
    });
}

/// Collects trace columns: `t_s`, `u_<input>`, `y_<output>` (measured), `yhat_<output>`,
/// `xhat_<state>`, `r_<output>` (residual), `stat_<output>` (the residual test's statistic),
/// `alarm_<output>`.
struct TraceWriter<'t> {
    trace: &'t mut Trace,
    t: Vec<f64>,
    u: Vec<Vec<f64>>,
    y: Vec<Vec<f64>>,
    yhat: Vec<Vec<f64>>,
    xhat: Vec<Vec<f64>>,
    r: Vec<Vec<f64>>,
    /// The residual test's statistic (`|r|` for the seed's test).
    stat: Vec<Vec<f64>>,
    alarm: Vec<Vec<bool>>,
    names: (Vec<String>, Vec<String>, Vec<String>),
    last_y: Vec<f64>,
}

impl<'t> TraceWriter<'t> {
    fn new(trace: &'t mut Trace, s: &LtiStudy, n: usize) -> Self {
        let p = &s.plant;
        let cols = |k: usize| vec![Vec::with_capacity(s.header.steps); k];
        TraceWriter {
            trace,
            t: Vec::with_capacity(s.header.steps),
            u: cols(p.n_inputs()),
            y: cols(p.n_outputs()),
            yhat: cols(p.n_outputs()),
            xhat: cols(n),
            r: cols(p.n_outputs()),
            stat: cols(p.n_outputs()),
            alarm: cols(p.n_outputs()).into_iter().map(|_| Vec::with_capacity(s.header.steps)).collect(),
            names: (p.input_names.clone(), p.output_names.clone(), p.state_names.clone()),
            last_y: vec![0.0; p.n_outputs()],
        }
    }

    fn before_step(&mut self, t: f64, u: &[f64], y: &[f64], xhat: &[f64]) {
        self.t.push(t);
        for (col, v) in self.u.iter_mut().zip(u.iter()) {
            col.push(*v);
        }
        for (col, v) in self.y.iter_mut().zip(y.iter()) {
            col.push(*v);
        }
        for (col, v) in self.xhat.iter_mut().zip(xhat.iter()) {
            col.push(*v);
        }
        self.last_y.copy_from_slice(y);
    }

    fn after_step(&mut self, residual: &[f64], statistic: &[f64], thresholds: &DVector<f64>) {
        for j in 0..residual.len() {
            self.r[j].push(residual[j]);
            self.yhat[j].push(self.last_y[j] - residual[j]);
            self.stat[j].push(statistic[j]);
            self.alarm[j].push(statistic[j] > thresholds[j]);
        }
    }

    /// Writes the columns, each cut to the samples completed (a trial that failed mid-sample).
    fn finish(mut self) {
        let done = self.r.first().map_or(self.t.len(), Vec::len);
        self.t.truncate(done);
        for c in self.u.iter_mut().chain(&mut self.y).chain(&mut self.yhat).chain(&mut self.xhat) {
            c.truncate(done);
        }
        let (inputs, outputs, states) = self.names;
        let tr = self.trace;
        tr.float_columns.push(("t_s".into(), self.t));
        let named = |prefix: &str, names: &[String], cols: Vec<Vec<f64>>| {
            names.iter().map(|n| format!("{prefix}_{n}")).zip(cols).collect::<Vec<_>>()
        };
        tr.float_columns.extend(named("u", &inputs, self.u));
        tr.float_columns.extend(named("y", &outputs, self.y));
        tr.float_columns.extend(named("yhat", &outputs, self.yhat));
        tr.float_columns.extend(named("xhat", &states, self.xhat));
        tr.float_columns.extend(named("r", &outputs, self.r));
        tr.float_columns.extend(named("stat", &outputs, self.stat));
        tr.bool_columns.extend(outputs.iter().map(|n| format!("alarm_{n}")).zip(self.alarm));
    }
}

#[cfg(test)]
mod tests {
    use super::super::filter::Gain;
    use super::super::trials::Engine;
    use super::*;
    use crate::engine::scenario::deck::FromDeck;
    use std::path::Path;

    const SEED000: &str = include_str!("../../../studies/seed000_pitch_rate.toml");

    fn seed000(faults: bool) -> LtiStudy {
        let mut s = LtiStudy::from_toml(SEED000, Path::new("studies/seed000_pitch_rate.toml")).unwrap();
        if !faults {
            s.faults.clear();
        }
        s
    }

    fn column<'t>(trace: &'t Trace, name: &str) -> &'t [f64] {
        &trace.float_columns.iter().find(|(n, _)| n == name).unwrap().1
    }

    fn stats(v: &[f64]) -> (f64, f64) {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
        (mean, var.sqrt())
    }

    fn run(study: &LtiStudy, trial: u64) -> (DetectorOutcome, Trace) {
        let mut trace = Trace::default();
        let (_, out) = Engine::new(study).simulate(trial, 0, &mut trace).unwrap();
        (out, trace)
    }

    #[test]
    fn pitch_rate_bias_moves_pitch_rate_residual_by_about_its_size() {
        let study = seed000(true);
        let (out, trace) = run(&study, 0);
        let filter = study.detectors[0].params.design(&study.design_plant, study.header.dt_s).unwrap();
        let q = 2;
        let r_q = column(&trace, "r_q_rad_s");
        // Before the fault: noise only. After the transient (slowest mode e^{-t}, 5 s = 0.7 %): shifted.
        let (before, _) = stats(&r_q[100..1000]);
        let (after, _) = stats(&r_q[1500..]);
        let expected = 0.1 * filter.signatures[(q, q)];
        // Discrete steady-state signature: 0.988 (the continuous analysis gives 1 + 0.0241 / 3 = 1.008;
        // K's tiny (q, q) entry makes the second-order ZOH terms visible).
        assert!((0.985..0.991).contains(&filter.signatures[(q, q)]), "signature {}", filter.signatures[(q, q)]);
        // The continuous design's signature, S_c = I + C (A - K C)^-1 K (bias b: e' = (A - K C) e - K b,
        // r = C e + b), from the gain alone: its (q, q) entry is the closed form 1 + 0.0241 / 3.
        let (p, k) = (&study.design_plant, &filter.continuous.as_ref().unwrap().K);
        let closed = (&p.A - k * &p.C).try_inverse().unwrap();
        let s_c = nalgebra::DMatrix::<f64>::identity(6, 6) + &p.C * closed * k;
        assert!((s_c[(q, q)] - (1.0 + 0.0241 / 3.0)).abs() < 1e-9, "continuous signature {}", s_c[(q, q)]);
        assert!(before.abs() < 0.002, "pre-fault mean {before}");
        assert!((after - expected).abs() < 0.002, "post-fault mean {after}, expected {expected}");
        // Detected right at the onset on the pitch-rate channel, no false alarm, isolated to q.
        let (t, j) = out.detection.unwrap();
        assert!((10.0..10.05).contains(&t) && j == q, "detection {t} on {j}");
        assert_eq!(out.false_alarm, None);
        // The signature direction names the pitch-rate sensor. The largest threshold-scaled residual does
        // not: the flight-path-angle residual moves by about -0.1 too, against a 0.01 rad threshold.
        assert_eq!(out.isolated_by_direction, Some(q));
        assert_eq!(out.isolated_by_max, Some(4));
        assert!((filter.signatures[(4, q)] + 0.99).abs() < 0.03, "gamma signature {}", filter.signatures[(4, q)]);
    }

    #[test]
    fn fault_free_residual_stays_at_noise_level() {
        let study = seed000(false);
        let (out, trace) = run(&study, 3);
        let sigma_q = study.sensor_sigma[2];
        assert!(Engine::new(&study).spec(3).fault.faults.is_empty());
        let r = column(&trace, "r_q_rad_s");
        let (mean, sd) = stats(r);
        // Zero mean within 4 standard errors; the residual is coloured by the filter, so the error of
        // its mean is that of n (1 - rho) / (1 + rho) independent samples (rho: lag-1 autocorrelation).
        let rho = r.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum::<f64>() / (sd * sd * (r.len() - 1) as f64);
        let n_eff = r.len() as f64 * (1.0 - rho) / (1.0 + rho);
        assert!(mean.abs() < 4.0 * sd / n_eff.sqrt(), "mean {mean}, sd {sd}, rho {rho}");
        // Its spread is the residual's law from the design's matrices (`false_alarms::residual_law`,
        // independent of the simulated loop), averaged over the trial's samples; within 4 standard errors of a sample
        // standard deviation of n_eff samples, sd / sqrt(2 n_eff) (about +-8 % here).
        let engine = Engine::new(&study);
        let f = engine.nominal_filters()[0].as_ref().unwrap();
        let (_, law) = super::super::false_alarms::residual_law(
            &f.model.Ad,
            &f.discrete.K,
            &f.model.C,
            &study.sensor_sigma,
            &study.process_sigma_per_step,
            r.len(),
        );
        let var_sum: f64 = law.iter().map(|sd| sd[2] * sd[2]).sum();
        let expected = (var_sum / r.len() as f64).sqrt();
        // The filter's feedback adds a little to the sensor noise (0.5 % here).
        assert!((1.0..1.01).contains(&(expected / sigma_q)), "{expected} vs sensor sigma {sigma_q}");
        let tolerance = 4.0 * expected / (2.0 * n_eff).sqrt();
        assert!((sd - expected).abs() < tolerance, "sd {sd} vs {expected} +- {tolerance} (sensor sigma {sigma_q})");
        assert!(out.profile_t_s.iter().all(Vec::is_empty), "no onset, no profile");
        assert_eq!(out.detection, None);
        assert_eq!(out.false_alarm, None);
        assert!(out.pre_onset_max_abs_residual[2] < study.detectors[0].params.thresholds[2]);
    }

    #[test]
    fn same_trial_same_numbers_other_trial_other_noise() {
        let study = seed000(true);
        let (a, ta) = run(&study, 5);
        let (b, tb) = run(&study, 5);
        let (_, tc) = run(&study, 6);
        assert_eq!(a, b);
        assert_eq!(column(&ta, "r_q_rad_s"), column(&tb, "r_q_rad_s"));
        assert_ne!(column(&ta, "r_q_rad_s"), column(&tc, "r_q_rad_s"));
    }

    #[test]
    fn without_trace_and_beside_other_detectors_the_outcome_is_the_same() {
        let mut study = seed000(true);
        let mut other = study.detectors[0].clone();
        other.name = "fast".into();
        let Gain::Eigenstructure { eigenvalues_per_s, .. } = &mut other.params.gain else { panic!("the seed's gain") };
        *eigenvalues_per_s = vec![-2.0, -4.0, -6.0, -8.0, -10.0];
        study.detectors.insert(0, other);
        let mut trace = Trace::default();
        let (_, alone) = Engine::new(&study).simulate(9, 1, &mut trace).unwrap();
        let together = Engine::new(&study).run(9);
        assert_eq!(together.detectors[1].as_ref().unwrap(), &alone);
        assert_ne!(together.detectors[0].as_ref().unwrap(), &alone, "another design, another residual");
    }

    #[test]
    fn first_passage_profile_gives_the_alarm_time_of_any_threshold() {
        let study = seed000(true);
        let (out, trace) = run(&study, 2);
        let r_q = column(&trace, "r_q_rad_s");
        let t_s = column(&trace, "t_s");
        let (pt, pv) = (&out.profile_t_s[2], &out.profile_value[2]);
        assert!(pv.windows(2).all(|w| w[1] > w[0]) && pt.windows(2).all(|w| w[1] >= w[0]));
        let post: Vec<(f64, f64)> =
            t_s.iter().zip(r_q).filter(|(t, _)| **t >= 10.0).map(|(t, r)| (*t, r.abs())).collect();
        let post_max = post.iter().map(|p| p.1).fold(0.0, f64::max);
        assert_eq!(*pv.last().unwrap(), post_max, "the profile ends at the post-onset maximum");
        for thr in [0.01, 0.05, 0.09, 0.1, 0.105, 0.11, 0.2] {
            let exact = post.iter().find(|(_, a)| *a > thr).map(|p| p.0);
            let from_profile = pt.iter().zip(pv).find(|(_, v)| **v > thr).map(|(t, _)| *t);
            assert_eq!(exact.is_some(), from_profile.is_some(), "threshold {thr}");
            if let (Some(e), Some(p)) = (exact, from_profile) {
                // Never earlier than the truth; later only while the running maximum is still below the
                // grid level above the threshold.
                let before_p = post.iter().filter(|q| q.0 < p).map(|q| q.1).fold(0.0, f64::max);
                let step = study.monte_carlo.common.profile.step();
                assert!(
                    p >= e && (p == e || before_p <= thr * (1.0 + step) * (1.0 + 1e-12)),
                    "threshold {thr}: exact {e}, profile {p}"
                );
            }
        }
    }
}
