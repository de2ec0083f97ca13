//! The synchronised session and its observations: each tracker frame with its exposure time,
//! the encoder counts interpolated at that time, the motion state and the phase of the
//! session plan it falls in.

use nalgebra::{Isometry3, Point3};
use sabr_model::{JointMotion, RobotParams};
use sabr_recording::Recording;

use crate::data::clock::{unwrap_counters, ClockFit};
use crate::data::encoders::EncoderTrack;
use crate::data::frames::{measured_frames, MeasuredFrame};
use crate::data::phases::{Phase, PhaseTable};
use crate::error::CalibrationError;

/// Half width (ns) of the central difference that gives the count rates.
const RATE_HALF_WINDOW_NS: f64 = 25e6;

/// One tracker frame matched to the encoders.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Tracker frame counter.
    pub frame: u32,
    /// Exposure time (host ns) assuming the latency `latency_s`.
    pub exposure_ns: f64,
    /// The latency (s) the counts were interpolated at.
    pub latency_s: f64,
    /// Phase of the session plan at the exposure time.
    pub phase: Phase,
    /// Encoder counts interpolated at the exposure time.
    pub counts: [f64; 5],
    /// Count rates at the exposure time (counts/s).
    pub count_rates: [f64; 5],
    /// Direction of the last significant motion of each joint.
    pub motion: JointMotion,
    /// Measured `T_Bb_Tf`.
    pub front: Option<Isometry3<f64>>,
    /// Measured `T_Bb_Tb`.
    pub back: Option<Isometry3<f64>>,
    /// Measured tip sphere centre in `Bb` (mm).
    pub tip: Option<Point3<f64>>,
}

impl Observation {
    /// Counts at the exposure time for a latency `latency_s` (s) instead of the one they
    /// were interpolated at, to first order in the difference.
    pub fn counts_at_latency(&self, latency_s: f64) -> [f64; 5] {
        let shift = latency_s - self.latency_s;
        std::array::from_fn(|j| self.counts[j] - shift * self.count_rates[j])
    }
}

/// Everything the observations are built from: frames, clocks, encoders and phases.
#[derive(Debug, Clone)]
pub struct SessionData {
    /// Tracker frames with the base marker, tools in `Bb`.
    pub frames: Vec<MeasuredFrame>,
    /// Unwrapped frame counter of each frame.
    pub ticks: Vec<i64>,
    /// The exposure clock.
    pub clock: ClockFit,
    /// The encoder stream.
    pub encoders: EncoderTrack,
    /// The phases.
    pub phases: PhaseTable,
}

impl SessionData {
    /// Synchronises `recording`: its tracker frames in `Bb` (tools relative to the base
    /// marker, moved with `robot`'s fixture pose), the clock line through their counters and
    /// host stamps (`tracker.csv`'s `t_ns`: when each frame became available at the tracker,
    /// as the live `sync` stamps them; a format v1 recording's arrival stamps), and the
    /// encoder track (gaps longer than `max_encoder_gap_ns` are not interpolated across).
    pub fn synchronise(
        recording: &Recording,
        robot: &RobotParams,
        phases: PhaseTable,
        max_encoder_gap_ns: i64,
    ) -> Result<Self, CalibrationError> {
        let (frames, stats) = measured_frames(&recording.tracker, &robot.markers.base_to_robot)?;
        if frames.is_empty() {
            return Err(CalibrationError::NoTrackerFrames(format!(
                "tracker.csv holds {} frames, none with the base marker and a robot tool: \
                 nothing to calibrate against",
                stats.frames_total
            )));
        }
        let counters: Vec<u32> = frames.iter().map(|f| f.frame).collect();
        let stamps: Vec<i64> = frames.iter().map(|f| f.t_ns).collect();
        let clock = ClockFit::fit(&counters, &stamps)?;
        let ticks = unwrap_counters(&counters)?;
        let encoders = EncoderTrack::new(&recording.encoders, max_encoder_gap_ns)?;
        Ok(Self {
            frames,
            ticks,
            clock,
            encoders,
            phases,
        })
    }
}

/// Observations at one latency, and the frames that could not be matched.
#[derive(Debug, Clone, Default)]
pub struct Observations {
    /// The matched frames in time order.
    pub items: Vec<Observation>,
    /// Frames whose exposure time fell outside the encoder stream or inside a gap.
    pub rejected_encoder_gap: usize,
}

impl SessionData {
    /// Exposure time (host ns) of frame `index` for a latency `latency_s`.
    pub fn exposure_ns(&self, index: usize, latency_s: f64) -> f64 {
        self.clock.line_ns(self.ticks[index]) - latency_s * 1e9
    }

    /// Matches every frame to the encoders at latency `latency_s` (s).
    pub fn observations(&self, latency_s: f64) -> Observations {
        let mut out = Observations::default();
        for (index, frame) in self.frames.iter().enumerate() {
            let exposure_ns = self.exposure_ns(index, latency_s);
            let matched = self.encoders.counts_at(exposure_ns).zip(
                self.encoders
                    .rate_at(exposure_ns, RATE_HALF_WINDOW_NS)
                    .or_else(|| {
                        self.encoders
                            .rate_at(exposure_ns, RATE_HALF_WINDOW_NS / 5.0)
                    }),
            );
            let Some((counts, count_rates)) = matched else {
                out.rejected_encoder_gap += 1;
                continue;
            };
            out.items.push(Observation {
                frame: frame.frame,
                exposure_ns,
                latency_s,
                phase: self.phases.at(exposure_ns),
                counts,
                count_rates,
                motion: self.encoders.motion_at(exposure_ns),
                front: frame.front,
                back: frame.back,
                tip: frame.tip,
            });
        }
        out
    }
}

/// Joint-angle range (rad, nominal gear ratios) each joint covers in the encoder samples of
/// `phase`.
pub fn joint_ranges(
    robot: &RobotParams,
    rows: &[sabr_recording::EncoderRow],
    phases: &PhaseTable,
    phase: Phase,
) -> [f64; 5] {
    let mut low = [f64::INFINITY; 5];
    let mut high = [f64::NEG_INFINITY; 5];
    for row in rows.iter().filter(|r| phases.at(r.t_ns as f64) == phase) {
        let motor = robot.motor_angles(&row.counts);
        for j in 0..5 {
            let q = robot.joints.gear_ratio[j] * motor[j];
            low[j] = low[j].min(q);
            high[j] = high[j].max(q);
        }
    }
    std::array::from_fn(|j| {
        let range = high[j] - low[j];
        if range.is_finite() {
            range
        } else {
            0.0
        }
    })
}
