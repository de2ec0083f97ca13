//! Effects beyond the paper's model: small typed extensions with their own parameters,
//! used by the simulator to build a true robot and by the calibrator to extend the model.

use serde::{Deserialize, Serialize};

/// A link of the 5-bars (or the needle offset) whose length an effect may change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
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

/// Motion state that history-dependent effects need: per joint, the sign (−1, 0, +1) of the
/// last significant motor velocity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointMotion {
    /// Sign of the last motion of each joint (0 = unknown / never moved).
    pub direction: [f64; 5],
}

/// One effect with its parameters. Joints are indexed 0..5 (θ1 = 0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
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
    /// Backlash: the joint lags by `width/2` behind the motor in the direction of motion.
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
pub fn gravity_feature(joint: usize, q: &crate::Joints) -> f64 {
    let _ = (joint, q);
    todo!()
}
