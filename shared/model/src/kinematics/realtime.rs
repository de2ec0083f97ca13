//! Forward and inverse kinematics on glam's f64 types, for the paths that run at 1–2 kHz (the
//! IK server, the motion executor's line, the simulated rig). Same model, candidate choice,
//! refusals and tolerances as [`super::forward`] and [`super::inverse`] (they share the
//! scalar steps); what is constant for a geometry is computed once in [`RealtimeGeometry`].
//! All poses in `Bb`, mm and rad.

use glam::{DAffine3, DMat3, DVec3};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, Unit, UnitQuaternion};

use super::roll;
use super::scalar::{
    check_finite_joints, check_gimbal_distance, check_gimbal_normal, check_inverse_inputs,
    front_plane_crossing, front_stage_unreachable, planar_length, refine_tilted, Candidates,
    IK_DIRECTION_TOLERANCE, IK_TIP_TOLERANCE_MM, ON_ROLL_AXIS, WRONG_SIDE,
};
use super::stage::FiveBar;
use super::{KinematicsError, NeedlePose};
use crate::{Geometry, Joints};

/// The joint-axis tilts of a geometry as rotations.
#[derive(Debug, Clone)]
struct AxisTilts {
    /// Per joint θ1..θ5: the stage-axis tilt `Rx(tilt[0])·Ry(tilt[1])` (θ1, θ2 in `Bf`,
    /// θ4, θ5 in the back stage plane); the identity at θ3.
    stage: [DMat3; 5],
    /// The θ3 axis: x of `Bb` turned by `Ry(tilt[0])·Rz(tilt[1])`, as that rotation.
    roll_axis: DMat3,
    /// True when some joint axis is tilted.
    any: bool,
}

/// The paper's model: no joint axis tilted.
const UNTILTED: AxisTilts = AxisTilts {
    stage: [DMat3::IDENTITY; 5],
    roll_axis: DMat3::IDENTITY,
    any: false,
};

impl AxisTilts {
    fn new(tilt: &[[f64; 2]; 5]) -> Self {
        let stage = std::array::from_fn(|joint| {
            let [about_x, about_y] = tilt[joint];
            if joint == 2 {
                DMat3::IDENTITY
            } else {
                DMat3::from_rotation_x(about_x) * DMat3::from_rotation_y(about_y)
            }
        });
        let [about_y, about_z] = tilt[2];
        Self {
            stage,
            roll_axis: DMat3::from_rotation_y(about_y) * DMat3::from_rotation_z(about_z),
            any: *tilt != [[0.0; 2]; 5],
        }
    }

    /// Effector point of a stage (mm, stage frame) from its link vectors, the proximal one
    /// turned by the tilt of joint `proximal` and the distal one by that of the next joint.
    fn stage_point(&self, proximal: usize, links: [(f64, f64); 2]) -> DVec3 {
        let [(px, py), (dx, dy)] = links;
        let (near, far) = (DVec3::new(px, py, 0.0), DVec3::new(dx, dy, 0.0));
        if self.any {
            self.stage[proximal] * near + self.stage[proximal + 1] * far
        } else {
            near + far
        }
    }

    /// Rotation by θ3 (rad) about the roll axis.
    fn roll(&self, theta3: f64) -> DMat3 {
        let roll = DMat3::from_rotation_x(theta3);
        if self.any {
            self.roll_axis * roll * self.roll_axis.transpose()
        } else {
            roll
        }
    }
}

/// A [`Geometry`] prepared for the real-time kinematics: the front base and its inverse as
/// affine maps, the axis tilts as rotations, the two 5-bars with their link lengths (mm).
#[derive(Debug, Clone)]
pub struct RealtimeGeometry {
    front: FiveBar,
    back: FiveBar,
    /// `d_offset` (mm).
    d_offset: f64,
    /// `l_n` (mm).
    l_n: f64,
    /// `T_Bb_Bf`.
    front_base: DAffine3,
    /// `T_Bf_Bb`.
    base_in_front: DAffine3,
    tilts: AxisTilts,
}

impl From<&Geometry> for RealtimeGeometry {
    fn from(geometry: &Geometry) -> Self {
        Self {
            front: FiveBar::front(geometry),
            back: FiveBar::back(geometry),
            d_offset: geometry.d_offset,
            l_n: geometry.l_n,
            front_base: affine(&geometry.front_base),
            base_in_front: affine(&geometry.front_base.inverse()),
            tilts: AxisTilts::new(&geometry.axis_tilt),
        }
    }
}

