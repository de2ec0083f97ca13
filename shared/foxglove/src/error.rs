//! Why an export or a live MCAP stream failed: each error names the file and, for a row, the
//! row's time stamp and what is wrong with it.

use std::path::PathBuf;

use sabr_model::{KinematicsError, ParamsError};
use sabr_recording::RecordingError;

/// An error of writing a recording as MCAP.
#[derive(Debug, thiserror::Error)]
pub enum McapExportError {
    /// The recording could not be read.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// A parameter file (`robot.toml` or a calibrated `params.toml`) is invalid.
    #[error("{path}: {cause}")]
    Params {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        cause: ParamsError,
    },
    /// A file could not be created, read or written.
    #[error("{path}: cannot {action}: {cause}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The cause.
        cause: std::io::Error,
    },
    /// The MCAP library refused a record.
    #[error("{path}: MCAP: {cause}")]
    Mcap {
        /// The MCAP file.
        path: PathBuf,
        /// The cause.
        cause: mcap::McapError,
    },
    /// A time stamp is negative: MCAP log times are unsigned.
    #[error("{what} t_ns = {t_ns}: negative time stamps cannot be MCAP log times")]
    NegativeTime {
        /// Which row (file and position).
        what: String,
        /// The time stamp (ns).
        t_ns: i64,
    },
    /// A message would go back in time on its topic.
    #[error("topic {topic}: log time {t_ns} ns is before the previous message's {previous_ns} ns")]
    BackInTime {
        /// The topic.
        topic: &'static str,
        /// The new message's log time (ns).
        t_ns: u64,
        /// The previous message's log time (ns).
        previous_ns: u64,
    },
    /// The joint offsets θ_off cannot be set.
    #[error("{0}")]
    NoJointOffsets(String),
    /// The forward kinematics has no solution for an encoder sample.
    #[error("{what} t_ns = {t_ns}: forward kinematics: {cause}")]
    Kinematics {
        /// Which row (file and position).
        what: String,
        /// The sample's time stamp (ns).
        t_ns: i64,
        /// Why.
        cause: KinematicsError,
    },
}
