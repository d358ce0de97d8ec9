//! The lane path: up to [`LANES`] trials advanced together, every per-step quantity stored lane-wise
//! (`[f64; LANES]`), so the products, noise scaling and alarm bookkeeping compile to vector
//! instructions (AVX2 when the CPU has it, chosen at run time).
//!
//! It computes exactly what the one-trial path ([`run_trial`](crate::methods::detection_filter::trial::run_trial)) computes for each of
//! its trials: the same operations in the same order per lane, each lane drawing from its own trial's
//! streams (a test compares the records of whole studies). Only the bookkeeping is arranged
//! differently, so that the common step (no new alarm, no new profile point) costs a few compares
//! per output:
//! - one running maximum per output serves as the pre-onset maximum until the onset and as the
//!   first-passage running maximum after it;
//! - a threshold is "armed" (finite) only while its alarm is still to be recorded (the first false
//!   alarm before the onset, the detection after it), and the next profile point has its level
//!   precomputed, so a lane leaves the vector loop only when something is recorded;
//! - a lane whose residual turns non-finite freezes its statistics, as the one-trial path stops them.

use nalgebra::DVector;

use crate::engine::results::schema::{ExactDelays, NO_LEVEL, ProfileGrid, close_profile, keep_exact};
use crate::engine::scenario::streams::{Substream, noise_rng};
use crate::fault::ActiveFaults;
use crate::methods::detection_filter::decision::{Decision, LaneStatistic};
use crate::methods::detection_filter::filter::{DetectionFilter, DetectionFilterParams};
use crate::methods::detection_filter::kernel::{FilterState, LANES, Lane, LaneFilter, LanePlant, PlantState, Vectors};
use crate::methods::detection_filter::normals::LaneNormals;
use crate::methods::detection_filter::scenario::TrialSpec;
use crate::methods::detection_filter::study::LtiStudy;
use crate::methods::detection_filter::trial::DetectorOutcome;

/// One detector configuration on a group of lanes: its products and per-lane designs (`None`: no
/// design for that lane, or an idle lane; such lanes get no outcome).
pub(super) struct LaneDetector<'f> {
    pub filter: &'f LaneFilter,
    pub designs: [Option<&'f DetectionFilter>; LANES],
    pub params: &'f DetectionFilterParams,
}

/// Runs the trials `specs` (1 to [`LANES`]) on the true plants `plant` with every detector.
/// Returns, per detector, one entry per trial in `specs`.
pub(super) fn run_lanes(
    study: &LtiStudy,
    plant: &LanePlant,
    specs: &[TrialSpec],
    detectors: &[LaneDetector],
) -> Vec<Vec<Option<DetectorOutcome>>> {
    assert!((1..=LANES).contains(&specs.len()), "a lane group holds 1 to {LANES} trials");
    #[cfg(target_arch = "x86_64")]
    match Vectors::current() {
        // SAFETY: `detect` names a form only when the CPU has its features.
        Vectors::Avx512 => return unsafe { run_avx512(study, plant, specs, detectors) },
        // SAFETY: as above.
        Vectors::Avx2 => return unsafe { run_avx2(study, plant, specs, detectors) },
        Vectors::Scalar => {}
    }
    run_lanes_in(study, plant, specs, detectors)
}

