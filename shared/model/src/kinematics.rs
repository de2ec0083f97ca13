//! Forward and inverse kinematics (robot-model.md §3–§4). All poses in `Bb`, mm and rad.

use nalgebra::{Isometry3, Point3, Unit, Vector3};

use crate::{Geometry, Joints};

/// The result of forward kinematics: needle and effector poses in `Bb`.
#[derive(Debug, Clone, PartialEq)]
pub struct NeedlePose {
    /// Needle tip `p_n` in `Bb` (mm).
    pub tip: Point3<f64>,
    /// Needle direction `z_N` in `Bb` (unit, towards the tip).
    pub direction: Unit<Vector3<f64>>,
    /// `T_Bb_N`: needle frame (origin at the tip).
    pub needle: Isometry3<f64>,
    /// `T_Bb_Ef`: front effector frame (origin at `p_f`).
    pub front_effector: Isometry3<f64>,
    /// `T_Bb_Eb`: back effector frame (origin at `p_b`).
    pub back_effector: Isometry3<f64>,
}

/// Why a kinematic solution does not exist.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum KinematicsError {
    /// An input is NaN or infinite.
    #[error("input is not finite: {0}")]
    NotFinite(&'static str),
    /// The target is outside the workspace; the message says which constraint failed.
    #[error("unreachable: {0}")]
    Unreachable(String),
}

/// Forward kinematics: joint angles → needle and effector poses in `Bb`.
pub fn forward(geometry: &Geometry, q: &Joints) -> Result<NeedlePose, KinematicsError> {
    let _ = (geometry, q);
    todo!()
}

/// Inverse kinematics: tip `p_n` (mm, `Bb`) and needle direction `z_N` → joints, the
/// solution nearest `near` (wrapped to within π of it). Unreachable targets are an error.
pub fn inverse(
    geometry: &Geometry,
    tip: &Point3<f64>,
    direction: &Vector3<f64>,
    near: &Joints,
) -> Result<Joints, KinematicsError> {
    let _ = (geometry, tip, direction, near);
    todo!()
}
