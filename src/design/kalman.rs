//! The steady-state Kalman filter of a discrete LTI model, in predictor form (a block):
//!
//! ```text
//! P = Ad P Ad' - Ad P C' (C P C' + R)^-1 C P Ad' + Q      the discrete algebraic Riccati equation
//! S = C P C' + R                                         innovation covariance
//! K = Ad P C' S^-1                                       xhat(k+1) = Ad xhat(k) + Bd u(k) + K (y(k) - C xhat(k) - D u(k))
//! ```
//! solved by iterating the Riccati recursion from `P = Q` until it stops changing. `Q` and `R` are the
//! process noise per step and the sensor noise covariances.
#![allow(non_snake_case)]

use nalgebra::DMatrix;

use super::DesignError;

/// A steady-state Kalman filter's gain and covariances.
#[derive(Debug, Clone)]
pub struct SteadyKalman {
    /// Predictor gain (n x m).
    pub K: DMatrix<f64>,
    /// Prior state covariance, the solution of the Riccati equation.
    pub P: DMatrix<f64>,
    /// Innovation covariance `C P C' + R`.
    pub S: DMatrix<f64>,
}

/// The steady-state filter of `(Ad, C)` with process noise `Q` per step and sensor noise `R`.
pub fn steady_state_kalman(
    Ad: &DMatrix<f64>,
    C: &DMatrix<f64>,
    Q: &DMatrix<f64>,
    R: &DMatrix<f64>,
) -> Result<SteadyKalman, DesignError> {
    let mut P = Q.clone();
    for _ in 0..200_000 {
        let S = C * &P * C.transpose() + R;
        let S_inv = S.clone().try_inverse().ok_or(DesignError::Decomposition { what: "inverse of C P C' + R" })?;
        let APCt = Ad * &P * C.transpose();
        let next = Ad * &P * Ad.transpose() - &APCt * &S_inv * APCt.transpose() + Q;
        let next = (&next + next.transpose()) * 0.5;
        let change = (&next - &P).amax();
        P = next;
        if !P.iter().all(|v| v.is_finite()) {
            break;
        }
        if change <= 1e-15 * P.amax().max(f64::MIN_POSITIVE) {
            let S = C * &P * C.transpose() + R;
            let S_inv = S.clone().try_inverse().ok_or(DesignError::Decomposition { what: "inverse of C P C' + R" })?;
            let K = Ad * &P * C.transpose() * S_inv;
            return Ok(SteadyKalman { K, P, S });
        }
    }
    Err(DesignError::Decomposition { what: "the Riccati recursion (no steady state: is (Ad, C) detectable?)" })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::LtiPlant;

    fn matrix(t: &toml::Value) -> DMatrix<f64> {
        let rows: Vec<Vec<f64>> = t
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r.as_array().unwrap().iter().map(|v| v.as_float().unwrap()).collect())
            .collect();
        DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
    }

    /// The seed-000 plant at 0.01 s, sensor sigmas of the robustness deck, process noise 1e-4 per step on
    /// every state: the gain against SciPy 1.17's `solve_discrete_are(Ad.T, C.T, Q, R)`, independent of
    /// this code.
    #[test]
    fn the_gain_matches_an_independent_riccati_solution_for_the_seed_plant() {
        let text = include_str!("../../studies/seed000_robustness.toml");
        let deck: toml::Table = toml::from_str(text).unwrap();
        let (a, c) = (matrix(&deck["plant"]["a"]), matrix(&deck["plant"]["c"]));
        let sigma: Vec<f64> =
            deck["noise"]["sensor_sigma"].as_array().unwrap().iter().map(|v| v.as_float().unwrap()).collect();
        let plant = LtiPlant {
            state_names: vec![String::new(); 5],
            input_names: vec![String::new(); 2],
            output_names: vec![String::new(); 6],
            A: a,
            B: DMatrix::zeros(5, 2),
            C: c,
            D: DMatrix::zeros(6, 2),
        };
        let d = plant.discretise(0.01);
        let Q = DMatrix::from_diagonal_element(5, 5, 1e-4);
        let R = DMatrix::from_fn(6, 6, |i, j| if i == j { sigma[i] * sigma[i] } else { 0.0 });
        let k = steady_state_kalman(&d.Ad, &d.C, &Q, &R).unwrap();
        // P solves the DARE.
        let S_inv = k.S.clone().try_inverse().unwrap();
        let APCt = &d.Ad * &k.P * d.C.transpose();
        let residual = &d.Ad * &k.P * d.Ad.transpose() - &APCt * S_inv * APCt.transpose() + &Q - &k.P;
        assert!(residual.amax() < 1e-12 * k.P.amax(), "{}", residual.amax());
        // Reference entries of K, printed by SciPy.
        for (i, j, want) in KALMAN_REFERENCE {
            assert!((k.K[(i, j)] - want).abs() < 1e-9, "K[{i},{j}] = {} against {want}", k.K[(i, j)]);
        }
    }

    /// Printed by `scripts/kalman_reference.py` (SciPy's matrix exponential and `solve_discrete_are`).
    const KALMAN_REFERENCE: [(usize, usize, f64); 30] = [
        (0, 0, 0.0951249219725038),
        (0, 1, -8.76063986602937e-17),
        (0, 2, -1.6951037188736074e-15),
        (0, 3, -3.1330933915583134e-16),
        (0, 4, -2.257029404955389e-16),
        (0, 5, 6.796440573540765e-18),
        (1, 0, 2.6610143218830175e-20),
        (1, 1, 0.6495254804317493),
        (1, 2, -0.012359308766185535),
        (1, 3, 0.3236115857699513),
        (1, 4, -0.32591389466179393),
        (1, 5, -1.9488073486906726e-07),
        (2, 0, -4.1112223104075666e-18),
        (2, 1, -0.050945127521055567),
        (2, 2, 0.8028429370400155),
        (2, 3, -0.025106386250023077),
        (2, 4, 0.025838741271032643),
        (2, 5, 7.568441041663678e-07),
        (3, 0, -1.6706139121720618e-19),
        (3, 1, 0.31670285370002677),
        (3, 2, 0.008122701613880956),
        (3, 3, 0.6458360497493365),
        (3, 4, 0.3291331960493138),
        (3, 5, 1.89685446334683e-07),
        (4, 0, 1.69523682087911e-16),
        (4, 1, -0.9121702637195305),
        (4, 2, 0.035757795082531144),
        (4, 3, 0.8979705228937421),
        (4, 4, 1.8101407866132824),
        (4, 5, 0.021643420841377003),
    ];
}
