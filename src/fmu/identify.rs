//! A linear model of an FMU plant identified from its responses about the trim, for an FMU with no
//! derivatives to differentiate (a co-simulation export, what Simulink gives).
//!
//! The method is the eigensystem realization algorithm (ERA; Juang and Pappa, J. Guidance 8(5), 1985)
//! on pulse responses, then the continuous model through the matrix logarithm:
//!
//! 1. **Pulse responses.** From the trim, input `j` is raised by `+h_j` for the first sample only
//!    (held over `dt` as every input is), then by `-h_j`, `h_j = PULSE_RELATIVE * max(|u_trim_j|, 1)`;
//!    the outputs' difference over `2 h_j` is column `j` of the Markov parameters `Y_0 = D`,
//!    `Y_k = C Ad^(k-1) Bd`. The central difference cancels the trim's own drift and the second-order
//!    terms of a nonlinear model.
//! 2. **ERA with a stride `m`.** The block Hankel matrices `H0 = [Y_(1 + m (i + j))]` and
//!    `H1 = [Y_(1 + m (i + j + 1))]` (`i, j < blocks`); the thin SVD `H0 = U S V'` kept to the deck's
//!    number of states `n`; then `Ad^m = S^-1/2 U' H1 V S^-1/2`, `Bd` the first block column of
//!    `S^1/2 V'`, `C` the first block row of `U S^1/2`. The stride spans [`SPAN_S`] with a few dozen
//!    samples, so slow modes (a phugoid) weigh in the Hankel matrix beside fast ones.
//! 3. **Continuous model.** `A = log(Ad^m) / (m dt)` (principal logarithm: every mode with
//!    `|Im(lambda)| m dt < pi`), `B = Phi^-1 Bd` with `Phi = int_0^dt exp(A t) dt` (the zero-order hold
//!    the study samples with gives back `Ad`, `Bd`).
//! 4. **The fit.** Every input at once a square wave of `VALIDATION_FACTOR h_j` (periods 2, 3, 5, ... s)
//!    for [`SPAN_S`]; per output, `100 (1 - |y - y_model| / |y - mean(y)|)` %, the FMU's response
//!    against the identified model's (the NRMSE fit of system-identification tools).
//!
//! The identified states are a realization's, not the FMU's: `[plant] states` only names them.

use nalgebra::{DMatrix, DVector};

use super::FmuError;
use super::plant::{FmuPlant, Linearisation};
use crate::lti::LtiPlant;

/// The pulse, relative to `max(|u_trim|, 1)` (a choice: small against the nonlinearity, whose error
/// the central difference makes second order, large against rounding in the outputs).
pub const PULSE_RELATIVE: f64 = 1e-4;
/// The time the Hankel matrices span, and the validation run's length (s; a choice).
pub const SPAN_S: f64 = 5.0;
/// The validation square waves' amplitude, in pulses.
pub const VALIDATION_FACTOR: f64 = 10.0;
/// The fit below which an identified model is refused (%, on every output; a choice: a model that
/// explains less than this of the FMU's response is not one to design a detector on).
pub const MIN_FIT_PERCENT: f64 = 90.0;
/// The share of the pulse responses, sampled at the study's step, the identified model may miss
/// before fdimc warns that a mode is faster than the ERA stride can see (a choice).
pub const MISSED_RESPONSE: f64 = 0.05;

/// An identified model and how well it fits.
#[derive(Debug, Clone)]
pub struct Identified {
    pub linearisation: Linearisation,
    /// Per mapped output, the NRMSE fit in % on the validation run.
    pub fit_percent: Vec<f64>,
}

