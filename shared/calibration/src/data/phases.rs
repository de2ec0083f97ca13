//! The phases of a calibration session (`phases.csv`) and the host-time intervals they
//! cover.

use sabr_recording::PhaseRow;

/// The phases of the session plan the calibration knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Homing into the mechanical stops, with a dwell.
    Homing,
    /// Excitation trajectory: the data of the fit.
    Excitation,
    /// Tip phase: the tip sphere is attached (needle length).
    Tip,
    /// Static validation poses: held out, never fitted.
    Validation,
    /// Outside every known phase (or in a user's own phase).
    Other,
}

impl Phase {
    /// The name used in `phases.csv`.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Homing => "homing",
            Phase::Excitation => "excitation",
            Phase::Tip => "tip",
            Phase::Validation => "validation",
            Phase::Other => "other",
        }
    }

    fn from_name(name: &str) -> Phase {
        match name {
            "homing" => Phase::Homing,
            "excitation" => Phase::Excitation,
            "tip" => Phase::Tip,
            "validation" => Phase::Validation,
            _ => Phase::Other,
        }
    }
}

/// Host-time intervals (ns) of the known phases.
#[derive(Debug, Clone, Default)]
pub struct PhaseTable {
    intervals: Vec<(i64, i64, Phase)>,
}

impl PhaseTable {
    /// Builds the table from `phases.csv` rows; unknown phases are ignored.
    pub fn new(rows: &[PhaseRow]) -> Self {
        let intervals = rows
            .iter()
            .map(|row| (row.t_start_ns, row.t_end_ns, Phase::from_name(&row.phase)))
            .filter(|(_, _, phase)| *phase != Phase::Other)
            .collect();
        Self { intervals }
    }

    /// The phase containing host time `t_ns`, or [`Phase::Other`].
    pub fn at(&self, t_ns: f64) -> Phase {
        self.intervals
            .iter()
            .find(|(start, end, _)| (*start as f64) <= t_ns && t_ns < *end as f64)
            .map_or(Phase::Other, |(_, _, phase)| *phase)
    }

    /// Whether `phase` occurs in the table.
    pub fn contains(&self, phase: Phase) -> bool {
        self.intervals.iter().any(|(_, _, p)| *p == phase)
    }

    /// The intervals (ns) of `phase`.
    pub fn intervals(&self, phase: Phase) -> impl Iterator<Item = (i64, i64)> + '_ {
        self.intervals
            .iter()
            .filter(move |(_, _, p)| *p == phase)
            .map(|(s, e, _)| (*s, *e))
    }
}
