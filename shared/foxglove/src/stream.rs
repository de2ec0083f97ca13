//! A session turned into MCAP messages as its rows come, in time order: what the offline
//! export and the live recorder share. Encoder samples give joint states and, once the joint
//! offsets are known, the model's frames; tracker frames give the measured tool frames, the
//! tip and (with a calibrated model) the residuals; phases give log lines.

use std::io::{Seek, Write};

use nalgebra::Point3;
use sabr_model::{DirectionTracker, JointMotion, Joints, RobotParams, DIRECTION_DEAD_BAND_COUNTS};
use sabr_recording::{EncoderRow, PhaseRow, Tool, ToolReading, TrackerRow};

use crate::error::McapExportError;
use crate::frames::{self, TRACKER};
use crate::history::{homing_offsets, EncoderHistory};
use crate::messages::{
    Color, FrameTransforms, JointState, LinePrimitive, Log, MarkerResidual, PoseInFrame,
    SceneEntity, SceneUpdate, SpherePrimitive, Time, ToolResidual, Vector3,
};
use crate::writer::{McapSink, Topic};

/// How far back encoder samples are kept: longer than a homing dwell and than any tracker
/// latency (ns).
const HISTORY_NS: i64 = 120_000_000_000;
/// The phase whose dwell at the mechanical stops sets the nominal joint offsets.
pub const HOMING_PHASE: &str = "homing";
/// Foxglove's `LogLevel` INFO.
const LOG_INFO: u8 = 2;
/// Diameter of the spheres drawn at the gimbal centres and the tip (m).
const SPHERE_M: f64 = 0.006;
/// Width of the needle line (m).
const NEEDLE_WIDTH_M: f64 = 0.0015;

/// What the stream writes beyond the rows themselves.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StreamOptions {
    /// Write `/calibration/residual` per tracker frame (for a calibrated model).
    pub residuals: bool,
}

/// Writes a session's rows as MCAP messages ([`Topic`]), each at its time stamp.
#[derive(Debug)]
pub struct SessionStream<W: Write + Seek> {
    sink: McapSink<W>,
    params: RobotParams,
    options: StreamOptions,
    latency_ns: i64,
    history: EncoderHistory,
    directions: DirectionTracker,
    motion: JointMotion,
    robot_started: bool,
    encoder_rows: u64,
    /// Residual distances written so far (mm): front, back, tip.
    residual_mm: [Vec<f64>; 3],
}

impl<W: Write + Seek> SessionStream<W> {
    /// A stream into `sink` with the model `params`; robot frames are written once
    /// `params` has joint offsets (or [`SessionStream::set_offsets`] gives them).
    pub fn new(sink: McapSink<W>, params: RobotParams, options: StreamOptions) -> Self {
        let latency_ms = params
            .calibration
            .as_ref()
            .and_then(|info| info.latency_ms)
            .unwrap_or(0.0);
        SessionStream {
            sink,
            params,
            options,
            latency_ns: (latency_ms * 1e6).round() as i64,
            history: EncoderHistory::new(HISTORY_NS),
            directions: DirectionTracker::new(DIRECTION_DEAD_BAND_COUNTS as f64),
            motion: JointMotion::default(),
            robot_started: false,
            encoder_rows: 0,
            residual_mm: Default::default(),
        }
    }

    /// Whether the model has joint offsets (so robot frames are written).
    pub fn has_offsets(&self) -> bool {
        self.params.joints.offset.is_some()
    }

    /// Sets the joint offsets θ_off (rad) from now on.
    fn set_offsets(&mut self, offsets: Joints) {
        self.params.joints.offset = Some(offsets);
    }

    /// Messages written per topic so far.
    pub fn message_counts(&self) -> std::collections::BTreeMap<Topic, u32> {
        self.sink.message_counts()
    }

    /// Writes one encoder sample: `/robot/joint_states`, and `/robot/tf` when the offsets
    /// are known (`/robot/tf_static` and `/robot/scene` before the first).
    pub fn encoder(&mut self, row: &EncoderRow) -> Result<(), McapExportError> {
        self.encoder_rows += 1;
        let what = || format!("encoders.csv sample {}", self.encoder_rows);
        let t = log_time(row.t_ns, what)?;
        let time = Time::from_ns(t);
        self.history.push(*row);
        self.motion = self.directions.update(&row.counts.map(|c| c as f64));
        let joints = self
            .params
            .joints_from_counts(&row.counts, &self.motion)
            .ok();
        let state = JointState {
            timestamp: time,
            name: ["theta1", "theta2", "theta3", "theta4", "theta5"],
            counts: row.counts,
            position_rad: joints,
        };
        self.sink.write(Topic::JointStates, t, &state)?;
        let Some(q) = joints else {
            return Ok(());
        };
        if !self.robot_started {
            self.robot_started = true;
            let transforms = frames::static_transforms(&self.params, time);
            self.sink
                .write(Topic::RobotTfStatic, t, &FrameTransforms { transforms })?;
            self.sink.write(Topic::RobotScene, t, &self.scene(time))?;
        }
        let (_, transforms) =
            frames::robot_transforms(&self.params, &q, time).map_err(|cause| {
                McapExportError::Kinematics {
                    what: what(),
                    t_ns: row.t_ns,
                    cause,
                }
            })?;
        self.sink
            .write(Topic::RobotTf, t, &FrameTransforms { transforms })
    }

