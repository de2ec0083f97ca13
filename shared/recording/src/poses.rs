//! Recording kind "poses v1": static measurement sets of a robot described by URDF
//! (`docs/poses-format.md`). A directory with
//!
//! - `robot.toml`: `format = "poses-v1"`, the URDF file (a path relative to the directory;
//!   the URDF is copied in, so a recording is self-contained) and the measured targets
//!   ([`PosesRobot`]);
//! - `poses.csv`: one row per static pose: set-up, sequence and order index, joint values by
//!   joint name, each target's measurement, optional standard deviations and temperature
//!   ([`PoseRow`]).
//!
//! [`PosesRecording::read`] reads and checks a whole recording; every error names the file,
//! the 1-based line, the column and the reason. [`PosesRecording::write`] writes one.

use std::path::{Component, Path, PathBuf};

mod header;
mod rows;

pub use crate::robot_toml::poses::{Measured, PosesRobot, Target, POSES_FORMAT};

use crate::error::{Problem, RecordingError};
use crate::format::ROBOT_TOML;
use crate::robot_toml::RobotToml;

/// File name of the pose table in a poses-v1 recording.
pub const POSES_CSV: &str = "poses.csv";

/// Largest deviation of a quaternion's norm from 1 that a reader accepts.
pub const UNIT_QUATERNION_TOLERANCE: f64 = 1e-6;

/// One target's measurement at one pose, in the set-up's measuring frame (e.g. the laser
/// tracker's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetMeasurement {
    /// Position (mm).
    pub position_mm: [f64; 3],
    /// Orientation as a unit quaternion `[w, x, y, z]` (pose targets only).
    pub orientation: Option<[f64; 4]>,
    /// Standard deviations of the position along the measuring frame's axes (mm).
    pub position_std_mm: Option<[f64; 3]>,
    /// Standard deviations of the orientation about three axes (rad; see the format doc for
    /// what the importer of each source puts here).
    pub orientation_std_rad: Option<[f64; 3]>,
}

/// One static pose: where the robot was, and what was measured there.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseRow {
    /// The 1-based line of `poses.csv` it was read from (0 for a row not read from a file).
    pub line: u64,
    /// The set-up: one placement of the measuring instrument.
    pub setup: String,
    /// The sequence (measurement run) the pose belongs to.
    pub sequence: String,
    /// Order of the pose within its sequence (strictly increasing).
    pub index: u64,
    /// Joint values (rad or mm), in [`PosesRecording::joints`] order.
    pub joints: Vec<f64>,
    /// One entry per target of [`PosesRobot::targets`]: `None` where the target was not
    /// measured at this pose.
    pub targets: Vec<Option<TargetMeasurement>>,
    /// Ambient temperature (°C), if recorded.
    pub temperature_c: Option<f64>,
}

/// A whole poses-v1 recording in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct PosesRecording {
    /// Where it was read from (for messages; not used by the writer).
    pub dir: PathBuf,
    /// The contents of `robot.toml`.
    pub robot: PosesRobot,
    /// The text of the URDF file `robot.urdf` names.
    pub urdf_text: String,
    /// The joints of the joint columns, in column order.
    pub joints: Vec<String>,
    /// The poses, in file order.
    pub rows: Vec<PoseRow>,
}

impl PosesRecording {
    /// Reads the poses-v1 recording in `dir`: `robot.toml`, the URDF it names and
    /// `poses.csv`, checking every row.
    pub fn read(dir: &Path) -> Result<PosesRecording, RecordingError> {
        let toml_path = dir.join(ROBOT_TOML);
        let robot = RobotToml::read(&toml_path)?.poses()?;
        let urdf_path = dir.join(checked_relative(&robot.urdf, &toml_path)?);
        let urdf_text = std::fs::read_to_string(&urdf_path)
            .map_err(|e| RecordingError::open(urdf_path, "read", e))?;
        let (joints, rows) = rows::read(&dir.join(POSES_CSV), &robot)?;
        Ok(PosesRecording {
            dir: dir.to_path_buf(),
            robot,
            urdf_text,
            joints,
            rows,
        })
    }

    /// Writes the recording to `dir` (created if absent): `robot.toml`, the URDF under the
    /// name `robot.urdf` gives, and `poses.csv`. Refuses to overwrite existing files and
    /// refuses rows a reader would reject.
    pub fn write(&self, dir: &Path) -> Result<(), RecordingError> {
        std::fs::create_dir_all(dir).map_err(|source| RecordingError::Io {
            path: dir.to_path_buf(),
            action: "create the directory",
            source,
        })?;
        let toml_path = dir.join(ROBOT_TOML);
        let urdf_path = dir.join(checked_relative(&self.robot.urdf, &toml_path)?);
        let robot_toml = self.robot.to_toml_string();
        rows::write(&dir.join(POSES_CSV), self)?;
        write_new(&toml_path, robot_toml.as_bytes())?;
        write_new(&urdf_path, self.urdf_text.as_bytes())
    }

    /// For each of `variables` (the robot's joint variable names, in the kinematics' order),
    /// the index of its value in [`PoseRow::joints`]. Every joint column must name a variable
    /// and every variable must have a column; the error names the column of `poses.csv`.
    pub fn joint_order(&self, variables: &[&str]) -> Result<Vec<usize>, RecordingError> {
        let path = self.dir.join(POSES_CSV);
        let header_error = |column: String, reason: String| RecordingError::Malformed {
            path: path.clone(),
            line: 1,
            problem: Problem::BadColumn { column, reason },
        };
        if let Some(extra) = self
            .joints
            .iter()
            .find(|j| !variables.contains(&j.as_str()))
        {
            return Err(header_error(
                format!("{}{extra}", header::JOINT_PREFIX),
                format!(
                    "the URDF has no joint variable `{extra}` (variables: {})",
                    variables.join(", ")
                ),
            ));
        }
        variables
            .iter()
            .map(|&variable| {
                self.joints
                    .iter()
                    .position(|j| j == variable)
                    .ok_or_else(|| {
                        header_error(
                            format!("{}{variable}", header::JOINT_PREFIX),
                            "missing: every joint variable of the URDF needs a column".into(),
                        )
                    })
            })
            .collect()
    }
}

/// `relative` if it is a relative path inside the recording (no `..`, not absolute).
fn checked_relative<'a>(relative: &'a str, toml_path: &Path) -> Result<&'a Path, RecordingError> {
    let path = Path::new(relative);
    let inside = !relative.is_empty()
        && path
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    if inside {
        Ok(path)
    } else {
        Err(RecordingError::Robot {
            path: toml_path.to_path_buf(),
            reason: format!(
                "key `urdf`: {relative:?} must be a relative path inside the recording"
            ),
        })
    }
}

/// Writes `bytes` to the new file `path` (refusing to overwrite) and syncs it.
fn write_new(path: &Path, bytes: &[u8]) -> Result<(), RecordingError> {
    use std::io::Write as _;
    let io_error = |action| {
        move |source| RecordingError::Io {
            path: path.to_path_buf(),
            action,
            source,
        }
    };
    let mut file = std::fs::File::create_new(path).map_err(io_error("create"))?;
    file.write_all(bytes).map_err(io_error("write"))?;
    file.sync_all().map_err(io_error("sync"))
}
