//! The calibration session inside a recording: from the start of its first calibration phase
//! (homing, excitation, tip, validation) to the end of its last, with margins.
//!
//! A recording may hold more than the session: the graph idling before it, or a straight-line
//! test driven with the new parameters after it. The calibration uses only the session's
//! encoder samples and tracker frames, so test data recorded afterwards never feeds back into
//! the model, and the live calibrator, which holds exactly the session when it calibrates,
//! gets the same result as `sabr calibrate` on the whole recording.

use sabr_recording::Recording;

use crate::data::phases::{Phase, PhaseTable};

/// Data kept before the first phase starts (ns): encoder samples that bracket the first
/// exposures. A live calibrator must be listening this long before the session starts.
pub const LEAD_NS: i64 = 100_000_000;
/// Data kept after the last phase ends (ns): tracker frames exposed before the end arrive
/// up to the tracker latency (tens of ms) later, and the encoders must bracket them.
pub const TAIL_NS: i64 = 500_000_000;

/// The phases that make up a calibration session.
const SESSION_PHASES: [Phase; 4] = [
    Phase::Homing,
    Phase::Excitation,
    Phase::Tip,
    Phase::Validation,
];

/// Host-time range (ns, `CLOCK_MONOTONIC`, inclusive) of the data a calibration uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionSpan {
    /// First time stamp used: the first phase start minus [`LEAD_NS`].
    pub start_ns: i64,
    /// Last time stamp used: the last phase end plus [`TAIL_NS`].
    pub end_ns: i64,
}

impl SessionSpan {
    /// The span of the calibration phases in `phases` (rows of `phases.csv`), or `None` when
    /// there is none.
    pub fn of(phases: &PhaseTable) -> Option<Self> {
        let intervals = SESSION_PHASES
            .iter()
            .flat_map(|&phase| phases.intervals(phase));
        let (start, end) = intervals.fold(None, |span: Option<(i64, i64)>, (s, e)| {
            Some(span.map_or((s, e), |(a, b)| (a.min(s), b.max(e))))
        })?;
        Some(Self {
            start_ns: start.saturating_sub(LEAD_NS),
            end_ns: end.saturating_add(TAIL_NS),
        })
    }

    /// True if `t_ns` lies in the span.
    pub fn contains(&self, t_ns: i64) -> bool {
        (self.start_ns..=self.end_ns).contains(&t_ns)
    }
}

/// `recording` with only the encoder samples and tracker rows (by their host stamps) inside
/// the session span; all of it when it has no calibration phase (the calibration then refuses
/// it for the missing phases). Phases and `robot.toml` are kept whole.
pub fn within_session(recording: &Recording) -> Recording {
    let Some(span) = SessionSpan::of(&PhaseTable::new(&recording.phases)) else {
        return recording.clone();
    };
    Recording {
        dir: recording.dir.clone(),
        robot_toml: recording.robot_toml.clone(),
        encoders: recording
            .encoders
            .iter()
            .filter(|row| span.contains(row.t_ns))
            .copied()
            .collect(),
        tracker: recording
            .tracker
            .iter()
            .filter(|row| span.contains(row.t_ns))
            .copied()
            .collect(),
        phases: recording.phases.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_recording::{EncoderRow, PhaseRow};

    fn phase(start: i64, end: i64, name: &str) -> PhaseRow {
        PhaseRow {
            t_start_ns: start,
            t_end_ns: end,
            phase: name.to_owned(),
        }
    }

    #[test]
    fn span_covers_the_calibration_phases_only() {
        let rows = [
            phase(5_000_000_000, 6_000_000_000, "homing"),
            phase(6_500_000_000, 9_000_000_000, "excitation"),
            phase(9_500_000_000, 10_000_000_000, "validation"),
            phase(12_000_000_000, 14_000_000_000, "line"),
        ];
        let span = SessionSpan::of(&PhaseTable::new(&rows)).unwrap();
        assert_eq!(span.start_ns, 5_000_000_000 - LEAD_NS);
        assert_eq!(span.end_ns, 10_000_000_000 + TAIL_NS);
        assert_eq!(SessionSpan::of(&PhaseTable::new(&rows[3..])), None);
    }

    #[test]
    fn data_outside_the_session_is_dropped() {
        let recording = Recording {
            dir: "rec".into(),
            robot_toml: String::new(),
            encoders: (0..30)
                .map(|k| EncoderRow {
                    t_ns: k * 1_000_000_000,
                    counts: [k; 5],
                })
                .collect(),
            tracker: Vec::new(),
            phases: vec![
                phase(10_000_000_000, 20_000_000_000, "excitation"),
                phase(25_000_000_000, 26_000_000_000, "line"),
            ],
        };
        let kept = within_session(&recording);
        let times: Vec<i64> = kept
            .encoders
            .iter()
            .map(|r| r.t_ns / 1_000_000_000)
            .collect();
        assert_eq!(times, (10..=20).collect::<Vec<_>>());
        assert_eq!(kept.phases, recording.phases);
    }
}