    /// Writes one tracker frame (its rows, one per tool): `/tracker/tf` with the pose tools
    /// seen, `/tracker/tip` when the tip was seen, and `/calibration/residual` when asked for.
    pub fn tracker_frame(&mut self, rows: &[TrackerRow]) -> Result<(), McapExportError> {
        let Some(first) = rows.first() else {
            return Ok(());
        };
        let what = || format!("tracker.csv frame {}", first.frame);
        let t = log_time(first.t_ns, what)?;
        let time = Time::from_ns(t);
        let transforms = frames::tracker_transforms(rows, time);
        self.sink
            .write(Topic::TrackerTf, t, &FrameTransforms { transforms })?;
        for row in rows {
            if let (Tool::Tip, ToolReading::Point { position, .. }) = (row.tool, &row.reading) {
                let tip = PoseInFrame {
                    timestamp: time,
                    frame_id: TRACKER.to_owned(),
                    pose: frames::pose(&nalgebra::Isometry3::translation(
                        position[0],
                        position[1],
                        position[2],
                    )),
                };
                self.sink.write(Topic::TrackerTip, t, &tip)?;
            }
        }
        if self.options.residuals {
            let residual = self.residual(rows, first, time);
            self.sink.write(Topic::Residual, t, &residual)?;
            for (distances, tool) in
                self.residual_mm
                    .iter_mut()
                    .zip([residual.front, residual.back, residual.tip])
            {
                distances.extend(tool.map(|tool| tool.distance_mm));
            }
        }
        Ok(())
    }

    /// Writes one phase as a `/phases` log line at its end. A `homing` phase sets the joint
    /// offsets from the encoder samples of its dwell at the stops when the model has none
    /// (so a live stream shows the robot from then on).
    pub fn phase(&mut self, row: &PhaseRow) -> Result<(), McapExportError> {
        if !self.has_offsets() && row.phase == HOMING_PHASE {
            let during = self.history.between(row.t_start_ns, row.t_end_ns);
            if let Some(offsets) = homing_offsets(&self.params, during) {
                self.set_offsets(offsets);
            }
        }
        let t = log_time(row.t_end_ns, || format!("phases.csv phase {:?}", row.phase))?;
        let seconds = (row.t_end_ns - row.t_start_ns) as f64 * 1e-9;
        let log = Log {
            timestamp: Time::from_ns(t),
            level: LOG_INFO,
            message: format!(
                "phase {} ended: {seconds:.3} s from t_ns {} to {}",
                row.phase, row.t_start_ns, row.t_end_ns
            ),
            name: "sabr".to_owned(),
            file: String::new(),
            line: 0,
        };
        self.sink.write(Topic::Phases, t, &log)
    }

    /// The median residual distance (mm) of the front marker, the back marker and the tip
    /// over the residuals written so far (`None` for a tool without any).
    pub fn median_residual_mm(&self) -> [Option<f64>; 3] {
        self.residual_mm.clone().map(|mut distances| {
            distances.sort_by(f64::total_cmp);
            distances.get(distances.len() / 2).copied()
        })
    }

    /// Hands every message written so far to the output (see [`McapSink::flush`]).
    pub fn flush(&mut self) -> Result<(), McapExportError> {
        self.sink.flush()
    }

    /// Finishes the file and returns the output.
    pub fn finish(self) -> Result<W, McapExportError> {
        self.sink.finish()
    }

