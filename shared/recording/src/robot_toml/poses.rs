//! `robot.toml` of a poses-v1 recording (`format = "poses-v1"`): the URDF and the measured
//! targets.

use serde::{Deserialize, Serialize};

/// The value of the `format` key of a poses-v1 `robot.toml`.
pub const POSES_FORMAT: &str = "poses-v1";

/// What the instrument measures of a target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Measured {
    /// Position and orientation (a 6-DOF probe, a marker tool).
    Pose,
    /// Position only (a prism, a single marker sphere).
    Point,
}

/// A measured target: a frame or point rigidly mounted, at an unknown place, on a link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// Unique name; the prefix of its columns in `poses.csv` (`<name>.x`, …).
    pub name: String,
    /// The URDF link it is mounted on.
    pub link: String,
    /// Pose or point.
    pub measured: Measured,
    /// Nominal mounting: the target's position in the link's frame (mm), a start value for
    /// the calibration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mounting_translation: Option<[f64; 3]>,
    /// Nominal mounting: the target frame's orientation in the link's frame as a rotation
    /// vector (rad); pose targets only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mounting_rotation: Option<[f64; 3]>,
}

/// The contents of a poses-v1 `robot.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PosesRobot {
    /// Always [`POSES_FORMAT`].
    pub format: String,
    /// The URDF file, relative to the recording directory.
    pub urdf: String,
    /// Gravity in the URDF's root frame (m/s²); absent means standard gravity along −z.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity_m_s2: Option<[f64; 3]>,
    /// The measured targets, in the order of their columns.
    pub targets: Vec<Target>,
}

impl PosesRobot {
    /// A robot description naming `urdf` with `targets`.
    pub fn new(urdf: impl Into<String>, targets: Vec<Target>) -> Self {
        PosesRobot {
            format: POSES_FORMAT.to_owned(),
            urdf: urdf.into(),
            gravity_m_s2: None,
            targets,
        }
    }

    /// Parses and checks a `robot.toml`; the error says which key is wrong and why.
    pub fn from_toml_str(text: &str) -> Result<Self, String> {
        let robot: PosesRobot = toml::from_str(text).map_err(|e| e.to_string())?;
        robot.check()?;
        Ok(robot)
    }

    /// The `robot.toml` text.
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).expect("a robot description serialises to TOML")
    }

    /// The target named `name`.
    pub fn target(&self, name: &str) -> Option<&Target> {
        self.targets.iter().find(|t| t.name == name)
    }

    fn check(&self) -> Result<(), String> {
        if self.format != POSES_FORMAT {
            return Err(format!(
                "key `format`: {:?} is not {POSES_FORMAT:?}",
                self.format
            ));
        }
        if self.targets.is_empty() {
            return Err("key `targets`: a recording needs at least one target".into());
        }
        let finite =
            |values: &Option<[f64; 3]>| values.is_none_or(|v| v.iter().all(|x| x.is_finite()));
        if !finite(&self.gravity_m_s2) {
            return Err("key `gravity_m_s2`: not finite".into());
        }
        for (i, target) in self.targets.iter().enumerate() {
            let key = |k: &str| format!("key `targets[{i}].{k}` (target {:?})", target.name);
            let valid_name = !target.name.is_empty()
                && target
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
            if !valid_name {
                return Err(format!(
                    "{}: a target name is letters, digits, `_` and `-`",
                    key("name")
                ));
            }
            if self.targets[..i].iter().any(|t| t.name == target.name) {
                return Err(format!("{}: two targets share the name", key("name")));
            }
            if target.name == "joint" {
                return Err(format!(
                    "{}: `joint` is reserved for joint columns",
                    key("name")
                ));
            }
            if !finite(&target.mounting_translation) || !finite(&target.mounting_rotation) {
                return Err(format!("{}: not finite", key("mounting_*")));
            }
            if target.measured == Measured::Point && target.mounting_rotation.is_some() {
                return Err(format!(
                    "{}: a point target has no orientation",
                    key("mounting_rotation")
                ));
            }
        }
        Ok(())
    }
}
