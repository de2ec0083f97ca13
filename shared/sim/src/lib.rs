//! The simulated rig: a true robot perturbed from nominal, encoder and tracker emulation,
//! injectable effects and a session plan like the paper's (docs/robot-model.md).
//!
//! The parts are independent of how they are driven:
//! - [`RobotTruth`] / [`TrueRobot`]: motor setpoints → true motor angles, counts, joints and
//!   poses (robot time in ns since power-up).
//! - [`EncoderClock`]: when the host samples the counters (1 kHz with jitter).
//! - [`TrackerEmulator`]: Polaris-like frames of the true tool poses (noise, latency, drops).
//! - `sabr_model::plan::SessionPlan`: homing, excitation, tip phase and validation poses
//!   (the plan `sabr-motion` runs on the real robot too).
//!
//! [`record_session`] runs them offline into a [`sabr_recording::Recording`] and a [`Truth`];
//! [`write_session`] writes both to disk (`DIR/` and `DIR/truth/`).

mod effect_spec;
mod encoder;
mod session;
mod tracker;
mod truth;
mod truth_files;

use std::path::PathBuf;

pub use effect_spec::SimEffect;
pub use encoder::{EncoderClock, EncoderConfig};
pub use sabr_model::EffectSpecError;
pub use session::{record_session, FrameTruth, Session, SimConfig, Truth, ValidationTruth};
pub use tracker::{Exposure, TrackerConfig, TrackerEmulator, TrackerFrame, TrackerTruth};
pub use truth::{
    quantise_counts, sag_deflection, LinkDrift, Perturbation, RobotTruth, ThermalDrift, ToolPoses,
    TrueRobot,
};
pub use truth_files::{truth_dir, write_session, TRUTH_DIR};

/// Why a session could not be simulated or written.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The configuration is invalid.
    #[error("invalid simulation config: {0}")]
    Config(String),
    /// The true robot would leave its reachable workspace.
    #[error(
        "plan leaves the reachable workspace at t = {t_s:.3} s (joints {joints:?} rad): {reason}"
    )]
    Unreachable {
        /// Robot time (s after power-up).
        t_s: f64,
        /// True joint angles there (rad).
        joints: sabr_model::Joints,
        /// What failed.
        reason: String,
    },
    /// Writing the recording failed.
    #[error(transparent)]
    Recording(#[from] sabr_recording::RecordingError),
    /// A truth file could not be created, written or read.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The cause.
        source: std::io::Error,
    },
    /// A truth file is malformed.
    #[error("{} line {line}: {reason}", path.display())]
    TruthFile {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 when the parser does not say).
        line: u64,
        /// What is wrong.
        reason: String,
    },
}
