//! The session plan, like the paper's: homing into the mechanical stops with a dwell, a
//! multi-sine excitation of all joints, a tip phase (tip sphere attached), and static
//! validation poses spread over the workspace. The plan is a commanded trajectory of paper
//! joints (rad) over robot time (ns since power-up); the true robot's stops may stop it.

use std::f64::consts::PI;

use rand::Rng;

use crate::{forward, Geometry, Joints};

/// Peak amplitude of the excitation per joint (rad).
pub const EXCITATION_AMPLITUDE: f64 = 0.2;
/// Peak amplitude of the tip-phase motion per joint (rad).
const TIP_AMPLITUDE: f64 = 0.12;
/// Distance kept between the excitation envelope and the nominal stops (rad).
const STOP_MARGIN: f64 = 0.06;
/// How far homing commands beyond the nominal stops (rad); more than the stop error.
const HOMING_OVERTRAVEL: f64 = 0.08;
/// Peak joint speed of point-to-point moves (rad/s).
const MOVE_SPEED: f64 = 0.3;
/// Shortest point-to-point move (s).
const MIN_MOVE_S: f64 = 0.8;
/// Multi-sine frequencies of joint 1 (Hz); joint i uses them × (1 + 0.09 i).
const SINE_FREQUENCIES_HZ: [f64; 3] = [0.05, 0.11, 0.23];
/// Share of the amplitude of each multi-sine component.
const SINE_SHARES: [f64; 3] = [0.5, 0.3, 0.2];
/// Candidates drawn per validation pose (the farthest from those chosen wins).
const VALIDATION_CANDIDATES: usize = 24;

/// Why a plan could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// No validation pose around the excitation centre is reachable.
    #[error("no reachable validation pose found around the centre")]
    NoValidationPose,
}

/// Phase durations at duration scale 1 (about 5 minutes in all).
#[derive(Debug, Clone, PartialEq)]
pub struct PlanDurations {
    /// Idle time after power-up (s).
    pub idle_s: f64,
    /// Dwell at the stops (s).
    pub homing_dwell_s: f64,
    /// Excitation (s).
    pub excitation_s: f64,
    /// Pause before and after the tip phase (tip sphere attach/detach) (s).
    pub pause_s: f64,
    /// Tip phase (s).
    pub tip_s: f64,
    /// Number of validation poses.
    pub validation_poses: usize,
    /// Dwell at each validation pose (s).
    pub validation_dwell_s: f64,
}

impl Default for PlanDurations {
    fn default() -> Self {
        PlanDurations {
            idle_s: 0.5,
            homing_dwell_s: 5.0,
            excitation_s: 180.0,
            pause_s: 1.0,
            tip_s: 45.0,
            validation_poses: 20,
            validation_dwell_s: 2.0,
        }
    }
}

impl PlanDurations {
    /// Durations scaled by `scale`, with floors that keep every phase usable.
    pub fn scaled(&self, scale: f64) -> Self {
        PlanDurations {
            idle_s: self.idle_s,
            homing_dwell_s: (self.homing_dwell_s * scale).max(1.0),
            excitation_s: (self.excitation_s * scale).max(4.0),
            pause_s: self.pause_s,
            tip_s: (self.tip_s * scale).max(2.0),
            validation_poses: ((self.validation_poses as f64 * scale).round() as usize).max(3),
            validation_dwell_s: (self.validation_dwell_s * scale).max(0.5),
        }
    }
}

/// One sine term of a multi-sine: `amplitude · sin(2π·frequency·t + phase)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sine {
    amplitude: f64,
    frequency_hz: f64,
    phase: f64,
}

/// What the command does within one segment.
#[derive(Debug, Clone, PartialEq)]
enum Motion {
    Hold(Joints),
    /// Cosine-profile move (zero velocity at both ends).
    Move {
        from: Joints,
        to: Joints,
    },
    /// Multi-sine about `centre`, faded in and out over `ramp_s`.
    MultiSine {
        centre: Joints,
        sines: Box<[[Sine; 3]; 5]>,
        ramp_s: f64,
    },
}

#[derive(Debug, Clone, PartialEq)]
struct Segment {
    start_ns: i64,
    end_ns: i64,
    motion: Motion,
}

/// A named phase of the session (robot time, ns).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PhaseSpan {
    /// `homing`, `excitation`, `tip` or `validation`.
    pub name: &'static str,
    /// Start (ns after power-up).
    pub start_ns: i64,
    /// End (ns after power-up).
    pub end_ns: i64,
}

