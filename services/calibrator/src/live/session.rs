//! The session as it arrives: the raw streams kept as recording rows, under the same rules
//! the recorder's writer applies, and what is still missing before a calibration.

use sabr_calibration::data::phases::PhaseTable;
use sabr_calibration::data::span::SessionSpan;
use sabr_msgs::{EncoderSample, PhaseMark, TrackerFrame};
use sabr_recording::{
    CsvFormat, EncoderRow, EncodersCsv, PhaseRow, PhasesCsv, Recording, TrackerCsv, TrackerRow,
};
use std::path::PathBuf;

use sabr_recording::live::{encoder_row, phase_row, tracker_rows};

/// Counters of the live streams, written to `live.json`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct StreamStats {
    /// Encoder samples kept.
    pub encoder_samples: u64,
    /// Encoder samples lost before they reached the calibrator (sequence-number gaps).
    pub encoder_lost: u64,
    /// Tracker frames kept.
    pub tracker_frames: u64,
    /// Tracker frames lost before they reached the calibrator (sequence-number gaps).
    pub tracker_lost: u64,
    /// Phases received.
    pub phases: u64,
    /// Rows the recording format refuses (as the recorder's writer does), each logged.
    pub refused_rows: u64,
}

/// The session's rows, in arrival order, as the recorder writes them.
#[derive(Debug)]
pub struct LiveSession {
    robot_toml: String,
    encoders: Vec<EncoderRow>,
    tracker: Vec<TrackerRow>,
    phases: Vec<PhaseRow>,
    encoder_state: <EncodersCsv as CsvFormat>::State,
    last_encoder_seq: Option<u64>,
    last_frame_seq: Option<u64>,
    stats: StreamStats,
}

/// What a calibration still waits for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Progress {
    /// These calibration phases have not been announced yet.
    Phases(Vec<&'static str>),
    /// All phases are in; the streams must reach the end of the session span (ns).
    Tail {
        /// End of the session span, host ns.
        end_ns: i64,
    },
    /// Everything the calibration uses has arrived.
    Complete,
}

/// The calibration phases, as named in `phases.csv`.
pub const CALIBRATION_PHASES: [&str; 4] = ["homing", "excitation", "tip", "validation"];

impl LiveSession {
    /// An empty session of the robot described by `robot_toml`.
    pub fn new(robot_toml: String) -> Self {
        Self {
            robot_toml,
            encoders: Vec::new(),
            tracker: Vec::new(),
            phases: Vec::new(),
            encoder_state: Default::default(),
            last_encoder_seq: None,
            last_frame_seq: None,
            stats: StreamStats::default(),
        }
    }

    /// Adds an encoder sample (refused, like the recorder, if its stamp does not advance).
    pub fn encoder(&mut self, sample: &EncoderSample) {
        self.stats.encoder_lost += gap(&mut self.last_encoder_seq, sample.seq);
        let row = encoder_row(sample);
        match EncodersCsv::check(&row, &mut self.encoder_state) {
            Ok(()) => {
                self.encoders.push(row);
                self.stats.encoder_samples += 1;
            }
            Err(problem) => self.refuse("encoder sample", sample.seq, &problem),
        }
    }

    /// Adds a tracker frame as its four tool rows (a row the format refuses is left out,
    /// like the recorder does).
    pub fn frame(&mut self, frame: &TrackerFrame) {
        self.stats.tracker_lost += gap(&mut self.last_frame_seq, frame.seq);
        for row in tracker_rows(frame) {
            match TrackerCsv::check(&row, &mut ()) {
                Ok(()) => self.tracker.push(row),
                Err(problem) => self.refuse("tracker frame", frame.seq, &problem),
            }
        }
        self.stats.tracker_frames += 1;
    }

    /// Adds a finished phase.
    pub fn phase(&mut self, mark: &PhaseMark) {
        let row = phase_row(mark);
        match PhasesCsv::check(&row, &mut ()) {
            Ok(()) => {
                tracing::info!(
                    phase = %row.phase,
                    duration_s = (row.t_end_ns - row.t_start_ns) as f64 * 1e-9,
                    "phase finished"
                );
                self.phases.push(row);
                self.stats.phases += 1;
            }
            Err(problem) => self.refuse("phase", mark.seq, &problem),
        }
    }

