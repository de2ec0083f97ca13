//! The effects of the library at a place of the robot, linearised about zero: what a
//! residual search proposes. For the joint-side effects, [`EffectSlot::joint_signals`] are
//! `∂q_j/∂p_k` (the change of the joint angle per unit of each parameter) as
//! [`apply_joint_effects`](crate::effects::apply_joint_effects) defines the effect, and
//! [`EffectSlot::effect`] turns linearised coefficients back into the effect.

use crate::effects::{gravity_feature, Effect, JointMotion, Link};
use crate::{Joints, JOINT_COUNT};

/// Harmonics of the motor angle a ripple is tried at.
pub const RIPPLE_HARMONICS: [u8; 3] = [1, 2, 3];

/// An effect of the library at a joint or link, without values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EffectSlot {
    /// Transmission ripple of a joint (0-based) at a harmonic of its motor angle.
    TransmissionRipple {
        /// Joint index 0..5.
        joint: usize,
        /// Cycles per motor revolution.
        harmonic: u8,
    },
    /// Backlash of a joint.
    Backlash {
        /// Joint index 0..5.
        joint: usize,
    },
    /// Joint compliance under gravity.
    JointCompliance {
        /// Joint index 0..5.
        joint: usize,
    },
    /// Link-length error.
    LinkLength {
        /// The link.
        link: Link,
    },
    /// Tilt of a joint's axis about one of its two perpendicular axes (0 or 1).
    AxisTilt {
        /// Joint index 0..5.
        joint: usize,
        /// Which perpendicular axis, 0 or 1.
        axis: usize,
    },
}

impl EffectSlot {
    /// Every slot of the library: per joint the ripple harmonics, backlash and compliance,
    /// then every link, then both tilts of every joint axis.
    pub fn all() -> Vec<EffectSlot> {
        let mut all = Vec::new();
        for joint in 0..JOINT_COUNT {
            all.extend(
                RIPPLE_HARMONICS.map(|harmonic| EffectSlot::TransmissionRipple { joint, harmonic }),
            );
            all.push(EffectSlot::Backlash { joint });
            all.push(EffectSlot::JointCompliance { joint });
        }
        all.extend(Link::ALL.map(|link| EffectSlot::LinkLength { link }));
        for joint in 0..JOINT_COUNT {
            all.extend([0, 1].map(|axis| EffectSlot::AxisTilt { joint, axis }));
        }
        all
    }

    /// The slot an effect occupies.
    pub fn of(effect: &Effect) -> EffectSlot {
        match *effect {
            Effect::TransmissionRipple {
                joint, harmonic, ..
            } => EffectSlot::TransmissionRipple {
                joint,
                harmonic: harmonic.round().clamp(0.0, 255.0) as u8,
            },
            Effect::Backlash { joint, .. } => EffectSlot::Backlash { joint },
            Effect::LinkLength { link, .. } => EffectSlot::LinkLength { link },
            Effect::JointCompliance { joint, .. } => EffectSlot::JointCompliance { joint },
            Effect::AxisTilt { joint, axis, .. } => EffectSlot::AxisTilt { joint, axis },
        }
    }

