//! The candidates of the residual loop: the effect library (transmission ripple, backlash,
//! joint compliance, link-length error) and diagnostic probes outside it (harmonics of the
//! joint angles, per-joint delay, drift in time, needle sag). Each candidate is a few
//! columns: the derivative of the whitened, weighted residual with respect to its
//! parameters at zero, i.e. the direction in which it would change the predictions.
//!
//! Joint-side candidates are `∂r/∂q_j · s(observation)` for a per-observation signal `s`
//! (a harmonic of the motor angle, the direction of motion, a gravity feature...); link
//! lengths come from finite differences of the kinematics.

use nalgebra::{DMatrix, Vector3};
use sabr_model::effects::gravity_feature;
use sabr_model::{Effect, Link};

use crate::joint_fit::JointFit;
use crate::layout::{CalibModel, ParamId, ParamLayout};
use crate::problem::Problem;
use crate::residual_loop::effect_params::{EffectField, EffectParam};
use crate::residuals::{predict, Quantity};

/// The links a link-length error may affect, in column order.
pub const LINKS: [Link; 5] = [Link::LF, Link::LFe, Link::LB, Link::LBe, Link::DOffset];
/// Harmonics of the motor and joint angles that are tried.
pub const HARMONICS: [u8; 3] = [1, 2, 3];

/// A candidate explanation of the residual.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Candidate {
    /// Library: transmission ripple of joint `joint` (0-based) at a motor-angle harmonic.
    Ripple {
        /// Joint index 0..5.
        joint: usize,
        /// Cycles per motor revolution.
        harmonic: u8,
    },
    /// Library: backlash of a joint.
    Backlash {
        /// Joint index 0..5.
        joint: usize,
    },
    /// Library: joint compliance under gravity.
    Compliance {
        /// Joint index 0..5.
        joint: usize,
    },
    /// Library: link-length error.
    LinkLength {
        /// The link.
        link: Link,
    },
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

/// Name of a link as in `params.toml`.
pub fn link_name(link: Link) -> &'static str {
    match link {
        Link::LF => "l_f",
        Link::LFe => "l_fe",
        Link::LB => "l_b",
        Link::LBe => "l_be",
        Link::DOffset => "d_offset",
    }
}

impl Candidate {
    /// Every candidate, library first.
    pub fn all() -> Vec<Candidate> {
        let mut all = Vec::new();
        for joint in 0..5 {
            all.extend(HARMONICS.map(|harmonic| Candidate::Ripple { joint, harmonic }));
            all.push(Candidate::Backlash { joint });
            all.push(Candidate::Compliance { joint });
        }
        all.extend(LINKS.map(|link| Candidate::LinkLength { link }));
        for joint in 0..5 {
            all.extend(HARMONICS.map(|harmonic| Candidate::JointHarmonic { joint, harmonic }));
            all.push(Candidate::JointDelay { joint });
            all.push(Candidate::OffsetDrift { joint });
        }
        all.push(Candidate::NeedleSag);
        all
    }

    /// Whether the candidate is an effect of the library (it can be added to the model);
    /// probes only point at structure the library does not explain.
    pub fn in_library(&self) -> bool {
        matches!(
            self,
            Candidate::Ripple { .. }
                | Candidate::Backlash { .. }
                | Candidate::Compliance { .. }
                | Candidate::LinkLength { .. }
        )
    }

    /// Number of columns (parameters of the linearised candidate).
    pub fn dim(&self) -> usize {
        match self {
            Candidate::Ripple { .. }
            | Candidate::JointHarmonic { .. }
            | Candidate::OffsetDrift { .. } => 2,
            _ => 1,
        }
    }

