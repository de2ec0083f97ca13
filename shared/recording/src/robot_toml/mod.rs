//! `robot.toml`, the robot description at the root of every recording, read in one place.
//!
//! The recorder and the calibrator read the file given by `--robot-toml`, [`Recording`]
//! and [`PosesRecording`] read the one in their directory; all of them go through
//! [`RobotToml`], which tells the two kinds apart by their `format` key:
//!
//! - `format = 1`: the biopsy robot's nominal model, read by the one parameter-file reader
//!   (`sabr_model::parse_params_file`; errors name the file, the line and the field);
//! - `format = "poses-v1"` (any string): an arm described by URDF and its measured targets
//!   ([`poses`]; another string is an error of that reader).
//!
//! [`Recording`]: crate::Recording
//! [`PosesRecording`]: crate::poses::PosesRecording

pub mod poses;

use std::path::{Path, PathBuf};

use sabr_model::RobotParams;

use crate::error::RecordingError;
use poses::{PosesRobot, POSES_FORMAT};

/// What a `robot.toml` describes.
#[derive(Debug, Clone, PartialEq)]
pub enum RobotDescription {
    /// The biopsy robot's model (`format = 1`).
    Biopsy(Box<RobotParams>),
    /// An arm described by URDF, with its measured targets (`format = "poses-v1"`).
    Poses(PosesRobot),
}

/// A `robot.toml` read and checked: where it is, its text (kept verbatim, as the recorder
/// copies it into each recording) and what it describes.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotToml {
    /// The file.
    pub path: PathBuf,
    /// Its text.
    pub text: String,
    /// What it describes.
    pub robot: RobotDescription,
}

impl RobotToml {
    /// Reads and checks the `robot.toml` at `path`.
    pub fn read(path: &Path) -> Result<Self, RecordingError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| RecordingError::open(path.to_owned(), "read", e))?;
        Self::parse(path, text)
    }

    /// Checks `text`, the contents of the `robot.toml` at `path`.
    pub fn parse(path: &Path, text: String) -> Result<Self, RecordingError> {
        let robot = if names_a_format_string(&text) {
            let robot =
                PosesRobot::from_toml_str(&text).map_err(|reason| RecordingError::Robot {
                    path: path.to_owned(),
                    reason,
                })?;
            RobotDescription::Poses(robot)
        } else {
            RobotDescription::Biopsy(Box::new(sabr_model::parse_params_file(path, &text)?))
        };
        Ok(Self {
            path: path.to_owned(),
            text,
            robot,
        })
    }

    /// The biopsy robot's model; an error naming the file for a poses-v1 description.
    pub fn biopsy(self) -> Result<RobotParams, RecordingError> {
        match self.robot {
            RobotDescription::Biopsy(params) => Ok(*params),
            RobotDescription::Poses(_) => Err(self.wrong_kind("format = 1 (the biopsy robot)")),
        }
    }

    /// The poses-v1 description; an error naming the file for a biopsy-robot model.
    pub fn poses(self) -> Result<PosesRobot, RecordingError> {
        match self.robot {
            RobotDescription::Poses(robot) => Ok(robot),
            RobotDescription::Biopsy(_) => {
                Err(self.wrong_kind(&format!("format = {POSES_FORMAT:?}")))
            }
        }
    }

    fn wrong_kind(&self, expected: &str) -> RecordingError {
        RecordingError::Robot {
            path: self.path.clone(),
            reason: format!("key `format`: expected {expected} for this kind of recording"),
        }
    }
}

/// Whether `text` is TOML whose `format` key is a string (a poses format), not a number.
fn names_a_format_string(text: &str) -> bool {
    toml::from_str::<toml::Table>(text)
        .is_ok_and(|table| table.get("format").is_some_and(toml::Value::is_str))
}

#[cfg(test)]
mod tests {
    use super::*;
    use poses::{Measured, Target};

    fn poses_text() -> String {
        PosesRobot::new(
            "arm.urdf",
            vec![Target {
                name: "probe".into(),
                link: "tool0".into(),
                measured: Measured::Point,
                mounting_translation: None,
                mounting_rotation: None,
            }],
        )
        .to_toml_string()
    }

    #[test]
    fn the_format_key_tells_the_kinds_apart() {
        let path = Path::new("rec/robot.toml");
        let nominal = RobotParams::nominal();
        let biopsy = RobotToml::parse(path, nominal.to_toml_string()).unwrap();
        assert_eq!(biopsy.clone().biopsy().unwrap(), nominal);
        let error = biopsy.poses().unwrap_err().to_string();
        assert!(error.starts_with("rec/robot.toml: key `format`"), "{error}");

        let poses = RobotToml::parse(path, poses_text()).unwrap();
        assert_eq!(poses.clone().poses().unwrap().urdf, "arm.urdf");
        let error = poses.biopsy().unwrap_err().to_string();
        assert!(error.contains("format = 1"), "{error}");
    }

    #[test]
    fn a_bad_biopsy_robot_toml_names_the_file_the_line_and_the_field() {
        let text = RobotParams::nominal()
            .to_toml_string()
            .replacen("l_b = ", "l_b = -", 1);
        let line = text.lines().position(|l| l.starts_with("l_b")).unwrap() + 1;
        let error = RobotToml::parse(Path::new("rec/robot.toml"), text)
            .unwrap_err()
            .to_string();
        assert!(
            error.starts_with(&format!("rec/robot.toml:{line}: field `geometry.l_b`")),
            "{error}"
        );
    }

    #[test]
    fn a_missing_file_is_named() {
        let error = RobotToml::read(Path::new("/nonexistent/robot.toml")).unwrap_err();
        assert!(
            error.to_string().contains("/nonexistent/robot.toml"),
            "{error}"
        );
    }
}