    /// The model against one tracker frame, at its exposure (its `t_ns`, when it became
    /// available at the tracker, minus the calibrated latency, counts interpolated between the encoder samples around it), relative to the
    /// base marker. The backlash direction is the one at the latest encoder sample, a few tens
    /// of ms later: it differs only right at a reversal.
    fn residual(&self, rows: &[TrackerRow], first: &TrackerRow, time: Time) -> MarkerResidual {
        let mut residual = MarkerResidual {
            timestamp: time,
            frame: first.frame,
            front: None,
            back: None,
            tip: None,
        };
        let base = rows.iter().find_map(|row| match (row.tool, &row.reading) {
            (
                Tool::Base,
                ToolReading::Pose {
                    quaternion,
                    position,
                    ..
                },
            ) => Some(frames::reading_pose(quaternion, position)),
            _ => None,
        });
        let predicted = self
            .history
            .counts_at(first.t_ns - self.latency_ns)
            .and_then(|counts| {
                let q = self
                    .params
                    .joints_from_fractional_counts(&counts, &self.motion)
                    .ok()?;
                let needle = sabr_model::forward(&self.params.effective_geometry(), &q).ok()?;
                Some(self.params.marker_poses(&needle))
            });
        let (Some(base), Some(predicted)) = (base, predicted) else {
            return residual;
        };
        let to_base = base.inverse();
        for row in rows {
            match (row.tool, &row.reading) {
                (
                    tool @ (Tool::Front | Tool::Back),
                    ToolReading::Pose {
                        quaternion,
                        position,
                        ..
                    },
                ) => {
                    let measured = to_base * frames::reading_pose(quaternion, position);
                    let model = if tool == Tool::Front {
                        predicted.front
                    } else {
                        predicted.back
                    };
                    let offset = measured.translation.vector - model.translation.vector;
                    let angle = measured.rotation.angle_to(&model.rotation).to_degrees();
                    let value = ToolResidual {
                        position_mm: offset.into(),
                        distance_mm: offset.norm(),
                        angle_deg: Some(angle),
                    };
                    if tool == Tool::Front {
                        residual.front = Some(value);
                    } else {
                        residual.back = Some(value);
                    }
                }
                (Tool::Tip, ToolReading::Point { position, .. }) => {
                    let measured = to_base * Point3::from(*position);
                    let offset = measured - predicted.tip;
                    residual.tip = Some(ToolResidual {
                        position_mm: offset.into(),
                        distance_mm: offset.norm(),
                        angle_deg: None,
                    });
                }
                _ => {}
            }
        }
        residual
    }

    /// The needle (from `p_r` to the tip) and spheres at the gimbal centres and the tip,
    /// locked to the model frames so they move with them.
    fn scene(&self, time: Time) -> SceneUpdate {
        let l_n_m = self.params.effective_geometry().l_n * 1e-3;
        let origin = frames::pose(&nalgebra::Isometry3::identity());
        let sphere = |color: Color| SpherePrimitive {
            pose: origin,
            size: Vector3 {
                x: SPHERE_M,
                y: SPHERE_M,
                z: SPHERE_M,
            },
            color,
        };
        let entity = |frame: &str, spheres, lines| SceneEntity {
            timestamp: time,
            frame_id: frame.to_owned(),
            id: frame.to_owned(),
            lifetime: Time { sec: 0, nsec: 0 },
            frame_locked: true,
            metadata: Vec::new(),
            arrows: Vec::new(),
            cubes: Vec::new(),
            spheres,
            cylinders: Vec::new(),
            lines,
            triangles: Vec::new(),
            texts: Vec::new(),
            models: Vec::new(),
        };
        let steel = Color {
            r: 0.8,
            g: 0.8,
            b: 0.85,
            a: 1.0,
        };
        let needle = LinePrimitive {
            kind: 0,
            pose: origin,
            thickness: NEEDLE_WIDTH_M,
            scale_invariant: false,
            points: vec![
                Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: -l_n_m,
                },
                Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                },
            ],
            color: steel,
            colors: Vec::new(),
            indices: Vec::new(),
        };
        let red = Color {
            r: 0.9,
            g: 0.2,
            b: 0.2,
            a: 1.0,
        };
        let blue = Color {
            r: 0.2,
            g: 0.4,
            b: 0.9,
            a: 1.0,
        };
        SceneUpdate {
            deletions: Vec::new(),
            entities: vec![
                entity(frames::NEEDLE, vec![sphere(red)], vec![needle]),
                entity(frames::FRONT_EFFECTOR, vec![sphere(blue)], Vec::new()),
                entity(frames::BACK_EFFECTOR, vec![sphere(blue)], Vec::new()),
            ],
        }
    }
}

/// `t_ns` as an MCAP log time; `what` names the row in the error for a negative one.
fn log_time(t_ns: i64, what: impl FnOnce() -> String) -> Result<u64, McapExportError> {
    u64::try_from(t_ns).map_err(|_| McapExportError::NegativeTime { what: what(), t_ns })
}
