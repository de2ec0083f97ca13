//! Effects beyond the paper's model, defined once for the simulator (which builds a true
//! robot with them), the calibration model (which carries them) and the residual loop
//! (which proposes them): what each effect is and how it acts on the joints or the geometry
//! (here), its text syntax ([`spec`]), and its linearisation at a joint or link
//! ([`linear`]).

pub mod linear;
pub mod play;
pub mod spec;

use serde::{Deserialize, Serialize};

use crate::JOINT_COUNT;
use play::{play_output, PlayMemory};

/// A link of the 5-bars (or the needle offset) whose length an effect may change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Link {
    /// Front proximal link `l_f`.
    LF,
    /// Front effector extension `l_fe`.
    LFe,
    /// Back proximal link `l_b`.
    LB,
    /// Back effector extension `l_be`.
    LBe,
    /// Needle offset `d_offset`.
    DOffset,
}

impl Link {
    /// Every link an effect may change, in `params.toml` order.
    pub const ALL: [Link; 5] = [Link::LF, Link::LFe, Link::LB, Link::LBe, Link::DOffset];

    /// Name as in `params.toml` (`l_f`, `l_fe`, `l_b`, `l_be`, `d_offset`).
    pub fn name(self) -> &'static str {
        match self {
            Link::LF => "l_f",
            Link::LFe => "l_fe",
            Link::LB => "l_b",
            Link::LBe => "l_be",
            Link::DOffset => "d_offset",
        }
    }

    /// The link of a `params.toml` name.
    pub fn from_name(name: &str) -> Option<Link> {
        Link::ALL.into_iter().find(|link| link.name() == name)
    }
}

/// Motion state that history-dependent effects need: per joint, the sign (−1, 0, +1) of the
/// last significant motor velocity and the recent turning points of its encoder count.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointMotion {
    /// Sign of the last motion of each joint (0 = unknown / never moved).
    pub direction: [f64; 5],
    /// Per joint: encoder counts where its direction last changed (the play operator's
    /// memory, see [`play`]).
    pub turns: [PlayMemory; 5],
}

impl JointMotion {
    /// Distance (encoder counts, ≥ 0) joint `joint` has travelled since its last turning
    /// point, at `counts`; `None` before it has moved.
    pub fn travel_since_turn(&self, joint: usize, counts: f64) -> Option<f64> {
        let last = *self.turns[joint].turns().first()?;
        Some((counts - last).abs())
    }
}

/// Encoder counts a joint must move back from its last extremum before its direction of
/// motion changes (the backlash direction rule shared by calibration and `sabr fk`).
pub const DIRECTION_DEAD_BAND_COUNTS: i64 = 2;

/// Follows the direction of motion of each joint through a time-ordered stream of encoder
/// counts, as it happens: a joint's direction changes once its count has moved back by at
/// least a dead-band from its last extremum, so a ±1-count dither at rest never flips it.
/// Before a joint's first such move its direction is 0 (unknown).
#[derive(Debug, Clone, PartialEq)]
pub struct DirectionTracker {
    dead_band_counts: f64,
    extremum: Option<[f64; JOINT_COUNT]>,
    motion: JointMotion,
}

impl DirectionTracker {
    /// A tracker that needs a move of `dead_band_counts` (encoder counts, at least 1) to
    /// start or reverse a joint's direction.
    pub fn new(dead_band_counts: f64) -> Self {
        Self {
            dead_band_counts: dead_band_counts.max(1.0),
            extremum: None,
            motion: JointMotion::default(),
        }
    }

    /// Takes the next counts (raw, possibly fractional) and returns the motion state there.
    pub fn update(&mut self, counts: &[f64; JOINT_COUNT]) -> JointMotion {
        let Some(extremum) = &mut self.extremum else {
            self.extremum = Some(*counts);
            return self.motion;
        };
        for joint in 0..JOINT_COUNT {
            let direction = &mut self.motion.direction[joint];
            let moved = counts[joint] - extremum[joint];
            if moved * *direction > 0.0 {
                extremum[joint] = counts[joint];
            } else if moved.abs() >= self.dead_band_counts {
                self.motion.turns[joint].push(extremum[joint], *direction == 0.0);
                *direction = moved.signum();
                extremum[joint] = counts[joint];
            }
        }
        self.motion
    }
}

