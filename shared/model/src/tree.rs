//! Kinematic trees of serial and branched arms (a robot described by URDF): links joined by
//! fixed, revolute (limited or continuous) and prismatic joints, mimic joints, forward
//! kinematics of every link, per-joint geometric error parameters with their Jacobian, and
//! static gravity torques.
//!
//! Frames and units: every pose is in the tree's root-link frame; lengths in millimetres,
//! angles in radians, masses in kilograms, gravity in m/s², torques in N·m (forces in N for
//! prismatic joints).
//!
//! - [`KinematicTree::new`] builds a tree from link and joint specifications (what
//!   [`crate::urdf`] reads from a URDF), checking that it is one connected tree.
//! - The tree's *variables* ([`JointVariable`]) are its independent joint coordinates: every
//!   revolute and prismatic joint that does not mimic another. [`KinematicTree::joint_vector`]
//!   turns values given by joint name into the variable vector the kinematics take.
//! - [`KinematicTree::forward`] computes a [`TreeState`]: every link's pose for a joint vector
//!   and a vector of geometric errors ([`geometric`]); [`KinematicTree::pose_jacobian`] and
//!   [`KinematicTree::point_jacobian`] differentiate a target on a link with respect to the
//!   errors and the joint variables; [`KinematicTree::gravity_torques`] gives the static
//!   gravity load of each variable.

use std::collections::HashMap;

use nalgebra::{Isometry3, Unit, Vector3};

mod build;
mod forward;
pub mod geometric;
mod gravity;

pub use forward::{TargetJacobian, TreeState};
pub use geometric::{ErrorComponent, ErrorParameter, ParameterUnit};
pub use gravity::{Payload, STANDARD_GRAVITY};

/// How a joint moves its child link relative to its parent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointType {
    /// No motion.
    Fixed,
    /// Rotation about the joint axis (rad); with limits (URDF `revolute`) or without
    /// (URDF `continuous`).
    Revolute,
    /// Translation along the joint axis (mm).
    Prismatic,
}

impl JointType {
    /// `fixed`, `revolute` or `prismatic`.
    pub fn name(self) -> &'static str {
        match self {
            JointType::Fixed => "fixed",
            JointType::Revolute => "revolute",
            JointType::Prismatic => "prismatic",
        }
    }

    /// The unit of the joint's coordinate: `rad` or `mm` (`""` for a fixed joint).
    pub fn unit(self) -> &'static str {
        match self {
            JointType::Fixed => "",
            JointType::Revolute => "rad",
            JointType::Prismatic => "mm",
        }
    }
}

/// The range a joint's coordinate may take (rad for revolute, mm for prismatic joints).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lowest value.
    pub lower: f64,
    /// Highest value.
    pub upper: f64,
}

/// A link's mass and centre of mass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    /// Mass (kg).
    pub mass_kg: f64,
    /// Centre of mass in the link's frame (mm).
    pub centre_of_mass_mm: Vector3<f64>,
}

/// A link as given to [`KinematicTree::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct LinkSpec {
    /// Unique name.
    pub name: String,
    /// Mass and centre of mass, if the description has them.
    pub inertial: Option<Inertial>,
}

/// The joint a mimic joint follows: `value = multiplier · value(joint) + offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct MimicSpec {
    /// Name of the joint followed.
    pub joint: String,
    /// Multiplier (dimensionless, or mm/rad between joints of different types).
    pub multiplier: f64,
    /// Offset (rad or mm, in the mimic joint's unit).
    pub offset: f64,
}

/// A joint as given to [`KinematicTree::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct JointSpec {
    /// Unique name.
    pub name: String,
    /// Name of the parent link.
    pub parent: String,
    /// Name of the child link.
    pub child: String,
    /// Pose of the joint frame in the parent link's frame (mm); the child link's frame is the
    /// joint frame moved by the joint.
    pub origin: Isometry3<f64>,
    /// How the joint moves.
    pub kind: JointType,
    /// Axis of motion in the joint frame (any non-zero length; ignored for fixed joints).
    pub axis: Vector3<f64>,
    /// Limits of the joint coordinate (`None`: unlimited, e.g. a continuous joint).
    pub limits: Option<JointLimits>,
    /// The joint this one follows, if it is a mimic joint.
    pub mimic: Option<MimicSpec>,
}