/// The result of [`RealtimeGeometry::forward`]: needle and effector poses in `Bb` (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealtimePose {
    /// Needle tip `p_n` in `Bb` (mm).
    pub tip: DVec3,
    /// Needle direction `z_N` in `Bb` (unit, towards the tip).
    pub direction: DVec3,
    /// `T_Bb_N`: needle frame (origin at the tip, mm).
    pub needle: DAffine3,
    /// `T_Bb_Ef`: front effector frame (origin at `p_f`, mm).
    pub front_effector: DAffine3,
    /// `T_Bb_Eb`: back effector frame (origin at `p_b`, mm).
    pub back_effector: DAffine3,
}

impl RealtimePose {
    /// The same poses as nalgebra types (what [`super::forward`] returns).
    pub fn to_nalgebra(&self) -> NeedlePose {
        NeedlePose {
            tip: Point3::from(self.tip.to_array()),
            direction: Unit::new_unchecked(self.direction.to_array().into()),
            needle: isometry(&self.needle),
            front_effector: isometry(&self.front_effector),
            back_effector: isometry(&self.back_effector),
        }
    }
}

/// A rigid transform (mm) as an affine map.
fn affine(pose: &Isometry3<f64>) -> DAffine3 {
    let rotation = pose.rotation.to_rotation_matrix();
    DAffine3::from_mat3_translation(
        DMat3::from_cols_slice(rotation.matrix().as_slice()),
        DVec3::from_array(pose.translation.vector.into()),
    )
}

