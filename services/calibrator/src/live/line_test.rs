//! The paper's straight-line test, evaluated against the simulated rig's truth.
//!
//! SIMULATION ONLY: the rig's truth (`sabr/rig/truth`, the true tip per tracker frame) is read
//! here to judge the calibrated model; it is never used to calibrate. The motion node drives
//! the needle tip along a straight line with the announced parameters (IK server); the
//! commanded tip at each tracker exposure is the calibrated model's FK of the motor setpoint in
//! force then (the inverse of what the IK server computed). Figures:
//! - tip path error: |true tip − commanded tip| at every exposure of the line phase;
//! - cross-track error: distance of the true tip from the commanded straight line;
//! - the paper's line-length comparison: the commanded length against the length the tracker
//!   measured (tip from the marker poses through the calibrated model, mean of the start and
//!   end holds) and the true length;
//! - each model's tip error along the line from the true encoder counts (nominal, the paper's
//!   stepwise method, final), the before/after of the calibration on the test motion.

use anyhow::{bail, Context};
use nalgebra::{Point3, Vector3};
use sabr_calibration::data::frames::measured_frames;
use sabr_calibration::model::biopsy::marker_ik::joints_from_markers;
use sabr_calibration::Calibration;
use sabr_model::{forward, JointMotion, RobotParams};
use sabr_msgs::{MotionState, MotionStatus, MotorSetpoint, PhaseMark, RigTruth, TrackerFrame};
use serde::Serialize;
use std::time::{Duration, Instant};

use sabr_recording::live::tracker_rows;

/// Longest hold averaged at each end of the line (ns).
const MAX_HOLD_NS: i64 = 500_000_000;
/// Longest wait after the line's phase mark for the truth to cover its end, and after the
/// motion finished for the line's phase mark.
const TRUTH_WAIT: Duration = Duration::from_secs(2);
/// Fewest truth samples in the line phase for an evaluation.
const MIN_SAMPLES: usize = 5;
/// Count change below which a joint counts as at rest (for the direction of motion).
const MOTION_DEAD_BAND_COUNTS: f64 = 0.5;

/// The streams the line test needs, kept as they arrive.
#[derive(Debug)]
pub struct LineTest {
    phase_name: String,
    truth: Vec<RigTruth>,
    setpoints: Vec<MotorSetpoint>,
    frames: Vec<TrackerFrame>,
    phase: Option<(PhaseMark, Instant)>,
    /// When the motion reported its sessions finished.
    motion_finished: Option<Instant>,
}

/// An error statistic over a set of samples (mm).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Root mean square (mm).
    pub rms_mm: f64,
    /// Largest (mm).
    pub max_mm: f64,
}

impl ErrorStats {
    fn of(errors: &[f64]) -> Self {
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
        Self {
            rms_mm: rms,
            max_mm: errors.iter().copied().fold(0.0, f64::max),
        }
    }
}

/// A model's tip error along the line, from the true encoder counts.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelError {
    /// `nominal`, `stepwise method` or `calibrated (final)`.
    pub model: String,
    /// |FK(model, true counts) − true tip| (mm).
    pub error: ErrorStats,
}

/// The evaluation written to `line_test.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LineTestReport {
    /// Says that this evaluation used the simulator's truth.
    pub note: &'static str,
    /// Phase name of the line.
    pub phase: String,
    /// Duration of the phase (s).
    pub duration_s: f64,
    /// Truth samples (tracker exposures) in the phase.
    pub samples: usize,
    /// |true tip − commanded tip| at every exposure (mm).
    pub tip_path_error: ErrorStats,
    /// Distance of the true tip from the commanded straight line (mm).
    pub cross_track_error: ErrorStats,
    /// Commanded line length between the start and end holds (mm).
    pub commanded_length_mm: f64,
    /// Line length measured by the tracker: marker poses through the calibrated model (mm).
    pub tracker_length_mm: Option<f64>,
    /// True line length (mm).
    pub true_length_mm: f64,
    /// Tip error of each model along the line.
    pub model_tip_error: Vec<ModelError>,
}

const NOTE: &str = "simulation only: evaluated against the simulated rig's truth \
                    (sabr/rig/truth), which is never used to calibrate";

impl LineTest {
    /// Waits for the phase named `phase_name`.
    pub fn new(phase_name: &str) -> Self {
        Self {
            phase_name: phase_name.to_owned(),
            truth: Vec::new(),
            setpoints: Vec::new(),
            frames: Vec::new(),
            phase: None,
            motion_finished: None,
        }
    }

    /// Keeps a truth sample.
    pub fn truth(&mut self, truth: RigTruth) {
        self.truth.push(truth);
    }

    /// Keeps a motor setpoint (in time order; an out-of-order one is dropped).
    pub fn setpoint(&mut self, setpoint: MotorSetpoint) {
        if self
            .setpoints
            .last()
            .is_none_or(|s| s.t_ns <= setpoint.t_ns)
        {
            self.setpoints.push(setpoint);
        }
    }

