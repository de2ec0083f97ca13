//! Reading a whole recording directory into memory.

use std::path::Path;

use crate::error::{DroppedTail, RecordingError};
use crate::format::{CsvFormat, ROBOT_TOML};
use crate::reader::{ReadOptions, RowReader};
use crate::robot_toml::RobotToml;
use crate::rows::Recording;
use crate::{EncodersCsv, PhasesCsv, TrackerCsv};

/// What a read recovered, and the truncated final lines it dropped (only with
/// [`ReadOptions::allow_truncated_tail`]; at most one per CSV file).
#[derive(Debug, Clone, PartialEq)]
pub struct Salvage {
    /// Every complete row of every file.
    pub recording: Recording,
    /// The final lines dropped because they were cut off mid-write.
    pub dropped: Vec<DroppedTail>,
}

impl Recording {
    /// Reads the recording in `dir`, strictly: any malformed line, including a final line cut
    /// off mid-write, is an error naming the file, line and reason.
    pub fn read(dir: &Path) -> Result<Recording, RecordingError> {
        Self::read_with(dir, ReadOptions::default()).map(|salvage| salvage.recording)
    }

    /// Reads a recording that may have been cut off mid-write (e.g. the recorder got SIGKILL):
    /// every complete row before a truncated final line is kept, and the dropped lines are
    /// listed. Any other malformed line is still an error.
    pub fn read_salvage(dir: &Path) -> Result<Salvage, RecordingError> {
        let options = ReadOptions {
            allow_truncated_tail: true,
        };
        Self::read_with(dir, options)
    }

    /// The biopsy robot's model of this recording: its `robot.toml` checked by
    /// [`RobotToml`] (errors name the file, the line and the field).
    pub fn robot(&self) -> Result<sabr_model::RobotParams, RecordingError> {
        RobotToml::parse(&self.dir.join(ROBOT_TOML), self.robot_toml.clone())?.biopsy()
    }

    /// Reads the recording in `dir` with `options`. `robot.toml` is kept as text (check it
    /// with [`Recording::robot`]).
    pub fn read_with(dir: &Path, options: ReadOptions) -> Result<Salvage, RecordingError> {
        let toml_path = dir.join(ROBOT_TOML);
        let robot_toml = std::fs::read_to_string(&toml_path)
            .map_err(|e| RecordingError::open(toml_path, "read", e))?;
        let mut dropped = Vec::new();
        let encoders = read_rows::<EncodersCsv>(dir, options, &mut dropped)?;
        let tracker = read_rows::<TrackerCsv>(dir, options, &mut dropped)?;
        let phases = read_rows::<PhasesCsv>(dir, options, &mut dropped)?;
        let recording = Recording {
            dir: dir.to_path_buf(),
            robot_toml,
            encoders,
            tracker,
            phases,
        };
        Ok(Salvage { recording, dropped })
    }
}

/// Every row of `dir`'s file of format `F`; a dropped truncated line is added to `dropped`.
fn read_rows<F: CsvFormat>(
    dir: &Path,
    options: ReadOptions,
    dropped: &mut Vec<DroppedTail>,
) -> Result<Vec<F::Row>, RecordingError> {
    let mut reader = RowReader::<F>::open_with(dir.join(F::FILE_NAME), options)?;
    let rows = reader.by_ref().collect::<Result<Vec<_>, _>>()?;
    dropped.extend(reader.dropped_tail().cloned());
    Ok(rows)
}
