//! Predictions and residuals of one observation, the tracker noise model that whitens them,
//! and the blocks the fits stack into one residual vector.

use nalgebra::Isometry3;
use sabr_model::{forward, Geometry, Joints, KinematicsError, MarkerMounts, NeedlePose};

use crate::layout::CalibModel;
pub use crate::noise::{NoiseModel, ToolNoise};
use crate::observations::Observation;
use crate::se3;

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
pub fn joint_angles(model: &CalibModel, obs: &Observation) -> Joints {
    let counts = obs.counts_at_latency(model.latency_s);
    let robot = &model.robot;
    let motor = robot.motor_angles_fractional(&counts);
    let offset = robot.joints.offset.unwrap_or_default();
    let paper: Joints = std::array::from_fn(|j| robot.joints.gear_ratio[j] * motor[j] + offset[j]);
    if robot.effects.is_empty() {
        paper
    } else {
        sabr_model::effects::apply_joint_effects(&robot.effects, &paper, &motor, &obs.motion)
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
pub fn predict(model: &CalibModel, obs: &Observation) -> Result<Prediction, KinematicsError> {
    predict_at(
        &model.robot.effective_geometry(),
        &model.robot.markers,
        joint_angles(model, obs),
    )
}

/// Raw pose residual: position (mm) and rotation vector (rad), measured minus predicted,
/// both in `Bb`.
pub fn pose_residual(measured: &Isometry3<f64>, predicted: &Isometry3<f64>) -> [f64; 6] {
    let dp = measured.translation.vector - predicted.translation.vector;
    let dr = se3::rotation_log(&(measured.rotation * predicted.rotation.inverse()));
    [dp.x, dp.y, dp.z, dr.x, dr.y, dr.z]
}

/// A measured quantity of an observation that yields residuals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// Front marker pose (6 residuals).
    Front,
    /// Back marker pose (6 residuals).
    Back,
    /// Tip sphere position (3 residuals).
    Tip,
}

impl Quantity {
    /// Number of residual rows.
    pub fn dim(self) -> usize {
        match self {
            Quantity::Tip => 3,
            _ => 6,
        }
    }

    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Quantity::Front => "front",
            Quantity::Back => "back",
            Quantity::Tip => "tip",
        }
    }
}

/// Raw residual (measured − predicted) of one quantity: `[dx, dy, dz]` mm then, for poses,
/// the rotation vector (rad). `None` when the observation lacks the measurement.
pub fn raw_residual(
    prediction: &Prediction,
    obs: &Observation,
    quantity: Quantity,
) -> Option<[f64; 6]> {
    match quantity {
        Quantity::Front => Some(pose_residual(&obs.front?, &prediction.front_marker)),
        Quantity::Back => Some(pose_residual(&obs.back?, &prediction.back_marker)),
        Quantity::Tip => {
            let d = obs.tip? - prediction.pose.tip;
            Some([d.x, d.y, d.z, 0.0, 0.0, 0.0])
        }
    }
}

/// One block of the stacked residual vector: a quantity of an observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Block {
    /// Index of the observation in the fitted slice.
    pub obs: usize,
    /// Which measurement.
    pub quantity: Quantity,
    /// First row in the stacked vector.
    pub row: usize,
}

/// The blocks of a set of observations: front and back poses wherever seen, the tip
/// wherever seen and `use_tip` allows. Returns the blocks and the number of rows.
pub fn blocks_of(
    observations: &[Observation],
    use_tip: impl Fn(&Observation) -> bool,
) -> (Vec<Block>, usize) {
    let mut blocks = Vec::new();
    let mut row = 0;
    for (index, obs) in observations.iter().enumerate() {
        let present = [
            (Quantity::Front, obs.front.is_some()),
            (Quantity::Back, obs.back.is_some()),
            (Quantity::Tip, obs.tip.is_some() && use_tip(obs)),
        ];
        for (quantity, seen) in present {
            if seen {
                blocks.push(Block {
                    obs: index,
                    quantity,
                    row,
                });
                row += quantity.dim();
            }
        }
    }
    (blocks, row)
}

/// Raw residual of every block (`None` where the kinematics fail), one prediction per
/// observation.
pub fn raw_block_residuals(
    model: &CalibModel,
    observations: &[Observation],
    blocks: &[Block],
) -> Vec<Option<[f64; 6]>> {
    let geometry = model.robot.effective_geometry();
    let mut out = Vec::with_capacity(blocks.len());
    for group in blocks.chunk_by(|a, b| a.obs == b.obs) {
        let obs = &observations[group[0].obs];
        let prediction = predict_at(&geometry, &model.robot.markers, joint_angles(model, obs)).ok();
        for block in group {
            out.push(
                prediction
                    .as_ref()
                    .and_then(|p| raw_residual(p, obs, block.quantity)),
            );
        }
    }
    out
}
