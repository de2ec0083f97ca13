//! The JSON schemas written into the MCAP file (schema encoding `jsonschema`), one per message
//! type of [`crate::messages`]. The `foxglove.*` ones follow Foxglove's published JSON
//! schemas, so Foxglove recognises them by name (3D panel, Log panel); `sabr.JointState` and
//! `sabr.MarkerResidual` are our own and documented here and in docs/robot-model.md §8.

use serde_json::{json, Value};

/// A schema: its name (what Foxglove matches on) and its JSON Schema text.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    /// The schema name, e.g. `foxglove.FrameTransforms`.
    pub name: &'static str,
    /// The JSON Schema document.
    pub json: Value,
}

impl Schema {
    /// The JSON Schema as bytes (what an MCAP schema record holds).
    pub fn bytes(&self) -> Vec<u8> {
        self.json.to_string().into_bytes()
    }
}

fn time(description: &str) -> Value {
    json!({
        "type": "object", "title": "time", "description": description,
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}
        }
    })
}

fn vector3(title: &str, description: &str) -> Value {
    json!({
        "type": "object", "title": title, "description": description,
        "properties": {
            "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}
        }
    })
}

fn quaternion(description: &str) -> Value {
    json!({
        "type": "object", "title": "foxglove.Quaternion", "description": description,
        "properties": {
            "x": {"type": "number"}, "y": {"type": "number"},
            "z": {"type": "number"}, "w": {"type": "number"}
        }
    })
}

fn pose(description: &str) -> Value {
    json!({
        "type": "object", "title": "foxglove.Pose", "description": description,
        "properties": {
            "position": vector3("foxglove.Vector3", "Point denoting position in 3D space"),
            "orientation": quaternion("Quaternion denoting orientation in 3D space")
        }
    })
}

fn color() -> Value {
    json!({
        "type": "object", "title": "foxglove.Color", "description": "A color in RGBA format",
        "properties": {
            "r": {"type": "number"}, "g": {"type": "number"},
            "b": {"type": "number"}, "a": {"type": "number"}
        }
    })
}

fn frame_transform() -> Value {
    json!({
        "type": "object", "title": "foxglove.FrameTransform",
        "description": "A transform between two reference frames in 3D space",
        "properties": {
            "timestamp": time("Timestamp of transform"),
            "parent_frame_id": {"type": "string", "description": "Name of the parent frame"},
            "child_frame_id": {"type": "string", "description": "Name of the child frame"},
            "translation": vector3("foxglove.Vector3",
                "Translation component of the transform (m)"),
            "rotation": quaternion("Rotation component of the transform")
        }
    })
}

/// `foxglove.FrameTransforms`.
pub fn frame_transforms() -> Schema {
    Schema {
        name: "foxglove.FrameTransforms",
        json: json!({
            "title": "foxglove.FrameTransforms",
            "description": "An array of FrameTransform messages",
            "type": "object",
            "properties": {
                "transforms": {"type": "array", "items": frame_transform(),
                    "description": "Array of transforms"}
            }
        }),
    }
}

/// `foxglove.PoseInFrame`.
pub fn pose_in_frame() -> Schema {
    Schema {
        name: "foxglove.PoseInFrame",
        json: json!({
            "title": "foxglove.PoseInFrame",
            "description": "A timestamped pose for an object or reference frame in 3D space",
            "type": "object",
            "properties": {
                "timestamp": time("Timestamp of pose"),
                "frame_id": {"type": "string", "description": "Frame of reference for pose position and orientation"},
                "pose": pose("Pose in 3D space")
            }
        }),
    }
}

/// `foxglove.Log`.
pub fn log() -> Schema {
    Schema {
        name: "foxglove.Log",
        json: json!({
            "title": "foxglove.Log",
            "description": "A log message",
            "type": "object",
            "properties": {
                "timestamp": time("Timestamp of log message"),
                "level": {"title": "foxglove.LogLevel", "description": "Log level",
                    "oneOf": [
                        {"title": "UNKNOWN", "const": 0}, {"title": "DEBUG", "const": 1},
                        {"title": "INFO", "const": 2}, {"title": "WARNING", "const": 3},
                        {"title": "ERROR", "const": 4}, {"title": "FATAL", "const": 5}
                    ]},
                "message": {"type": "string", "description": "Log message"},
                "name": {"type": "string", "description": "Process or node name"},
                "file": {"type": "string", "description": "Filename"},
                "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"}
            }
        }),
    }
}

