//! The biopsy model's candidates for the residual loop: the effect library of `sabr_model`
//! at every joint and link ([`EffectSlot`]) and diagnostic probes outside it (harmonics of the
//! joint angles, per-joint delay, drift in time, needle sag). Each candidate is a few
//! columns: the derivative of the whitened, weighted residual with respect to its
//! parameters at zero, i.e. the direction in which it would change the predictions.
//!
//! Joint-side candidates are `∂r/∂q_j · s(observation)` for a per-observation signal `s`
//! (the library's [`EffectSlot::joint_signals`], or a probe's); link lengths come from
//! finite differences of the kinematics.

use nalgebra::{DMatrix, Vector3};
use sabr_model::effects::apply_joint_effects;
use sabr_model::effects::linear::RIPPLE_HARMONICS;
use sabr_model::{Effect, EffectSlot, JointMotion, Link, JOINT_COUNT};

use crate::data::session::Observation;
use crate::model::biopsy::params::{EffectParam, ParamId};
use crate::model::biopsy::predict::predict;
use crate::model::biopsy::{BiopsyModel, TIP};
use crate::model::{CandidateInfo, ParamLayout, Problem};

/// A candidate explanation of the residual.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Candidate {
    /// An effect of the library at a joint or link.
    Library(EffectSlot),
    /// Probe: a harmonic of the joint angle (not of the motor angle).
    JointHarmonic {
        /// Joint index 0..5.
        joint: usize,
        /// Cycles per joint revolution.
        harmonic: u8,
    },
    /// Probe: error proportional to the joint velocity (a delay of this joint's encoder).
    JointDelay {
        /// Joint index 0..5.
        joint: usize,
    },
    /// Probe: the joint offset drifting in time (linear and quadratic).
    OffsetDrift {
        /// Joint index 0..5.
        joint: usize,
    },
    /// Probe: the tip deflected along gravity in proportion to the needle's elevation
    /// (`cos` of it: the gravity component perpendicular to the needle).
    NeedleSag,
}

impl Candidate {
    /// Every candidate, library first.
    pub fn all() -> Vec<Candidate> {
        let mut all: Vec<Candidate> = EffectSlot::all()
            .into_iter()
            .map(Candidate::Library)
            .collect();
        for joint in 0..JOINT_COUNT {
            all.extend(
                RIPPLE_HARMONICS.map(|harmonic| Candidate::JointHarmonic { joint, harmonic }),
            );
            all.push(Candidate::JointDelay { joint });
            all.push(Candidate::OffsetDrift { joint });
        }
        all.push(Candidate::NeedleSag);
        all
    }

    /// Number of columns (parameters of the linearised candidate).
    pub fn dim(&self) -> usize {
        match self {
            Candidate::Library(slot) => slot.dim(),
            Candidate::JointHarmonic { .. } | Candidate::OffsetDrift { .. } => 2,
            _ => 1,
        }
    }