/// One effect with its parameters. Joints are indexed 0..5 (θ1 = 0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Effect {
    /// Transmission ripple (e.g. capstan eccentricity): adds
    /// `amplitude · sin(harmonic · θ_enc + phase)` (rad at the joint) to the joint angle.
    TransmissionRipple {
        /// Joint index 0..5.
        joint: usize,
        /// Harmonic of the motor angle (cycles per motor revolution).
        harmonic: f64,
        /// Amplitude at the joint (rad).
        amplitude: f64,
        /// Phase (rad).
        phase: f64,
    },
    /// Backlash, a play operator of full width `width`: the joint lags by `width/2` behind
    /// the motor while it moves; after a reversal it stays put until the motor has crossed
    /// the whole gap (see [`play`]).
    Backlash {
        /// Joint index 0..5.
        joint: usize,
        /// Full dead-band width at the joint (rad).
        width: f64,
    },
    /// Link-length error: `delta` mm added to the named link.
    LinkLength {
        /// Which link.
        link: Link,
        /// Added length (mm).
        delta: f64,
    },
    /// Joint-axis misalignment: the axis of `joint` turned by `angle` about the first
    /// (`axis = 0`) or second (`axis = 1`) axis perpendicular to it (see
    /// [`Geometry::axis_tilt`](crate::Geometry::axis_tilt)).
    AxisTilt {
        /// Joint index 0..5.
        joint: usize,
        /// Which perpendicular axis, 0 or 1.
        axis: usize,
        /// Tilt angle (rad).
        angle: f64,
    },
    /// Joint compliance under gravity: adds `gain · g_i(q)` where `g_i` is the joint's
    /// normalised gravity-torque feature (see [`gravity_feature`]).
    JointCompliance {
        /// Joint index 0..5.
        joint: usize,
        /// Deflection per unit gravity feature (rad).
        gain: f64,
    },
}

/// Normalised gravity-torque feature of joint `joint` at joint angles `q` (dimensionless,
/// magnitude ≤ 1), gravity along −y of `Bb`.
///
/// - θ1, θ2 (front stage, whose plane is the x-y plane of `Bf` ≈ `Bb`, so it contains gravity):
///   the gravity torque about the joint axis of a link at absolute angle θ is ∝ cos θ, so the
///   feature is `cos θ_j`.
/// - θ4, θ5 (back stage, its plane turned by θ3 about x): only the in-plane part `cos θ3` of
///   gravity loads them, so the feature is `cos θ3 · cos θ_j`.
/// - θ3 (the back stage rolling about x): gravity at the stage's centre of mass
///   `Rx(θ3)·(X, Y, 0)` has the torque `g·Y·sin θ3` about x. With `Y` normalised by the link
///   length to `(sin θ4 + sin θ5)/2` the feature is `sin θ3 · (sin θ4 + sin θ5)/2`.
///
/// An index ≥ 5 has no feature (0).
pub fn gravity_feature(joint: usize, q: &crate::Joints) -> f64 {
    match joint {
        0 | 1 => q[joint].cos(),
        2 => q[2].sin() * 0.5 * (q[3].sin() + q[4].sin()),
        3 | 4 => q[2].cos() * q[joint].cos(),
        _ => 0.0,
    }
}

/// How encoder counts become joint angles (docs/robot-model.md §2), as the history-dependent
/// effects need it: the motor angle per count `2π / cpr` (rad) and the gear ratio `GR`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EncoderScale {
    /// Gear ratio joint/motor of each joint.
    pub gear_ratio: crate::Joints,
    /// Motor angle per encoder count of each joint (rad).
    pub motor_rad_per_count: crate::Joints,
}

