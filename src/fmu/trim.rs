//! A trim solved on the FMU itself: the free inputs and parameters (an initial angle of attack, an
//! elevator, a throttle) that make chosen variables (state derivatives, `der(V_m_s)`, ...) zero right
//! after initialisation. Newton's method on a central-difference Jacobian, each evaluation a reset
//! instance initialised with the candidate values, with step halving while the residual does not fall.
//! Works on either interface: it only sets values before initialisation and reads variables after it.

use super::plant::RELATIVE_STEP;
use super::{Fmu, FmuError, Interface};

/// What to solve: values set before initialisation in every evaluation (`fixed`, then the `free`
/// ones at the candidate), the variables driven to zero, and when to stop.
pub struct TrimProblem<'a> {
    pub interface: Interface,
    /// (value reference, value) set first: the deck's parameters and the inputs that are not free.
    pub fixed: &'a [(u32, f64)],
    /// (value reference, starting guess) of each free input or parameter.
    pub free: &'a [(u32, f64)],
    /// Value references of the variables to make zero, as many as `free`.
    pub zero: &'a [u32],
    pub stop_s: f64,
    /// Converged when every `|zero|` is at most this.
    pub tolerance: f64,
}

/// A solved trim: the free values, the variables' values there, and the Newton steps taken.
#[derive(Debug, Clone, PartialEq)]
pub struct Trim {
    pub values: Vec<f64>,
    pub residual: Vec<f64>,
    pub steps: usize,
}

/// Newton steps before giving up, and halvings of one step.
const MAX_STEPS: usize = 50;
const MAX_HALVINGS: usize = 30;

/// Solves `p` on `fmu`; fails with the residual reached when it does not converge.
pub fn solve(fmu: &Fmu, p: &TrimProblem) -> Result<Trim, FmuError> {
    let n = p.free.len();
    assert_eq!(n, p.zero.len(), "the caller checks as many variables as free values");
    let mut instance = fmu.instantiate(p.interface, "fdimc-trim")?;
    let free_vrs: Vec<u32> = p.free.iter().map(|f| f.0).collect();
    let mut eval = |z: &[f64]| -> Result<Vec<f64>, FmuError> {
        instance.reset()?;
        for &(vr, v) in p.fixed {
            instance.set_real(&[vr], &[v])?;
        }
        instance.set_real(&free_vrs, z)?;
        instance.initialise(0.0, p.stop_s)?;
        let mut f = vec![0.0; n];
        instance.get_real(p.zero, &mut f)?;
        Ok(f)
    };
    // NaN is the worst residual, never a small one (f64::max would drop it).
    let worst = |f: &[f64]| f.iter().fold(0.0f64, |m, v| if v.is_nan() { f64::INFINITY } else { m.max(v.abs()) });
    let mut z: Vec<f64> = p.free.iter().map(|f| f.1).collect();
    let mut f = eval(&z)?;
    for steps in 0..=MAX_STEPS {
        if worst(&f) <= p.tolerance {
            return Ok(Trim { values: z, residual: f, steps });
        }
        if steps == MAX_STEPS {
            break;
        }
        let mut jacobian = nalgebra::DMatrix::zeros(n, n);
        for k in 0..n {
            // The linearisation's step, for the same balance of truncation and rounding.
            let h = RELATIVE_STEP * z[k].abs().max(1.0);
            let (mut zp, mut zm) = (z.clone(), z.clone());
            zp[k] += h;
            zm[k] -= h;
            let (fp, fm) = (eval(&zp)?, eval(&zm)?);
            for r in 0..n {
                jacobian[(r, k)] = (fp[r] - fm[r]) / (zp[k] - zm[k]);
            }
        }
        let step = jacobian.lu().solve(&nalgebra::DVector::from_column_slice(&f)).ok_or_else(|| {
            FmuError::Invalid(format!(
                "{}: the trim's Jacobian is singular at [{}]: the free values do not move the variables to zero \
                 independently",
                fmu.file_name(),
                list(&z)
            ))
        })?;
        // Halve the step until the residual falls (Newton far from the solution may overshoot).
        let mut scale = 1.0;
        let mut taken = None;
        for _ in 0..MAX_HALVINGS {
            let candidate: Vec<f64> = z.iter().zip(step.iter()).map(|(v, d)| v - scale * d).collect();
            if let Ok(fc) = eval(&candidate)
                && worst(&fc) < worst(&f)
            {
                taken = Some((candidate, fc));
                break;
            }
            scale /= 2.0;
        }
        match taken {
            Some((zc, fc)) => (z, f) = (zc, fc),
            None => break,
        }
    }
    Err(FmuError::Invalid(format!(
        "{}: the trim did not converge: at [{}] the largest |variable| is {:e} (tolerance {:e}); give better \
         starting values",
        fmu.file_name(),
        list(&z),
        worst(&f),
        p.tolerance
    )))
}

fn list(v: &[f64]) -> String {
    v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(", ")
}