    /// Class name: the effect's (`transmission_ripple`, `backlash`, `joint_compliance`,
    /// `link_length`) or the probe's.
    pub fn class(&self) -> &'static str {
        match self {
            Candidate::Library(slot) => slot.class(),
            Candidate::JointHarmonic { .. } => "joint_angle_harmonic",
            Candidate::JointDelay { .. } => "joint_velocity",
            Candidate::OffsetDrift { .. } => "drift_in_time",
            Candidate::NeedleSag => "needle_elevation",
        }
    }

    /// The joint (0-based) it acts on, if any.
    pub fn joint(&self) -> Option<usize> {
        match *self {
            Candidate::Library(slot) => slot.joint(),
            Candidate::JointHarmonic { joint, .. }
            | Candidate::JointDelay { joint }
            | Candidate::OffsetDrift { joint } => Some(joint),
            Candidate::NeedleSag => None,
        }
    }

    fn harmonic(&self) -> Option<u8> {
        match *self {
            Candidate::Library(EffectSlot::TransmissionRipple { harmonic, .. })
            | Candidate::JointHarmonic { harmonic, .. } => Some(harmonic),
            _ => None,
        }
    }

    fn link(&self) -> Option<Link> {
        match *self {
            Candidate::Library(EffectSlot::LinkLength { link }) => Some(link),
            _ => None,
        }
    }

    /// Human-readable label, joints numbered 1..5, e.g. `transmission_ripple θ2 h1`.
    pub fn label(&self) -> String {
        let mut label = self.class().to_string();
        if let Some(joint) = self.joint() {
            label.push_str(&format!(" θ{}", joint + 1));
        }
        if let Some(harmonic) = self.harmonic() {
            label.push_str(&format!(" h{harmonic}"));
        }
        if let Some(link) = self.link() {
            label.push_str(&format!(" {}", link.name()));
        }
        if let Candidate::Library(EffectSlot::AxisTilt { axis, .. }) = self {
            label.push_str(&format!(" axis {}", axis + 1));
        }
        label
    }

    /// What the signal is, for reports.
    pub fn signal(&self) -> &'static str {
        match self {
            Candidate::Library(EffectSlot::TransmissionRipple { .. }) => {
                "sin/cos of the harmonic of the motor angle"
            }
            Candidate::Library(EffectSlot::Backlash { .. }) => {
                "offset of a 6 mrad play (sign of the velocity, ramping after each reversal)"
            }
            Candidate::Library(EffectSlot::JointCompliance { .. }) => "gravity-torque feature",
            Candidate::Library(EffectSlot::LinkLength { .. }) => "sensitivity to the link length",
            Candidate::Library(EffectSlot::AxisTilt { .. }) => {
                "sensitivity to the tilt of the joint axis"
            }
            Candidate::JointHarmonic { .. } => "sin/cos of the harmonic of the joint angle",
            Candidate::JointDelay { .. } => "joint velocity",
            Candidate::OffsetDrift { .. } => "time (linear and quadratic)",
            Candidate::NeedleSag => "needle elevation (gravity across the needle at the tip)",
        }
    }

    /// What the candidate is, for the residual loop.
    pub fn info(&self) -> CandidateInfo {
        CandidateInfo {
            class: self.class(),
            label: self.label(),
            signal: self.signal(),
            dim: self.dim(),
            in_library: matches!(self, Candidate::Library(_)),
            joint: self.joint().map(|j| j + 1),
            link: self.link().map(|l| l.name().to_string()),
            harmonic: match self {
                Candidate::Library(_) => self.harmonic().map(f64::from),
                _ => None,
            },
        }
    }

    /// The library effect with the linearised coefficients; `None` for probes or when the
    /// coefficients contradict the effect.
    pub fn effect(&self, coefficients: &[f64]) -> Option<Effect> {
        match self {
            Candidate::Library(slot) => slot.effect(coefficients),
            _ => None,
        }
    }
}

/// Backlash width (rad) whose play shapes the backlash candidates' signal: a play's offset
/// ramps over the first gap-width of travel after each reversal, which a narrower trial
/// (or the sign of the velocity, the limit of zero width) misses for the wide plays of
/// real transmissions (5–10 mrad).
const BACKLASH_TRIAL_WIDTH: f64 = 0.006;

/// Per-observation signals the joint-side candidates multiply `∂r/∂q_j` by.
struct Signals {
    motor: [f64; 5],
    joints: [f64; 5],
    velocity: [f64; 5],
    motion: JointMotion,
    /// Per joint: the offset of a play of [`BACKLASH_TRIAL_WIDTH`], per unit width.
    play: [f64; 5],
    time: f64,
}

/// The columns of `candidates` for `problem` at `model` (see the module docs).
pub fn candidate_columns(
    model: &BiopsyModel,
    problem: &Problem<'_, BiopsyModel>,
    candidates: &[Candidate],
) -> DMatrix<f64> {
    let (probe, layout) = probe_model(model);
    let derivatives = problem.with_layout(&layout).jacobian(&probe);
    let signals = observation_signals(model, problem.observations);
    let width: usize = candidates.iter().map(Candidate::dim).sum();
    let mut columns = DMatrix::zeros(problem.rows, width);
    let mut col = 0;
    for candidate in candidates {
        match *candidate {
            Candidate::Library(EffectSlot::LinkLength { link }) => {
                let k = Link::ALL.iter().position(|l| *l == link).unwrap_or(0);
                columns.set_column(col, &derivatives.column(JOINT_COUNT + k));
            }
            Candidate::Library(EffectSlot::AxisTilt { joint, axis }) => {
                let k = JOINT_COUNT + Link::ALL.len() + 2 * joint + axis;
                columns.set_column(col, &derivatives.column(k));
            }
            Candidate::NeedleSag => needle_sag_column(model, problem, &mut columns, col),
            _ => {
                for block in problem.blocks {
                    let s = &signals[block.obs];
                    let values = joint_signal(candidate, s);
                    let joint = candidate.joint().unwrap_or(0);
                    for row in block.row..block.row + block.dim {
                        let d = derivatives[(row, joint)];
                        for (k, v) in values.iter().take(candidate.dim()).enumerate() {
                            columns[(row, col + k)] = d * v;
                        }
                    }
                }
            }
        }
        col += candidate.dim();
    }
    columns
}