    /// The counters so far.
    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// The span of the session's data the calibration uses, once a phase is in.
    pub fn span(&self) -> Option<SessionSpan> {
        SessionSpan::of(&PhaseTable::new(&self.phases))
    }

    /// Host stamp of the first encoder sample kept, ns.
    pub fn first_encoder_ns(&self) -> Option<i64> {
        self.encoders.first().map(|row| row.t_ns)
    }

    /// What the calibration still waits for.
    pub fn progress(&self) -> Progress {
        let missing: Vec<&'static str> = CALIBRATION_PHASES
            .into_iter()
            .filter(|name| !self.phases.iter().any(|row| row.phase == *name))
            .collect();
        if !missing.is_empty() {
            return Progress::Phases(missing);
        }
        let Some(span) = self.span() else {
            return Progress::Phases(CALIBRATION_PHASES.to_vec());
        };
        let reached = |last: Option<i64>| last.is_some_and(|t| t > span.end_ns);
        if reached(self.encoders.last().map(|r| r.t_ns))
            && reached(self.tracker.last().map(|r| r.t_ns))
        {
            Progress::Complete
        } else {
            Progress::Tail {
                end_ns: span.end_ns,
            }
        }
    }

    /// The session as a recording named `dir` (the calibration keeps its span).
    pub fn to_recording(&self, dir: PathBuf) -> Recording {
        Recording {
            dir,
            robot_toml: self.robot_toml.clone(),
            encoders: self.encoders.clone(),
            tracker: self.tracker.clone(),
            phases: self.phases.clone(),
        }
    }

    fn refuse(&mut self, what: &str, seq: u64, problem: &impl std::fmt::Display) {
        self.stats.refused_rows += 1;
        tracing::warn!(seq, "{what} not kept: {problem}");
    }
}

/// Samples missing between the previous sequence number and `seq` (0 on a restart).
fn gap(last: &mut Option<u64>, seq: u64) -> u64 {
    let lost = match *last {
        Some(previous) if seq > previous => seq - previous - 1,
        _ => 0,
    };
    *last = Some(seq);
    lost
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_msgs::FixedString;

    fn mark(name: &str, start_s: i64, end_s: i64) -> PhaseMark {
        PhaseMark {
            seq: 0,
            t_start_ns: start_s * 1_000_000_000,
            t_end_ns: end_s * 1_000_000_000,
            phase: FixedString::new(name).unwrap(),
        }
    }

    fn sample(seq: u64, t_ns: i64) -> EncoderSample {
        EncoderSample {
            seq,
            t_ns,
            counts: [seq as i64; 5],
        }
    }

    #[test]
    fn waits_for_every_phase_then_for_the_tail() {
        let mut session = LiveSession::new(String::new());
        session.encoder(&sample(1, 1_000_000_000));
        session.phase(&mark("homing", 2, 3));
        session.phase(&mark("excitation", 3, 5));
        assert_eq!(
            session.progress(),
            Progress::Phases(vec!["tip", "validation"])
        );
        session.phase(&mark("tip", 5, 6));
        session.phase(&mark("validation", 6, 8));
        let end_ns = 8_000_000_000 + sabr_calibration::data::span::TAIL_NS;
        assert_eq!(session.progress(), Progress::Tail { end_ns });
        session.encoder(&sample(2, end_ns + 1));
        let frame = TrackerFrame {
            seq: 1,
            arrival_t_ns: end_ns + 2,
            available_t_ns: end_ns + 1,
            ..TrackerFrame::default()
        };
        session.frame(&frame);
        assert_eq!(session.progress(), Progress::Complete);
    }

    #[test]
    fn gaps_are_counted_and_stale_stamps_refused_like_the_recorder() {
        let mut session = LiveSession::new(String::new());
        session.encoder(&sample(1, 10));
        session.encoder(&sample(4, 20));
        session.encoder(&sample(5, 20));
        let stats = session.stats();
        assert_eq!(stats.encoder_lost, 2);
        assert_eq!(stats.encoder_samples, 2);
        assert_eq!(stats.refused_rows, 1);
        let recording = session.to_recording("live".into());
        assert_eq!(recording.encoders.len(), 2);
    }
}
