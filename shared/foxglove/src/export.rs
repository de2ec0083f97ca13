//! A whole recording (format v2, or v1) written as one MCAP file, every message at its row's time
//! stamp and all topics interleaved in time order.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use sabr_model::RobotParams;
use sabr_recording::{Recording, TrackerRow, ROBOT_TOML};

use crate::error::McapExportError;
use crate::history::homing_offsets;
use crate::stream::{SessionStream, StreamOptions, HOMING_PHASE};
use crate::writer::{McapSink, Topic};

/// Which model places the robot's frames.
#[derive(Debug, Clone, PartialEq)]
pub enum ExportModel {
    /// The recording's nominal `robot.toml`, with the joint offsets its homing phase gives.
    Nominal,
    /// A calibrated model (a `params.toml` with joint offsets): the residual per tracker frame
    /// is written too.
    Calibrated(Box<RobotParams>),
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportSummary {
    /// Messages per topic.
    pub messages: BTreeMap<Topic, u32>,
    /// Tracker frames of the recording (groups of rows with one frame counter and stamp).
    pub tracker_frames: usize,
    /// With a calibrated model: the median residual distance (mm) of the front marker, the
    /// back marker and the tip (`None` for a tool never seen).
    pub median_residual_mm: Option<[Option<f64>; 3]>,
}

/// Reads a calibrated `params.toml`; it must have joint offsets.
pub fn read_calibrated_params(path: &Path) -> Result<RobotParams, McapExportError> {
    let text = std::fs::read_to_string(path).map_err(|cause| McapExportError::Io {
        path: path.to_path_buf(),
        action: "read",
        cause,
    })?;
    let params = RobotParams::from_toml_str(&text).map_err(|cause| McapExportError::Params {
        path: path.to_path_buf(),
        cause,
    })?;
    if params.joints.offset.is_none() {
        return Err(McapExportError::NoJointOffsets(format!(
            "{}: field `joints.joint_offset`: missing; a calibrated params.toml has the joint offsets",
            path.display()
        )));
    }
    Ok(params)
}

/// The tracker rows grouped into frames: consecutive rows with the same frame counter and
/// time stamp.
pub fn tracker_frames(rows: &[TrackerRow]) -> Vec<&[TrackerRow]> {
    rows.chunk_by(|a, b| a.frame == b.frame && a.t_ns == b.t_ns)
        .collect()
}

/// Writes `recording` as MCAP to the new file `out` (an existing file is not overwritten).
pub fn export_recording(
    recording: &Recording,
    model: &ExportModel,
    out: &Path,
) -> Result<ExportSummary, McapExportError> {
    let (params, options) = match model {
        ExportModel::Nominal => (nominal_params(recording)?, StreamOptions::default()),
        ExportModel::Calibrated(params) => ((**params).clone(), StreamOptions { residuals: true }),
    };
    let file = File::create_new(out).map_err(|cause| McapExportError::Io {
        path: out.to_path_buf(),
        action: "create (it must not exist yet)",
        cause,
    })?;
    let sink = McapSink::new(BufWriter::new(file), out)?;
    let mut stream = SessionStream::new(sink, params, options);
    let frames = tracker_frames(&recording.tracker);
    let mut phases: Vec<_> = recording.phases.iter().collect();
    phases.sort_by_key(|phase| phase.t_end_ns);

    let (mut e, mut f, mut p) = (0, 0, 0);
    loop {
        let encoder_t = recording.encoders.get(e).map(|row| row.t_ns);
        let frame_t = frames.get(f).map(|rows| rows[0].t_ns);
        let phase_t = phases.get(p).map(|row| row.t_end_ns);
        let next = [encoder_t, frame_t, phase_t]
            .into_iter()
            .enumerate()
            .filter_map(|(source, t)| Some((t?, source)))
            .min();
        match next {
            None => break,
            Some((_, 0)) => {
                stream.encoder(&recording.encoders[e])?;
                e += 1;
            }
            Some((_, 1)) => {
                stream.tracker_frame(frames[f])?;
                f += 1;
            }
            Some(_) => {
                stream.phase(phases[p])?;
                p += 1;
            }
        }
    }
    let messages = stream.message_counts();
    let median_residual_mm = options.residuals.then(|| stream.median_residual_mm());
    let mut output = stream.finish()?;
    let io_error = |action| {
        move |cause| McapExportError::Io {
            path: out.to_path_buf(),
            action,
            cause,
        }
    };
    output.flush().map_err(io_error("write"))?;
    output
        .into_inner()
        .map_err(|e| io_error("write")(e.into_error()))?
        .sync_all()
        .map_err(io_error("sync"))?;
    Ok(ExportSummary {
        messages,
        tracker_frames: frames.len(),
        median_residual_mm,
    })
}

/// The recording's `robot.toml` with the joint offsets of its homing phase (if it has none).
fn nominal_params(recording: &Recording) -> Result<RobotParams, McapExportError> {
    let toml_path = recording.dir.join(ROBOT_TOML);
    let mut params = RobotParams::from_toml_str(&recording.robot_toml).map_err(|cause| {
        McapExportError::Params {
            path: toml_path,
            cause,
        }
    })?;
    if params.joints.offset.is_some() {
        return Ok(params);
    }
    let phases_path = recording.dir.join("phases.csv");
    let homing = recording
        .phases
        .iter()
        .find(|phase| phase.phase == HOMING_PHASE)
        .ok_or_else(|| {
            McapExportError::NoJointOffsets(format!(
                "{}: no `{HOMING_PHASE}` phase to set the joint offsets from: give a calibration \
                 (a directory with params.toml)",
                phases_path.display()
            ))
        })?;
    let during = recording
        .encoders
        .iter()
        .filter(|row| (homing.t_start_ns..=homing.t_end_ns).contains(&row.t_ns));
    let offsets = homing_offsets(&params, during).ok_or_else(|| {
        McapExportError::NoJointOffsets(format!(
            "{}: the `{HOMING_PHASE}` phase ({} to {} ns) has no encoder samples to set the \
             joint offsets from",
            phases_path.display(),
            homing.t_start_ns,
            homing.t_end_ns
        ))
    })?;
    params.joints.offset = Some(offsets);
    Ok(params)
}