/// Applies the joint-side effects (ripple, backlash, compliance) of `effects` to the
/// paper-model joint angles `q_paper` (rad), given the motor angles θ_enc (rad), the
/// encoder `scale` and the motion state. Link-length effects are not joint-side and are ignored here.
///
/// - ripple adds `amplitude · sin(harmonic · θ_enc,j + phase)`;
/// - backlash adds `y − x`, the play operator's output `y` minus its input `x = q_paper,j`
///   ([`play::play_output`] over the joint's turning points): `−direction·width/2` in
///   steady motion, unchanged from before a reversal until the motor has crossed the gap;
/// - compliance adds `gain · gravity_feature(j, q_paper)` (the deflection is small, so the
///   feature is evaluated at the undeflected joints).
///
/// Effects naming a joint index ≥ 5 are ignored (parameter validation rejects them).
pub fn apply_joint_effects(
    effects: &[Effect],
    q_paper: &crate::Joints,
    motor_angles: &crate::Joints,
    scale: &EncoderScale,
    motion: &JointMotion,
) -> crate::Joints {
    let mut q = *q_paper;
    for effect in effects {
        match *effect {
            Effect::TransmissionRipple {
                joint,
                harmonic,
                amplitude,
                phase,
            } if joint < JOINT_COUNT => {
                q[joint] += amplitude * (harmonic * motor_angles[joint] + phase).sin();
            }
            Effect::Backlash { joint, width } if joint < JOINT_COUNT => {
                q[joint] +=
                    backlash_offset(joint, width, q_paper[joint], motor_angles, scale, motion);
            }
            Effect::JointCompliance { joint, gain } if joint < JOINT_COUNT => {
                q[joint] += gain * gravity_feature(joint, q_paper);
            }
            _ => {}
        }
    }
    q
}

/// `y − x` (rad) of the play operator of full width `width` on joint `joint` (see
/// [`apply_joint_effects`]).
fn backlash_offset(
    joint: usize,
    width: f64,
    x: f64,
    motor_angles: &crate::Joints,
    scale: &EncoderScale,
    motion: &JointMotion,
) -> f64 {
    let memory = &motion.turns[joint];
    // The input at a turning point: x moved back by the joint travel since then.
    let (ratio, per_count) = (scale.gear_ratio[joint], scale.motor_rad_per_count[joint]);
    let mut turns_rad = [0.0; play::PLAY_MEMORY];
    let turns = memory.turns();
    for (slot, &turn) in turns_rad.iter_mut().zip(turns) {
        *slot = x - ratio * (motor_angles[joint] - per_count * turn);
    }
    play_output(
        0.5 * width,
        x,
        motion.direction[joint],
        &turns_rad[..turns.len()],
        memory.starts_from_rest(),
    ) - x
}

/// A numeric field of an [`Effect`]: what a fit moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EffectField {
    /// Ripple amplitude at the joint (rad).
    Amplitude,
    /// Ripple phase (rad).
    Phase,
    /// Backlash width at the joint (rad).
    Width,
    /// Link-length change (mm).
    Delta,
    /// Compliance gain (rad per unit gravity feature).
    Gain,
    /// Axis tilt angle (rad).
    Angle,
}

impl EffectField {
    /// Field name as in `params.toml`.
    pub fn name(self) -> &'static str {
        match self {
            EffectField::Amplitude => "amplitude",
            EffectField::Phase => "phase",
            EffectField::Width => "width",
            EffectField::Delta => "delta",
            EffectField::Gain => "gain",
            EffectField::Angle => "angle",
        }
    }

    /// Unit of the field's value.
    pub fn unit(self) -> &'static str {
        match self {
            EffectField::Delta => "mm",
            _ => "rad",
        }
    }
}

