//! Recordings as MCAP files for Foxglove: the robot model's frames moving with the encoders,
//! the tracker's marker frames and tip, joint states, session phases and, with a calibrated
//! model, the residual per tracker frame. Messages are JSON with Foxglove's well-known
//! schemas where one fits (`foxglove.FrameTransforms`, `foxglove.PoseInFrame`,
//! `foxglove.SceneUpdate`, `foxglove.Log`) and our own documented ones otherwise
//! (`sabr.JointState`, `sabr.MarkerResidual`); the topics are in docs/robot-model.md §8.
//!
//! - [`export_recording`] writes a whole recording (`sabr export mcap`).
//! - [`SessionStream`] writes rows as they come (the live recorder).
//!
//! Layers, each using only those above it: messages, schemas → frames, writer, history →
//! stream → export.

pub mod error;
pub mod export;
pub mod frames;
pub mod history;
pub mod messages;
pub mod schemas;
pub mod stream;
pub mod writer;

pub use error::McapExportError;
pub use export::{export_recording, read_calibrated_params, ExportModel, ExportSummary};
pub use stream::{SessionStream, StreamOptions};
pub use writer::{McapSink, Topic};
