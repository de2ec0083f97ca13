//! Static gravity torques from the links' masses: the generalised force gravity exerts on
//! each joint variable, `τ_v = Σ_links m g · ∂p_com/∂q_v`, for joint compliance under
//! gravity (a joint deflects by `c_v · τ_v`).

use nalgebra::{Point3, Vector3};

use super::{JointType, KinematicTree, LinkId, TreeState};

/// Standard gravity pointing along −z of the root frame (m/s²): the usual mounting of an
/// arm on a floor.
pub const STANDARD_GRAVITY: Vector3<f64> = Vector3::new(0.0, 0.0, -9.80665);

/// A mass carried by a link beyond the link's own (a tool, a probe).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Payload {
    /// The link carrying it.
    pub link: LinkId,
    /// Mass (kg).
    pub mass_kg: f64,
    /// Its centre of mass in the link's frame (mm).
    pub centre_of_mass_mm: Point3<f64>,
}

impl KinematicTree {
    /// The gravity torque on each joint variable (N·m for revolute, N for prismatic ones),
    /// at `state`, for gravity `gravity` (m/s², root frame) acting on every link's inertial
    /// and on `payloads`. Positive means gravity pulls the variable towards larger values;
    /// a mimic joint's torque is added to its driver's, times the mimic multiplier.
    pub fn gravity_torques(
        &self,
        state: &TreeState,
        gravity: &Vector3<f64>,
        payloads: &[Payload],
    ) -> Vec<f64> {
        let mut torques = vec![0.0; self.variables.len()];
        let link_masses = self.links.iter().enumerate().filter_map(|(index, link)| {
            let inertial = link.inertial?;
            Some((
                index,
                inertial.mass_kg,
                Point3::from(inertial.centre_of_mass_mm),
            ))
        });
        let payload_masses = payloads
            .iter()
            .map(|p| (p.link.0, p.mass_kg, p.centre_of_mass_mm));
        for (link, mass, centre) in link_masses.chain(payload_masses) {
            if mass == 0.0 {
                continue;
            }
            let centre = state.link_poses[link] * centre;
            let weight = gravity * mass;
            for &index in &self.chains[link] {
                let joint = &self.joints[index];
                let Some(drive) = joint.drive else { continue };
                let screws = &state.screws[index];
                // ∂p/∂q in mm per rad (revolute) or mm per mm (prismatic).
                let velocity = match joint.kind {
                    JointType::Revolute => {
                        screws.motion_axis.cross(&(centre.coords - screws.point)) * 1e-3
                    }
                    _ => screws.motion_axis,
                };
                torques[drive.variable] += drive.multiplier * weight.dot(&velocity);
            }
        }
        torques
    }
}
