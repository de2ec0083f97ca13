//! The frame tree shown in Foxglove's 3D panel and the transforms that build it, from the
//! tracker's readings and from the model's forward kinematics (docs/robot-model.md §1, §3,
//! §5). Foxglove works in metres, so every translation is converted from mm here.
//!
//! ```text
//! tracker (S) ─┬─ base_marker (M) ── robot_base (Bb) ─┬─ front_base (Bf)
//!              │                                      ├─ front_effector (Ef) ── front_marker (Tf)
//!              │                                      ├─ back_effector (Eb) ── back_marker (Tb)
//!              │                                      └─ needle (N, origin at the tip)
//!              ├─ front_marker_measured
//!              └─ back_marker_measured
//! ```

use nalgebra::{Isometry3, Point3, Quaternion as NQuaternion, Translation3, UnitQuaternion};
use sabr_model::{forward, Joints, KinematicsError, NeedlePose, RobotParams};
use sabr_recording::{Tool, ToolReading, TrackerRow};

use crate::messages::{FrameTransform, Pose, Quaternion, Time, Vector3};

/// The tracker's camera frame `S`.
pub const TRACKER: &str = "tracker";
/// The base marker tool `M`, as the tracker sees it.
pub const BASE_MARKER: &str = "base_marker";
/// The robot base `Bb`.
pub const ROBOT_BASE: &str = "robot_base";
/// The front-stage base `Bf`.
pub const FRONT_BASE: &str = "front_base";
/// The front effector `Ef` (origin at the front gimbal centre).
pub const FRONT_EFFECTOR: &str = "front_effector";
/// The back effector `Eb` (origin at the back gimbal centre).
pub const BACK_EFFECTOR: &str = "back_effector";
/// The front marker tool `Tf` where the model puts it.
pub const FRONT_MARKER: &str = "front_marker";
/// The back marker tool `Tb` where the model puts it.
pub const BACK_MARKER: &str = "back_marker";
/// The needle frame `N` (origin at the tip, z along the needle).
pub const NEEDLE: &str = "needle";
/// The front marker tool `Tf` where the tracker sees it.
pub const FRONT_MARKER_MEASURED: &str = "front_marker_measured";
/// The back marker tool `Tb` where the tracker sees it.
pub const BACK_MARKER_MEASURED: &str = "back_marker_measured";

/// Metres per millimetre.
const M_PER_MM: f64 = 1e-3;

/// A position in mm as a Foxglove vector in metres.
pub fn metres(point: &Point3<f64>) -> Vector3 {
    Vector3 {
        x: point.x * M_PER_MM,
        y: point.y * M_PER_MM,
        z: point.z * M_PER_MM,
    }
}

/// A rotation as a Foxglove quaternion.
pub fn quaternion(rotation: &UnitQuaternion<f64>) -> Quaternion {
    Quaternion {
        x: rotation.i,
        y: rotation.j,
        z: rotation.k,
        w: rotation.w,
    }
}

/// A pose in mm as a Foxglove pose in metres.
pub fn pose(pose: &Isometry3<f64>) -> Pose {
    Pose {
        position: metres(&Point3::from(pose.translation.vector)),
        orientation: quaternion(&pose.rotation),
    }
}

/// The transform `T_parent_child` (mm) at `time`.
pub fn transform(
    time: Time,
    parent: &str,
    child: &str,
    parent_to_child: &Isometry3<f64>,
) -> FrameTransform {
    let Pose {
        position,
        orientation,
    } = pose(parent_to_child);
    FrameTransform {
        timestamp: time,
        parent_frame_id: parent.to_owned(),
        child_frame_id: child.to_owned(),
        translation: position,
        rotation: orientation,
    }
}

/// The transforms that do not change with the joints: `T_M_Bb`, `T_Bb_Bf`, `T_Ef_Tf`,
/// `T_Eb_Tb` of `params`.
pub fn static_transforms(params: &RobotParams, time: Time) -> Vec<FrameTransform> {
    let geometry = params.effective_geometry();
    let markers = &params.markers;
    vec![
        transform(time, BASE_MARKER, ROBOT_BASE, &markers.base_to_robot),
        transform(time, ROBOT_BASE, FRONT_BASE, &geometry.front_base),
        transform(time, FRONT_EFFECTOR, FRONT_MARKER, &markers.front_mount),
        transform(time, BACK_EFFECTOR, BACK_MARKER, &markers.back_mount),
    ]
}

/// The model's moving frames for joint angles `q`: `T_Bb_Ef`, `T_Bb_Eb`, `T_Bb_N`, and the
/// needle pose they come from.
pub fn robot_transforms(
    params: &RobotParams,
    q: &Joints,
    time: Time,
) -> Result<(NeedlePose, Vec<FrameTransform>), KinematicsError> {
    let needle = forward(&params.effective_geometry(), q)?;
    let transforms = vec![
        transform(time, ROBOT_BASE, FRONT_EFFECTOR, &needle.front_effector),
        transform(time, ROBOT_BASE, BACK_EFFECTOR, &needle.back_effector),
        transform(time, ROBOT_BASE, NEEDLE, &needle.needle),
    ];
    Ok((needle, transforms))
}

/// The frame a marker tool's tracker reading places, if it is a pose tool.
fn measured_frame(tool: Tool) -> Option<&'static str> {
    match tool {
        Tool::Base => Some(BASE_MARKER),
        Tool::Front => Some(FRONT_MARKER_MEASURED),
        Tool::Back => Some(BACK_MARKER_MEASURED),
        Tool::Tip => None,
    }
}

/// A tracker pose reading as `T_S_X` (mm), normalising the quaternion.
pub fn reading_pose(quaternion: &[f64; 4], position: &[f64; 3]) -> Isometry3<f64> {
    let [w, x, y, z] = *quaternion;
    Isometry3::from_parts(
        Translation3::new(position[0], position[1], position[2]),
        UnitQuaternion::from_quaternion(NQuaternion::new(w, x, y, z)),
    )
}

/// The transforms of one tracker frame's rows: `T_S_M`, `T_S_Tf`, `T_S_Tb` for the pose tools
/// seen (missing tools and the tip point give none).
pub fn tracker_transforms(rows: &[TrackerRow], time: Time) -> Vec<FrameTransform> {
    rows.iter()
        .filter_map(|row| match (&row.reading, measured_frame(row.tool)) {
            (
                ToolReading::Pose {
                    quaternion,
                    position,
                    ..
                },
                Some(child),
            ) => Some(transform(
                time,
                TRACKER,
                child,
                &reading_pose(quaternion, position),
            )),
            _ => None,
        })
        .collect()
}
