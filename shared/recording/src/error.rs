//! Errors of reading and writing recordings: each names the file, the line and the reason.

use std::fmt;
use std::io;
use std::path::PathBuf;

use crate::rows::Tool;

/// What is wrong with one line (header or row) of a recording CSV.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Problem {
    /// The file has no header line at all.
    #[error("empty file: expected the header `{expected}`")]
    EmptyFile {
        /// The header the file should start with.
        expected: String,
    },
    /// The header line is not the one of this file.
    #[error("wrong header: expected `{expected}`, found `{found}`")]
    WrongHeader {
        /// The header the file should start with.
        expected: String,
        /// The header line found.
        found: String,
    },
    /// The header or a row has fewer fields than the format's columns.
    #[error("missing column `{column}` (found {found} fields)")]
    MissingColumn {
        /// The first absent column.
        column: &'static str,
        /// How many fields the line has.
        found: usize,
    },
    /// A field that must hold a number is empty.
    #[error("field `{column}`: empty, expected a number")]
    MissingNumber {
        /// The column.
        column: &'static str,
    },
    /// A field that must hold an integer does not.
    #[error("field `{column}`: invalid integer {value:?}")]
    InvalidInteger {
        /// The column.
        column: &'static str,
        /// The field's text.
        value: String,
    },
    /// A field that must hold a float does not.
    #[error("field `{column}`: invalid float {value:?}")]
    InvalidFloat {
        /// The column.
        column: &'static str,
        /// The field's text.
        value: String,
    },
    /// A float field holds NaN or an infinity.
    #[error("field `{column}`: {value} is not a finite number")]
    NotFinite {
        /// The column.
        column: &'static str,
        /// The value.
        value: f64,
    },
    /// A text field is not valid UTF-8.
    #[error("field `{column}`: not valid UTF-8")]
    InvalidUtf8 {
        /// The column.
        column: &'static str,
    },
    /// The `tool` field is not base, front, back or tip.
    #[error("field `tool`: unknown tool {0:?} (expected base, front, back or tip)")]
    UnknownTool(String),
    /// The `status` field is not ok or missing.
    #[error("field `status`: unknown status {0:?} (expected ok or missing)")]
    UnknownStatus(String),
    /// A `tip` row has a quaternion field filled in.
    #[error("field `{column}`: a tip row has no quaternion, found {value:?}")]
    QuaternionOnTip {
        /// The quaternion column.
        column: &'static str,
        /// The field's text.
        value: String,
    },
    /// A row with status `missing` has a number filled in.
    #[error("field `{column}`: must be empty when status is missing, found {value:?}")]
    NumberOnMissingRow {
        /// The column.
        column: &'static str,
        /// The field's text.
        value: String,
    },
    /// A tracker row's reading is of the wrong kind for its tool (writer only: a pose for the
    /// tip, or a point for a 6-DOF marker).
    #[error("a {tool} row cannot hold a {reading}")]
    ReadingDoesNotFitTool {
        /// The row's tool.
        tool: Tool,
        /// `pose` or `point`.
        reading: &'static str,
    },
    /// An `encoders.csv` time stamp is not after the previous row's.
    #[error(
        "field `t_ns`: {t_ns} is not after the previous row's {previous_t_ns} \
         (encoder time stamps must increase)"
    )]
    NonMonotonicTime {
        /// This row's stamp (ns).
        t_ns: i64,
        /// The previous row's stamp (ns).
        previous_t_ns: i64,
    },
    /// A tracker row arrived before its frame became available (format v2).
    #[error(
        "field `arrival_t_ns`: {arrival_t_ns} is before the frame became available at \
         t_ns {t_ns}"
    )]
    ArrivalBeforeAvailable {
        /// The availability stamp, `t_ns` (ns).
        t_ns: i64,
        /// The arrival stamp (ns).
        arrival_t_ns: i64,
    },
    /// A phase ends before it starts.
    #[error("phase ends before it starts: t_end_ns {t_end_ns} < t_start_ns {t_start_ns}")]
    EndBeforeStart {
        /// Start (ns).
        t_start_ns: i64,
        /// End (ns).
        t_end_ns: i64,
    },
    /// A phase has an empty name.
    #[error("field `phase`: empty phase name")]
    EmptyPhaseName,
    /// A column of a header is missing, repeated, unknown or out of place.
    #[error("column `{column}`: {reason}")]
    BadColumn {
        /// The column's name.
        column: String,
        /// What is wrong.
        reason: String,
    },
    /// A field of a row whose columns are named by the header (poses v1) is malformed.
    #[error("field `{column}`: {reason}")]
    BadField {
        /// The column's name.
        column: String,
        /// What is wrong.
        reason: String,
    },
}