/// Which variable drives a moving joint: `value = multiplier · q[variable] + offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Index into the joint vector.
    pub variable: usize,
    /// 1 for an independent joint, the (composed) mimic multiplier otherwise.
    pub multiplier: f64,
    /// 0 for an independent joint, the (composed) mimic offset otherwise.
    pub offset: f64,
}

/// A link of a built tree.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeLink {
    /// Name.
    pub name: String,
    /// The joint whose child this link is (`None` for the root).
    pub parent_joint: Option<usize>,
    /// Mass and centre of mass.
    pub inertial: Option<Inertial>,
}

/// A joint of a built tree.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeJoint {
    /// Name.
    pub name: String,
    /// Index of the parent link.
    pub parent_link: usize,
    /// Index of the child link.
    pub child_link: usize,
    /// Pose of the joint frame in the parent link's frame (mm).
    pub origin: Isometry3<f64>,
    /// How the joint moves.
    pub kind: JointType,
    /// Unit axis of motion in the joint frame.
    pub axis: Unit<Vector3<f64>>,
    /// Limits of the joint's own coordinate (`None`: unlimited).
    pub limits: Option<JointLimits>,
    /// The variable that moves it (`None` for a fixed joint).
    pub drive: Option<Drive>,
    /// Index of its first geometric error parameter (six in a row; `None` for a fixed joint).
    pub first_error: Option<usize>,
}

/// An independent joint coordinate: an entry of the joint vector.
#[derive(Debug, Clone, PartialEq)]
pub struct JointVariable {
    /// The joint's name.
    pub name: String,
    /// Index of the joint.
    pub joint: usize,
    /// Revolute (rad) or prismatic (mm).
    pub kind: JointType,
    /// Its limits (`None`: unlimited).
    pub limits: Option<JointLimits>,
}

/// A link of a tree, by index (from [`KinematicTree::link_id`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LinkId(pub(crate) usize);

impl LinkId {
    /// The link's index in [`KinematicTree::links`].
    pub fn index(self) -> usize {
        self.0
    }
}

