//! Recording format v2 (docs/robot-model.md §7): a directory with `robot.toml`, `encoders.csv`,
//! `tracker.csv` and `phases.csv`. Version 2 added `tracker.csv`'s `arrival_t_ns` column and made
//! its `t_ns` the time the frame became available at the tracker; the version shows in that
//! header (`robot.toml`'s `format` is the version of the model parameters, not of the
//! recording). Version 1 recordings are still read ([`TrackerRow`]); writing produces v2.
//!
//! - [`Recording::read`] reads a whole recording; [`Recording::read_salvage`] reads one cut off
//!   mid-write (e.g. by SIGKILL), keeping every complete row and saying what it dropped.
//! - [`EncoderReader`], [`TrackerReader`] and [`PhaseReader`] stream one CSV row by row.
//! - [`RecordingWriter`] writes a recording row by row (optionally flushing continuously);
//!   [`write_all`] writes a [`Recording`] in one call.
//!
//! The static measurement sets of arms described by URDF are a second recording kind,
//! "poses v1" ([`poses`]). Both kinds' `robot.toml` is read by [`RobotToml`].
//!
//! Every error names the file, the 1-based line and the reason ([`RecordingError`]). Floats are
//! written in Rust's shortest round-trip form, so write → read gives back the same bits.

mod encoders;
mod error;
mod format;
#[cfg(feature = "live")]
pub mod live;
mod phases;
pub mod poses;
mod reader;
mod recording;
pub mod robot_toml;
mod rows;
mod tracker;
mod writer;

pub use encoders::EncodersCsv;
pub use error::{DroppedTail, Problem, RecordingError};
pub use format::{CsvFormat, Fields, RecordBuilder, ROBOT_TOML};
pub use phases::PhasesCsv;
pub use reader::{EncoderReader, PhaseReader, ReadOptions, RowReader, TrackerReader};
pub use recording::Salvage;
pub use robot_toml::{RobotDescription, RobotToml};
pub use rows::{EncoderRow, PhaseRow, Recording, Tool, ToolReading, TrackerRow};
pub use tracker::TrackerCsv;
pub use writer::{write_all, FlushPolicy, RecordingWriter};
