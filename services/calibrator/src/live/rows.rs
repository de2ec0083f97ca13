//! The live messages as recording rows (robot-model.md §7), exactly as `sabr-recorder` writes
//! them, so that the session the live calibrator holds in memory is the recording on disk.

use sabr_msgs::{EncoderSample, PhaseMark, Tool, ToolSample, ToolStatus, TrackerFrame};
use sabr_recording::{EncoderRow, PhaseRow, ToolReading, TrackerRow};

/// `encoders.csv` row of an encoder sample: its host stamp and raw counts.
pub fn encoder_row(sample: &EncoderSample) -> EncoderRow {
    EncoderRow {
        t_ns: sample.t_ns,
        counts: sample.counts,
    }
}

/// The four `tracker.csv` rows of a tracker frame (base, front, back, tip), stamped with the
/// frame's arrival time. A tool that is missing or not enabled is a `missing` row.
pub fn tracker_rows(frame: &TrackerFrame) -> [TrackerRow; 4] {
    Tool::ALL.map(|tool| TrackerRow {
        t_ns: frame.arrival_t_ns,
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

fn recording_tool(tool: Tool) -> sabr_recording::Tool {
    match tool {
        Tool::Base => sabr_recording::Tool::Base,
        Tool::Front => sabr_recording::Tool::Front,
        Tool::Back => sabr_recording::Tool::Back,
        Tool::Tip => sabr_recording::Tool::Tip,
    }
}

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