impl Effect {
    /// Class name as in `params.toml`'s `kind`: `transmission_ripple`, `backlash`,
    /// `link_length` or `joint_compliance`.
    pub fn class(&self) -> &'static str {
        match self {
            Effect::TransmissionRipple { .. } => "transmission_ripple",
            Effect::Backlash { .. } => "backlash",
            Effect::LinkLength { .. } => "link_length",
            Effect::JointCompliance { .. } => "joint_compliance",
            Effect::AxisTilt { .. } => "axis_tilt",
        }
    }

    /// The fields a fit of the effect moves (the ripple's harmonic is a discrete choice).
    pub fn fields(&self) -> &'static [EffectField] {
        match self {
            Effect::TransmissionRipple { .. } => &[EffectField::Amplitude, EffectField::Phase],
            Effect::Backlash { .. } => &[EffectField::Width],
            Effect::LinkLength { .. } => &[EffectField::Delta],
            Effect::JointCompliance { .. } => &[EffectField::Gain],
            Effect::AxisTilt { .. } => &[EffectField::Angle],
        }
    }

    /// The value of `field`; `None` when the effect has no such field.
    pub fn field(&self, field: EffectField) -> Option<f64> {
        match (self, field) {
            (Effect::TransmissionRipple { amplitude, .. }, EffectField::Amplitude) => {
                Some(*amplitude)
            }
            (Effect::TransmissionRipple { phase, .. }, EffectField::Phase) => Some(*phase),
            (Effect::Backlash { width, .. }, EffectField::Width) => Some(*width),
            (Effect::LinkLength { delta, .. }, EffectField::Delta) => Some(*delta),
            (Effect::JointCompliance { gain, .. }, EffectField::Gain) => Some(*gain),
            (Effect::AxisTilt { angle, .. }, EffectField::Angle) => Some(*angle),
            _ => None,
        }
    }

    /// Sets `field` to `value`; returns false (and changes nothing) when the effect has no
    /// such field.
    pub fn set_field(&mut self, field: EffectField, value: f64) -> bool {
        let slot = match (self, field) {
            (Effect::TransmissionRipple { amplitude, .. }, EffectField::Amplitude) => amplitude,
            (Effect::TransmissionRipple { phase, .. }, EffectField::Phase) => phase,
            (Effect::Backlash { width, .. }, EffectField::Width) => width,
            (Effect::LinkLength { delta, .. }, EffectField::Delta) => delta,
            (Effect::JointCompliance { gain, .. }, EffectField::Gain) => gain,
            (Effect::AxisTilt { angle, .. }, EffectField::Angle) => angle,
            _ => return false,
        };
        *slot = value;
        true
    }
}

