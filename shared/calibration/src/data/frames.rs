//! Tracker frames as measurements in the robot base `Bb`: every tool is taken relative to
//! the base marker, `T_M_X = T_S_M⁻¹ · T_S_X` (docs/robot-model.md §5, paper eq. 13), then
//! mapped into the robot base with the fixture pose `T_M_Bb`.

use nalgebra::{Isometry3, Point3};
use sabr_recording::{Tool, ToolReading, TrackerRow};

use crate::error::CalibrationError;
use crate::math::se3;

/// One tracker frame, tools expressed in the robot base `Bb` (mm).
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredFrame {
    /// Tracker frame counter.
    pub frame: u32,
    /// The frame's host stamp (ns, `CLOCK_MONOTONIC`): when it became available at the
    /// tracker, `tracker.csv`'s `t_ns` (in a format v1 recording, the arrival stamp).
    pub t_ns: i64,
    /// Measured `T_Bb_Tf` (front marker tool), if seen.
    pub front: Option<Isometry3<f64>>,
    /// Measured `T_Bb_Tb` (back marker tool), if seen.
    pub back: Option<Isometry3<f64>>,
    /// Measured tip sphere centre in `Bb` (mm), if seen.
    pub tip: Option<Point3<f64>>,
}

/// Counts of what the tracker stream held.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct FrameStats {
    /// Distinct tracker frames in `tracker.csv`.
    pub frames_total: usize,
    /// Frames dropped because the base marker was missing (nothing can be made relative).
    pub frames_without_base: usize,
    /// Frames dropped because no robot tool (front, back, tip) was seen.
    pub frames_without_robot_tools: usize,
}

/// Raw readings of one frame in the tracker frame `S`.
#[derive(Default)]
struct RawFrame {
    base: Option<Isometry3<f64>>,
    front: Option<Isometry3<f64>>,
    back: Option<Isometry3<f64>>,
    tip: Option<Point3<f64>>,
}

/// Groups `tracker.csv` rows by frame (rows of one frame are adjacent) and expresses the
/// robot tools in `Bb`. Frames without the base marker or without any robot tool are
/// dropped and counted. Errors on a pose whose quaternion is not a rotation.
pub fn measured_frames(
    rows: &[TrackerRow],
    base_to_robot: &Isometry3<f64>,
) -> Result<(Vec<MeasuredFrame>, FrameStats), CalibrationError> {
    let robot_from_marker = base_to_robot.inverse();
    let mut frames = Vec::new();
    let mut stats = FrameStats::default();
    let mut start = 0;
    while start < rows.len() {
        let frame = rows[start].frame;
        let end = start
            + rows[start..]
                .iter()
                .take_while(|row| row.frame == frame)
                .count();
        stats.frames_total += 1;
        let raw = raw_frame(&rows[start..end])?;
        start = end;
        let Some(base) = raw.base else {
            stats.frames_without_base += 1;
            continue;
        };
        if raw.front.is_none() && raw.back.is_none() && raw.tip.is_none() {
            stats.frames_without_robot_tools += 1;
            continue;
        }
        let to_robot = robot_from_marker * base.inverse();
        frames.push(MeasuredFrame {
            frame,
            t_ns: rows[end - 1].t_ns,
            front: raw.front.map(|p| to_robot * p),
            back: raw.back.map(|p| to_robot * p),
            tip: raw.tip.map(|p| to_robot * p),
        });
    }
    Ok((frames, stats))
}