    /// Class name: `transmission_ripple`, `backlash`, `joint_compliance`, `link_length`, or
    /// the probe's name.
    pub fn class(&self) -> &'static str {
        match self {
            Candidate::Ripple { .. } => "transmission_ripple",
            Candidate::Backlash { .. } => "backlash",
            Candidate::Compliance { .. } => "joint_compliance",
            Candidate::LinkLength { .. } => "link_length",
            Candidate::JointHarmonic { .. } => "joint_angle_harmonic",
            Candidate::JointDelay { .. } => "joint_velocity",
            Candidate::OffsetDrift { .. } => "drift_in_time",
            Candidate::NeedleSag => "needle_elevation",
        }
    }

    /// The joint (0-based) it acts on, if any.
    pub fn joint(&self) -> Option<usize> {
        match *self {
            Candidate::Ripple { joint, .. }
            | Candidate::Backlash { joint }
            | Candidate::Compliance { joint }
            | Candidate::JointHarmonic { joint, .. }
            | Candidate::JointDelay { joint }
            | Candidate::OffsetDrift { joint } => Some(joint),
            _ => None,
        }
    }

    /// Human-readable label, joints numbered 1..5, e.g. `transmission_ripple θ2 h1`.
    pub fn label(&self) -> String {
        let mut label = self.class().to_string();
        if let Some(joint) = self.joint() {
            label.push_str(&format!(" θ{}", joint + 1));
        }
        match *self {
            Candidate::Ripple { harmonic, .. } | Candidate::JointHarmonic { harmonic, .. } => {
                label.push_str(&format!(" h{harmonic}"));
            }
            Candidate::LinkLength { link } => label.push_str(&format!(" {}", link_name(link))),
            _ => {}
        }
        label
    }

    /// What the signal is, for reports.
    pub fn signal(&self) -> &'static str {
        match self {
            Candidate::Ripple { .. } => "sin/cos of the harmonic of the motor angle",
            Candidate::Backlash { .. } => "sign of the joint velocity",
            Candidate::Compliance { .. } => "gravity-torque feature",
            Candidate::LinkLength { .. } => "sensitivity to the link length",
            Candidate::JointHarmonic { .. } => "sin/cos of the harmonic of the joint angle",
            Candidate::JointDelay { .. } => "joint velocity",
            Candidate::OffsetDrift { .. } => "time (linear and quadratic)",
            Candidate::NeedleSag => "needle elevation (gravity across the needle at the tip)",
        }
    }

    /// The library effect with the linearised coefficients `coefficients` (one per column,
    /// parameter units); `None` for probes or when the coefficients contradict the effect
    /// (a backlash must have a positive width).
    pub fn effect(&self, coefficients: &[f64]) -> Option<Effect> {
        match *self {
            Candidate::Ripple { joint, harmonic } => {
                let (in_phase, quadrature) = (coefficients[0], coefficients[1]);
                Some(Effect::TransmissionRipple {
                    joint,
                    harmonic: f64::from(harmonic),
                    amplitude: in_phase.hypot(quadrature),
                    phase: quadrature.atan2(in_phase),
                })
            }
            Candidate::Backlash { joint } => (coefficients[0] > 0.0).then_some(Effect::Backlash {
                joint,
                width: coefficients[0],
            }),
            Candidate::Compliance { joint } => Some(Effect::JointCompliance {
                joint,
                gain: coefficients[0],
            }),
            Candidate::LinkLength { link } => Some(Effect::LinkLength {
                link,
                delta: coefficients[0],
            }),
            _ => None,
        }
    }

    /// The library candidate an effect of the model is (to avoid proposing it again).
    pub fn of_effect(effect: &Effect) -> Candidate {
        match *effect {
            Effect::TransmissionRipple {
                joint, harmonic, ..
            } => Candidate::Ripple {
                joint,
                harmonic: harmonic.round().clamp(0.0, 255.0) as u8,
            },
            Effect::Backlash { joint, .. } => Candidate::Backlash { joint },
            Effect::LinkLength { link, .. } => Candidate::LinkLength { link },
            Effect::JointCompliance { joint, .. } => Candidate::Compliance { joint },
        }
    }
}

/// Per-observation signals the joint-side candidates multiply `∂r/∂q_j` by.
struct Signals {
    motor: [f64; 5],
    joints: [f64; 5],
    velocity: [f64; 5],
    direction: [f64; 5],
    time: f64,
}

/// The columns of a set of candidates at a fit, and the derivatives they are built from.
#[derive(Debug, Clone)]
pub struct CandidateColumns {
    /// `∂r/∂q_j` of every residual row (whitened, weighted), one column per joint.
    pub joint_derivatives: DMatrix<f64>,
    /// The candidates' columns, `dim()` consecutive columns each, in candidate order.
    pub columns: DMatrix<f64>,
}

/// Computes the columns of `candidates` at the solution of `fit`.
pub fn candidate_columns(fit: &JointFit, candidates: &[Candidate]) -> CandidateColumns {
    let model = &fit.model;
    let (probe, layout) = probe_model(model);
    let problem = Problem {
        layout: &layout,
        ..fit.problem()
    };
    let derivatives = problem.jacobian(&probe);
    let joint_derivatives = derivatives.columns(0, 5).into_owned();
    let signals = observation_signals(fit);
    let width: usize = candidates.iter().map(Candidate::dim).sum();
    let mut columns = DMatrix::zeros(fit.rows, width);
    let mut col = 0;
    for candidate in candidates {
        match *candidate {
            Candidate::LinkLength { link } => {
                let k = LINKS.iter().position(|l| *l == link).unwrap_or(0);
                columns.set_column(col, &derivatives.column(5 + k));
            }
            Candidate::NeedleSag => needle_sag_column(fit, &mut columns, col),
            _ => {
                for block in &fit.blocks {
                    let s = &signals[block.obs];
                    let values = joint_signal(candidate, s);
                    let joint = candidate.joint().unwrap_or(0);
                    for row in block.row..block.row + block.quantity.dim() {
                        let d = joint_derivatives[(row, joint)];
                        for (k, v) in values.iter().take(candidate.dim()).enumerate() {
                            columns[(row, col + k)] = d * v;
                        }
                    }
                }
            }
        }
        col += candidate.dim();
    }
    CandidateColumns {
        joint_derivatives,
        columns,
    }
}