/// A static validation pose: the window during which the robot holds it (robot time, ns).
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationWindow {
    /// Start of the hold (ns after power-up).
    pub start_ns: i64,
    /// End of the hold (ns after power-up).
    pub end_ns: i64,
    /// Commanded paper joints (rad).
    pub joints: Joints,
}

/// The whole commanded session.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionPlan {
    segments: Vec<Segment>,
    phases: Vec<PhaseSpan>,
    validation: Vec<ValidationWindow>,
}

/// Centre of the excitation: each joint's ±[`EXCITATION_AMPLITUDE`] envelope ends
/// 0.06 rad short of its nominal stop, on the stop's side of the home pose.
pub fn excitation_centre(home_stops: &Joints, home: &Joints) -> Joints {
    std::array::from_fn(|i| {
        let side = (home_stops[i] - home[i]).signum();
        home_stops[i] - side * (STOP_MARGIN + EXCITATION_AMPLITUDE)
    })
}

fn seconds(s: f64) -> i64 {
    (s * 1e9).round() as i64
}

fn smooth_step(s: f64) -> f64 {
    0.5 * (1.0 - (PI * s.clamp(0.0, 1.0)).cos())
}

fn move_duration_s(from: &Joints, to: &Joints) -> f64 {
    let distance = from
        .iter()
        .zip(to)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    (PI / 2.0 * distance / MOVE_SPEED).max(MIN_MOVE_S)
}

fn random_sines(rng: &mut impl Rng, amplitude: f64, frequency_scale: f64) -> [[Sine; 3]; 5] {
    std::array::from_fn(|joint| {
        std::array::from_fn(|k| Sine {
            amplitude: amplitude * SINE_SHARES[k],
            frequency_hz: SINE_FREQUENCIES_HZ[k] * (1.0 + 0.09 * joint as f64) * frequency_scale,
            phase: rng.random_range(0.0..2.0 * PI),
        })
    })
}

/// Builds the segment list, phase by phase.
struct Builder {
    segments: Vec<Segment>,
    phases: Vec<PhaseSpan>,
    now_ns: i64,
    at: Joints,
}

impl Builder {
    fn push(&mut self, duration_s: f64, motion: Motion) -> (i64, i64) {
        let start_ns = self.now_ns;
        self.now_ns += seconds(duration_s);
        self.segments.push(Segment {
            start_ns,
            end_ns: self.now_ns,
            motion,
        });
        (start_ns, self.now_ns)
    }

    fn hold(&mut self, duration_s: f64) -> (i64, i64) {
        self.push(duration_s, Motion::Hold(self.at))
    }

    fn move_to(&mut self, to: Joints) -> (i64, i64) {
        let duration = move_duration_s(&self.at, &to);
        let span = self.push(duration, Motion::Move { from: self.at, to });
        self.at = to;
        span
    }

    fn multi_sine(&mut self, duration_s: f64, sines: [[Sine; 3]; 5]) -> (i64, i64) {
        let ramp_s = (duration_s / 4.0).min(4.0);
        self.push(
            duration_s,
            Motion::MultiSine {
                centre: self.at,
                sines: Box::new(sines),
                ramp_s,
            },
        )
    }

    fn phase(&mut self, name: &'static str, (start_ns, end_ns): (i64, i64)) {
        self.phases.push(PhaseSpan {
            name,
            start_ns,
            end_ns,
        });
    }
}

/// Chooses validation poses about `centre` spread over the workspace: each the candidate
/// whose tip (nominal FK) is farthest from the tips already chosen.
fn validation_poses(
    geometry: &Geometry,
    centre: &Joints,
    count: usize,
    rng: &mut impl Rng,
) -> Result<Vec<Joints>, PlanError> {
    let reach = 0.85 * EXCITATION_AMPLITUDE;
    let mut chosen: Vec<(Joints, nalgebra::Point3<f64>)> = Vec::with_capacity(count);
    for _ in 0..count {
        let mut best: Option<(f64, Joints, nalgebra::Point3<f64>)> = None;
        for _ in 0..VALIDATION_CANDIDATES {
            let q: Joints = std::array::from_fn(|i| centre[i] + rng.random_range(-reach..=reach));
            let Ok(pose) = forward(geometry, &q) else {
                continue;
            };
            let spread = chosen
                .iter()
                .map(|(_, tip)| (tip - pose.tip).norm())
                .fold(f64::INFINITY, f64::min);
            if best.as_ref().is_none_or(|(d, _, _)| spread > *d) {
                best = Some((spread, q, pose.tip));
            }
        }
        let (_, q, tip) = best.ok_or(PlanError::NoValidationPose)?;
        chosen.push((q, tip));
    }
    Ok(chosen.into_iter().map(|(q, _)| q).collect())
}

