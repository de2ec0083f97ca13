//! The rows of a recording and the whole recording in memory (docs/robot-model.md §7).

use std::fmt;
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

impl Tool {
    /// Every tool, in the order the tracker reports them.
    pub const ALL: [Tool; 4] = [Tool::Base, Tool::Front, Tool::Back, Tool::Tip];

    /// The name used in the `tool` column of `tracker.csv`: `base`, `front`, `back` or `tip`.
    pub fn name(self) -> &'static str {
        match self {
            Tool::Base => "base",
            Tool::Front => "front",
            Tool::Back => "back",
            Tool::Tip => "tip",
        }
    }

    /// The tool named `name` in the `tool` column, if any (exact, lower case).
    pub fn from_name(name: &str) -> Option<Tool> {
        Tool::ALL.into_iter().find(|tool| tool.name() == name)
    }
}

impl fmt::Display for Tool {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
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
    /// When the frame became available at the tracker, estimated on the host: host
    /// `CLOCK_MONOTONIC` ns. The time every reader dates the frame by (the frame clock line,
    /// the latency). In a format v1 recording, the arrival stamp (v1 had no other).
    pub t_ns: i64,
    /// When the reply carrying the frame arrived at the host, host `CLOCK_MONOTONIC` ns (not
    /// before `t_ns`). In a format v1 recording, equal to `t_ns`.
    pub arrival_t_ns: i64,
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