fn raw_frame(rows: &[TrackerRow]) -> Result<RawFrame, CalibrationError> {
    let mut raw = RawFrame::default();
    for row in rows {
        match (row.tool, row.reading) {
            (_, ToolReading::Missing) => {}
            (Tool::Tip, ToolReading::Point { position, .. }) => {
                raw.tip = Some(finite_point(row.frame, position)?);
            }
            (
                tool @ (Tool::Base | Tool::Front | Tool::Back),
                ToolReading::Pose {
                    quaternion,
                    position,
                    ..
                },
            ) => {
                let rotation = se3::unit_quaternion(quaternion).ok_or_else(|| {
                    CalibrationError::BadTrackerRow {
                        frame: row.frame,
                        reason: format!(
                            "{tool:?} quaternion {quaternion:?} is not a unit quaternion"
                        ),
                    }
                })?;
                let position = finite_point(row.frame, position)?;
                let pose = Isometry3::from_parts(position.coords.into(), rotation);
                match tool {
                    Tool::Base => raw.base = Some(pose),
                    Tool::Front => raw.front = Some(pose),
                    _ => raw.back = Some(pose),
                }
            }
            (tool, reading) => {
                return Err(CalibrationError::BadTrackerRow {
                    frame: row.frame,
                    reason: format!("tool {tool:?} cannot carry the reading {reading:?}"),
                })
            }
        }
    }
    Ok(raw)
}

fn finite_point(frame: u32, position: [f64; 3]) -> Result<Point3<f64>, CalibrationError> {
    if position.iter().all(|v| v.is_finite()) {
        Ok(Point3::from(position))
    } else {
        Err(CalibrationError::BadTrackerRow {
            frame,
            reason: format!("position {position:?} is not finite"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn pose_row(frame: u32, tool: Tool, pose: &Isometry3<f64>) -> TrackerRow {
        let q = pose.rotation.into_inner();
        let t = pose.translation.vector;
        TrackerRow {
            t_ns: 1_000 + i64::from(frame),
            arrival_t_ns: 1_500 + i64::from(frame),
            frame,
            tool,
            reading: ToolReading::Pose {
                quaternion: [q.w, q.i, q.j, q.k],
                position: [t.x, t.y, t.z],
                rms: 0.1,
            },
        }
    }

    #[test]
    fn tools_are_made_relative_to_the_base_marker_and_moved_into_the_robot_base() {
        let t_s_m = se3::isometry(Vector3::new(10.0, 20.0, 900.0), Vector3::new(0.1, 0.2, 0.3));
        let t_m_bb = se3::isometry(Vector3::new(80.0, -40.0, 50.0), Vector3::zeros());
        let t_bb_tf = se3::isometry(Vector3::new(1.0, -90.0, 115.0), Vector3::new(0.0, 0.0, 0.4));
        let t_s_tf = t_s_m * t_m_bb * t_bb_tf;
        let rows = vec![
            pose_row(7, Tool::Base, &t_s_m),
            pose_row(7, Tool::Front, &t_s_tf),
            TrackerRow {
                t_ns: 1007,
                arrival_t_ns: 1507,
                frame: 7,
                tool: Tool::Back,
                reading: ToolReading::Missing,
            },
            pose_row(8, Tool::Front, &t_s_tf),
        ];
        let (frames, stats) = measured_frames(&rows, &t_m_bb).unwrap();
        assert_eq!(frames.len(), 1);
        assert_eq!(stats.frames_total, 2);
        assert_eq!(stats.frames_without_base, 1);
        let front = frames[0].front.unwrap();
        assert!((front.translation.vector - t_bb_tf.translation.vector).norm() < 1e-9);
        assert!(front.rotation.angle_to(&t_bb_tf.rotation) < 1e-9);
        assert!(frames[0].back.is_none());
    }

    #[test]
    fn a_non_unit_quaternion_is_an_error_naming_the_frame() {
        let mut row = pose_row(3, Tool::Base, &Isometry3::identity());
        row.reading = ToolReading::Pose {
            quaternion: [0.5, 0.0, 0.0, 0.0],
            position: [0.0; 3],
            rms: 0.1,
        };
        let error = measured_frames(&[row], &Isometry3::identity()).unwrap_err();
        assert!(error.to_string().contains("frame 3"), "{error}");
    }
}
