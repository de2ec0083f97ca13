//! Calibration parameters: geometry, joint/encoder map, marker mountings and effects,
//! loaded from `robot.toml` (format 1) or from a calibrated `params.toml` (a superset).
//!
//! The file layout is docs/robot-model.md §7. A calibrated `params.toml` adds
//! `joints.joint_offset = [θ_off,1..5]` (rad), `[[effects]]` tables (an [`Effect`] each, tagged
//! by `kind`) and an optional free-form `[calibration]` table ([`CalibrationInfo`]).

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::effects::{apply_joint_effects, EncoderScale, Link};
use crate::{Counts, Effect, JointMotion, Joints, JOINT_COUNT};

/// The only parameter-file format this crate reads and writes.
pub const FORMAT_VERSION: u32 = 1;

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
    /// Joint-axis misalignment (rad), per joint θ1..θ5: two small rotations of the joint's
    /// axis about the axes perpendicular to it (docs/robot-model.md §3). For θ1, θ2 (axis z
    /// of `Bf`) and θ4, θ5 (axis z of the back stage plane) the tilt is
    /// `Rx(tilt[0])·Ry(tilt[1])` in that frame; for θ3 (axis x of `Bb`) it is
    /// `Ry(tilt[0])·Rz(tilt[1])` in `Bb`. All zero in the paper's model.
    pub axis_tilt: [[f64; 2]; 5],
}

/// Encoder-to-joint map of docs/robot-model.md §2: `θ = GR · 2π · counts / cpr + θ_off`.
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

/// Free-form metadata of a calibration run (the `[calibration]` table of a `params.toml`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CalibrationInfo {
    /// Tracker latency estimated by the calibration (ms), if it was estimated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency_ms: Option<f64>,
    /// Where the calibration came from (e.g. the recording directory).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Any other keys, kept as written.
    #[serde(flatten)]
    pub extra: BTreeMap<String, toml::Value>,
}

/// Where the tracker should see the tools for a needle pose, all in the base-marker frame `M`
/// (mm): `T_M_X = T_M_Bb · T_Bb_X` (docs/robot-model.md §5).
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerPoses {
    /// `T_M_Tf`: the front marker tool.
    pub front: Isometry3<f64>,
    /// `T_M_Tb`: the back marker tool.
    pub back: Isometry3<f64>,
    /// The needle tip in `M` (where the `tip` sphere is).
    pub tip: Point3<f64>,
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
    /// Metadata of the calibration that produced these parameters (`None` in a `robot.toml`).
    pub calibration: Option<CalibrationInfo>,
}

/// Why a parameter file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    /// TOML syntax or type error, as the parser reports it (with line and column).
    #[error("{message}")]
    Syntax {
        /// The parser's message.
        message: String,
        /// 1-based line the parser points at, if it points at one.
        line: Option<usize>,
    },
    /// A key is missing or has an invalid value.
    #[error("field `{field}`: {reason}")]
    Field {
        /// Dotted key path, e.g. `joints.gear_ratio`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl ParamsError {
    /// The 1-based line of `text` (the parsed file) this error is about: the parser's line
    /// for a syntax error, the line that sets the field (or opens its table) for a value
    /// error; `None` when the text does not show it (a field that is absent).
    pub fn line_in(&self, text: &str) -> Option<usize> {
        match self {
            ParamsError::Syntax { line, .. } => *line,
            ParamsError::Field { field, .. } => line_of_field(text, field),
        }
    }

    fn field(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Field {
            field: field.into(),
            reason: reason.into(),
        }
    }

    fn offsets_undefined() -> Self {
        Self::field(
            "joints.joint_offset",
            "the joint offsets are not defined (a robot.toml has none): home or calibrate first",
        )
    }
}

/// The 1-based line of `text` that sets the dotted `field` (`joints.counts_per_rev[2]`: the
/// key `counts_per_rev` under `[joints]`), else the line of its table header.
fn line_of_field(text: &str, field: &str) -> Option<usize> {
    let path = field.split('[').next().unwrap_or(field);
    let (table, key) = path.rsplit_once('.').unwrap_or(("", path));
    let mut current = "";
    let mut header = None;
    for (index, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if let Some(name) = line.strip_prefix('[') {
            current = name
                .trim_start_matches('[')
                .split(']')
                .next()
                .unwrap_or("")
                .trim();
            if current == path {
                return Some(index + 1);
            }
            if current == table && header.is_none() {
                header = Some(index + 1);
            }
            continue;
        }
        let sets_key = line
            .strip_prefix(key)
            .is_some_and(|rest| rest.trim_start().starts_with('='));
        if current == table && sets_key {
            return Some(index + 1);
        }
    }
    header
}