/// Why a tree could not be built or a query on it was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TreeError {
    /// The robot description is not valid XML or not URDF.
    #[error("not a valid URDF: {0}")]
    Urdf(String),
    /// A joint type the kinematics do not model.
    #[error("joint `{joint}`: type {kind} is not supported (fixed, revolute, continuous and prismatic are)")]
    UnsupportedJoint {
        /// The joint.
        joint: String,
        /// Its URDF type.
        kind: String,
    },
    /// Two links share a name.
    #[error("two links are named `{0}`")]
    DuplicateLink(String),
    /// Two joints share a name.
    #[error("two joints are named `{0}`")]
    DuplicateJoint(String),
    /// A joint names a link that does not exist.
    #[error("joint `{joint}`: unknown {role} link `{link}`")]
    UnknownLink {
        /// The joint.
        joint: String,
        /// `parent` or `child`.
        role: &'static str,
        /// The link named.
        link: String,
    },
    /// A link is the child of two joints.
    #[error("link `{link}` is the child of two joints, `{first}` and `{second}`")]
    TwoParents {
        /// The link.
        link: String,
        /// One joint.
        first: String,
        /// The other.
        second: String,
    },
    /// No link or more than one link has no parent joint.
    #[error("a tree needs exactly one root link (one without a parent joint), found {0:?}")]
    Roots(Vec<String>),
    /// A link cannot be reached from the root (the joints form a loop).
    #[error("link `{0}` is not connected to the root (the joints form a loop)")]
    Disconnected(String),
    /// A moving joint has a zero or non-finite axis.
    #[error("joint `{0}`: the axis must be a finite, non-zero vector")]
    BadAxis(String),
    /// A joint's origin or limits are not finite or the limits are empty.
    #[error("joint `{joint}`: {reason}")]
    BadJoint {
        /// The joint.
        joint: String,
        /// What is wrong.
        reason: String,
    },
    /// A mimic joint follows a joint that does not exist, is fixed, or follows it back.
    #[error("joint `{joint}`: cannot mimic `{mimicked}`: {reason}")]
    BadMimic {
        /// The mimic joint.
        joint: String,
        /// The joint it names.
        mimicked: String,
        /// Why not.
        reason: &'static str,
    },
    /// A link has a negative or non-finite mass or centre of mass.
    #[error("link `{0}`: the mass must be finite and not negative, the centre of mass finite")]
    BadInertial(String),
    /// A link name that the tree does not have.
    #[error("unknown link `{name}` (links: {known})")]
    UnknownLinkName {
        /// The name asked for.
        name: String,
        /// The tree's links, comma-separated.
        known: String,
    },
    /// A joint name that the tree does not have.
    #[error("unknown joint `{name}` (joint variables: {known})")]
    UnknownJoint {
        /// The name given.
        name: String,
        /// The tree's variables, comma-separated.
        known: String,
    },
    /// A value was given for a joint that is not a variable.
    #[error("joint `{name}` is {reason}: it takes no value")]
    NotAVariable {
        /// The joint.
        name: String,
        /// `fixed`, or `a mimic of <joint>`.
        reason: String,
    },
    /// A joint was given two values.
    #[error("joint `{0}` was given twice")]
    DuplicateValue(String),
    /// A variable was given no value.
    #[error("no value for joint `{0}`")]
    MissingValue(String),
    /// A vector has the wrong length.
    #[error("{what}: expected {expected} values, found {found}")]
    WrongLength {
        /// Which vector.
        what: &'static str,
        /// Its length for this tree.
        expected: usize,
        /// The length given.
        found: usize,
    },
    /// A value is NaN or infinite.
    #[error("{what} `{name}`: {value} is not a finite number")]
    NotFinite {
        /// `joint` or `error parameter`.
        what: &'static str,
        /// Which one.
        name: String,
        /// The value.
        value: f64,
    },
    /// A joint is outside its limits.
    #[error("joint `{joint}`: {value} {unit} is outside its limits [{lower}, {upper}]")]
    OutOfLimits {
        /// The joint.
        joint: String,
        /// Its value (rad or mm).
        value: f64,
        /// `rad` or `mm`.
        unit: &'static str,
        /// Lower limit.
        lower: f64,
        /// Upper limit.
        upper: f64,
    },
}

/// A serial or branched robot: links, joints in topological order (every joint after the
/// joint of its parent link), the joint variables and the geometric error parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct KinematicTree {
    name: String,
    links: Vec<TreeLink>,
    joints: Vec<TreeJoint>,
    variables: Vec<JointVariable>,
    errors: Vec<ErrorParameter>,
    /// Per link: the moving joints from the root to the link, root first.
    chains: Vec<Vec<usize>>,
    root: usize,
    link_names: HashMap<String, usize>,
}

impl KinematicTree {
    /// The robot's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Every link; a [`LinkId`] indexes this slice.
    pub fn links(&self) -> &[TreeLink] {
        &self.links
    }

    /// Every joint, in topological order.
    pub fn joints(&self) -> &[TreeJoint] {
        &self.joints
    }

    /// The joint variables, in joint-vector order (the order of the joints in the tree).
    pub fn variables(&self) -> &[JointVariable] {
        &self.variables
    }

    /// The geometric error parameters, in error-vector order ([`geometric`]).
    pub fn error_parameters(&self) -> &[ErrorParameter] {
        &self.errors
    }

    /// The root link.
    pub fn root(&self) -> LinkId {
        LinkId(self.root)
    }

