//! Geometric error parameters: a small error transform at the origin of every moving joint.
//!
//! The joint frame of a moving joint becomes `origin · E(e)` with
//! `E(e) = Trans(tx, ty, tz) · Rx(rx) · Ry(ry) · Rz(rz)`, six parameters per joint, in the
//! joint frame (translations in mm, rotations in rad). Errors of fixed joints are not
//! separate parameters: each is absorbed by the next moving joint's error (or by the
//! target's mounting after the last moving joint, or by the set-up frame before the first).
//!
//! Why per-joint error transforms (and not DH or Hayati): they apply to any URDF joint
//! without first converting the description to DH, they have no singular case (DH
//! parameters are ill-conditioned for parallel axes, which is why Hayati's β is added), and
//! their Jacobian is exact and cheap (each component is an elementary screw). The set is
//! complete — any small change of a joint's placement is one — but redundant: the rotation
//! about a revolute joint's axis is its zero offset; the translation along it is, for
//! parallel neighbours, the same as the neighbour's; and errors of the first and last joints
//! overlap the set-up frame and the target mounting. Identifiability analysis (in the
//! calibration engine) prunes those directions.

use std::fmt;

/// Which of the six components of a joint's error transform.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorComponent {
    /// Translation along the joint frame's x axis (mm).
    Tx,
    /// Translation along y (mm).
    Ty,
    /// Translation along z (mm).
    Tz,
    /// Rotation about x (rad), applied first.
    Rx,
    /// Rotation about the once-rotated y (rad).
    Ry,
    /// Rotation about the twice-rotated z (rad), applied last.
    Rz,
}

impl ErrorComponent {
    /// The six components in parameter order.
    pub const ALL: [ErrorComponent; 6] = [
        ErrorComponent::Tx,
        ErrorComponent::Ty,
        ErrorComponent::Tz,
        ErrorComponent::Rx,
        ErrorComponent::Ry,
        ErrorComponent::Rz,
    ];

    /// `tx`, `ty`, `tz`, `rx`, `ry` or `rz`.
    pub fn suffix(self) -> &'static str {
        match self {
            ErrorComponent::Tx => "tx",
            ErrorComponent::Ty => "ty",
            ErrorComponent::Tz => "tz",
            ErrorComponent::Rx => "rx",
            ErrorComponent::Ry => "ry",
            ErrorComponent::Rz => "rz",
        }
    }

    /// Millimetres for translations, radians for rotations.
    pub fn unit(self) -> ParameterUnit {
        match self {
            ErrorComponent::Tx | ErrorComponent::Ty | ErrorComponent::Tz => {
                ParameterUnit::Millimetre
            }
            _ => ParameterUnit::Radian,
        }
    }
}

/// The unit of a parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ParameterUnit {
    /// Millimetres.
    Millimetre,
    /// Radians.
    Radian,
}

impl ParameterUnit {
    /// `mm` or `rad`.
    pub fn symbol(self) -> &'static str {
        match self {
            ParameterUnit::Millimetre => "mm",
            ParameterUnit::Radian => "rad",
        }
    }

    /// The typical size of a geometric error in this unit: 1 mm, or 1 mrad (which moves a
    /// point 1 m away by 1 mm). Solvers divide by it to make columns comparable.
    pub fn scale(self) -> f64 {
        match self {
            ParameterUnit::Millimetre => 1.0,
            ParameterUnit::Radian => 1e-3,
        }
    }
}

impl fmt::Display for ParameterUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

/// One geometric error parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorParameter {
    /// `<joint>.<component>`, e.g. `elbow_joint.ty`.
    pub name: String,
    /// Index of the joint in [`super::KinematicTree::joints`].
    pub joint: usize,
    /// Which component.
    pub component: ErrorComponent,
    /// Its unit.
    pub unit: ParameterUnit,
    /// Its typical size in that unit ([`ParameterUnit::scale`]).
    pub scale: f64,
}

/// The six error parameters of the joint `name` at position `joint`.
pub(crate) fn joint_error_parameters(
    name: &str,
    joint: usize,
) -> impl Iterator<Item = ErrorParameter> + '_ {
    ErrorComponent::ALL
        .into_iter()
        .map(move |component| ErrorParameter {
            name: format!("{name}.{}", component.suffix()),
            joint,
            component,
            unit: component.unit(),
            scale: component.unit().scale(),
        })
}