/// Largest tracker latency a parameter set may hold (ms): exposure to arrival of a frame.
pub const MAX_LATENCY_MS: f64 = 1000.0;

/// Iterations and tolerance (rad) of the fixed point that inverts the joint-side effects.
const EFFECT_INVERSION_ITERATIONS: usize = 100;
const EFFECT_INVERSION_TOLERANCE: f64 = 1e-13;

impl RobotParams {
    /// The nominal model of docs/robot-model.md (the `robot.toml` example), without offsets.
    pub fn nominal() -> Self {
        Self {
            geometry: Geometry {
                l_f: 50.0,
                l_fe: 20.0,
                l_b: 50.0,
                l_be: 20.0,
                d_offset: 20.0,
                l_n: 180.0,
                front_base: Isometry3::translation(0.0, 0.0, 100.0),
                axis_tilt: [[0.0; 2]; 5],
            },
            joints: JointCalibration {
                counts_per_rev: [2000, 2000, 4000, 2000, 2000],
                gear_ratio: [0.1, 0.1, 0.05, 0.1, 0.1],
                offset: None,
                home_stops: [-2.2, -0.9, -0.2, -2.55, -0.75],
            },
            markers: MarkerMounts {
                base_to_robot: Isometry3::translation(80.0, -40.0, 50.0),
                front_mount: Isometry3::translation(0.0, 0.0, 15.0),
                back_mount: Isometry3::translation(0.0, 0.0, -15.0),
            },
            tracker_rate_hz: 20.0,
            effects: Vec::new(),
            calibration: None,
        }
    }

    /// Parses a `robot.toml` (format 1) or a calibrated `params.toml`.
    ///
    /// Syntax and type errors carry the parser's line and column; value errors name the
    /// dotted field and the reason.
    pub fn from_toml_str(text: &str) -> Result<Self, ParamsError> {
        let file: ParamsFile = toml::from_str(text).map_err(|error| ParamsError::Syntax {
            message: error.to_string(),
            line: error
                .span()
                .map(|span| text[..span.start.min(text.len())].matches('\n').count() + 1),
        })?;
        let params = file.into_params()?;
        params.validate()?;
        Ok(params)
    }

    /// Serialises the complete model as a `params.toml` readable by [`Self::from_toml_str`].
    /// Numbers round-trip exactly; so do rotations built from rotation vectors of moderate
    /// size (see `rotation_vector`), others come back within about 1 ulp.
    pub fn to_toml_string(&self) -> String {
        toml::to_string(&ParamsFile::from_params(self))
            .expect("the parameter file layout is always representable in TOML")
    }

