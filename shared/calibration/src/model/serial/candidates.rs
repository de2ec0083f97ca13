//! The effects a serial arm can carry beyond its geometry, each linear in its parameters:
//!
//! - **periodic** joint errors (gear and encoder eccentricity, strain-wave ripple): the
//!   joint reads `q` but stands at `q + a·sin(h·q̃) + b·cos(h·q̃)`, harmonic `h` of one
//!   revolute joint, where `q̃` is `q` clamped to the range the calibration poses covered (a
//!   sum of harmonics fitted on part of a turn is not known on the rest; held constant
//!   there, it cannot blow up);
//! - **gravity compliance**: the joint yields by `c·τ_links + k·τ_1kg`, with the links'
//!   static gravity torque and the torque of 1 kg at the target (a probe of unknown mass);
//! - **thermal expansion**: every position in the robot's root frame grows by `α·(T − T₀)`;
//! - **drift** of a set-up: the instrument's frame slides by `d·s` with the order `s ∈ [0,1]`
//!   of the pose in its sequence.

use sabr_model::tree::JointType;

use crate::model::serial::observation::PoseObservation;
use crate::model::CandidateInfo;

/// Highest harmonic of a joint angle the periodic family offers.
pub const MAX_HARMONIC: u16 = 30;

/// An effect a serial arm may carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SerialEffect {
    /// Harmonic `harmonic` of joint variable `variable` (coefficients: sin, cos; rad).
    Periodic {
        /// Joint variable index.
        variable: u16,
        /// Harmonic number (1 = once per turn).
        harmonic: u16,
    },
    /// Compliance of joint variable `variable` under gravity.
    Compliance {
        /// Joint variable index.
        variable: u16,
    },
    /// Isotropic thermal expansion of the arm about its root.
    Thermal,
    /// Drift of set-up `setup`'s instrument frame with the order of the poses.
    Drift {
        /// Set-up index.
        setup: u16,
    },
}

impl SerialEffect {
    /// Number of parameters.
    pub fn dim(self) -> usize {
        match self {
            SerialEffect::Periodic { .. } | SerialEffect::Compliance { .. } => 2,
            SerialEffect::Thermal => 1,
            SerialEffect::Drift { .. } => 3,
        }
    }

    /// The class name, as in reports and the parameter file.
    pub fn class(self) -> &'static str {
        match self {
            SerialEffect::Periodic { .. } => "periodic",
            SerialEffect::Compliance { .. } => "gravity_compliance",
            SerialEffect::Thermal => "thermal_expansion",
            SerialEffect::Drift { .. } => "drift",
        }
    }

    /// The names of its parameters.
    pub fn fields(self) -> &'static [&'static str] {
        match self {
            SerialEffect::Periodic { .. } => &["sin", "cos"],
            SerialEffect::Compliance { .. } => &["per_link_torque", "per_payload_kg"],
            SerialEffect::Thermal => &["alpha"],
            SerialEffect::Drift { .. } => &["dx", "dy", "dz"],
        }
    }

    /// The units of its parameters, for a joint of type `kind` where it has one.
    pub fn unit(self, kind: JointType, field: usize) -> &'static str {
        match (self, kind, field) {
            (SerialEffect::Periodic { .. }, _, _) => "rad",
            (SerialEffect::Compliance { .. }, JointType::Prismatic, 0) => "mm/N",
            (SerialEffect::Compliance { .. }, JointType::Prismatic, _) => "mm/kg",
            (SerialEffect::Compliance { .. }, _, 0) => "rad/(N·m)",
            (SerialEffect::Compliance { .. }, _, _) => "rad/kg",
            (SerialEffect::Thermal, _, _) => "1/°C",
            (SerialEffect::Drift { .. }, _, _) => "mm",
        }
    }

    /// The joint-coordinate offset features of a joint effect at `obs` (what multiplies
    /// each coefficient), with the variable they move; `None` for a non-joint effect.
    /// `covered` is the calibrated range of each variable (rad or mm).
    pub fn joint_features(
        self,
        obs: &PoseObservation,
        covered: &[[f64; 2]],
    ) -> Option<(usize, [f64; 2])> {
        match self {
            SerialEffect::Periodic { variable, harmonic } => {
                let v = usize::from(variable);
                let [lo, hi] = covered[v];
                let angle = f64::from(harmonic) * obs.joints[v].clamp(lo, hi.max(lo));
                Some((usize::from(variable), [angle.sin(), angle.cos()]))
            }
            SerialEffect::Compliance { variable } => {
                Some((usize::from(variable), obs.gravity[usize::from(variable)]))
            }
            SerialEffect::Thermal | SerialEffect::Drift { .. } => None,
        }
    }

    /// What it is, for the loop and reports; `joint_name` names a variable, `setup_name` a
    /// set-up.
    pub fn info(
        self,
        joint_name: impl Fn(usize) -> String,
        setup_name: impl Fn(usize) -> String,
    ) -> CandidateInfo {
        let (label, signal, joint, link, harmonic) = match self {
            SerialEffect::Periodic { variable, harmonic } => (
                format!("periodic {} ×{harmonic}", joint_name(variable.into())),
                "sine and cosine of a multiple of the joint angle",
                Some(usize::from(variable)),
                None,
                Some(f64::from(harmonic)),
            ),
            SerialEffect::Compliance { variable } => (
                format!("gravity compliance {}", joint_name(variable.into())),
                "static gravity torque of the joint",
                Some(usize::from(variable)),
                None,
                None,
            ),
            SerialEffect::Thermal => (
                "thermal expansion".to_string(),
                "temperature times the position in the robot base",
                None,
                None,
                None,
            ),
            SerialEffect::Drift { setup } => (
                format!("drift {}", setup_name(setup.into())),
                "order of the pose in its sequence",
                None,
                Some(setup_name(setup.into())),
                None,
            ),
        };
        CandidateInfo {
            class: self.class(),
            label,
            signal,
            dim: self.dim(),
            in_library: true,
            joint,
            link,
            harmonic,
        }
    }
}
