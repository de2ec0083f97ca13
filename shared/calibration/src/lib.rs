//! The SABR calibration engine: turns a recording into a calibrated robot model, a JSON
//! report and an HTML report. `sabr calibrate` and the live calibrator process share this
//! one code path ([`calibrate`]).
//!
//! Layers, each using only those below it (read top-down, or bottom-up to see what each
//! builds on):
//!
//! - [`calibrate`] — the biopsy robot's pipeline: recording → time sync → stepwise method →
//!   joint fit → residual loop → validation → report and calibrated parameters.
//! - [`report`] — `report.json` (what every layer found), `report.html` with the residual
//!   plots, atomic output files.
//! - [`discovery`] — the residual loop: candidates from the model, score tests in sample and
//!   held out, forward selection, refits, significance against the measurement noise.
//! - [`fit`] — Levenberg–Marquardt, the joint robust fit of a parameter layout,
//!   identifiability, held-out checks.
//! - [`model`] — the robot-model boundary ([`model::RobotModel`]): parameters, measured
//!   quantities, residual blocks, noise, the stacked problem; and its first implementation,
//!   the biopsy robot's closed-chain model ([`model::biopsy`]).
//! - [`data`] — a recording of the biopsy robot → observations: tracker frames in the robot
//!   base, the exposure clock, the encoder stream, phases, model-free latency.
//! - [`math`], [`error`] — robust statistics, rigid motions; why a calibration is refused.
//!
//! The fit and discovery layers know only the [`model::RobotModel`] trait: another robot
//! plugs in by implementing it (and a [`model::Dataset`] of its observations).

pub mod calibrate;
pub mod calibrate_serial;
pub mod data;
pub mod discovery;
pub mod error;
pub mod fit;
pub mod math;
pub mod model;
pub mod report;

pub use calibrate::{calibrate, write_outputs, Calibration, CalibrationOptions};
pub use error::CalibrationError;
pub use model::biopsy::BiopsyModel;
pub use model::RobotModel;
pub use report::output::OutputError;
pub use report::Report;