    /// Class name, as [`Effect::class`].
    pub fn class(self) -> &'static str {
        match self {
            EffectSlot::TransmissionRipple { .. } => "transmission_ripple",
            EffectSlot::Backlash { .. } => "backlash",
            EffectSlot::JointCompliance { .. } => "joint_compliance",
            EffectSlot::LinkLength { .. } => "link_length",
            EffectSlot::AxisTilt { .. } => "axis_tilt",
        }
    }

    /// Number of linearised parameters.
    pub fn dim(self) -> usize {
        match self {
            EffectSlot::TransmissionRipple { .. } => 2,
            _ => 1,
        }
    }

    /// The joint (0-based) it acts on; `None` for a link.
    pub fn joint(self) -> Option<usize> {
        match self {
            EffectSlot::TransmissionRipple { joint, .. }
            | EffectSlot::Backlash { joint }
            | EffectSlot::JointCompliance { joint }
            | EffectSlot::AxisTilt { joint, .. } => Some(joint),
            EffectSlot::LinkLength { .. } => None,
        }
    }

    /// `∂q_joint/∂p_k` of a joint-side slot at motor angles `motor` (rad), paper joints
    /// `joints` (rad) and motion state `motion`: ripple `[sin hθ_enc, cos hθ_enc]` (in-phase
    /// and quadrature amplitudes), backlash `[−direction/2]` (per unit width), compliance
    /// `[gravity feature]` (per unit gain). Zeros for a link or an axis tilt (they act
    /// through the geometry).
    pub fn joint_signals(self, motor: &Joints, joints: &Joints, motion: &JointMotion) -> [f64; 2] {
        match self {
            EffectSlot::TransmissionRipple { joint, harmonic } => {
                let (sin, cos) = (f64::from(harmonic) * motor[joint]).sin_cos();
                [sin, cos]
            }
            EffectSlot::Backlash { joint } => [-0.5 * motion.direction[joint], 0.0],
            EffectSlot::JointCompliance { joint } => [gravity_feature(joint, joints), 0.0],
            EffectSlot::LinkLength { .. } | EffectSlot::AxisTilt { .. } => [0.0, 0.0],
        }
    }

    /// The effect with linearised coefficients `coefficients` (one per parameter, the units
    /// of [`EffectSlot::joint_signals`], mm for a link); `None` when they contradict the
    /// effect (a backlash must have a positive width).
    pub fn effect(self, coefficients: &[f64]) -> Option<Effect> {
        match self {
            EffectSlot::TransmissionRipple { joint, harmonic } => {
                let (in_phase, quadrature) = (coefficients[0], coefficients[1]);
                Some(Effect::TransmissionRipple {
                    joint,
                    harmonic: f64::from(harmonic),
                    amplitude: in_phase.hypot(quadrature),
                    phase: quadrature.atan2(in_phase),
                })
            }
            EffectSlot::Backlash { joint } => (coefficients[0] > 0.0).then_some(Effect::Backlash {
                joint,
                width: coefficients[0],
            }),
            EffectSlot::JointCompliance { joint } => Some(Effect::JointCompliance {
                joint,
                gain: coefficients[0],
            }),
            EffectSlot::LinkLength { link } => Some(Effect::LinkLength {
                link,
                delta: coefficients[0],
            }),
            EffectSlot::AxisTilt { joint, axis } => Some(Effect::AxisTilt {
                joint,
                axis,
                angle: coefficients[0],
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::apply_joint_effects;

    const Q: Joints = [-2.3, -0.8, 0.1, -2.7, -0.6];
    const MOTOR: Joints = [1.0, -2.0, 3.0, 0.5, 7.0];

    /// The joint signals are the derivatives of the effect as `apply_joint_effects` applies
    /// it, and the effect rebuilt from coefficients reproduces the linear model.
    #[test]
    fn joint_signals_linearise_the_applied_effects() {
        let motion = JointMotion {
            direction: [1.0, -1.0, 1.0, -1.0, 1.0],
            ..JointMotion::default()
        };
        let scale = crate::effects::EncoderScale {
            gear_ratio: [0.1; 5],
            motor_rad_per_count: [1e-3; 5],
        };
        for slot in EffectSlot::all() {
            if matches!(slot, EffectSlot::AxisTilt { .. }) {
                continue;
            }
            let Some(joint) = slot.joint() else { continue };
            let coefficients = [1e-4, -2e-4];
            let effect = slot
                .effect(&coefficients[..slot.dim()])
                .expect("a valid effect");
            let q = apply_joint_effects(std::slice::from_ref(&effect), &Q, &MOTOR, &scale, &motion);
            let s = slot.joint_signals(&MOTOR, &Q, &motion);
            let linear: f64 = (0..slot.dim()).map(|k| s[k] * coefficients[k]).sum();
            assert!(
                (q[joint] - Q[joint] - linear).abs() < 1e-12,
                "{slot:?}: {} vs {linear}",
                q[joint] - Q[joint]
            );
            assert_eq!(EffectSlot::of(&effect), slot);
            assert_eq!(slot.class(), effect.class());
        }
        assert_eq!(EffectSlot::all().len(), 5 * 5 + 5 + 10);
        assert!(EffectSlot::Backlash { joint: 0 }.effect(&[-0.01]).is_none());
    }
}