    /// Keeps a tracker frame.
    pub fn frame(&mut self, frame: TrackerFrame) {
        self.frames.push(frame);
    }

    /// Notes the line's phase mark (other phases are ignored).
    pub fn phase(&mut self, mark: &PhaseMark) {
        if mark.phase.as_str() == self.phase_name && self.phase.is_none() {
            self.phase = Some((*mark, Instant::now()));
        }
    }

    /// Follows the motion while waiting for the line: a fault ends the test with an error.
    pub fn motion_status(&mut self, status: &MotionStatus) -> anyhow::Result<()> {
        match status.state {
            MotionState::Faulted => bail!(
                "the straight-line test did not complete: the motion faulted ({})",
                status.reason.as_str()
            ),
            MotionState::Finished => {
                self.motion_finished.get_or_insert_with(Instant::now);
                Ok(())
            }
            MotionState::Idle | MotionState::Moving => Ok(()),
        }
    }

    /// The evaluation, once the line phase has ended and the truth covers it; an error when
    /// the motion finished without the line phase.
    pub fn evaluate_when_complete(
        &self,
        calibration: &Calibration,
    ) -> anyhow::Result<Option<LineTestReport>> {
        let Some((mark, seen)) = &self.phase else {
            if self
                .motion_finished
                .is_some_and(|t| t.elapsed() > TRUTH_WAIT)
            {
                bail!(
                    "the motion finished without a `{}` phase: no straight-line test to evaluate",
                    self.phase_name
                );
            }
            return Ok(None);
        };
        let covered = self.truth.iter().any(|t| t.exposure_t_ns >= mark.t_end_ns);
        if !covered && seen.elapsed() < TRUTH_WAIT {
            return Ok(None);
        }
        self.evaluate(mark, calibration).map(Some)
    }

    fn evaluate(
        &self,
        mark: &PhaseMark,
        calibration: &Calibration,
    ) -> anyhow::Result<LineTestReport> {
        let (start, end) = (mark.t_start_ns, mark.t_end_ns);
        let mut samples: Vec<&RigTruth> = self
            .truth
            .iter()
            .filter(|t| (start..=end).contains(&t.exposure_t_ns))
            .collect();
        samples.sort_by_key(|t| t.exposure_t_ns);
        if samples.len() < MIN_SAMPLES {
            bail!(
                "the line phase ({:.2} s) holds {} truth samples, need at least {MIN_SAMPLES}",
                (end - start) as f64 * 1e-9,
                samples.len()
            );
        }
        let params = &calibration.params;
        let commanded: Vec<Point3<f64>> = samples
            .iter()
            .map(|t| self.commanded_tip(params, t.exposure_t_ns))
            .collect::<anyhow::Result<_>>()?;
        let truth: Vec<Point3<f64>> = samples.iter().map(|t| Point3::from(t.tip_mm)).collect();
        let path: Vec<f64> = truth
            .iter()
            .zip(&commanded)
            .map(|(t, c)| (t - c).norm())
            .collect();
        let hold = MAX_HOLD_NS.min((end - start) / 4);
        let in_start: Vec<bool> = samples
            .iter()
            .map(|t| t.exposure_t_ns <= start + hold)
            .collect();
        let in_end: Vec<bool> = samples
            .iter()
            .map(|t| t.exposure_t_ns >= end - hold)
            .collect();
        let (cmd_a, cmd_b) = (mean(&commanded, &in_start), mean(&commanded, &in_end));
        let (true_a, true_b) = (mean(&truth, &in_start), mean(&truth, &in_end));
        let axis = (cmd_b - cmd_a)
            .try_normalize(1e-9)
            .context("the commanded line has no length")?;
        let cross: Vec<f64> = truth
            .iter()
            .map(|p| {
                let d = p - cmd_a;
                (d - axis * d.dot(&axis)).norm()
            })
            .collect();
        let tracker_length_mm = self.tracker_length(calibration, &samples, &in_start, &in_end);
        Ok(LineTestReport {
            note: NOTE,
            phase: self.phase_name.clone(),
            duration_s: (end - start) as f64 * 1e-9,
            samples: samples.len(),
            tip_path_error: ErrorStats::of(&path),
            cross_track_error: ErrorStats::of(&cross),
            commanded_length_mm: (cmd_b - cmd_a).norm(),
            tracker_length_mm,
            true_length_mm: (true_b - true_a).norm(),
            model_tip_error: model_errors(calibration, &samples)?,
        })
    }

    /// FK of the calibrated model at the setpoint in force at `t_ns`.
    fn commanded_tip(&self, params: &RobotParams, t_ns: i64) -> anyhow::Result<Point3<f64>> {
        let index = self.setpoints.partition_point(|s| s.t_ns <= t_ns);
        let setpoint = index
            .checked_sub(1)
            .map(|i| &self.setpoints[i])
            .with_context(|| format!("no motor setpoint in force at t = {t_ns} ns"))?;
        tip(params, &setpoint.target_counts, &JointMotion::default())
            .with_context(|| format!("setpoint {}", setpoint.seq))
    }

