//! The SABR robot model: joint/encoder map, forward and inverse kinematics of the two
//! 5-bar stages and the needle, marker poses, calibration parameters and effect models.
//!
//! Everything follows `docs/robot-model.md` (the project contract). Units: millimetres and
//! radians. No I/O: parameter files are parsed from and written to strings.

pub mod effects;
pub mod kinematics;
pub mod params;

pub use effects::{DirectionTracker, Effect, JointMotion, Link, DIRECTION_DEAD_BAND_COUNTS};
pub use kinematics::{forward, inverse, KinematicsError, NeedlePose, HOME_JOINTS};
pub use params::{
    CalibrationInfo, Geometry, JointCalibration, MarkerMounts, MarkerPoses, ParamsError,
    RobotParams,
};

/// A joint vector θ1..θ5 in radians (docs/robot-model.md §2).
pub type Joints = [f64; 5];

/// Raw incremental encoder counts c1..c5, zero at power-up.
pub type Counts = [i64; 5];

/// Number of joints (and motors) of the robot.
pub const JOINT_COUNT: usize = 5;
