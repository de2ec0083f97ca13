//! The live graph's messages as recording rows (docs/robot-model.md §7): the one conversion
//! `sabr-recorder` writes to disk and the live calibrator keeps in memory, so both hold the same
//! session. Behind the `live` feature, so offline users of the format do not link iceoryx2.

use crate::rows::{EncoderRow, PhaseRow, Tool as RecordedTool, ToolReading, TrackerRow};
use sabr_msgs::{EncoderSample, PhaseMark, Tool, ToolSample, ToolStatus, TrackerFrame};

/// `encoders.csv` row of an encoder sample: its host stamp and raw counts.
pub fn encoder_row(sample: &EncoderSample) -> EncoderRow {
    EncoderRow {
        t_ns: sample.t_ns,
        counts: sample.counts,
    }
}

/// The four `tracker.csv` rows of a tracker frame (base, front, back, tip), stamped with the
/// time the frame became available at the tracker (`t_ns`) and its arrival time. A tool that is
/// missing or not enabled is a `missing` row.
pub fn tracker_rows(frame: &TrackerFrame) -> [TrackerRow; 4] {
    Tool::ALL.map(|tool| TrackerRow {
        t_ns: frame.available_t_ns,
        arrival_t_ns: frame.arrival_t_ns,
        frame: frame.frame_number,
        tool: recording_tool(tool),
        reading: reading(tool, frame.tool(tool)),
    })
}

/// `phases.csv` row of a finished phase.
pub fn phase_row(mark: &PhaseMark) -> PhaseRow {
    PhaseRow {
        t_start_ns: mark.t_start_ns,
        t_end_ns: mark.t_end_ns,
        phase: mark.phase.as_str().to_owned(),
    }
}

/// The recording's name for a tracker tool.
fn recording_tool(tool: Tool) -> RecordedTool {
    match tool {
        Tool::Base => RecordedTool::Base,
        Tool::Front => RecordedTool::Front,
        Tool::Back => RecordedTool::Back,
        Tool::Tip => RecordedTool::Tip,
    }
}

/// A tool's reading as recorded: a pose for the markers, a point for the tip. The format has
/// no `disabled` status: a tool not enabled on the tracker is recorded as `missing`.
fn reading(tool: Tool, sample: &ToolSample) -> ToolReading {
    match (sample.status, tool) {
        (ToolStatus::Missing | ToolStatus::Disabled, _) => ToolReading::Missing,
        (ToolStatus::Ok, Tool::Tip) => ToolReading::Point {
            position: sample.position_mm,
            rms: sample.rms_mm,
        },
        (ToolStatus::Ok, _) => ToolReading::Pose {
            quaternion: sample.quaternion,
            position: sample.position_mm,
            rms: sample.rms_mm,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_becomes_four_rows_in_tool_order_with_its_availability_and_arrival_stamps() {
        let seen = ToolSample {
            status: ToolStatus::Ok,
            quaternion: [0.5, 0.5, -0.5, 0.5],
            position_mm: [1.0, -2.0, -900.0],
            rms_mm: 0.12,
        };
        let mut frame = TrackerFrame {
            seq: 7,
            arrival_t_ns: 123_456_789,
            available_t_ns: 122_856_789,
            sent_t_ns: 123_458_789,
            frame_number: 42,
            tools: [seen; 4],
        };
        frame.tools[Tool::Back as usize].status = ToolStatus::Disabled;
        frame.tools[Tool::Front as usize].status = ToolStatus::Missing;
        let rows = tracker_rows(&frame);
        let tools: Vec<_> = rows.iter().map(|r| r.tool.name()).collect();
        assert_eq!(tools, ["base", "front", "back", "tip"]);
        assert!(rows
            .iter()
            .all(|r| (r.t_ns, r.arrival_t_ns, r.frame) == (122_856_789, 123_456_789, 42)));
        assert!(matches!(rows[0].reading, ToolReading::Pose { rms, .. } if rms == 0.12));
        assert_eq!(rows[1].reading, ToolReading::Missing);
        assert_eq!(rows[2].reading, ToolReading::Missing);
        assert_eq!(
            rows[3].reading,
            ToolReading::Point {
                position: [1.0, -2.0, -900.0],
                rms: 0.12
            }
        );
    }
}