    /// Line length from the tracker's marker poses at the start and end holds, through the
    /// calibrated model's marker IK; `None` when a hold has no usable frame.
    fn tracker_length(
        &self,
        calibration: &Calibration,
        samples: &[&RigTruth],
        in_start: &[bool],
        in_end: &[bool],
    ) -> Option<f64> {
        let params = &calibration.params;
        let geometry = params.effective_geometry();
        let measured_tip = |truth: &RigTruth| -> Option<Point3<f64>> {
            let frame = self
                .frames
                .iter()
                .find(|f| f.frame_number == truth.frame_number)?;
            let rows = tracker_rows(frame);
            let (measured, _) = measured_frames(&rows, &params.markers.base_to_robot).ok()?;
            let measured = measured.first()?;
            let start = params
                .joints_from_fractional_counts(&truth.counts, &JointMotion::default())
                .ok()?;
            let prediction = joints_from_markers(
                &geometry,
                &params.markers,
                &calibration.fit.noise,
                measured.front.as_ref()?,
                measured.back.as_ref()?,
                start,
            )?;
            Some(prediction.pose.tip)
        };
        let hold_mean = |mask: &[bool]| -> Option<Point3<f64>> {
            let tips: Vec<Point3<f64>> = samples
                .iter()
                .zip(mask)
                .filter(|(_, &m)| m)
                .filter_map(|(t, _)| measured_tip(t))
                .collect();
            (!tips.is_empty()).then(|| mean(&tips, &vec![true; tips.len()]))
        };
        Some((hold_mean(in_end)? - hold_mean(in_start)?).norm())
    }
}

impl LineTestReport {
    /// The lines printed at the end of the main job.
    pub fn text(&self) -> String {
        let mut text = format!(
            "straight-line test ({}): {:.2} s, {} tracker exposures\n",
            NOTE, self.duration_s, self.samples
        );
        text.push_str(&format!(
            "  tip path error vs truth: RMS {:.3} mm, max {:.3} mm (cross-track RMS {:.3} mm)\n",
            self.tip_path_error.rms_mm, self.tip_path_error.max_mm, self.cross_track_error.rms_mm
        ));
        let tracker = self
            .tracker_length_mm
            .map_or("–".to_owned(), |l| format!("{l:.3} mm"));
        text.push_str(&format!(
            "  line length: commanded {:.3} mm, tracker {tracker}, true {:.3} mm\n",
            self.commanded_length_mm, self.true_length_mm
        ));
        text.push_str("  model tip error along the line (true counts vs true tip):\n");
        for model in &self.model_tip_error {
            text.push_str(&format!(
                "    {:<22} RMS {:>7.3} mm, max {:>7.3} mm\n",
                model.model, model.error.rms_mm, model.error.max_mm
            ));
        }
        text
    }
}

/// Tip error of the nominal, stepwise-method and final models from the true counts.
fn model_errors(
    calibration: &Calibration,
    samples: &[&RigTruth],
) -> anyhow::Result<Vec<ModelError>> {
    let models = [
        ("nominal", &calibration.nominal.robot),
        ("stepwise method", &calibration.stepwise.robot),
        ("calibrated (final)", &calibration.params),
    ];
    models
        .into_iter()
        .map(|(name, params)| {
            let mut motion = JointMotion::default();
            let mut previous: Option<[f64; 5]> = None;
            let mut errors = Vec::with_capacity(samples.len());
            for truth in samples {
                if let Some(previous) = previous {
                    for ((direction, now), before) in
                        motion.direction.iter_mut().zip(truth.counts).zip(previous)
                    {
                        let change = now - before;
                        if change.abs() > MOTION_DEAD_BAND_COUNTS {
                            *direction = change.signum();
                        }
                    }
                }
                previous = Some(truth.counts);
                let predicted = tip(params, &truth.counts, &motion)
                    .with_context(|| format!("{name} model, frame {}", truth.frame_number))?;
                errors.push((predicted - Point3::from(truth.tip_mm)).norm());
            }
            Ok(ModelError {
                model: name.to_owned(),
                error: ErrorStats::of(&errors),
            })
        })
        .collect()
}

/// The tip (mm, `Bb`) of `params` at fractional `counts`.
fn tip(
    params: &RobotParams,
    counts: &[f64; 5],
    motion: &JointMotion,
) -> anyhow::Result<Point3<f64>> {
    let joints = params.joints_from_fractional_counts(counts, motion)?;
    Ok(forward(&params.effective_geometry(), &joints)?.tip)
}

/// Mean of the points selected by `mask`.
fn mean(points: &[Point3<f64>], mask: &[bool]) -> Point3<f64> {
    let (sum, n) = points
        .iter()
        .zip(mask)
        .filter(|(_, &m)| m)
        .fold((Vector3::zeros(), 0usize), |(s, n), (p, _)| {
            (s + p.coords, n + 1)
        });
    Point3::from(sum / n.max(1) as f64)
}
