//! Robot descriptions in URDF (parsed from a string with the `urdf-rs` crate; reading the
//! file is the caller's job): links with their inertials, fixed, revolute, continuous and
//! prismatic joints with limits, mimic joints. URDF's metres become millimetres.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::tree::{
    Inertial, JointLimits, JointSpec, JointType, KinematicTree, LinkSpec, MimicSpec, TreeError,
};

/// Millimetres per URDF metre.
const MM_PER_M: f64 = 1000.0;

impl KinematicTree {
    /// The kinematic tree described by the URDF document `text`. Floating, planar and
    /// spherical joints are refused, as are descriptions that are not one connected tree.
    pub fn from_urdf_str(text: &str) -> Result<Self, TreeError> {
        let robot = urdf_rs::read_from_string(text).map_err(|e| TreeError::Urdf(e.to_string()))?;
        let links = robot.links.iter().map(link_spec).collect();
        let joints = robot
            .joints
            .iter()
            .map(joint_spec)
            .collect::<Result<Vec<_>, _>>()?;
        KinematicTree::new(robot.name, links, joints)
    }
}

/// A URDF pose (m, roll-pitch-yaw) as an isometry in mm.
fn isometry(pose: &urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = pose.xyz.0;
    let [roll, pitch, yaw] = pose.rpy.0;
    Isometry3::from_parts(
        Translation3::new(x * MM_PER_M, y * MM_PER_M, z * MM_PER_M),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

fn link_spec(link: &urdf_rs::Link) -> LinkSpec {
    let [x, y, z] = link.inertial.origin.xyz.0;
    let mass_kg = link.inertial.mass.value;
    LinkSpec {
        name: link.name.clone(),
        inertial: (mass_kg != 0.0).then(|| Inertial {
            mass_kg,
            centre_of_mass_mm: Vector3::new(x, y, z) * MM_PER_M,
        }),
    }
}

fn joint_spec(joint: &urdf_rs::Joint) -> Result<JointSpec, TreeError> {
    use urdf_rs::JointType as Urdf;
    let (kind, limited, unit) = match joint.joint_type {
        Urdf::Fixed => (JointType::Fixed, false, 1.0),
        Urdf::Revolute => (JointType::Revolute, true, 1.0),
        Urdf::Continuous => (JointType::Revolute, false, 1.0),
        Urdf::Prismatic => (JointType::Prismatic, true, MM_PER_M),
        Urdf::Floating | Urdf::Planar | Urdf::Spherical => {
            return Err(TreeError::UnsupportedJoint {
                joint: joint.name.clone(),
                kind: format!("{:?}", joint.joint_type).to_lowercase(),
            })
        }
    };
    let limits = limited.then_some(JointLimits {
        lower: joint.limit.lower * unit,
        upper: joint.limit.upper * unit,
    });
    let mimic = joint.mimic.as_ref().map(|mimic| MimicSpec {
        joint: mimic.joint.clone(),
        multiplier: mimic.multiplier.unwrap_or(1.0),
        offset: mimic.offset.unwrap_or(0.0) * unit,
    });
    Ok(JointSpec {
        name: joint.name.clone(),
        parent: joint.parent.link.clone(),
        child: joint.child.link.clone(),
        origin: isometry(&joint.origin),
        kind,
        axis: Vector3::from(joint.axis.xyz.0),
        limits,
        mimic,
    })
}