/// Identifies an `n`-state model of `plant` about its trim at step `dt_s` (see the module docs).
pub fn identify(plant: &FmuPlant, n: usize, dt_s: f64, output_names: &[String]) -> Result<Identified, FmuError> {
    let (nu, ny) = (plant.input_vrs.len(), plant.output_vrs.len());
    let invalid = |why: String| FmuError::Invalid(format!("{}: {why}", plant.fmu.file_name()));
    let blocks = (n + 5).max(10);
    let stride = ((SPAN_S / (2.0 * blocks as f64 * dt_s)).floor() as usize).max(1);
    let samples = 1 + stride * 2 * blocks;
    let pulse: Vec<f64> = plant.input_trim.iter().map(|u| PULSE_RELATIVE * u.abs().max(1.0)).collect();

    // Markov parameters Y_k (ny x nu), k = 0..samples.
    let mut markov = vec![DMatrix::zeros(ny, nu); samples];
    for j in 0..nu {
        let plus = respond(plant, samples, dt_s, |k, u| u[j] = if k == 0 { pulse[j] } else { 0.0 })?;
        let minus = respond(plant, samples, dt_s, |k, u| u[j] = if k == 0 { -pulse[j] } else { 0.0 })?;
        for (k, y) in markov.iter_mut().enumerate() {
            for r in 0..ny {
                y[(r, j)] = (plus[k][r] - minus[k][r]) / (2.0 * pulse[j]);
            }
        }
    }
    let hankel = |shift: usize| {
        let mut h = DMatrix::zeros(blocks * ny, blocks * nu);
        for i in 0..blocks {
            for j in 0..blocks {
                h.view_mut((i * ny, j * nu), (ny, nu)).copy_from(&markov[1 + stride * (i + j + shift)]);
            }
        }
        h
    };
    let (h0, h1) = (hankel(0), hankel(1));
    if n > blocks * ny.min(nu) {
        return Err(invalid(format!("{n} states cannot be identified from {nu} inputs and {ny} outputs")));
    }
    let svd = h0.clone().svd(true, true);
    let (u, v_t) = (svd.u.expect("asked for U"), svd.v_t.expect("asked for V'"));
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let kept = &order[..n];
    let sigma: Vec<f64> = kept.iter().map(|&k| svd.singular_values[k]).collect();
    if sigma.last().is_none_or(|&s| !(s > sigma[0] * 1e-12)) {
        return Err(invalid(format!(
            "its pulse responses show fewer than {n} states (Hankel singular values {sigma:?}): give [plant] fewer states"
        )));
    }
    let un = DMatrix::from_fn(u.nrows(), n, |r, c| u[(r, kept[c])]);
    let vn_t = DMatrix::from_fn(n, v_t.ncols(), |r, c| v_t[(kept[r], c)]);
    let root = DVector::from_iterator(n, sigma.iter().map(|s| s.sqrt()));
    let inv_root = DMatrix::from_diagonal(&root.map(|s| 1.0 / s));
    let a_stride = &inv_root * un.transpose() * &h1 * vn_t.transpose() * &inv_root;
    let bd = (DMatrix::from_diagonal(&root) * &vn_t).columns(0, nu).into_owned();
    let c = (&un * DMatrix::from_diagonal(&root)).rows(0, ny).into_owned();
    let d = markov[0].clone();

    let a = crate::linalg::logm(&a_stride)
        .ok_or_else(|| invalid("the identified discrete model has no real logarithm (a mode too fast or too oscillatory for the study's step)".into()))?
        / (stride as f64 * dt_s);
    // Phi = int_0^dt exp(A t) dt: the input block of the zero-order hold with B = I.
    let hold = hold_model(&a, &DMatrix::identity(n, n), &DMatrix::zeros(0, n), &DMatrix::zeros(0, n));
    let b = hold.discretise(dt_s).Bd.lu().solve(&bd).ok_or_else(|| invalid("the hold matrix is singular".into()))?;

    let fit_percent = fit(plant, &hold_model(&a, &b, &c, &d), dt_s, &pulse)?;
    // A fit far below zero is a model whose response grows past the FMU's: its digits say nothing.
    let percent = |f: f64| if f < -1000.0 { "below -1000 %".to_string() } else { format!("{f:.3} %") };
    let fits: Vec<String> =
        output_names.iter().zip(&fit_percent).map(|(name, f)| format!("{name} {}", percent(*f))).collect();
    // The Hankel singular values kept and the first dropped, relative to the largest: a gap after the
    // n-th says the order is right; none says the model has more (or fewer) states than the deck's.
    let relative: Vec<String> =
        order.iter().take(n + 1).map(|&k| format!("{:.1e}", svd.singular_values[k] / sigma[0])).collect();
    let method = format!(
        "{}'s pulse responses about the trim by ERA: {n} states, {blocks} x {blocks} blocks every {} s, \
         pulses {PULSE_RELATIVE:e} x max(|u_trim|, 1); Hankel singular values kept {} | next {}; fit on {SPAN_S} s of \
         square waves: {}",
        plant.fmu.file_name(),
        stride as f64 * dt_s,
        relative[..n].join(" "),
        relative.get(n).map_or("none", String::as_str),
        fits.join(", ")
    );
    if let Some((name, worst)) =
        output_names.iter().zip(&fit_percent).find(|(_, f)| !(**f >= MIN_FIT_PERCENT)).map(|(n, f)| (n, *f))
    {
        return Err(invalid(format!(
            "the identified model fits its response poorly: {name} {}, below the {MIN_FIT_PERCENT} % fdimc accepts \
             ({}); the FMU is too nonlinear about the trim, has more states than [plant] names, or a mode faster than \
             its pulse responses sampled every {} s see (pi / {} s = {:.3} rad/s; a faster one is aliased into a \
             slower one): give [plant] a, b, c, or a model-exchange FMU with linearise = true",
            percent(worst),
            fits.join(", "),
            stride as f64 * dt_s,
            stride as f64 * dt_s,
            std::f64::consts::PI / (stride as f64 * dt_s)
        )));
    }
    // The model against the pulse responses at every step, not just the stride's: what it misses there
    // is a mode faster than the stride's Nyquist frequency (aliased into a slow one), or unmodelled.
    let model = hold_model(&a, &b, &c, &d);
    let at_dt = model.discretise(dt_s);
    let (mut missed, mut total) = (0.0, 0.0);
    let mut x = at_dt.Bd.clone();
    for y in markov.iter().skip(1) {
        let predicted = &at_dt.C * &x;
        missed += (y - &predicted).norm_squared();
        total += y.norm_squared();
        x = &at_dt.Ad * &x;
    }
    let mut warnings = Vec::new();
    let share = (missed / total.max(f64::MIN_POSITIVE)).sqrt();
    if share > MISSED_RESPONSE {
        warnings.push(format!(
            "the identified model misses {:.0} % of {}'s pulse responses sampled every {dt_s} s: a mode faster \
             than the identification sees (pi / {} s = {:.3} rad/s), aliased into a slower one, or one the {n} \
             states do not hold; the fastest identified mode is {:.3} rad/s",
            100.0 * share,
            plant.fmu.file_name(),
            stride as f64 * dt_s,
            std::f64::consts::PI / (stride as f64 * dt_s),
            a.clone().complex_eigenvalues().iter().map(|l| l.norm()).fold(0.0, f64::max)
        ));
    }
    let linearisation =
        Linearisation { a, b, c, d, x_trim: Vec::new(), derivative_at_trim: Vec::new(), method, warnings };
    Ok(Identified { linearisation, fit_percent })
}