    /// The link named `name`.
    pub fn link_id(&self, name: &str) -> Result<LinkId, TreeError> {
        self.link_names
            .get(name)
            .map(|&index| LinkId(index))
            .ok_or_else(|| TreeError::UnknownLinkName {
                name: name.to_owned(),
                known: join_names(self.links.iter().map(|link| link.name.as_str())),
            })
    }

    /// The index in the joint vector of the variable named `name`; an error names the joint
    /// and says whether it is unknown, fixed or a mimic joint.
    pub fn variable_index(&self, name: &str) -> Result<usize, TreeError> {
        if let Some(index) = self.variables.iter().position(|v| v.name == name) {
            return Ok(index);
        }
        match self.joints.iter().find(|joint| joint.name == name) {
            Some(joint) => Err(TreeError::NotAVariable {
                name: name.to_owned(),
                reason: match joint.drive {
                    None => "fixed".to_owned(),
                    Some(drive) => {
                        format!("a mimic of `{}`", self.variables[drive.variable].name)
                    }
                },
            }),
            None => Err(TreeError::UnknownJoint {
                name: name.to_owned(),
                known: join_names(self.variables.iter().map(|v| v.name.as_str())),
            }),
        }
    }

    /// The joint vector for values given by joint name (rad or mm): every variable exactly
    /// once, no fixed or mimic joint, every value finite.
    pub fn joint_vector<'a>(
        &self,
        values: impl IntoIterator<Item = (&'a str, f64)>,
    ) -> Result<Vec<f64>, TreeError> {
        let mut vector = vec![None; self.variables.len()];
        for (name, value) in values {
            let index = self.variable_index(name)?;
            if vector[index].replace(value).is_some() {
                return Err(TreeError::DuplicateValue(name.to_owned()));
            }
        }
        let vector = vector
            .into_iter()
            .zip(&self.variables)
            .map(|(value, variable)| {
                value.ok_or_else(|| TreeError::MissingValue(variable.name.clone()))
            })
            .collect::<Result<Vec<_>, _>>()?;
        self.check_joints(&vector)?;
        Ok(vector)
    }

    /// Checks that `joints` is a finite joint vector of this tree.
    pub fn check_joints(&self, joints: &[f64]) -> Result<(), TreeError> {
        check_vector("joint vector", joints, self.variables.len())?;
        match joints
            .iter()
            .zip(&self.variables)
            .find(|(v, _)| !v.is_finite())
        {
            Some((&value, variable)) => Err(TreeError::NotFinite {
                what: "joint",
                name: variable.name.clone(),
                value,
            }),
            None => Ok(()),
        }
    }

    /// Checks every moving joint (mimic joints included, through their drive) against its
    /// limits; the error names the first joint outside them.
    pub fn check_limits(&self, joints: &[f64]) -> Result<(), TreeError> {
        self.check_joints(joints)?;
        for joint in &self.joints {
            let (Some(drive), Some(limits)) = (joint.drive, joint.limits) else {
                continue;
            };
            let value = drive.multiplier * joints[drive.variable] + drive.offset;
            if !(limits.lower..=limits.upper).contains(&value) {
                return Err(TreeError::OutOfLimits {
                    joint: joint.name.clone(),
                    value,
                    unit: joint.kind.unit(),
                    lower: limits.lower,
                    upper: limits.upper,
                });
            }
        }
        Ok(())
    }

    /// The error vector of the nominal geometry (all zeros).
    pub fn nominal_errors(&self) -> Vec<f64> {
        vec![0.0; self.errors.len()]
    }
}

/// `names` joined by `, `.
fn join_names<'a>(names: impl Iterator<Item = &'a str>) -> String {
    names.collect::<Vec<_>>().join(", ")
}

/// Checks the length of `values`.
fn check_vector(what: &'static str, values: &[f64], expected: usize) -> Result<(), TreeError> {
    if values.len() == expected {
        Ok(())
    } else {
        Err(TreeError::WrongLength {
            what,
            expected,
            found: values.len(),
        })
    }
}