/// The fit's model with a zero link-length effect per link appended, and the layout of the
/// five joint offsets (whose derivatives are `∂r/∂q_j`) and the five link deltas.
fn probe_model(model: &CalibModel) -> (CalibModel, ParamLayout) {
    let mut probe = model.clone();
    let first = probe.robot.effects.len();
    probe
        .robot
        .effects
        .extend(LINKS.map(|link| Effect::LinkLength { link, delta: 0.0 }));
    let mut ids: Vec<ParamId> = (0..5).map(ParamId::JointOffset).collect();
    ids.extend((0..LINKS.len()).map(|k| {
        ParamId::Effect(EffectParam {
            index: first + k,
            field: EffectField::Delta,
        })
    }));
    (probe, ParamLayout { ids })
}

fn observation_signals(fit: &JointFit) -> Vec<Signals> {
    let model = &fit.model;
    let robot = &model.robot;
    let times: Vec<f64> = fit.observations.iter().map(|o| o.exposure_ns).collect();
    let (start, end) = times
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| {
            (a.min(*t), b.max(*t))
        });
    let span = (end - start).max(1.0);
    fit.observations
        .iter()
        .map(|obs| {
            let counts = obs.counts_at_latency(model.latency_s);
            let motor = robot.motor_angles_fractional(&counts);
            let rates = robot.motor_angles_fractional(&obs.count_rates);
            let offset = robot.joints.offset.unwrap_or_default();
            Signals {
                motor,
                joints: std::array::from_fn(|j| robot.joints.gear_ratio[j] * motor[j] + offset[j]),
                velocity: std::array::from_fn(|j| robot.joints.gear_ratio[j] * rates[j]),
                direction: obs.motion.direction,
                time: 2.0 * (obs.exposure_ns - start) / span - 1.0,
            }
        })
        .collect()
}

/// The signal values (up to two) a joint-side candidate multiplies `∂r/∂q_j` by.
fn joint_signal(candidate: &Candidate, s: &Signals) -> [f64; 2] {
    match *candidate {
        Candidate::Ripple { joint, harmonic } => {
            let (sin, cos) = (f64::from(harmonic) * s.motor[joint]).sin_cos();
            [sin, cos]
        }
        Candidate::Backlash { joint } => [-0.5 * s.direction[joint], 0.0],
        Candidate::Compliance { joint } => [gravity_feature(joint, &s.joints), 0.0],
        Candidate::JointHarmonic { joint, harmonic } => {
            let (sin, cos) = (f64::from(harmonic) * s.joints[joint]).sin_cos();
            [sin, cos]
        }
        Candidate::JointDelay { joint } => [s.velocity[joint], 0.0],
        Candidate::OffsetDrift { .. } => [s.time, s.time * s.time],
        Candidate::LinkLength { .. } | Candidate::NeedleSag => [0.0, 0.0],
    }
}

/// Column of a sag of the tip along the gravity component across the needle (gravity is
/// −y of `Bb`): `∂r/∂ε = −W·g⊥` on tip rows.
fn needle_sag_column(fit: &JointFit, columns: &mut DMatrix<f64>, col: usize) {
    for (b, block) in fit.blocks.iter().enumerate() {
        if block.quantity != Quantity::Tip {
            continue;
        }
        let obs = &fit.observations[block.obs];
        let Ok(prediction) = predict(&fit.model, obs) else {
            continue;
        };
        let z = prediction.pose.direction.into_inner();
        let gravity = Vector3::new(0.0, -1.0, 0.0);
        let across = gravity - z * gravity.dot(&z);
        let mut white = [0.0; 3];
        fit.noise.of(Quantity::Tip).whiten(
            &[-across.x, -across.y, -across.z, 0.0, 0.0, 0.0],
            3,
            &mut white,
        );
        let scale = fit.weights[b].sqrt();
        for (k, v) in white.iter().enumerate() {
            columns[(block.row + k, col)] = scale * v;
        }
    }
}
