//! Fit layer, for any [`RobotModel`](crate::model::RobotModel): the Levenberg–Marquardt
//! solve ([`solve`]), the joint robust fit of a parameter layout ([`joint_fit`]), the
//! identifiability of its parameters ([`identifiability`]) and the minimal set it leaves
//! ([`pruning`]), ridge-regularised Gauss–Newton steps ([`ridge`]) and held-out checks
//! ([`validation`]).

pub mod identifiability;
pub mod joint_fit;
pub mod pruning;
pub mod ridge;
pub mod solve;
pub mod validation;
