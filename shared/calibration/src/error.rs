//! Why a calibration was refused. Every variant says what is missing or wrong in the
//! recording, so that a bad recording never yields a silently bad model.

/// A calibration failure, with what is missing and why it matters.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    /// `robot.toml` of the recording is invalid (the error names the file, line and field).
    #[error(transparent)]
    RobotToml(sabr_recording::RecordingError),
    /// The recording has no usable tracker frames at all.
    #[error("{0}")]
    NoTrackerFrames(String),
    /// A phase the calibration needs is absent from `phases.csv`.
    #[error("phase `{phase}` is missing from phases.csv: {why}")]
    MissingPhase {
        /// Phase name (homing, excitation, tip, validation).
        phase: &'static str,
        /// What the phase is needed for.
        why: &'static str,
    },
    /// A phase is present but holds too little usable data.
    #[error("phase `{phase}`: {reason}")]
    InsufficientData {
        /// Phase name.
        phase: &'static str,
        /// What is lacking.
        reason: String,
    },
    /// A joint did not move enough during the excitation to identify its parameters.
    #[error(
        "joint {joint} moved only {range_rad:.4} rad during the excitation (need at least \
         {needed_rad:.4} rad): its gear ratio is not identifiable"
    )]
    TooLittleMotion {
        /// Joint number 1..5.
        joint: usize,
        /// Range of the joint angle seen during the excitation (rad).
        range_rad: f64,
        /// The minimum range required (rad).
        needed_rad: f64,
    },
    /// A tracker row is unusable (e.g. a quaternion that is not a rotation).
    #[error("tracker.csv, frame {frame}: {reason}")]
    BadTrackerRow {
        /// Tracker frame counter of the row.
        frame: u32,
        /// What is wrong with it.
        reason: String,
    },
    /// The tracker frame counter or the stamps do not allow a clock fit.
    #[error("time synchronisation: {0}")]
    TimeSync(String),
    /// An optimisation step failed (numerical trouble or an unreachable model).
    #[error("{stage}: {reason}")]
    Fit {
        /// Which stage (stepwise, joint fit, ...).
        stage: &'static str,
        /// What went wrong.
        reason: String,
    },
}