impl Effect {
    /// Checks the parameters: joint index < 5, finite numbers, non-negative backlash width.
    /// The error says what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        let (joint, numbers): (Option<usize>, Vec<(&str, f64)>) = match *self {
            Effect::TransmissionRipple {
                joint,
                harmonic,
                amplitude,
                phase,
            } => (
                Some(joint),
                vec![
                    ("harmonic", harmonic),
                    ("amplitude", amplitude),
                    ("phase", phase),
                ],
            ),
            Effect::Backlash { joint, width } => {
                if width < 0.0 {
                    return Err(format!("backlash width must not be negative, got {width}"));
                }
                (Some(joint), vec![("width", width)])
            }
            Effect::LinkLength { delta, .. } => (None, vec![("delta", delta)]),
            Effect::JointCompliance { joint, gain } => (Some(joint), vec![("gain", gain)]),
            Effect::AxisTilt { joint, axis, angle } => {
                if axis > 1 {
                    return Err(format!("axis tilt axis must be 0 or 1, got {axis}"));
                }
                (Some(joint), vec![("angle", angle)])
            }
        };
        if let Some(joint) = joint {
            if joint >= JOINT_COUNT {
                return Err(format!(
                    "joint index {joint} is out of range (joints are 0..{JOINT_COUNT})"
                ));
            }
        }
        for (name, value) in numbers {
            if !value.is_finite() {
                return Err(format!("`{name}` must be finite, got {value}"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const Q: crate::Joints = [-2.3, -0.8, 0.1, -2.7, -0.6];
    const MOTOR: crate::Joints = [1.0, -2.0, 3.0, 0.5, 7.0];

    const SCALE: EncoderScale = EncoderScale {
        gear_ratio: [0.1, 0.1, 0.05, 0.1, 0.1],
        motor_rad_per_count: [std::f64::consts::TAU / 2000.0; 5],
    };

    fn apply(effects: &[Effect], direction: [f64; 5]) -> crate::Joints {
        let motion = JointMotion {
            direction,
            ..JointMotion::default()
        };
        apply_joint_effects(effects, &Q, &MOTOR, &SCALE, &motion)
    }

    #[test]
    fn direction_tracker_ignores_dither_and_flips_after_the_dead_band() {
        let mut tracker = DirectionTracker::new(2.0);
        let at =
            |tracker: &mut DirectionTracker, c0: f64| tracker.update(&[c0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(at(&mut tracker, 100.0).direction[0], 0.0);
        assert_eq!(at(&mut tracker, 101.0).direction[0], 0.0, "dither at rest");
        assert_eq!(at(&mut tracker, 99.0).direction[0], 0.0, "dither at rest");
        assert_eq!(at(&mut tracker, 102.0).direction[0], 1.0, "first move");
        assert_eq!(at(&mut tracker, 110.0).direction[0], 1.0);
        assert_eq!(
            at(&mut tracker, 109.0).direction[0],
            1.0,
            "within the dead-band"
        );
        assert_eq!(at(&mut tracker, 108.0).direction[0], -1.0, "reversed");
        assert_eq!(at(&mut tracker, 109.0).direction[0], -1.0);
        assert_eq!(at(&mut tracker, 110.0).direction[0], 1.0);
        assert_eq!(
            tracker.update(&[110.0, 1.0, -1.0, 1.0, 0.0]).direction[1..],
            [0.0; 4][..],
            "the other joints only dithered"
        );
    }

    #[test]
    fn every_field_round_trips_and_mismatches_are_inert() {
        let mut effects = vec![
            Effect::TransmissionRipple {
                joint: 1,
                harmonic: 2.0,
                amplitude: 0.001,
                phase: 0.3,
            },
            Effect::LinkLength {
                link: Link::LF,
                delta: 0.2,
            },
            Effect::Backlash {
                joint: 3,
                width: 0.004,
            },
            Effect::JointCompliance {
                joint: 2,
                gain: -0.002,
            },
        ];
        let mut value = 0.0;
        for effect in &mut effects {
            for &field in effect.fields() {
                value += 0.01;
                assert!(effect.set_field(field, value));
                assert_eq!(effect.field(field), Some(value), "{}", field.name());
            }
        }
        assert_eq!(value, 0.05, "five fields in all");
        assert_eq!(EffectField::Delta.unit(), "mm");
        assert_eq!(EffectField::Phase.unit(), "rad");
        let before = effects.clone();
        assert_eq!(effects[1].field(EffectField::Gain), None);
        assert!(!effects[1].set_field(EffectField::Gain, 5.0));
        assert_eq!(effects, before);
    }

    #[test]
    fn ripple_follows_the_motor_angle_of_its_joint() {
        let effect = Effect::TransmissionRipple {
            joint: 4,
            harmonic: 2.0,
            amplitude: 0.003,
            phase: 0.4,
        };
        let q = apply(&[effect], [0.0; 5]);
        assert_eq!(q[..4], Q[..4]);
        assert!((q[4] - (Q[4] + 0.003 * (2.0 * 7.0 + 0.4f64).sin())).abs() < 1e-15);
    }

    #[test]
    fn backlash_lags_behind_the_motion() {
        let effect = Effect::Backlash {
            joint: 1,
            width: 0.01,
        };
        let forward = apply(std::slice::from_ref(&effect), [0.0, 1.0, 0.0, 0.0, 0.0]);
        let backward = apply(std::slice::from_ref(&effect), [0.0, -1.0, 0.0, 0.0, 0.0]);
        let unknown = apply(&[effect], [0.0; 5]);
        assert!((forward[1] - (Q[1] - 0.005)).abs() < 1e-15);
        assert!((backward[1] - (Q[1] + 0.005)).abs() < 1e-15);
        assert_eq!(unknown, Q);
    }

    /// After a reversal the joint holds still until the motor has crossed the gap: a
    /// tracker fed a stroke up and back reproduces the play operator through the counts.
    #[test]
    fn backlash_holds_the_joint_through_the_gap_after_a_reversal() {
        let width = 0.01;
        let effect = Effect::Backlash { joint: 1, width };
        let joint_per_count = SCALE.gear_ratio[1] * SCALE.motor_rad_per_count[1];
        let mut tracker = DirectionTracker::new(2.0);
        let joint_at = |tracker: &mut DirectionTracker, counts: f64| {
            let all = [0.0, counts, 0.0, 0.0, 0.0];
            let motion = tracker.update(&all);
            let motor: crate::Joints =
                std::array::from_fn(|i| all[i] * SCALE.motor_rad_per_count[i]);
            let paper: crate::Joints = std::array::from_fn(|i| SCALE.gear_ratio[i] * motor[i]);
            let q = apply_joint_effects(
                std::slice::from_ref(&effect),
                &paper,
                &motor,
                &SCALE,
                &motion,
            );
            (paper[1], q[1])
        };
        // Up by 1000 counts (0.314 rad at the joint), in steps of one count.
        let mut last = (0.0, 0.0);
        for c in 0..=1000 {
            last = joint_at(&mut tracker, f64::from(c));
        }
        assert!(
            (last.1 - (last.0 - 0.5 * width)).abs() < 1e-12,
            "lags by half the gap"
        );
        let top = last.1;
        // Back down: the gap is 0.01 / joint_per_count ≈ 31.8 counts wide. A causal tracker
        // sees the reversal once the count has moved back by its dead band (2 counts).
        let gap_counts = width / joint_per_count;
        let late = 2.0 * joint_per_count;
        for c in (900..1000).rev() {
            let (x, y) = joint_at(&mut tracker, f64::from(c));
            let travel = 1000.0 - f64::from(c);
            if travel < gap_counts - 1.0 {
                assert!(
                    (y - top).abs() <= late + 1e-12,
                    "in the gap after {travel} counts"
                );
            } else if travel > gap_counts + 1.0 {
                assert!((y - (x + 0.5 * width)).abs() < 1e-12, "engaged again");
            }
        }
    }

    #[test]
    fn compliance_scales_the_gravity_feature() {
        let effect = Effect::JointCompliance {
            joint: 2,
            gain: 0.02,
        };
        let q = apply(&[effect], [0.0; 5]);
        assert!((q[2] - (Q[2] + 0.02 * gravity_feature(2, &Q))).abs() < 1e-15);
        assert_ne!(q[2], Q[2]);
    }

    #[test]
    fn link_lengths_leave_the_joints_alone() {
        let effect = Effect::LinkLength {
            link: Link::LF,
            delta: 0.3,
        };
        assert_eq!(apply(&[effect], [1.0; 5]), Q);
    }

    #[test]
    fn gravity_features_are_bounded_torques() {
        // A proximal front link pointing straight down (−y) carries no gravity torque,
        // a horizontal one the most.
        let mut q = Q;
        q[0] = -std::f64::consts::FRAC_PI_2;
        assert!(gravity_feature(0, &q).abs() < 1e-15);
        q[0] = 0.0;
        assert_eq!(gravity_feature(0, &q), 1.0);
        // The back stage rolled by θ3 = 0 hangs in the vertical plane: no torque about x.
        q[2] = 0.0;
        assert_eq!(gravity_feature(2, &q), 0.0);
        // Rolled by 90°, its plane is horizontal: no in-plane gravity on θ4, θ5.
        q[2] = std::f64::consts::FRAC_PI_2;
        assert!(gravity_feature(3, &q).abs() < 1e-15);
        assert!(gravity_feature(2, &q).abs() > 0.1);
        for joint in 0..5 {
            for k in 0..100 {
                let angles: crate::Joints = std::array::from_fn(|i| 0.37 * (k * (i + 1)) as f64);
                assert!(gravity_feature(joint, &angles).abs() <= 1.0);
            }
        }
        assert_eq!(gravity_feature(5, &Q), 0.0);
    }
}
