//! The SABR robot model: joint/encoder map, forward and inverse kinematics of the two
//! 5-bar stages and the needle, marker poses, calibration parameters, effect models and the
//! calibration session plan (which the simulator and the motion executor both run).
//!
//! Everything follows `docs/robot-model.md` (the project contract). Units: millimetres and
//! radians. The only I/O is reading a parameter file ([`params_file`], the one reader every
//! process uses); everything else works on strings and values.
//!
//! Serial and branched arms described by URDF are [`tree::KinematicTree`]s
//! ([`KinematicTree::from_urdf_str`]): forward kinematics of every link, geometric error
//! parameters with their Jacobian, gravity torques.

pub mod effects;
pub mod kinematics;
pub mod params;
pub mod params_file;
pub mod plan;
pub mod tree;
pub mod urdf;

pub use effects::linear::EffectSlot;
pub use effects::spec::{EffectSpec, EffectSpecError};
pub use effects::{
    DirectionTracker, Effect, EffectField, EncoderScale, JointMotion, Link,
    DIRECTION_DEAD_BAND_COUNTS,
};
pub use kinematics::realtime;
pub use kinematics::{forward, inverse, KinematicsError, NeedlePose, HOME_JOINTS};
pub use params::{
    CalibrationInfo, Geometry, JointCalibration, MarkerMounts, MarkerPoses, ParamsError,
    RobotParams, MAX_LATENCY_MS,
};
pub use params_file::{parse_params_file, read_params_file, ParamsFileError};
pub use tree::{KinematicTree, LinkId, TargetJacobian, TreeError, TreeState};

/// A joint vector θ1..θ5 in radians (docs/robot-model.md §2).
pub type Joints = [f64; 5];

/// Raw incremental encoder counts c1..c5, zero at power-up.
pub type Counts = [i64; 5];

/// Number of joints (and motors) of the robot.
pub const JOINT_COUNT: usize = 5;
