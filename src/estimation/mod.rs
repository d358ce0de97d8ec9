//! Estimation building blocks shared by the detectors: the extended Kalman filter and its
//! strong-tracking forms ([`stekf`]), and the Bayesian model-probability recursion of multiple-model
//! banks ([`bank`]).
//!
//! Everything here is fixed-size (nalgebra `SMatrix`) because these filters run every sample of every
//! trial; numerical trouble (a singular innovation covariance, a covariance that lost symmetry or
//! positive definiteness, a non-finite estimate) is counted and reported, never a panic.

pub mod bank;
pub mod fixed;
pub mod stekf;
pub mod ukf;

pub use bank::{FloorRule, LikelihoodForm, ModelProbabilities};
pub use stekf::{DiscreteModel, Fading, FilterHealth, Innovation, Stekf};
