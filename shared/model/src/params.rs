//! Calibration parameters: geometry, joint/encoder map, marker mountings and effects,
//! loaded from `robot.toml` (format 1) or from a calibrated `params.toml` (a superset).

use nalgebra::Isometry3;

use crate::{Counts, Effect, JointMotion, Joints};

/// Link lengths (mm), needle length (mm) and the front-base pose `T_Bb_Bf`.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// Front proximal link length `l_f` (mm).
    pub l_f: f64,
    /// Front effector extension `l_fe` (mm).
    pub l_fe: f64,
    /// Back proximal link length `l_b` (mm).
    pub l_b: f64,
    /// Back effector extension `l_be` (mm).
    pub l_be: f64,
    /// Perpendicular offset of the needle line from the back gimbal centre (mm).
    pub d_offset: f64,
    /// Needle length from `p_r` to the tip (mm).
    pub l_n: f64,
    /// `T_Bb_Bf`: pose of the front-stage base in the robot base (mm).
    pub front_base: Isometry3<f64>,
}

/// Encoder-to-joint map of robot-model.md §2: `θ = GR · 2π · counts / cpr + θ_off`.
#[derive(Debug, Clone, PartialEq)]
pub struct JointCalibration {
    /// Counts per motor revolution (4 × CPT).
    pub counts_per_rev: [u32; 5],
    /// Gear ratio joint/motor (dimensionless).
    pub gear_ratio: [f64; 5],
    /// Joint offsets θ_off (rad); `None` until homing or calibration defines them.
    pub offset: Option<Joints>,
    /// Nominal joint angles at the mechanical stops used for homing (rad).
    pub home_stops: Joints,
}

/// Marker mountings (mm, rad).
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerMounts {
    /// `T_M_Bb`: robot base in the base-marker frame (known from the fixture).
    pub base_to_robot: Isometry3<f64>,
    /// `T_Ef_Tf`: front marker tool in the front effector frame.
    pub front_mount: Isometry3<f64>,
    /// `T_Eb_Tb`: back marker tool in the back effector frame.
    pub back_mount: Isometry3<f64>,
}

/// The complete robot model: what `robot.toml` holds plus, once calibrated, joint offsets
/// and effects.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotParams {
    /// Geometry (mm).
    pub geometry: Geometry,
    /// Joint/encoder map.
    pub joints: JointCalibration,
    /// Marker mountings.
    pub markers: MarkerMounts,
    /// Tracker frame rate (Hz).
    pub tracker_rate_hz: f64,
    /// Effects beyond the paper's model, applied by [`RobotParams::joints_from_counts`] and FK.
    pub effects: Vec<Effect>,
}

/// Why a parameter file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    /// TOML syntax or type error, with the line reported by the parser.
    #[error("{0}")]
    Syntax(String),
    /// A key is missing or has an invalid value.
    #[error("field `{field}`: {reason}")]
    Field {
        /// Dotted key path, e.g. `joints.gear_ratio`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl RobotParams {
    /// The nominal model of robot-model.md (the `robot.toml` example), without offsets.
    pub fn nominal() -> Self {
        todo!()
    }

    /// Parses a `robot.toml` (format 1) or a calibrated `params.toml`.
    pub fn from_toml_str(text: &str) -> Result<Self, ParamsError> {
        let _ = text;
        todo!()
    }

    /// Serialises the complete model as a `params.toml` readable by [`Self::from_toml_str`].
    pub fn to_toml_string(&self) -> String {
        todo!()
    }

    /// Motor angles θ_enc = 2π·counts/cpr (rad).
    pub fn motor_angles(&self, counts: &Counts) -> Joints {
        let _ = counts;
        todo!()
    }

    /// Joint angles (rad) from counts: `GR·θ_enc + θ_off`, then the joint-side effects
    /// (ripple, backlash given `motion`, compliance). Errors when the offsets are undefined.
    pub fn joints_from_counts(
        &self,
        counts: &Counts,
        motion: &JointMotion,
    ) -> Result<Joints, ParamsError> {
        let _ = (counts, motion);
        todo!()
    }

    /// Inverse of [`Self::joints_from_counts`] for a static pose: the (fractional) counts that
    /// give joint angles `q`. Errors when the offsets are undefined.
    pub fn counts_from_joints(
        &self,
        q: &Joints,
        motion: &JointMotion,
    ) -> Result<[f64; 5], ParamsError> {
        let _ = (q, motion);
        todo!()
    }

    /// The geometry with link-length effects applied (what FK/IK should use).
    pub fn effective_geometry(&self) -> Geometry {
        todo!()
    }
}