    /// Checks every value: finite numbers, positive lengths, non-zero gear ratios, joint
    /// indices < 5, positive effective link lengths.
    pub fn validate(&self) -> Result<(), ParamsError> {
        let g = &self.geometry;
        for (name, value) in [
            ("l_f", g.l_f),
            ("l_fe", g.l_fe),
            ("l_b", g.l_b),
            ("l_be", g.l_be),
            ("d_offset", g.d_offset),
            ("l_n", g.l_n),
        ] {
            check_positive(&format!("geometry.{name}"), value)?;
        }
        check_pose("geometry.front_base", &g.front_base)?;
        let j = &self.joints;
        for (i, &cpr) in j.counts_per_rev.iter().enumerate() {
            if cpr == 0 {
                return Err(ParamsError::field(
                    format!("joints.counts_per_rev[{i}]"),
                    "must be positive, got 0",
                ));
            }
        }
        for (i, &ratio) in j.gear_ratio.iter().enumerate() {
            let field = format!("joints.gear_ratio[{i}]");
            check_finite(&field, ratio)?;
            if ratio == 0.0 {
                return Err(ParamsError::field(field, "must not be zero"));
            }
        }
        check_all_finite("joints.home_stops", &j.home_stops)?;
        if let Some(offset) = &j.offset {
            check_all_finite("joints.joint_offset", offset)?;
        }
        let m = &self.markers;
        check_pose("markers.base_to_robot", &m.base_to_robot)?;
        check_pose("markers.front_mount", &m.front_mount)?;
        check_pose("markers.back_mount", &m.back_mount)?;
        check_positive("tracker.rate_hz", self.tracker_rate_hz)?;
        for (i, effect) in self.effects.iter().enumerate() {
            effect
                .validate()
                .map_err(|reason| ParamsError::field(format!("effects[{i}]"), reason))?;
        }
        let e = self.effective_geometry();
        for (name, value) in [
            ("l_f", e.l_f),
            ("l_fe", e.l_fe),
            ("l_b", e.l_b),
            ("l_be", e.l_be),
            ("d_offset", e.d_offset),
        ] {
            if value.is_nan() || value <= 0.0 {
                return Err(ParamsError::field(
                    "effects",
                    format!("link-length effects make {name} = {value}, not positive"),
                ));
            }
        }
        if let Some(calibration) = &self.calibration {
            if let Some(latency) = calibration.latency_ms {
                if !(0.0..=MAX_LATENCY_MS).contains(&latency) {
                    return Err(ParamsError::field(
                        "calibration.latency_ms",
                        format!("latency {latency} ms is outside 0..={MAX_LATENCY_MS} ms"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Motor angles θ_enc = 2π·counts/cpr (rad).
    pub fn motor_angles(&self, counts: &Counts) -> Joints {
        self.motor_angles_fractional(&counts.map(|c| c as f64))
    }

    /// The encoder scale (motor angle per count, gear ratio) the history-dependent effects
    /// use.
    pub fn encoder_scale(&self) -> EncoderScale {
        EncoderScale {
            gear_ratio: self.joints.gear_ratio,
            motor_rad_per_count: std::array::from_fn(|i| {
                std::f64::consts::TAU / f64::from(self.joints.counts_per_rev[i])
            }),
        }
    }

    /// Motor angles θ_enc = 2π·counts/cpr (rad) from fractional counts (e.g. interpolated).
    pub fn motor_angles_fractional(&self, counts: &[f64; 5]) -> Joints {
        std::array::from_fn(|i| {
            std::f64::consts::TAU * counts[i] / f64::from(self.joints.counts_per_rev[i])
        })
    }

    /// Joint angles (rad) from counts: `GR·θ_enc + θ_off`, then the joint-side effects
    /// (ripple, backlash given `motion`, compliance). Errors when the offsets are undefined.
    pub fn joints_from_counts(
        &self,
        counts: &Counts,
        motion: &JointMotion,
    ) -> Result<Joints, ParamsError> {
        self.joints_from_fractional_counts(&counts.map(|c| c as f64), motion)
    }

    /// [`Self::joints_from_counts`] for fractional counts (e.g. interpolated or computed by
    /// [`Self::counts_from_joints`]).
    pub fn joints_from_fractional_counts(
        &self,
        counts: &[f64; 5],
        motion: &JointMotion,
    ) -> Result<Joints, ParamsError> {
        let offset = self
            .joints
            .offset
            .ok_or_else(ParamsError::offsets_undefined)?;
        let motor = self.motor_angles_fractional(counts);
        let paper: Joints =
            std::array::from_fn(|i| self.joints.gear_ratio[i] * motor[i] + offset[i]);
        Ok(apply_joint_effects(
            &self.effects,
            &paper,
            &motor,
            &self.encoder_scale(),
            motion,
        ))
    }

    /// Inverse of [`Self::joints_from_counts`] for a static pose: the (fractional) counts that
    /// give joint angles `q`. Errors when the offsets are undefined, when `q` is not finite or
    /// when the effects cannot be inverted (they would have to be implausibly large).
    pub fn counts_from_joints(
        &self,
        q: &Joints,
        motion: &JointMotion,
    ) -> Result<[f64; 5], ParamsError> {
        let offset = self
            .joints
            .offset
            .ok_or_else(ParamsError::offsets_undefined)?;
        if q.iter().any(|v| !v.is_finite()) {
            return Err(ParamsError::field("q", "joint angles are not finite"));
        }
        let ratio = &self.joints.gear_ratio;
        // Fixed point on the motor angles: θ_enc = (q − θ_off − Δ(θ_enc)) / GR, where Δ is the
        // (small, slowly varying) joint-side effect; it converges when |∂Δ/∂θ_enc| < |GR|.
        let scale = self.encoder_scale();
        let mut motor: Joints = std::array::from_fn(|i| (q[i] - offset[i]) / ratio[i]);
        for _ in 0..EFFECT_INVERSION_ITERATIONS {
            let paper: Joints = std::array::from_fn(|i| ratio[i] * motor[i] + offset[i]);
            let actual = apply_joint_effects(&self.effects, &paper, &motor, &scale, motion);
            let mut largest_error: f64 = 0.0;
            for i in 0..JOINT_COUNT {
                let error = q[i] - actual[i];
                motor[i] += error / ratio[i];
                largest_error = largest_error.max(error.abs());
            }
            if largest_error <= EFFECT_INVERSION_TOLERANCE {
                return Ok(self.counts_from_motor_angles(&motor));
            }
        }
        Err(ParamsError::field(
            "effects",
            "the joint-side effects cannot be inverted (they change too fast with the motor angle)",
        ))
    }

    /// Fractional counts for motor angles θ_enc (rad): `cpr·θ_enc/2π`.
    pub fn counts_from_motor_angles(&self, motor: &Joints) -> [f64; 5] {
        std::array::from_fn(|i| {
            motor[i] * f64::from(self.joints.counts_per_rev[i]) / std::f64::consts::TAU
        })
    }

    /// The geometry with link-length and axis-tilt effects applied (what FK/IK should use).
    pub fn effective_geometry(&self) -> Geometry {
        let mut geometry = self.geometry.clone();
        for effect in &self.effects {
            match *effect {
                Effect::LinkLength { link, delta } => {
                    let length = match link {
                        Link::LF => &mut geometry.l_f,
                        Link::LFe => &mut geometry.l_fe,
                        Link::LB => &mut geometry.l_b,
                        Link::LBe => &mut geometry.l_be,
                        Link::DOffset => &mut geometry.d_offset,
                    };
                    *length += delta;
                }
                Effect::AxisTilt { joint, axis, angle } if joint < JOINT_COUNT && axis < 2 => {
                    geometry.axis_tilt[joint][axis] += angle;
                }
                _ => {}
            }
        }
        geometry
    }
}

fn check_finite(field: &str, value: f64) -> Result<(), ParamsError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ParamsError::field(
            field,
            format!("must be finite, got {value}"),
        ))
    }
}

fn check_positive(field: &str, value: f64) -> Result<(), ParamsError> {
    check_finite(field, value)?;
    if value > 0.0 {
        Ok(())
    } else {
        Err(ParamsError::field(
            field,
            format!("must be positive, got {value}"),
        ))
    }
}

fn check_all_finite(field: &str, values: &[f64]) -> Result<(), ParamsError> {
    for (i, &value) in values.iter().enumerate() {
        check_finite(&format!("{field}[{i}]"), value)?;
    }
    Ok(())
}

fn check_pose(field: &str, pose: &Isometry3<f64>) -> Result<(), ParamsError> {
    check_all_finite(
        &format!("{field}_translation"),
        pose.translation.vector.as_slice(),
    )?;
    check_all_finite(
        &format!("{field}_rotation"),
        pose.rotation.coords.as_slice(),
    )
}

/// A pose from a translation (mm) and a rotation vector (rad).
fn pose(translation: [f64; 3], rotation: [f64; 3]) -> Isometry3<f64> {
    Isometry3::new(Vector3::from(translation), Vector3::from(rotation))
}

/// Translation (mm) and rotation vector (rad) of a pose.
fn pose_parts(pose: &Isometry3<f64>) -> ([f64; 3], [f64; 3]) {
    (
        pose.translation.vector.into(),
        rotation_vector(&pose.rotation),
    )
}

/// The rotation vector (rad) of `rotation`, chosen so that [`pose`] rebuilds exactly the same
/// quaternion (the file round-trips bit for bit) and, among those, with the fewest
/// significant digits. `scaled_axis` alone can be 1 ulp off; for poses built from a rotation
/// vector with components within ±1 rad an exact one is always found (tested). Otherwise (large
/// rotations, quaternions from elsewhere) the nearest is returned: then the file round-trips to
/// within about 1 ulp, and exactly from the second round on.
fn rotation_vector(rotation: &UnitQuaternion<f64>) -> [f64; 3] {
    let exact = |v: [f64; 3]| UnitQuaternion::from_scaled_axis(Vector3::from(v)) == *rotation;
    let nearest: [f64; 3] = rotation.scaled_axis().into();
    for digits in 1..=17 {
        let rounded = nearest.map(|x| round_to_significant_digits(x, digits));
        if exact(rounded) {
            return rounded;
        }
    }
    const ULP_STEPS: [i64; 7] = [0, 1, -1, 2, -2, 3, -3];
    for dx in ULP_STEPS {
        for dy in ULP_STEPS {
            for dz in ULP_STEPS {
                let nudged = [
                    nudge(nearest[0], dx),
                    nudge(nearest[1], dy),
                    nudge(nearest[2], dz),
                ];
                if exact(nudged) {
                    return nudged;
                }
            }
        }
    }
    nearest
}

/// `x` rounded to `digits` significant decimal digits.
fn round_to_significant_digits(x: f64, digits: usize) -> f64 {
    format!("{x:.*e}", digits - 1).parse().unwrap_or(x)
}

/// `x` moved by `steps` units in the last place (same sign; 0 stays 0).
fn nudge(x: f64, steps: i64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let bits = x.to_bits() as i64 + steps;
    f64::from_bits(bits as u64)
}

/// The file layout of docs/robot-model.md §7 (plus the calibrated extensions).
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParamsFile {
    format: u32,
    geometry: GeometryFile,
    joints: JointsFile,
    markers: MarkersFile,
    tracker: TrackerFile,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    effects: Vec<Effect>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    calibration: Option<CalibrationInfo>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GeometryFile {
    l_f: f64,
    l_fe: f64,
    l_b: f64,
    l_be: f64,
    d_offset: f64,
    l_n: f64,
    front_base_translation: [f64; 3],
    front_base_rotation: [f64; 3],
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct JointsFile {
    counts_per_rev: [u32; 5],
    gear_ratio: [f64; 5],
    home_stops: [f64; 5],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    joint_offset: Option<[f64; 5]>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct MarkersFile {
    base_to_robot_translation: [f64; 3],
    base_to_robot_rotation: [f64; 3],
    front_mount_translation: [f64; 3],
    front_mount_rotation: [f64; 3],
    back_mount_translation: [f64; 3],
    back_mount_rotation: [f64; 3],
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TrackerFile {
    rate_hz: f64,
}

impl ParamsFile {
    fn into_params(self) -> Result<RobotParams, ParamsError> {
        if self.format != FORMAT_VERSION {
            return Err(ParamsError::field(
                "format",
                format!(
                    "unsupported format {}, this build reads format {FORMAT_VERSION}",
                    self.format
                ),
            ));
        }
        let g = self.geometry;
        let m = self.markers;
        Ok(RobotParams {
            geometry: Geometry {
                l_f: g.l_f,
                l_fe: g.l_fe,
                l_b: g.l_b,
                l_be: g.l_be,
                d_offset: g.d_offset,
                l_n: g.l_n,
                front_base: pose(g.front_base_translation, g.front_base_rotation),
                axis_tilt: [[0.0; 2]; 5],
            },
            joints: JointCalibration {
                counts_per_rev: self.joints.counts_per_rev,
                gear_ratio: self.joints.gear_ratio,
                offset: self.joints.joint_offset,
                home_stops: self.joints.home_stops,
            },
            markers: MarkerMounts {
                base_to_robot: pose(m.base_to_robot_translation, m.base_to_robot_rotation),
                front_mount: pose(m.front_mount_translation, m.front_mount_rotation),
                back_mount: pose(m.back_mount_translation, m.back_mount_rotation),
            },
            tracker_rate_hz: self.tracker.rate_hz,
            effects: self.effects,
            calibration: self.calibration,
        })
    }

    fn from_params(params: &RobotParams) -> Self {
        let g = &params.geometry;
        let m = &params.markers;
        let (front_base_translation, front_base_rotation) = pose_parts(&g.front_base);
        let (base_to_robot_translation, base_to_robot_rotation) = pose_parts(&m.base_to_robot);
        let (front_mount_translation, front_mount_rotation) = pose_parts(&m.front_mount);
        let (back_mount_translation, back_mount_rotation) = pose_parts(&m.back_mount);
        Self {
            format: FORMAT_VERSION,
            geometry: GeometryFile {
                l_f: g.l_f,
                l_fe: g.l_fe,
                l_b: g.l_b,
                l_be: g.l_be,
                d_offset: g.d_offset,
                l_n: g.l_n,
                front_base_translation,
                front_base_rotation,
            },
            joints: JointsFile {
                counts_per_rev: params.joints.counts_per_rev,
                gear_ratio: params.joints.gear_ratio,
                home_stops: params.joints.home_stops,
                joint_offset: params.joints.offset,
            },
            markers: MarkersFile {
                base_to_robot_translation,
                base_to_robot_rotation,
                front_mount_translation,
                front_mount_rotation,
                back_mount_translation,
                back_mount_rotation,
            },
            tracker: TrackerFile {
                rate_hz: params.tracker_rate_hz,
            },
            effects: params.effects.clone(),
            calibration: params.calibration.clone(),
        }
    }
}
