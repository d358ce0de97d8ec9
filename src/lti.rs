//! Linear time-invariant plants and their exact discretisation.
//!
//! `x' = A x + B u`, `y = C x + D u`. Zero-order hold at step `dt_s` through one matrix exponential
//! of the augmented matrix: `exp([[A, B], [0, 0]] dt) = [[Ad, Bd], [0, I]]` (Van Loan), exact for
//! inputs held constant over each step.
#![allow(non_snake_case)]

use nalgebra::DMatrix;

use crate::linalg;

/// A continuous-time LTI plant with named states, inputs and outputs (names carry units).
#[derive(Debug, Clone)]
pub struct LtiPlant {
    pub state_names: Vec<String>,
    pub input_names: Vec<String>,
    pub output_names: Vec<String>,
    pub A: DMatrix<f64>,
    pub B: DMatrix<f64>,
    pub C: DMatrix<f64>,
    pub D: DMatrix<f64>,
}

/// The same plant sampled with a zero-order hold: `x(k+1) = Ad x(k) + Bd u(k)`, `y(k) = C x(k) + D u(k)`.
#[derive(Debug, Clone)]
pub struct DiscreteLti {
    pub Ad: DMatrix<f64>,
    pub Bd: DMatrix<f64>,
    pub C: DMatrix<f64>,
    pub D: DMatrix<f64>,
    pub dt_s: f64,
}

/// Ranks that decide what a detection filter can do with this plant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct StructuralRanks {
    pub states: usize,
    pub controllability_rank: usize,
    pub observability_rank: usize,
}

impl LtiPlant {
    pub fn n_states(&self) -> usize {
        self.A.nrows()
    }
    pub fn n_inputs(&self) -> usize {
        self.B.ncols()
    }
    pub fn n_outputs(&self) -> usize {
        self.C.nrows()
    }

    /// Zero-order-hold discretisation at `dt_s` (see the module docs).
    pub fn discretise(&self, dt_s: f64) -> DiscreteLti {
        let (n, m) = (self.n_states(), self.n_inputs());
        let mut aug = DMatrix::<f64>::zeros(n + m, n + m);
        aug.view_mut((0, 0), (n, n)).copy_from(&(&self.A * dt_s));
        aug.view_mut((0, n), (n, m)).copy_from(&(&self.B * dt_s));
        let e = aug.exp();
        DiscreteLti {
            Ad: e.view((0, 0), (n, n)).into_owned(),
            Bd: e.view((0, n), (n, m)).into_owned(),
            C: self.C.clone(),
            D: self.D.clone(),
            dt_s,
        }
    }

    /// Dimensions of the controllable and observable subspaces, the ranks of the controllability and
    /// observability matrices in exact arithmetic, by the orthogonal staircase (`None` for non-finite
    /// matrices).
    pub fn structural_ranks(&self) -> Option<StructuralRanks> {
        Some(StructuralRanks {
            states: self.n_states(),
            controllability_rank: linalg::staircase(&self.A, &self.B)?.controllable,
            observability_rank: linalg::observable(&self.A, &self.C)?.controllable,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plant(A: DMatrix<f64>, B: DMatrix<f64>, C: DMatrix<f64>) -> LtiPlant {
        let names = |k: usize, p: &str| (0..k).map(|i| format!("{p}{i}")).collect();
        LtiPlant {
            state_names: names(A.nrows(), "x"),
            input_names: names(B.ncols(), "u"),
            output_names: names(C.nrows(), "y"),
            D: DMatrix::zeros(C.nrows(), B.ncols()),
            A,
            B,
            C,
        }
    }

    #[test]
    fn zoh_of_double_integrator_is_exact() {
        let p = plant(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::identity(2, 2),
        );
        let dt = 0.1;
        let d = p.discretise(dt);
        let ad = DMatrix::from_row_slice(2, 2, &[1.0, dt, 0.0, 1.0]);
        let bd = DMatrix::from_row_slice(2, 1, &[dt * dt / 2.0, dt]);
        assert!((d.Ad - ad).norm() < 1e-14);
        assert!((d.Bd - bd).norm() < 1e-14);
    }

    #[test]
    fn zoh_of_first_order_lag_is_exact() {
        // x' = -a x + a u: Ad = e^{-a dt}, Bd = 1 - e^{-a dt}.
        let a = 3.0;
        let dt = 0.05;
        let p = plant(DMatrix::from_element(1, 1, -a), DMatrix::from_element(1, 1, a), DMatrix::identity(1, 1));
        let d = p.discretise(dt);
        assert!((d.Ad[(0, 0)] - (-a * dt).exp()).abs() < 1e-15);
        assert!((d.Bd[(0, 0)] - (1.0 - (-a * dt).exp())).abs() < 1e-15);
    }

    #[test]
    fn ranks_of_uncontrollable_but_observable_pair() {
        // x1' = 0 (no input reaches it), x2' = u; both measured.
        let p = plant(DMatrix::zeros(2, 2), DMatrix::from_row_slice(2, 1, &[0.0, 1.0]), DMatrix::identity(2, 2));
        let r = p.structural_ranks().unwrap();
        assert_eq!((r.controllability_rank, r.observability_rank), (1, 2));
    }
}
