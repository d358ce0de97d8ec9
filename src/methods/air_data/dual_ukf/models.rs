//! The two models of method 002's dual UKF (module docs of [`super`]): the no-fault model of the body
//! velocity and the fault model with the three air-data biases, as sigma-point models.
#![allow(non_snake_case)]

use nalgebra::{SVector, Vector3};

use crate::estimation::DiscreteModel;
use crate::estimation::ukf::{SigmaModel, SigmaPoints};
use crate::methods::air_data::flight::{InertialInterval, air_data_from_velocity, propagate_velocity};

/// Models: 0 no fault, 1 fault (biases).
pub const MODELS: usize = 2;
/// Air-data components (airspeed, alpha, beta).
pub const COMPONENTS: usize = 3;

/// The no-fault model: `x = (u, v, w)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoFaultModel {
    pub dt_s: f64,
}

impl DiscreteModel<3, 3> for NoFaultModel {
    type Input = InertialInterval;
    fn transition(&self, x: &SVector<f64, 3>, u: &InertialInterval) -> SVector<f64, 3> {
        propagate_velocity(x, u, self.dt_s)
    }
    fn measurement(&self, x: &SVector<f64, 3>) -> SVector<f64, 3> {
        air_data_from_velocity(x).to_vector()
    }
}

impl SigmaModel<3, 3> for NoFaultModel {}

/// The fault model: `x = (u, v, w, b_V, b_alpha, b_beta)`, biases constant (their random walk is in `Q`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultModel {
    pub dt_s: f64,
}

impl DiscreteModel<6, 3> for FaultModel {
    type Input = InertialInterval;
    fn transition(&self, x: &SVector<f64, 6>, u: &InertialInterval) -> SVector<f64, 6> {
        let velocity = x.fixed_rows::<3>(0).into_owned();
        let next = propagate_velocity(&velocity, u, self.dt_s);
        SVector::<f64, 6>::new(next[0], next[1], next[2], x[3], x[4], x[5])
    }
    fn measurement(&self, x: &SVector<f64, 6>) -> SVector<f64, 3> {
        air_data_from_velocity(&x.fixed_rows::<3>(0).into_owned()).to_vector() + x.fixed_rows::<3>(3)
    }
}

/// The fault model's points share the centre's air data and propagated velocity where their velocity is
/// the centre's to the bit: the bias columns of the lower Cholesky factor are zero in the velocity rows,
/// so six of the 13 points move only the biases. Atan2, asin and the propagation are then evaluated for
/// 7 points instead of 13, with the same numbers (the test compares them to the bit).
impl SigmaModel<6, 3> for FaultModel {
    fn measurement_points(&self, X: &SigmaPoints<6, 6>) -> SigmaPoints<6, 3> {
        let centre = velocity_of(&X.center);
        let centre_air = air_data_from_velocity(&centre).to_vector();
        X.map(|x| {
            let v = velocity_of(x);
            let air = if same_bits(v.as_slice(), centre.as_slice()) {
                centre_air
            } else {
                air_data_from_velocity(&v).to_vector()
            };
            air + x.fixed_rows::<3>(3)
        })
    }

    fn transition_points(&self, X: &SigmaPoints<6, 6>, u: &InertialInterval) -> SigmaPoints<6, 6> {
        let centre = velocity_of(&X.center);
        let centre_next = propagate_velocity(&centre, u, self.dt_s);
        X.map(|x| {
            let v = velocity_of(x);
            let next = if same_bits(v.as_slice(), centre.as_slice()) {
                centre_next
            } else {
                propagate_velocity(&v, u, self.dt_s)
            };
            SVector::<f64, 6>::new(next[0], next[1], next[2], x[3], x[4], x[5])
        })
    }
}

pub(super) fn velocity_of(x: &SVector<f64, 6>) -> Vector3<f64> {
    x.fixed_rows::<3>(0).into_owned()
}

/// Every number of `a` has the bits of its counterpart in `b` (so -0.0 differs from 0.0, and a NaN
/// equals a NaN of the same bits).
pub(super) fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(p, q)| p.to_bits() == q.to_bits())
}