/// The lane loops with 512-bit vectors: a lane group's quantity in two registers instead of four.
/// The same operations (Rust never fuses a multiply and an add), so the same numbers as AVX2's.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn run_avx512(
    study: &LtiStudy,
    plant: &LanePlant,
    specs: &[TrialSpec],
    detectors: &[LaneDetector],
) -> Vec<Vec<Option<DetectorOutcome>>> {
    run_lanes_in(study, plant, specs, detectors)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn run_avx2(
    study: &LtiStudy,
    plant: &LanePlant,
    specs: &[TrialSpec],
    detectors: &[LaneDetector],
) -> Vec<Vec<Option<DetectorOutcome>>> {
    run_lanes_in(study, plant, specs, detectors)
}

#[inline(always)]
fn run_lanes_in(
    study: &LtiStudy,
    plant: &LanePlant,
    specs: &[TrialSpec],
    detectors: &[LaneDetector],
) -> Vec<Vec<Option<DetectorOutcome>>> {
    let s = study;
    let (n, nu, ny) = (s.plant.n_states(), s.plant.n_inputs(), s.plant.n_outputs());
    // Idle lanes repeat the last trial; their results are dropped.
    let spec = |l: usize| &specs[l.min(specs.len() - 1)];
    let has_process_noise = s.has_process_noise();
    let normals =
        |substream| LaneNormals::new(std::array::from_fn(|l| noise_rng(s.header.seed, spec(l).noise_trial, substream)));
    let mut sensor_normals = normals(Substream::SensorNoise);
    // Student-t channels: each lane's scale draws, as the trial-at-a-time path draws them.
    let mut tails: Option<Vec<crate::engine::scenario::noise::TailScales>> = (0..LANES)
        .map(|l| crate::engine::scenario::streams::tail_scales(&s.sensor_law, s.header.seed, spec(l).noise_trial))
        .collect();
    let mut process_normals = has_process_noise.then(|| normals(Substream::ProcessNoise));
    let mut draws = vec![[0.0; LANES]; ny.max(n)];
    let sensor_sigma: Vec<Lane> =
        s.sensor_sigma.iter().map(|sigma| std::array::from_fn(|l| sigma * spec(l).noise_scale)).collect();
    let process_sigma: Vec<Lane> = s.process_sigma_per_step.iter().map(|&sigma| [sigma; LANES]).collect();
    let mut faults: Vec<ActiveFaults> = (0..LANES).map(|l| ActiveFaults::new(spec(l).fault.faults.clone())).collect();
    let onset_s: Lane = std::array::from_fn(|l| faults[l].first_onset_s().unwrap_or(f64::INFINITY));

    let x0: Vec<Lane> = s.initial_state.iter().map(|&v| [v; LANES]).collect();
    let mut plant_state = PlantState::new(&x0, nu);
    let mut r = vec![0.0; nu];
    let mut y = vec![[0.0; LANES]; ny];
    // Detectors whose filters do the same arithmetic read one filter's residuals: per detector, the
    // index of the filter it reads in `filters`.
    let mut filters: Vec<&LaneFilter> = Vec::new();
    let filter_of: Vec<usize> = detectors
        .iter()
        .map(|d| match filters.iter().position(|f| f.same_arithmetic(d.filter)) {
            Some(i) => i,
            None => {
                filters.push(d.filter);
                filters.len() - 1
            }
        })
        .collect();
    let mut filter_states: Vec<FilterState<Lane>> = filters.iter().map(|_| FilterState::new(&x0, nu, ny)).collect();
    let exact: [ExactDelays; LANES] = std::array::from_fn(|l| spec(l).exact_delays(s));
    let mut trackers: Vec<LaneTracker> =
        detectors.iter().map(|d| LaneTracker::new(d, onset_s, exact, ny, s.monte_carlo.common.profile)).collect();

    for k in 0..s.header.steps {
        let t = k as f64 * s.header.dt_s;
        r.fill(0.0);
        for e in &s.excitations {
            r[e.input] += e.value(t);
        }
        for (lanes, &v) in plant_state.reference_mut().iter_mut().zip(&r) {
            *lanes = [v; LANES];
        }
        plant.measure(&plant_state, &mut y);
        sensor_normals.fill(&mut draws[..ny]);
        if let Some(tails) = tails.as_mut() {
            for (l, lane) in tails.iter_mut().enumerate() {
                for (j, row) in draws[..ny].iter_mut().enumerate() {
                    row[l] = lane.shape(j, row[l]);
                }
            }
        }
        add_scaled(&mut y, &sensor_sigma, &draws);
        for (l, f) in faults.iter_mut().enumerate() {
            if t >= onset_s[l] {
                f.apply_to_lane(t, &mut y, l);
            }
        }
        plant.close_loop(&mut plant_state, &y);

        for (f, st) in filters.iter().zip(filter_states.iter_mut()) {
            f.step(st, plant_state.inputs(), &y);
        }
        for (tracker, &f) in trackers.iter_mut().zip(&filter_of) {
            tracker.observe(t, filter_states[f].residual());
        }

        plant.advance(&mut plant_state, |x_next| {
            if let Some(normals) = process_normals.as_mut() {
                normals.fill(&mut draws[..n]);
                add_scaled(x_next, &process_sigma, &draws);
            }
        });
    }
    trackers.into_iter().map(|tracker| tracker.finish(specs.len())).collect()
}

// The lane-wise loops below copy each lane vector into a local, compute, then store it: with every
// load before every store, the compiler needs no proof that the vectors do not overlap and packs
// the eight lanes into two AVX2 registers (element by element through memory, they stayed scalar).
// Flags are u64 per lane, the width of the f64 compares.

/// `y += sigma * e`, lane by lane.
#[inline(always)]
fn add_scaled(y: &mut [Lane], sigma: &[Lane], e: &[Lane]) {
    for ((yj, sigma), e) in y.iter_mut().zip(sigma).zip(e) {
        let (mut v, sigma, e) = (*yj, *sigma, *e);
        for l in 0..LANES {
            v[l] += sigma[l] * e[l];
        }
        *yj = v;
    }
}

/// `abs = |residual|`; per lane, 1 if any |residual| is not finite.
#[inline(always)]
fn abs_and_non_finite(residual: &[Lane], abs: &mut [Lane]) -> [u64; LANES] {
    let mut non_finite = [0u64; LANES];
    for (abs, r) in abs.iter_mut().zip(residual) {
        let (r, mut a) = (*r, [0.0; LANES]);
        for l in 0..LANES {
            a[l] = r[l].abs();
            non_finite[l] |= !(a[l] <= f64::MAX) as u64;
        }
        *abs = a;
    }
    non_finite
}

/// Per lane, 1 if any of `values` is not finite (NaN or infinite).
#[inline(always)]
fn non_finite_lanes(values: &[Lane]) -> [u64; LANES] {
    let mut flag = [0u64; LANES];
    for v in values {
        for l in 0..LANES {
            flag[l] |= !(v[l].abs() <= f64::MAX) as u64;
        }
    }
    flag
}

/// `g = max(0, g + |r| - drift)` per output and lane, in the one-trial path's order of operations;
/// `abs` becomes `g`, the statistic the bookkeeping sees.
#[inline(always)]
fn cusum_step(abs: &mut [Lane], drift: &[f64], g: &mut [Lane]) {
    for ((abs, drift), g) in abs.iter_mut().zip(drift).zip(g) {
        let (a, mut sum) = (*abs, *g);
        for l in 0..LANES {
            let v = sum[l] + a[l] - drift;
            sum[l] = if v.is_finite() { v.max(0.0) } else { v };
        }
        (*g, *abs) = (sum, sum);
    }
}

/// The Kalman chi-square test per lane: `r' S^-1 r` (each lane's own `S^-1`, `s_inv[i * ny + j]`) into
/// the window `ring` (oldest at `head` once full), and the window's sum, oldest first, into every
/// output's `abs`: the one-trial path's sums, in its order, from -0.0 (kalman_chi2.rs).
#[inline(always)]
fn nis_step(residual: &[Lane], abs: &mut [Lane], window: &mut NisWindow) {
    let ny = residual.len();
    let mut nis = [-0.0f64; LANES];
    for i in 0..ny {
        let mut inner = [-0.0f64; LANES];
        for j in 0..ny {
            let (s, r) = (window.s_inv[i * ny + j], residual[j]);
            for l in 0..LANES {
                inner[l] += s[l] * r[l];
            }
        }
        let r = residual[i];
        for l in 0..LANES {
            nis[l] += r[l] * inner[l];
        }
    }
    let size = window.ring.len();
    if window.filled < size {
        window.ring[window.filled] = nis;
        window.filled += 1;
    } else {
        window.ring[window.head] = nis;
        window.head = (window.head + 1) % size;
    }
    // Oldest first: from `head` to the end, then the start up to `head` (0 until the ring is full).
    let mut sum = [-0.0f64; LANES];
    let (newer, older) = window.ring[..window.filled].split_at(window.head);
    for v in older.iter().chain(newer) {
        for l in 0..LANES {
            sum[l] += v[l];
        }
    }
    abs.iter_mut().for_each(|a| *a = sum);
}

/// The Kalman chi-square test's memory for a group of lanes.
struct NisWindow {
    /// `S^-1` entry by entry (row-major), each lane's design's own (zeros for a lane without one).
    s_inv: Vec<Lane>,
    /// The last `window` values of `r' S^-1 r`.
    ring: Vec<Lane>,
    filled: usize,
    head: usize,
}

/// The statistic the bookkeeping sees, per output: `|r_j|` or what a test makes of the residual.
enum LaneTest {
    Absolute,
    /// `kind = "cusum"`: per output the drift and the sums.
    Cusum(Vec<f64>, Vec<Lane>),
    /// `kind = "kalman_chi2"`.
    Nis(NisWindow),
}

impl LaneTest {
    fn new(d: &LaneDetector, ny: usize) -> Self {
        if let Some(LaneStatistic::Accumulated { drift }) = d.params.decision.as_ref().and_then(Decision::on_lanes) {
            return LaneTest::Cusum(drift, vec![[0.0; LANES]; ny]);
        }
        // A test designed with each filter (the Kalman test's S is the design's): read per lane.
        let per_lane: [Option<LaneStatistic>; LANES] =
            std::array::from_fn(|l| d.designs[l].and_then(|f| f.decision.on_lanes()));
        let window = per_lane.iter().find_map(|s| match s {
            Some(LaneStatistic::WindowedNis { window, .. }) => Some(*window),
            _ => None,
        });
        let Some(window) = window else { return LaneTest::Absolute };
        let s_inv = (0..ny * ny)
            .map(|k| {
                std::array::from_fn(|l| match &per_lane[l] {
                    Some(LaneStatistic::WindowedNis { s_inv, .. }) => s_inv[(k / ny, k % ny)],
                    _ => 0.0,
                })
            })
            .collect();
        LaneTest::Nis(NisWindow { s_inv, ring: vec![[0.0; LANES]; window], filled: 0, head: 0 })
    }
}

/// Updates the running maximum (and when it was reached) of every output; per lane, 1 if an
/// |residual| passes an armed threshold or the next profile level.
#[inline(always)]
fn running_max_and_events(
    t: f64,
    abs: &[Lane],
    max: &mut [Lane],
    max_t: &mut [Lane],
    armed: &[Lane],
    next_kept: &[Lane],
) -> [u64; LANES] {
    let mut event = [0u64; LANES];
    for ((((abs, max), max_t), armed), next_kept) in abs.iter().zip(max).zip(max_t).zip(armed).zip(next_kept) {
        let (a, mut m, mut m_t, armed, next_kept) = (*abs, *max, *max_t, *armed, *next_kept);
        for l in 0..LANES {
            // All ones where the maximum rises: a bitwise select, which vectorises where `if` did not.
            let rise = 0u64.wrapping_sub((a[l] > m[l]) as u64);
            m[l] = f64::from_bits((a[l].to_bits() & rise) | (m[l].to_bits() & !rise));
            m_t[l] = f64::from_bits((t.to_bits() & rise) | (m_t[l].to_bits() & !rise));
            event[l] |= ((a[l] > armed[l]) | (a[l] > next_kept[l])) as u64;
        }
        (*max, *max_t) = (m, m_t);
    }
    event
}

/// The earliest time a live lane may pass one of its exact delays ([`ExactDelays::next_check_s`]).
fn next_exact_s(exact: &[ExactDelays; LANES], live: &[bool; LANES]) -> f64 {
    (0..LANES).filter(|&l| live[l]).map(|l| exact[l].next_check_s()).fold(f64::INFINITY, f64::min)
}

/// [`crate::methods::detection_filter::trial::Tracker`]'s bookkeeping for a group of lanes (see the module docs for the arrangement).
struct LaneTracker<'f> {
    designs: [Option<&'f DetectionFilter>; LANES],
    thresholds: Vec<f64>,
    /// Per output: the threshold while an alarm is still to be recorded in that lane, else +inf.
    armed: Vec<Lane>,
    /// Per output: the largest |residual| so far, before the onset; the running maximum after it.
    max: Vec<Lane>,
    /// Per output: when the running maximum was reached (after the onset).
    max_t: Vec<Lane>,
    /// Per output: a post-onset statistic above this adds a profile point (+inf before the onset, -inf
    /// at it: the first point), and the grid that places the points ([`ProfileGrid::keep`]).
    next_kept: Vec<Lane>,
    /// Per output: the level index of `next_kept` ([`ProfileGrid::keep`]).
    next_level: Vec<[i32; LANES]>,
    grid: ProfileGrid,
    /// Per lane: where its profiles keep the running maximum exactly, and the earliest time a live lane
    /// may pass one (before it, no lane does).
    exact: [ExactDelays; LANES],
    next_exact_s: f64,
    abs: Vec<Lane>,
    /// What replaces `abs` as the statistic, for a test other than `|r|`.
    test: LaneTest,
    onset_s: Lane,
    /// The earliest onset of a live lane still before it: until then no lane crosses its onset.
    next_onset_s: f64,
    after_onset: [bool; LANES],
    live: [bool; LANES],
    /// `max` and `max_t` of a lane when its residual turned non-finite.
    frozen: Vec<Option<(Vec<f64>, Vec<f64>)>>,
    iso_start: Lane,
    iso_end: Lane,
    /// Bounds of every lane's isolation window: outside them no lane is in its window.
    iso_first_start: f64,
    iso_last_end: f64,
    iso_sum: Vec<Lane>,
    iso_count: [usize; LANES],
    isolation: (f64, f64),
    out: Vec<DetectorOutcome>,
}

impl<'f> LaneTracker<'f> {
    fn new(d: &LaneDetector<'f>, onset_s: Lane, exact: [ExactDelays; LANES], ny: usize, grid: ProfileGrid) -> Self {
        let live: [bool; LANES] = std::array::from_fn(|l| d.designs[l].is_some());
        let thresholds: Vec<f64> = d.params.thresholds.iter().copied().collect();
        LaneTracker {
            designs: d.designs,
            armed: thresholds
                .iter()
                .map(|&thr| std::array::from_fn(|l| if live[l] { thr } else { f64::INFINITY }))
                .collect(),
            thresholds,
            max: vec![[0.0; LANES]; ny],
            max_t: vec![[f64::NAN; LANES]; ny],
            next_kept: vec![[f64::INFINITY; LANES]; ny],
            next_level: vec![[NO_LEVEL; LANES]; ny],
            grid,
            exact,
            next_exact_s: next_exact_s(&exact, &live),
            abs: vec![[0.0; LANES]; ny],
            test: LaneTest::new(d, ny),
            onset_s,
            next_onset_s: (0..LANES).filter(|&l| live[l]).map(|l| onset_s[l]).fold(f64::INFINITY, f64::min),
            after_onset: [false; LANES],
            live,
            frozen: vec![None; LANES],
            iso_start: [f64::INFINITY; LANES],
            iso_end: [f64::NEG_INFINITY; LANES],
            iso_first_start: f64::INFINITY,
            iso_last_end: f64::NEG_INFINITY,
            iso_sum: vec![[0.0; LANES]; ny],
            iso_count: [0; LANES],
            isolation: (d.params.isolation_delay_s, d.params.isolation_window_s),
            out: (0..LANES)
                .map(|_| DetectorOutcome {
                    pre_onset_max_abs_residual: vec![0.0; ny],
                    profile_t_s: vec![Vec::new(); ny],
                    profile_value: vec![Vec::new(); ny],
                    ..Default::default()
                })
                .collect(),
        }
    }

    #[inline(always)]
    fn observe(&mut self, t: f64, residual: &[Lane]) {
        if t >= self.next_onset_s {
            for l in 0..LANES {
                if !self.after_onset[l] && self.live[l] && t >= self.onset_s[l] {
                    self.cross_onset(l);
                }
            }
            self.next_onset_s = (0..LANES)
                .filter(|&l| self.live[l] && !self.after_onset[l])
                .map(|l| self.onset_s[l])
                .fold(f64::INFINITY, f64::min);
        }
        let non_finite = abs_and_non_finite(residual, &mut self.abs);
        if non_finite.iter().any(|&b| b != 0) {
            for l in 0..LANES {
                if non_finite[l] != 0 && self.live[l] {
                    self.diverge(l, t);
                }
            }
        }
        match &mut self.test {
            LaneTest::Absolute => {}
            LaneTest::Cusum(drift, g) => cusum_step(&mut self.abs, drift, g),
            LaneTest::Nis(window) => nis_step(residual, &mut self.abs, window),
        }
        if !matches!(self.test, LaneTest::Absolute) {
            // A statistic that overflows from a finite residual has diverged, as in the one-trial path.
            let non_finite = non_finite_lanes(&self.abs);
            for l in 0..LANES {
                if non_finite[l] != 0 && self.live[l] {
                    self.diverge(l, t);
                }
            }
        }
        // After the divergence checks, as the one-trial path (a lane that diverges here keeps no point).
        if t >= self.next_exact_s {
            self.keep_exact(t);
        }
        let event = running_max_and_events(t, &self.abs, &mut self.max, &mut self.max_t, &self.armed, &self.next_kept);
        if event.iter().any(|&e| e != 0) {
            for l in 0..LANES {
                if event[l] != 0 {
                    self.record(l, t);
                }
            }
        }
        if t < self.iso_first_start || t >= self.iso_last_end {
            return;
        }
        let mut in_window = [false; LANES];
        for l in 0..LANES {
            in_window[l] = t >= self.iso_start[l] && t < self.iso_end[l];
        }
        if in_window.iter().any(|&w| w) {
            for l in 0..LANES {
                if in_window[l] {
                    for (sum, r) in self.iso_sum.iter_mut().zip(residual) {
                        sum[l] += r[l];
                    }
                    self.iso_count[l] += 1;
                }
            }
        }
    }

    /// Lane `l` reaches its fault onset: the maximum so far is the pre-onset maximum; the detection
    /// alarm is armed and the first-passage profile starts.
    #[cold]
    fn cross_onset(&mut self, l: usize) {
        self.after_onset[l] = true;
        for j in 0..self.max.len() {
            self.out[l].pre_onset_max_abs_residual[j] = self.max[j][l];
            self.max[j][l] = f64::NEG_INFINITY;
            self.max_t[j][l] = f64::NAN;
            self.next_kept[j][l] = f64::NEG_INFINITY;
            self.next_level[j][l] = NO_LEVEL;
            self.armed[j][l] = self.thresholds[j];
        }
    }

    /// The lanes whose sample at `t` is the first past one of their exact delays keep their running
    /// maxima so far in their profiles, as [`FirstPassage`](crate::engine::results::schema::FirstPassage) does.
    #[cold]
    fn keep_exact(&mut self, t: f64) {
        for l in 0..LANES {
            if self.live[l] && self.after_onset[l] && self.exact[l].passed(t) {
                for j in 0..self.max.len() {
                    let out = &mut self.out[l];
                    keep_exact(self.max_t[j][l], self.max[j][l], &mut out.profile_t_s[j], &mut out.profile_value[j]);
                }
            }
        }
        self.next_exact_s = next_exact_s(&self.exact, &self.live);
    }

    #[cold]
    fn diverge(&mut self, l: usize, t: f64) {
        self.live[l] = false;
        self.out[l].diverged_at_s = Some(t);
        self.frozen[l] = Some((self.max.iter().map(|m| m[l]).collect(), self.max_t.iter().map(|m| m[l]).collect()));
        for j in 0..self.max.len() {
            self.armed[j][l] = f64::INFINITY;
            self.next_kept[j][l] = f64::INFINITY;
        }
        self.iso_end[l] = f64::NEG_INFINITY;
    }

    /// Lane `l` has a new profile point or an alarm to record at `t`.
    #[cold]
    fn record(&mut self, l: usize, t: f64) {
        let mut alarm = None;
        for j in 0..self.abs.len() {
            let a = self.abs[j][l];
            if let Some(v) = self.grid.keep(&mut self.next_kept[j][l], &mut self.next_level[j][l], a) {
                self.out[l].profile_t_s[j].push(t);
                self.out[l].profile_value[j].push(v);
            }
            if alarm.is_none() && a > self.armed[j][l] {
                alarm = Some(j);
            }
        }
        let Some(j) = alarm else { return };
        if self.after_onset[l] {
            self.out[l].detection = Some((t, j));
            self.iso_start[l] = t + self.isolation.0;
            self.iso_end[l] = self.iso_start[l] + self.isolation.1;
            self.iso_first_start = self.iso_first_start.min(self.iso_start[l]);
            self.iso_last_end = self.iso_last_end.max(self.iso_end[l]);
        } else {
            self.out[l].false_alarm = Some((t, j));
        }
        for armed in &mut self.armed {
            armed[l] = f64::INFINITY;
        }
    }

    /// Outcomes of the first `trials` lanes (`None` where the lane had no design).
    fn finish(mut self, trials: usize) -> Vec<Option<DetectorOutcome>> {
        let ny = self.max.len();
        let mut outcomes = Vec::with_capacity(trials);
        for (l, mut out) in self.out.drain(..).take(trials).enumerate() {
            let Some(design) = self.designs[l] else {
                outcomes.push(None);
                continue;
            };
            let (max, max_t) = self.frozen[l].take().unwrap_or_else(|| {
                (self.max.iter().map(|m| m[l]).collect(), self.max_t.iter().map(|m| m[l]).collect())
            });
            if self.after_onset[l] {
                for j in 0..ny {
                    // The final maximum closes the profile, as in the one-trial path.
                    close_profile(max_t[j], max[j], &mut out.profile_t_s[j], &mut out.profile_value[j]);
                }
            } else {
                out.pre_onset_max_abs_residual = max;
            }
            if self.iso_count[l] > 0 {
                let mean = DVector::from_fn(ny, |j, _| self.iso_sum[j][l] / self.iso_count[l] as f64);
                out.isolated_by_max = Some(design.isolate_by_max(&mean));
                out.isolated_by_direction = Some(design.isolate_by_direction(&mean));
            }
            outcomes.push(Some(out));
        }
        outcomes
    }
}