/// The final line of a file cut off mid-write, which a lenient read dropped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DroppedTail {
    /// The file.
    pub path: PathBuf,
    /// The 1-based line number of the dropped line.
    pub line: u64,
    /// Its text (fields joined by commas; empty for an empty file).
    pub text: String,
}

impl fmt::Display for DroppedTail {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} line {}: dropped the truncated final line {:?}",
            self.path.display(),
            self.line,
            self.text
        )
    }
}

/// An error reading or writing a recording. The message always names the file; problems with
/// the content also name the 1-based line.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// A file of the recording does not exist.
    #[error("{}: missing file", path.display())]
    MissingFile {
        /// The file.
        path: PathBuf,
    },
    /// A recording's `robot.toml` is malformed (poses v1), or of the other kind.
    #[error("{}: {reason}", path.display())]
    Robot {
        /// The file.
        path: PathBuf,
        /// Which key is wrong and why.
        reason: String,
    },
    /// A recording's `robot.toml` of the biopsy robot is unreadable or invalid (names the
    /// file, the line and the field).
    #[error(transparent)]
    Params(#[from] sabr_model::ParamsFileError),
    /// The operating system refused an operation on a file.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done (`open`, `read`, `create`, `write`, ...).
        action: &'static str,
        /// The cause.
        source: io::Error,
    },
    /// A line of a file is malformed.
    #[error("{} line {line}: {problem}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// The 1-based line.
        line: u64,
        /// What is wrong.
        problem: Problem,
    },
    /// The file ends in a line without a line terminator: it was cut off mid-write (e.g. the
    /// recorder got SIGKILL). A lenient read ([`crate::ReadOptions::allow_truncated_tail`])
    /// drops that line instead and keeps every complete row before it.
    #[error(
        "{} line {line}: truncated final line {text:?} (no line terminator: the file was cut \
         off mid-write; read it with allow_truncated_tail to keep the complete rows before it)",
        path.display()
    )]
    TruncatedTail {
        /// The file.
        path: PathBuf,
        /// The 1-based line of the truncated line.
        line: u64,
        /// Its text (fields joined by commas).
        text: String,
    },
    /// The writer refused a row that a reader would reject; nothing was written.
    #[error("{} line {line}: refusing to write the row: {problem}", path.display())]
    Refused {
        /// The file.
        path: PathBuf,
        /// The 1-based line the row would have had.
        line: u64,
        /// What is wrong with the row.
        problem: Problem,
    },
}

impl RecordingError {
    /// The problem with the content, for malformed lines and refused rows.
    pub fn problem(&self) -> Option<&Problem> {
        match self {
            RecordingError::Malformed { problem, .. } | RecordingError::Refused { problem, .. } => {
                Some(problem)
            }
            _ => None,
        }
    }

    /// An error opening `path` for `action`; a missing file gets its own variant.
    pub(crate) fn open(path: PathBuf, action: &'static str, source: io::Error) -> Self {
        if source.kind() == io::ErrorKind::NotFound {
            RecordingError::MissingFile { path }
        } else {
            RecordingError::Io {
                path,
                action,
                source,
            }
        }
    }

    /// A `csv` crate error while reading or writing `path`.
    pub(crate) fn csv(path: PathBuf, action: &'static str, error: csv::Error) -> Self {
        let source = match error.into_kind() {
            csv::ErrorKind::Io(source) => source,
            other => io::Error::other(format!("{other:?}")),
        };
        RecordingError::Io {
            path,
            action,
            source,
        }
    }
}