/// An affine map with an orthonormal linear part as a rigid transform (mm).
fn isometry(pose: &DAffine3) -> Isometry3<f64> {
    let rotation =
        Rotation3::from_matrix_unchecked(Matrix3::from_column_slice(&pose.matrix3.to_cols_array()));
    Isometry3::from_parts(
        Translation3::from(pose.translation.to_array()),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

/// The gimbal centres and needle frame axes in `Bb` (mm), before the poses are built.
struct NeedleChain {
    /// Front effector point in `Bf` (mm).
    front_local: DVec3,
    /// Rotation of the back stage about its θ3 axis.
    roll: DMat3,
    /// Back gimbal centre `p_b`.
    p_b: DVec3,
    /// Needle axes `x_N`, `y_N`, `z_N`.
    axes: [DVec3; 3],
    /// Tip `p_n`.
    tip: DVec3,
}

impl RealtimeGeometry {
    /// Steps 1–4 of docs/robot-model.md §3 with the joint axes turned by `tilts`.
    fn needle_chain(&self, q: &Joints, tilts: &AxisTilts) -> Result<NeedleChain, KinematicsError> {
        check_finite_joints(q, "joint angles")?;
        let front_local = tilts.stage_point(0, self.front.link_vectors(q[0], q[1]));
        let back_local = tilts.stage_point(3, self.back.link_vectors(q[3], q[4]));
        let p_f = self.front_base.transform_point3(front_local);
        let roll = tilts.roll(q[2]);
        let p_b = roll * back_local;
        let a_b = roll.y_axis;

        let d = self.d_offset;
        let to_front = p_f - p_b;
        let distance = to_front.length();
        check_gimbal_distance(distance, d)?;
        let e = to_front / distance;
        let normal = a_b.cross(e);
        let normal_norm = normal.length();
        check_gimbal_normal(normal_norm)?;
        let n = normal / normal_norm;
        let e_perp = n.cross(e);
        let cos_alpha = d / distance;
        let sin_alpha = (1.0 - cos_alpha * cos_alpha).sqrt();
        // The perpendicular foot with x_N·n > 0, as in `super::needle_chain`.
        let y_n = -(cos_alpha * e + sin_alpha * e_perp);
        let p_r = p_b - d * y_n;
        let z_n = (p_f - p_r).normalize();
        let x_n = y_n.cross(z_n);
        Ok(NeedleChain {
            front_local,
            roll,
            p_b,
            axes: [x_n, y_n, z_n],
            tip: p_r + self.l_n * z_n,
        })
    }

    /// Forward kinematics: joint angles θ1..θ5 (rad) → needle and effector poses in `Bb`.
    pub fn forward(&self, q: &Joints) -> Result<RealtimePose, KinematicsError> {
        let chain = self.needle_chain(q, &self.tilts)?;
        let [x_n, y_n, z_n] = chain.axes;
        let front_rotation = self.tilts.stage[1] * DMat3::from_rotation_z(q[1]);
        let back_rotation = chain.roll * self.tilts.stage[4] * DMat3::from_rotation_z(q[4]);
        Ok(RealtimePose {
            tip: chain.tip,
            direction: z_n,
            needle: DAffine3::from_mat3_translation(DMat3::from_cols(x_n, y_n, z_n), chain.tip),
            front_effector: self.front_base
                * DAffine3::from_mat3_translation(front_rotation, chain.front_local),
            back_effector: DAffine3::from_mat3_translation(back_rotation, chain.p_b),
        })
    }

    /// Inverse kinematics: tip `p_n` (mm, `Bb`) and needle direction `z_N` (`Bb`, any
    /// non-zero length) → joints θ1..θ5 (rad), the solution nearest `near` (wrapped to within
    /// π of it). Unreachable targets are an error, never clamped. Same semantics as
    /// [`super::inverse`]: its tip is within 1e-6 mm of `tip`.
    pub fn inverse(
        &self,
        tip: DVec3,
        direction: DVec3,
        near: &Joints,
    ) -> Result<Joints, KinematicsError> {
        self.solve(tip, direction, near, self.tilts.any)
    }

    /// [`Self::inverse`]; with `tilted` false, of the chain without its axis tilts (the closed
    /// form alone).
    fn solve(
        &self,
        tip: DVec3,
        direction: DVec3,
        near: &Joints,
        tilted: bool,
    ) -> Result<Joints, KinematicsError> {
        let length = check_inverse_inputs(&tip.to_array(), &direction.to_array(), near)?;
        let z = direction / length;
        if tilted {
            return self.inverse_tilted(tip, z, near);
        }
        let p_r = tip - self.l_n * z;

        // p_f: the needle line p_r + t·z meets the plane z = 0 of Bf.
        let origin = self.base_in_front.transform_point3(p_r);
        let along = self.base_in_front.transform_vector3(z);
        let t = front_plane_crossing(origin.z, along.z)?;
        let front = self
            .front
            .inverse(origin.x + t * along.x, origin.y + t * along.y)
            .map_err(front_stage_unreachable)?;
        let p_f = p_r + t * z;

        let d = self.d_offset;
        let mut candidates = Candidates::new(near);
        for &v in roll::gimbal_plane_directions(&p_r.to_array(), &z.to_array(), d).iter() {
            let v = DVec3::from_array(v);
            let p_b = p_r + d * v;
            let radius = planar_length(p_b.y, p_b.z);
            if radius.is_nan() || radius <= 1e-9 {
                candidates.refuse(ON_ROLL_AXIS);
                continue;
            }
            let a_b = DVec3::new(0.0, -p_b.y / radius, -p_b.z / radius);
            // Keep only the rolls whose perpendicular foot forward kinematics picks.
            if v.cross(z).dot(a_b.cross(p_f - p_b)) <= 0.0 {
                candidates.refuse(WRONG_SIDE);
                continue;
            }
            let theta3 = (-p_b.z).atan2(-p_b.y);
            match self.back.inverse(p_b.x, -radius) {
                Ok(back) => candidates.add(theta3, &back, &front),
                Err(reason) => candidates.refuse_back(reason),
            }
        }
        candidates.nearest(|q| self.reproduces(q, tip, z, &UNTILTED))
    }

    /// The closed-form solution of the untilted chain, refined by Newton steps on the tilted
    /// one (§4), for the unit direction `z`.
    fn inverse_tilted(
        &self,
        tip: DVec3,
        z: DVec3,
        near: &Joints,
    ) -> Result<Joints, KinematicsError> {
        let q = self.solve(tip, z, near, false)?;
        let across = z.cross(DVec3::X);
        let first = if across.length() > 0.1 {
            across.normalize()
        } else {
            z.cross(DVec3::Y).normalize()
        };
        let second = z.cross(first);
        let equations = |q: &Joints| -> Option<[f64; 5]> {
            let chain = self.needle_chain(q, &self.tilts).ok()?;
            let d = chain.tip - tip;
            let axis = chain.axes[2];
            Some([d.x, d.y, d.z, axis.dot(first), axis.dot(second)])
        };
        refine_tilted(q, equations, |q| self.reproduces(q, tip, z, &self.tilts))
    }

    /// True when FK of `q` (with `tilts`) puts the tip within 1e-6 mm of `tip` and the needle
    /// along `z`.
    fn reproduces(&self, q: &Joints, tip: DVec3, z: DVec3, tilts: &AxisTilts) -> bool {
        match self.needle_chain(q, tilts) {
            Ok(chain) => {
                (chain.tip - tip).length() <= IK_TIP_TOLERANCE_MM
                    && (chain.axes[2] - z).length() <= IK_DIRECTION_TOLERANCE
            }
            Err(_) => false,
        }
    }
}
