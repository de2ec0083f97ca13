//! The messages written to the MCAP file, as serde types serialised to JSON. Field names and
//! layouts are those of Foxglove's well-known schemas (`foxglove.*`) and of our own
//! (`sabr.*`, documented in [`crate::schemas`]). Foxglove works in metres: every pose and
//! point here is in metres; our own schemas say their unit in each field name.

use serde::Serialize;

/// A time stamp in Foxglove's `time` layout: seconds and nanoseconds since an epoch (here the
/// host `CLOCK_MONOTONIC` of the recording).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: u64,
    /// Nanoseconds within the second, 0..1e9.
    pub nsec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch.
    pub fn from_ns(ns: u64) -> Self {
        Time {
            sec: ns / 1_000_000_000,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// A 3-D vector or point (metres for positions): `foxglove.Vector3` / `foxglove.Point3`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// A unit quaternion: `foxglove.Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w (the scalar part).
    pub w: f64,
}

/// A pose: `foxglove.Pose` (position in metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Pose {
    /// Position (m).
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `foxglove.FrameTransform`: the pose of `child_frame_id` in `parent_frame_id`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameTransform {
    /// When the transform holds.
    pub timestamp: Time,
    /// The parent frame.
    pub parent_frame_id: String,
    /// The child frame.
    pub child_frame_id: String,
    /// Child origin in the parent frame (m).
    pub translation: Vector3,
    /// Child orientation in the parent frame.
    pub rotation: Quaternion,
}

/// `foxglove.FrameTransforms`: several transforms at once.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameTransforms {
    /// The transforms.
    pub transforms: Vec<FrameTransform>,
}

/// `foxglove.PoseInFrame`: a pose in a named frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseInFrame {
    /// When the pose was measured.
    pub timestamp: Time,
    /// The frame the pose is in.
    pub frame_id: String,
    /// The pose (m).
    pub pose: Pose,
}

/// `foxglove.Log`: one line of text in Foxglove's Log panel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Log {
    /// When it happened.
    pub timestamp: Time,
    /// Severity: 2 = INFO (Foxglove's `LogLevel`).
    pub level: u8,
    /// The text.
    pub message: String,
    /// Who logged it.
    pub name: String,
    /// Source file (empty: none).
    pub file: String,
    /// Source line (0: none).
    pub line: u32,
}

/// `sabr.JointState`: one encoder sample and the joint angles the model gives for it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointState {
    /// The sample's host time stamp.
    pub timestamp: Time,
    /// Joint names `theta1`..`theta5`.
    pub name: [&'static str; 5],
    /// Raw encoder counts c1..c5.
    pub counts: [i64; 5],
    /// Joint angles θ1..θ5 (rad); `None` while the joint offsets are unknown.
    pub position_rad: Option<[f64; 5]>,
}

/// Residual of one marker tool: measured minus predicted, in the base-marker frame `M`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ToolResidual {
    /// Position residual (mm) in `M`.
    pub position_mm: [f64; 3],
    /// Its length (mm).
    pub distance_mm: f64,
    /// Rotation angle between measured and predicted orientation (deg); `None` for the tip.
    pub angle_deg: Option<f64>,
}

/// `sabr.MarkerResidual`: the calibrated model against one tracker frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MarkerResidual {
    /// The tracker frame's host arrival stamp.
    pub timestamp: Time,
    /// The tracker's frame counter.
    pub frame: u32,
    /// The front marker `Tf` (`None`: not seen, or no model prediction).
    pub front: Option<ToolResidual>,
    /// The back marker `Tb`.
    pub back: Option<ToolResidual>,
    /// The tip sphere.
    pub tip: Option<ToolResidual>,
}

/// `foxglove.Color`, components 0..1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Color {
    /// Red.
    pub r: f64,
    /// Green.
    pub g: f64,
    /// Blue.
    pub b: f64,
    /// Opacity.
    pub a: f64,
}

/// `foxglove.SpherePrimitive`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpherePrimitive {
    /// Centre and orientation (m).
    pub pose: Pose,
    /// Diameters along x, y, z (m).
    pub size: Vector3,
    /// Colour.
    pub color: Color,
}

/// `foxglove.LinePrimitive`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LinePrimitive {
    /// 0 = LINE_STRIP (Foxglove's `LineType`).
    #[serde(rename = "type")]
    pub kind: u8,
    /// Origin of the points (m).
    pub pose: Pose,
    /// Width (m, or pixels when `scale_invariant`).
    pub thickness: f64,
    /// Whether `thickness` is in pixels.
    pub scale_invariant: bool,
    /// The points (m).
    pub points: Vec<Vector3>,
    /// Colour of the whole line.
    pub color: Color,
    /// Per-point colours (empty: `color`).
    pub colors: Vec<Color>,
    /// Point indices (empty: all points in order).
    pub indices: Vec<u32>,
}

/// `foxglove.SceneEntity` with the primitive kinds this crate draws (the others are empty).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneEntity {
    /// When it was made.
    pub timestamp: Time,
    /// The frame it is drawn in.
    pub frame_id: String,
    /// Identifier (an entity replaces an earlier one with the same id).
    pub id: String,
    /// How long it stays (zero: until replaced).
    pub lifetime: Time,
    /// Whether it follows `frame_id` as that frame moves.
    pub frame_locked: bool,
    /// Key-value metadata (none).
    pub metadata: Vec<()>,
    /// Arrows (none).
    pub arrows: Vec<()>,
    /// Cubes (none).
    pub cubes: Vec<()>,
    /// Spheres.
    pub spheres: Vec<SpherePrimitive>,
    /// Cylinders (none).
    pub cylinders: Vec<()>,
    /// Lines.
    pub lines: Vec<LinePrimitive>,
    /// Triangle lists (none).
    pub triangles: Vec<()>,
    /// Texts (none).
    pub texts: Vec<()>,
    /// Models (none).
    pub models: Vec<()>,
}

/// `foxglove.SceneUpdate`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneUpdate {
    /// Deletions (none).
    pub deletions: Vec<()>,
    /// Entities to add or replace.
    pub entities: Vec<SceneEntity>,
}
