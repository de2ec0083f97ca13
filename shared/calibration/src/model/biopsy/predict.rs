//! What the biopsy model predicts for one observation: joint angles from the encoder
//! counts (shifted to the model's latency, effects applied), the needle and effector poses by
//! forward kinematics, and the marker poses; and the raw residual of each measured quantity.

use nalgebra::Isometry3;
use sabr_model::{forward, Geometry, Joints, KinematicsError, MarkerMounts, NeedlePose};

use crate::data::session::Observation;
use crate::math::se3::pose_residual;
use crate::model::biopsy::{BiopsyModel, BACK, FRONT, TIP};
use crate::model::QuantityKind;

/// What the model predicts for one observation (all in `Bb`).
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Joint angles (rad).
    pub joints: Joints,
    /// Needle and effector poses.
    pub pose: NeedlePose,
    /// Predicted `T_Bb_Tf`.
    pub front_marker: Isometry3<f64>,
    /// Predicted `T_Bb_Tb`.
    pub back_marker: Isometry3<f64>,
}

/// Joint angles (rad) of `model` for an observation (counts shifted to the model latency).
pub fn joint_angles(model: &BiopsyModel, obs: &Observation) -> Joints {
    let counts = obs.counts_at_latency(model.latency_s);
    let robot = &model.robot;
    let motor = robot.motor_angles_fractional(&counts);
    let offset = robot.joints.offset.unwrap_or_default();
    let paper: Joints = std::array::from_fn(|j| robot.joints.gear_ratio[j] * motor[j] + offset[j]);
    if robot.effects.is_empty() {
        paper
    } else {
        sabr_model::effects::apply_joint_effects(
            &robot.effects,
            &paper,
            &motor,
            &robot.encoder_scale(),
            &obs.motion,
        )
    }
}

/// Marker poses `T_Bb_Tf`, `T_Bb_Tb` of a needle pose with the given mountings.
pub fn marker_poses(pose: &NeedlePose, mounts: &MarkerMounts) -> (Isometry3<f64>, Isometry3<f64>) {
    (
        pose.front_effector * mounts.front_mount,
        pose.back_effector * mounts.back_mount,
    )
}

/// Full prediction at joints `q` with an already effective `geometry`.
pub fn predict_at(
    geometry: &Geometry,
    mounts: &MarkerMounts,
    q: Joints,
) -> Result<Prediction, KinematicsError> {
    let pose = forward(geometry, &q)?;
    let (front_marker, back_marker) = marker_poses(&pose, mounts);
    Ok(Prediction {
        joints: q,
        pose,
        front_marker,
        back_marker,
    })
}

/// Full prediction of `model` for an observation.
pub fn predict(model: &BiopsyModel, obs: &Observation) -> Result<Prediction, KinematicsError> {
    predict_at(
        &model.robot.effective_geometry(),
        &model.robot.markers,
        joint_angles(model, obs),
    )
}

/// Raw residual (measured − predicted) of one quantity: `[dx, dy, dz]` mm then, for the
/// marker poses, the rotation vector (rad). `None` when the observation lacks the
/// measurement.
pub fn raw_residual(
    prediction: &Prediction,
    obs: &Observation,
    kind: QuantityKind,
) -> Option<[f64; 6]> {
    match kind {
        FRONT => Some(pose_residual(&obs.front?, &prediction.front_marker)),
        BACK => Some(pose_residual(&obs.back?, &prediction.back_marker)),
        TIP => {
            let d = obs.tip? - prediction.pose.tip;
            Some([d.x, d.y, d.z, 0.0, 0.0, 0.0])
        }
        _ => None,
    }
}