/// `∂r/∂q_j` of every residual row of `problem` at `model` (whitened, weighted), one column
/// per joint: the joint-offset columns of the Jacobian.
pub fn joint_derivatives(model: &BiopsyModel, problem: &Problem<'_, BiopsyModel>) -> DMatrix<f64> {
    let layout = ParamLayout::new((0..JOINT_COUNT).map(ParamId::JointOffset).collect());
    problem.with_layout(&layout).jacobian(model)
}

/// The model with a zero link-length effect per link and a zero tilt per joint axis
/// appended, and the layout of the five joint offsets (whose derivatives are `∂r/∂q_j`),
/// the five link deltas and the ten tilt angles (joint-major).
fn probe_model(model: &BiopsyModel) -> (BiopsyModel, ParamLayout<ParamId>) {
    let mut probe = model.clone();
    let first = probe.robot.effects.len();
    probe
        .robot
        .effects
        .extend(Link::ALL.map(|link| Effect::LinkLength { link, delta: 0.0 }));
    for joint in 0..JOINT_COUNT {
        probe
            .robot
            .effects
            .extend([0, 1].map(|axis| Effect::AxisTilt {
                joint,
                axis,
                angle: 0.0,
            }));
    }
    let mut ids: Vec<ParamId> = (0..JOINT_COUNT).map(ParamId::JointOffset).collect();
    ids.extend((first..probe.robot.effects.len()).map(|index| {
        let field = probe.robot.effects[index].fields()[0];
        ParamId::Effect(EffectParam { index, field })
    }));
    (probe, ParamLayout::new(ids))
}

fn observation_signals(model: &BiopsyModel, observations: &[Observation]) -> Vec<Signals> {
    let robot = &model.robot;
    let (start, end) = observations
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), o| {
            (a.min(o.exposure_ns), b.max(o.exposure_ns))
        });
    let span = (end - start).max(1.0);
    let scale = robot.encoder_scale();
    observations
        .iter()
        .map(|obs| {
            let counts = obs.counts_at_latency(model.latency_s);
            let motor = robot.motor_angles_fractional(&counts);
            let rates = robot.motor_angles_fractional(&obs.count_rates);
            let offset = robot.joints.offset.unwrap_or_default();
            let joints: [f64; 5] =
                std::array::from_fn(|j| robot.joints.gear_ratio[j] * motor[j] + offset[j]);
            let play = std::array::from_fn(|joint| {
                let trial = Effect::Backlash {
                    joint,
                    width: BACKLASH_TRIAL_WIDTH,
                };
                let q = apply_joint_effects(&[trial], &joints, &motor, &scale, &obs.motion);
                (q[joint] - joints[joint]) / BACKLASH_TRIAL_WIDTH
            });
            Signals {
                motor,
                joints,
                velocity: std::array::from_fn(|j| robot.joints.gear_ratio[j] * rates[j]),
                motion: obs.motion,
                play,
                time: 2.0 * (obs.exposure_ns - start) / span - 1.0,
            }
        })
        .collect()
}

/// The signal values (up to two) a joint-side candidate multiplies `∂r/∂q_j` by.
fn joint_signal(candidate: &Candidate, s: &Signals) -> [f64; 2] {
    match *candidate {
        Candidate::Library(EffectSlot::Backlash { joint }) => [s.play[joint], 0.0],
        Candidate::Library(slot) => slot.joint_signals(&s.motor, &s.joints, &s.motion),
        Candidate::JointHarmonic { joint, harmonic } => {
            let (sin, cos) = (f64::from(harmonic) * s.joints[joint]).sin_cos();
            [sin, cos]
        }
        Candidate::JointDelay { joint } => [s.velocity[joint], 0.0],
        Candidate::OffsetDrift { .. } => [s.time, s.time * s.time],
        Candidate::NeedleSag => [0.0, 0.0],
    }
}

/// Column of a sag of the tip along the gravity component across the needle (gravity is
/// −y of `Bb`): `∂r/∂ε = −W·g⊥` on tip rows.
fn needle_sag_column(
    model: &BiopsyModel,
    problem: &Problem<'_, BiopsyModel>,
    columns: &mut DMatrix<f64>,
    col: usize,
) {
    for (b, block) in problem.blocks.iter().enumerate() {
        if block.kind != TIP {
            continue;
        }
        let obs = &problem.observations[block.obs];
        let Ok(prediction) = predict(model, obs) else {
            continue;
        };
        let z = prediction.pose.direction.into_inner();
        let gravity = Vector3::new(0.0, -1.0, 0.0);
        let across = gravity - z * gravity.dot(&z);
        let mut white = [0.0; 3];
        problem.noise.whiten(
            block,
            &[-across.x, -across.y, -across.z, 0.0, 0.0, 0.0],
            &mut white,
        );
        let scale = problem.weights[b].sqrt();
        for (k, v) in white.iter().enumerate() {
            columns[(block.row + k, col)] = scale * v;
        }
    }
}
