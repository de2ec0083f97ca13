//! A recording that lacks what the calibration needs is refused with an error saying what
//! is missing, never calibrated into a silently bad model.

mod common;

use common::session;
use sabr_calibration::{calibrate, CalibrationError, CalibrationOptions};
use sabr_recording::{Recording, Tool, ToolReading};

fn short_recording() -> Recording {
    session(3, 0.1).0
}

fn error_of(recording: &Recording) -> CalibrationError {
    calibrate(recording, &CalibrationOptions::default()).expect_err("must be refused")
}

#[test]
fn a_missing_phase_is_named() {
    for phase in ["homing", "excitation", "tip", "validation"] {
        let mut recording = short_recording();
        recording.phases.retain(|p| p.phase != phase);
        let error = error_of(&recording);
        assert!(
            matches!(error, CalibrationError::MissingPhase { .. }),
            "{error}"
        );
        assert!(error.to_string().contains(&format!("`{phase}`")), "{error}");
    }
}

#[test]
fn no_tracker_frames_or_no_base_marker_is_refused() {
    let mut recording = short_recording();
    recording.tracker.clear();
    let error = error_of(&recording);
    assert!(
        matches!(error, CalibrationError::NoTrackerFrames(_)),
        "{error}"
    );

    let mut recording = short_recording();
    for row in recording
        .tracker
        .iter_mut()
        .filter(|r| r.tool == Tool::Base)
    {
        row.reading = ToolReading::Missing;
    }
    let error = error_of(&recording);
    assert!(error.to_string().contains("base marker"), "{error}");
}

#[test]
fn a_joint_that_did_not_move_makes_its_gear_ratio_unidentifiable() {
    let mut recording = short_recording();
    for row in &mut recording.encoders {
        row.counts[2] = 0;
    }
    let error = error_of(&recording);
    assert!(
        matches!(error, CalibrationError::TooLittleMotion { joint: 3, .. }),
        "{error}"
    );
    assert!(
        error.to_string().contains("gear ratio is not identifiable"),
        "{error}"
    );
}

/// The refusal of a short session in which `tools` are never seen: it must name the tip phase.
fn tip_phase_refusal(tools: &[Tool]) -> CalibrationError {
    let mut recording = short_recording();
    for row in recording
        .tracker
        .iter_mut()
        .filter(|r| tools.contains(&r.tool))
    {
        row.reading = ToolReading::Missing;
    }
    let error = error_of(&recording);
    assert!(
        matches!(
            error,
            CalibrationError::InsufficientData { phase: "tip", .. }
        ),
        "{error}"
    );
    error
}

#[test]
fn a_tip_phase_without_tip_readings_leaves_the_needle_length_unidentified() {
    let error = tip_phase_refusal(&[Tool::Tip]);
    assert!(error.to_string().contains("needle length"), "{error}");
}

#[test]
fn missing_tip_readings_are_named_even_when_the_latency_cannot_be_estimated() {
    // Without the back marker the latency search has no frames to work with.
    let error = tip_phase_refusal(&[Tool::Tip, Tool::Back]);
    assert!(
        error.to_string().contains("0 tip-sphere readings"),
        "{error}"
    );
}

#[test]
fn a_homing_phase_without_a_dwell_is_refused() {
    let mut recording = short_recording();
    let homing: Vec<(i64, i64)> = recording
        .phases
        .iter()
        .filter(|p| p.phase == "homing")
        .map(|p| (p.t_start_ns, p.t_end_ns))
        .collect();
    for row in &mut recording.encoders {
        if homing.iter().any(|(s, e)| (*s..*e).contains(&row.t_ns)) {
            row.counts[0] += (row.t_ns / 20_000_000) % 2 * 40;
        }
    }
    let error = error_of(&recording);
    assert!(
        matches!(
            error,
            CalibrationError::InsufficientData {
                phase: "homing",
                ..
            }
        ),
        "{error}"
    );
}