impl SessionPlan {
    /// Builds the plan for a robot powered up at `power_up` (paper joints, rad), homing to the
    /// nominal `home_stops`, exciting about `centre`, and choosing validation poses with the
    /// nominal `geometry` (what a planner knows).
    pub fn build(
        geometry: &Geometry,
        home_stops: &Joints,
        centre: &Joints,
        power_up: &Joints,
        durations: &PlanDurations,
        rng: &mut impl Rng,
    ) -> Result<Self, PlanError> {
        let mut b = Builder {
            segments: Vec::new(),
            phases: Vec::new(),
            now_ns: 0,
            at: *power_up,
        };
        b.hold(durations.idle_s);
        let overtravel: Joints = std::array::from_fn(|i| {
            let side = (home_stops[i] - centre[i]).signum();
            home_stops[i] + side * HOMING_OVERTRAVEL
        });
        b.move_to(overtravel);
        let span = b.hold(durations.homing_dwell_s);
        b.phase("homing", span);

        b.move_to(*centre);
        let sines = random_sines(rng, EXCITATION_AMPLITUDE, 1.0);
        let span = b.multi_sine(durations.excitation_s, sines);
        b.phase("excitation", span);

        b.hold(durations.pause_s);
        let sines = random_sines(rng, TIP_AMPLITUDE, 0.7);
        let span = b.multi_sine(durations.tip_s, sines);
        b.phase("tip", span);
        b.hold(durations.pause_s);

        let poses = validation_poses(geometry, centre, durations.validation_poses, rng)?;
        let start_ns = b.now_ns;
        let mut validation = Vec::with_capacity(poses.len());
        for q in poses {
            b.move_to(q);
            let (hold_start, hold_end) = b.hold(durations.validation_dwell_s);
            validation.push(ValidationWindow {
                start_ns: hold_start,
                end_ns: hold_end,
                joints: q,
            });
        }
        let end_ns = b.now_ns;
        b.phase("validation", (start_ns, end_ns));
        Ok(SessionPlan {
            segments: b.segments,
            phases: b.phases,
            validation,
        })
    }

    /// End of the session (ns after power-up).
    pub fn end_ns(&self) -> i64 {
        self.segments.last().map_or(0, |s| s.end_ns)
    }

    /// The phases in time order.
    pub fn phases(&self) -> &[PhaseSpan] {
        &self.phases
    }

    /// The validation holds in time order.
    pub fn validation(&self) -> &[ValidationWindow] {
        &self.validation
    }

    /// Whether the tip sphere is attached at `t_ns` (during the tip phase only).
    pub fn tip_attached(&self, t_ns: i64) -> bool {
        self.phases
            .iter()
            .any(|p| p.name == "tip" && p.start_ns <= t_ns && t_ns < p.end_ns)
    }

    /// The commanded paper joints (rad) at `t_ns` (held before the start and after the end).
    pub fn joints_at(&self, t_ns: i64) -> Joints {
        let index = self
            .segments
            .partition_point(|s| s.end_ns <= t_ns)
            .min(self.segments.len() - 1);
        let segment = &self.segments[index];
        let elapsed_s = (t_ns - segment.start_ns).max(0) as f64 * 1e-9;
        let length_s = (segment.end_ns - segment.start_ns) as f64 * 1e-9;
        match &segment.motion {
            Motion::Hold(q) => *q,
            Motion::Move { from, to } => {
                let s = smooth_step(elapsed_s / length_s);
                std::array::from_fn(|i| from[i] + s * (to[i] - from[i]))
            }
            Motion::MultiSine {
                centre,
                sines,
                ramp_s,
            } => {
                let t = elapsed_s.min(length_s);
                let window = smooth_step(t / ramp_s) * smooth_step((length_s - t) / ramp_s);
                std::array::from_fn(|i| {
                    let wave: f64 = sines[i]
                        .iter()
                        .map(|s| s.amplitude * (2.0 * PI * s.frequency_hz * t + s.phase).sin())
                        .sum();
                    centre[i] + window * wave
                })
            }
        }
    }
}