/// An unnamed linear model of the matrices.
fn hold_model(a: &DMatrix<f64>, b: &DMatrix<f64>, c: &DMatrix<f64>, d: &DMatrix<f64>) -> LtiPlant {
    LtiPlant {
        state_names: Vec::new(),
        input_names: Vec::new(),
        output_names: Vec::new(),
        A: a.clone(),
        B: b.clone(),
        C: c.clone(),
        D: d.clone(),
    }
}

/// The mapped outputs (deviations from their trim) at samples `0..samples` of a flight from the trim
/// whose input deviations `input(k, u)` sets at sample `k`.
fn respond(
    plant: &FmuPlant,
    samples: usize,
    dt_s: f64,
    mut input: impl FnMut(usize, &mut [f64]),
) -> Result<Vec<Vec<f64>>, FmuError> {
    let mut flight = plant.start(&[])?;
    let (mut u, mut y) = (vec![0.0; plant.input_vrs.len()], vec![0.0; plant.output_vrs.len()]);
    let mut out = Vec::with_capacity(samples);
    for k in 0..samples {
        input(k, &mut u);
        flight.set_inputs(&u)?;
        flight.outputs(&mut y)?;
        out.push(y.clone());
        flight.advance(k as f64 * dt_s, dt_s)?;
    }
    Ok(out)
}

/// The NRMSE fit (%) per output of `model` against the FMU, both driven from the trim by square waves
/// of `VALIDATION_FACTOR` pulses on every input (periods 2, 3, 5, 7, ... s).
fn fit(plant: &FmuPlant, model: &LtiPlant, dt_s: f64, pulse: &[f64]) -> Result<Vec<f64>, FmuError> {
    const PERIODS_S: [f64; 8] = [2.0, 3.0, 5.0, 7.0, 11.0, 13.0, 17.0, 19.0];
    let samples = (SPAN_S / dt_s).round() as usize;
    let wave = |k: usize, j: usize| {
        let period = PERIODS_S[j % PERIODS_S.len()];
        let sign = if ((k as f64 * dt_s) / period).fract() < 0.5 { 1.0 } else { -1.0 };
        sign * VALIDATION_FACTOR * pulse[j]
    };
    // Less the unforced flight: a trim that is not quite an equilibrium drifts by itself.
    let unforced = respond(plant, samples, dt_s, |_, u| u.fill(0.0))?;
    let mut measured = respond(plant, samples, dt_s, |k, u| {
        for (j, v) in u.iter_mut().enumerate() {
            *v = wave(k, j);
        }
    })?;
    for (y, y0) in measured.iter_mut().zip(&unforced) {
        y.iter_mut().zip(y0).for_each(|(v, v0)| *v -= v0);
    }
    let discrete = model.discretise(dt_s);
    let ny = model.n_outputs();
    let mut x = DVector::zeros(model.n_states());
    let (mut error, mut spread) = (vec![0.0; ny], vec![0.0; ny]);
    let mean: Vec<f64> = (0..ny).map(|r| measured.iter().map(|y| y[r]).sum::<f64>() / samples as f64).collect();
    for (k, y) in measured.iter().enumerate() {
        let u = DVector::from_fn(model.n_inputs(), |j, _| wave(k, j));
        let predicted = &discrete.C * &x + &discrete.D * &u;
        for r in 0..ny {
            error[r] += (y[r] - predicted[r]).powi(2);
            spread[r] += (y[r] - mean[r]).powi(2);
        }
        x = &discrete.Ad * &x + &discrete.Bd * &u;
    }
    Ok((0..ny).map(|r| 100.0 * (1.0 - (error[r] / spread[r]).sqrt())).collect())
}
