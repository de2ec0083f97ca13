//! Observations: each tracker frame with its exposure time, the encoder counts interpolated
//! at that time, the motion state and the phase of the session plan it falls in.

use nalgebra::{Isometry3, Point3};
use sabr_model::{JointMotion, RobotParams};
use sabr_recording::PhaseRow;

use crate::frames::MeasuredFrame;
use crate::timesync::{ClockFit, EncoderTrack};

/// Half width (ns) of the central difference that gives the count rates.
const RATE_HALF_WINDOW_NS: f64 = 25e6;

/// The phases of the session plan the calibration knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Homing into the mechanical stops, with a dwell.
    Homing,
    /// Excitation trajectory: the data of the fit.
    Excitation,
    /// Tip phase: the tip sphere is attached (needle length).
    Tip,
    /// Static validation poses: held out, never fitted.
    Validation,
    /// Outside every known phase (or in a user's own phase).
    Other,
}

impl Phase {
    /// The name used in `phases.csv`.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Homing => "homing",
            Phase::Excitation => "excitation",
            Phase::Tip => "tip",
            Phase::Validation => "validation",
            Phase::Other => "other",
        }
    }

    fn from_name(name: &str) -> Phase {
        match name {
            "homing" => Phase::Homing,
            "excitation" => Phase::Excitation,
            "tip" => Phase::Tip,
            "validation" => Phase::Validation,
            _ => Phase::Other,
        }
    }
}

/// Host-time intervals (ns) of the known phases.
#[derive(Debug, Clone, Default)]
pub struct PhaseTable {
    intervals: Vec<(i64, i64, Phase)>,
}

impl PhaseTable {
    /// Builds the table from `phases.csv` rows; unknown phases are ignored.
    pub fn new(rows: &[PhaseRow]) -> Self {
        let intervals = rows
            .iter()
            .map(|row| (row.t_start_ns, row.t_end_ns, Phase::from_name(&row.phase)))
            .filter(|(_, _, phase)| *phase != Phase::Other)
            .collect();
        Self { intervals }
    }

    /// The phase containing host time `t_ns`, or [`Phase::Other`].
    pub fn at(&self, t_ns: f64) -> Phase {
        self.intervals
            .iter()
            .find(|(start, end, _)| (*start as f64) <= t_ns && t_ns < *end as f64)
            .map_or(Phase::Other, |(_, _, phase)| *phase)
    }

    /// Whether `phase` occurs in the table.
    pub fn contains(&self, phase: Phase) -> bool {
        self.intervals.iter().any(|(_, _, p)| *p == phase)
    }

    /// The intervals (ns) of `phase`.
    pub fn intervals(&self, phase: Phase) -> impl Iterator<Item = (i64, i64)> + '_ {
        self.intervals
            .iter()
            .filter(move |(_, _, p)| *p == phase)
            .map(|(s, e, _)| (*s, *e))
    }
}

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
