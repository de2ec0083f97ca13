//! Recording format v1 (robot-model.md §7): a directory with `robot.toml`, `encoders.csv`,
//! `tracker.csv` and `phases.csv`. Streaming readers and writers; every error names the
//! file, the line and the reason.

use std::path::PathBuf;

/// One encoder sample: host `CLOCK_MONOTONIC` stamp (ns) and raw counts c1..c5.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EncoderRow {
    /// Host monotonic time stamp (ns).
    pub t_ns: i64,
    /// Raw counts, zero at power-up.
    pub counts: [i64; 5],
}

/// Which tracker tool a row is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Tool {
    /// Base marker `M`.
    Base,
    /// Front effector marker `Tf`.
    Front,
    /// Back effector marker `Tb`.
    Back,
    /// Single sphere on the needle tip (position only).
    Tip,
}

/// A tool measurement in the tracker frame `S`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ToolReading {
    /// The tool was not seen in this frame.
    Missing,
    /// A 6-DOF pose: unit quaternion (w, x, y, z), position (mm), RMS fit error (mm).
    Pose {
        /// Quaternion w, x, y, z.
        quaternion: [f64; 4],
        /// Position in `S` (mm).
        position: [f64; 3],
        /// RMS fit error (mm).
        rms: f64,
    },
    /// A 3-D point (the tip sphere): position in `S` (mm) and RMS (mm).
    Point {
        /// Position in `S` (mm).
        position: [f64; 3],
        /// RMS fit error (mm).
        rms: f64,
    },
}

/// One row of `tracker.csv`: one tool in one tracker frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerRow {
    /// Host arrival stamp (ns).
    pub t_ns: i64,
    /// Tracker frame counter.
    pub frame: u32,
    /// Which tool.
    pub tool: Tool,
    /// The reading.
    pub reading: ToolReading,
}

/// One row of `phases.csv`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PhaseRow {
    /// Start (ns, host monotonic).
    pub t_start_ns: i64,
    /// End (ns, host monotonic).
    pub t_end_ns: i64,
    /// Phase name: homing, excitation, tip, validation, or a user's own.
    pub phase: String,
}

/// A whole recording in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// Where it was read from (for messages).
    pub dir: PathBuf,
    /// The text of `robot.toml` (parse it with `sabr_model::RobotParams::from_toml_str`).
    pub robot_toml: String,
    /// Encoder samples in file order.
    pub encoders: Vec<EncoderRow>,
    /// Tracker rows in file order.
    pub tracker: Vec<TrackerRow>,
    /// Phases in file order.
    pub phases: Vec<PhaseRow>,
}
