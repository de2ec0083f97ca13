//! Why a serial-arm calibration or evaluation is refused: each error names the file (and
//! line, column or field where there is one) and the reason.

use std::path::PathBuf;

use sabr_model::TreeError;
use sabr_recording::RecordingError;

use crate::error::CalibrationError;

/// A refused serial-arm calibration or evaluation.
#[derive(Debug, thiserror::Error)]
pub enum SerialError {
    /// The recording could not be read or its columns do not match the URDF.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// The URDF the recording names is not a kinematic tree the engine can model.
    #[error("{path}: {source}")]
    Urdf {
        /// The URDF file.
        path: PathBuf,
        /// Why.
        source: TreeError,
    },
    /// A target of `robot.toml` names a link the URDF does not have.
    #[error("{path}: target `{target}`: {source}")]
    Target {
        /// The `robot.toml` file.
        path: PathBuf,
        /// The target.
        target: String,
        /// Why.
        source: TreeError,
    },
    /// A row's joint values cannot be used (e.g. not finite for the kinematics).
    #[error("{path}:{line}: {reason}")]
    Row {
        /// `poses.csv`.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// Why.
        reason: String,
    },
    /// A set-up has too few poses, or poses that do not span space, to be registered.
    #[error("{path}: set-up `{setup}`: {reason}")]
    Setup {
        /// `poses.csv`.
        path: PathBuf,
        /// The set-up id.
        setup: String,
        /// Why.
        reason: String,
    },
    /// A parameter file is malformed or does not fit the recording's robot.
    #[error("{path}:{line}:{column}: {reason}")]
    Params {
        /// The parameter file.
        path: PathBuf,
        /// 1-based line (0 when the problem is not at one place).
        line: usize,
        /// 1-based column (0 when the problem is not at one place).
        column: usize,
        /// Which field is wrong and why.
        reason: String,
    },
    /// A fit failed numerically.
    #[error(transparent)]
    Fit(#[from] CalibrationError),
}