/// `foxglove.SceneUpdate`, with the primitives this crate draws (spheres and lines) spelled
/// out; the other primitive arrays are always empty.
pub fn scene_update() -> Schema {
    let unused = json!({"type": "array", "items": {"type": "object"},
        "description": "Not used by sabr (always empty)"});
    let sphere = json!({
        "type": "object", "title": "foxglove.SpherePrimitive",
        "properties": {
            "pose": pose("Position of the center of the sphere and orientation of the sphere"),
            "size": vector3("foxglove.Vector3", "Size (diameter) of the sphere along each axis"),
            "color": color()
        }
    });
    let line = json!({
        "type": "object", "title": "foxglove.LinePrimitive",
        "properties": {
            "type": {"title": "foxglove.LineType", "oneOf": [
                {"title": "LINE_STRIP", "const": 0}, {"title": "LINE_LOOP", "const": 1},
                {"title": "LINE_LIST", "const": 2}]},
            "pose": pose("Origin of lines relative to reference frame"),
            "thickness": {"type": "number", "minimum": 0},
            "scale_invariant": {"type": "boolean"},
            "points": {"type": "array", "items": vector3("foxglove.Point3", "Point")},
            "color": color(),
            "colors": {"type": "array", "items": color()},
            "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}}
        }
    });
    let entity = json!({
        "type": "object", "title": "foxglove.SceneEntity",
        "properties": {
            "timestamp": time("Timestamp of the entity"),
            "frame_id": {"type": "string"},
            "id": {"type": "string"},
            "lifetime": {"type": "object", "title": "duration",
                "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer", "minimum": 0}}},
            "frame_locked": {"type": "boolean"},
            "metadata": unused, "arrows": unused, "cubes": unused,
            "spheres": {"type": "array", "items": sphere},
            "cylinders": unused,
            "lines": {"type": "array", "items": line},
            "triangles": unused, "texts": unused, "models": unused
        }
    });
    Schema {
        name: "foxglove.SceneUpdate",
        json: json!({
            "title": "foxglove.SceneUpdate",
            "description": "An update to the entities displayed in a 3D scene",
            "type": "object",
            "properties": {
                "deletions": unused,
                "entities": {"type": "array", "items": entity}
            }
        }),
    }
}

/// `sabr.JointState`: one encoder sample. `counts` are the raw counts c1..c5,
/// `position_rad` the joint angles θ1..θ5 (rad) of the model (null while the joint offsets
/// are unknown), `name` the joint names theta1..theta5.
pub fn joint_state() -> Schema {
    let five = |items: Value, description: &str| {
        json!({"type": "array", "items": items, "minItems": 5, "maxItems": 5,
            "description": description})
    };
    Schema {
        name: "sabr.JointState",
        json: json!({
            "title": "sabr.JointState",
            "description": "One encoder sample of the SABR robot and its joint angles",
            "type": "object",
            "properties": {
                "timestamp": time("Host CLOCK_MONOTONIC time stamp of the sample"),
                "name": five(json!({"type": "string"}), "Joint names theta1..theta5"),
                "counts": five(json!({"type": "integer"}), "Raw encoder counts c1..c5, zero at power-up"),
                "position_rad": {
                    "oneOf": [five(json!({"type": "number"}), "Joint angles (rad)"), {"type": "null"}],
                    "description": "Joint angles theta1..theta5 (rad) of the model; null while the joint offsets are unknown"
                }
            }
        }),
    }
}

/// `sabr.MarkerResidual`: per tracker frame, measured minus predicted pose of each tool in
/// the base-marker frame `M` (position in mm, angle in degrees); null where the tool was not
/// seen or the model has no prediction.
pub fn marker_residual() -> Schema {
    let tool = |description: &str| {
        json!({
            "oneOf": [{
                "type": "object",
                "properties": {
                    "position_mm": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3,
                        "description": "Measured minus predicted position in M (mm)"},
                    "distance_mm": {"type": "number", "description": "Length of position_mm (mm)"},
                    "angle_deg": {"oneOf": [{"type": "number"}, {"type": "null"}],
                        "description": "Angle between measured and predicted orientation (deg); null for the tip"}
                }
            }, {"type": "null"}],
            "description": description
        })
    };
    Schema {
        name: "sabr.MarkerResidual",
        json: json!({
            "title": "sabr.MarkerResidual",
            "description": "The calibrated model of the SABR robot against one tracker frame",
            "type": "object",
            "properties": {
                "timestamp": time("Host arrival time stamp of the tracker frame"),
                "frame": {"type": "integer", "minimum": 0, "description": "Tracker frame counter"},
                "front": tool("Front marker Tf"),
                "back": tool("Back marker Tb"),
                "tip": tool("Tip sphere")
            }
        }),
    }
}
