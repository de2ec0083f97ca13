//! Forward and inverse kinematics (docs/robot-model.md §3–§4). All poses in `Bb`, mm and rad.
//! [`forward`] and [`inverse`] work on nalgebra types (the calibration's); [`realtime`] is the
//! same kinematics on glam's f64 types for the paths that run at 1–2 kHz.

use nalgebra::{
    Isometry3, Matrix3, Point3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3,
};

use crate::{Geometry, Joints, MarkerPoses, RobotParams};

pub mod realtime;
mod roll;
mod scalar;
mod stage;

use scalar::{
    check_finite_joints, check_gimbal_distance, check_gimbal_normal, check_inverse_inputs,
    front_plane_crossing, front_stage_unreachable, planar_length, refine_tilted, Candidates,
    IK_DIRECTION_TOLERANCE, IK_TIP_TOLERANCE_MM, ON_ROLL_AXIS, WRONG_SIDE,
};
use stage::FiveBar;

/// The home pose of docs/robot-model.md §3 (needle along +z, tip at (0, −90, 180) mm in `Bb`):
/// joint angles θ1..θ5 (rad). A good `near` for [`inverse`] when nothing better is known.
pub const HOME_JOINTS: Joints = [-2.368404, -0.777628, 0.0, -2.685073, -0.601543];

/// The result of forward kinematics: needle and effector poses in `Bb`.
#[derive(Debug, Clone, PartialEq)]
pub struct NeedlePose {
    /// Needle tip `p_n` in `Bb` (mm).
    pub tip: Point3<f64>,
    /// Needle direction `z_N` in `Bb` (unit, towards the tip).
    pub direction: Unit<Vector3<f64>>,
    /// `T_Bb_N`: needle frame (origin at the tip).
    pub needle: Isometry3<f64>,
    /// `T_Bb_Ef`: front effector frame (origin at `p_f`).
    pub front_effector: Isometry3<f64>,
    /// `T_Bb_Eb`: back effector frame (origin at `p_b`).
    pub back_effector: Isometry3<f64>,
}

/// Why a kinematic solution does not exist.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum KinematicsError {
    /// An input is NaN or infinite.
    #[error("input is not finite: {0}")]
    NotFinite(&'static str),
    /// The target is outside the workspace; the message says which constraint failed.
    #[error("unreachable: {0}")]
    Unreachable(String),
}

/// The gimbal centres and the needle frame axes, in `Bb` (mm): what FK computes before it
/// builds poses.
struct NeedleChain {
    /// Front effector point in `Bf` (mm; in its plane z = 0 unless θ1 or θ2 is tilted).
    front_local: Vector3<f64>,
    /// Rotation of the back stage about its (possibly tilted) θ3 axis.
    roll: Rotation3<f64>,
    /// Back gimbal centre `p_b`.
    p_b: Vector3<f64>,
    /// Needle axes `x_N`, `y_N`, `z_N`.
    axes: [Vector3<f64>; 3],
    /// Tip `p_n`.
    tip: Vector3<f64>,
}

/// The tilt of a stage joint's axis (z of its stage plane): `Rx(tilt[0])·Ry(tilt[1])`.
fn stage_tilt(tilt: [f64; 2]) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::x_axis(), tilt[0])
        * Rotation3::from_axis_angle(&Vector3::y_axis(), tilt[1])
}

/// Effector point of a stage (mm, stage frame) from its proximal and distal link vectors,
/// each turned by the tilt of the joint that drives it.
fn stage_point(links: [(f64, f64); 2], tilts: [[f64; 2]; 2]) -> Vector3<f64> {
    links
        .iter()
        .zip(tilts)
        .map(|(&(x, y), tilt)| {
            let v = Vector3::new(x, y, 0.0);
            if tilt == [0.0; 2] {
                v
            } else {
                stage_tilt(tilt) * v
            }
        })
        .sum()
}

/// Rotation by θ3 about the roll axis, x of `Bb` tilted by `Ry(tilt[0])·Rz(tilt[1])`.
fn roll_rotation(theta3: f64, tilt: [f64; 2]) -> Rotation3<f64> {
    let roll = Rotation3::from_axis_angle(&Vector3::x_axis(), theta3);
    if tilt == [0.0; 2] {
        return roll;
    }
    let axis = Rotation3::from_axis_angle(&Vector3::y_axis(), tilt[0])
        * Rotation3::from_axis_angle(&Vector3::z_axis(), tilt[1]);
    axis * roll * axis.inverse()
}

/// Steps 1–4 of docs/robot-model.md §3 without building poses.
fn needle_chain(geometry: &Geometry, q: &Joints) -> Result<NeedleChain, KinematicsError> {
    check_finite_joints(q, "joint angles")?;
    let tilt = &geometry.axis_tilt;
    let front_local = stage_point(
        FiveBar::front(geometry).link_vectors(q[0], q[1]),
        [tilt[0], tilt[1]],
    );
    let back_local = stage_point(
        FiveBar::back(geometry).link_vectors(q[3], q[4]),
        [tilt[3], tilt[4]],
    );
    let p_f = geometry.front_base * Point3::from(front_local);
    let roll = roll_rotation(q[2], tilt[2]);
    let p_b = roll * back_local;
    let a_b = roll * Vector3::y();

    let d = geometry.d_offset;
    let to_front = p_f.coords - p_b;
    let distance = to_front.norm();
    check_gimbal_distance(distance, d)?;
    let e = to_front / distance;
    let normal = a_b.cross(&e);
    let normal_norm = normal.norm();
    check_gimbal_normal(normal_norm)?;
    let n = normal / normal_norm;
    let e_perp = n.cross(&e);
    let cos_alpha = d / distance;
    let sin_alpha = (1.0 - cos_alpha * cos_alpha).sqrt();
    // Of p_r = p_b + d(cos α e ± sin α e⊥), '+' is the one with x_N·n > 0: in the
    // right-handed basis (e, e⊥, n), y_N = −(cos α e ± sin α e⊥) and z_N ∝ sin α e ∓ cos α e⊥,
    // so x_N = y_N × z_N = ±n.
    let y_n = -(cos_alpha * e + sin_alpha * e_perp);
    let p_r = p_b - d * y_n;
    let z_n = (p_f.coords - p_r).normalize();
    let x_n = y_n.cross(&z_n);
    Ok(NeedleChain {
        front_local,
        roll,
        p_b,
        axes: [x_n, y_n, z_n],
        tip: p_r + geometry.l_n * z_n,
    })
}

impl RobotParams {
    /// The marker tool poses (in the base-marker frame `M`) for a needle pose from
    /// [`forward`]: `T_M_Tf = T_M_Bb · T_Bb_Ef · T_Ef_Tf`, likewise for the back.
    pub fn marker_poses(&self, pose: &NeedlePose) -> MarkerPoses {
        let base = &self.markers.base_to_robot;
        MarkerPoses {
            front: base * pose.front_effector * self.markers.front_mount,
            back: base * pose.back_effector * self.markers.back_mount,
            tip: base * pose.tip,
        }
    }
}

/// Forward kinematics: joint angles → needle and effector poses in `Bb`.
pub fn forward(geometry: &Geometry, q: &Joints) -> Result<NeedlePose, KinematicsError> {
    let chain = needle_chain(geometry, q)?;
    let [x_n, y_n, z_n] = chain.axes;
    let needle_rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
        Matrix3::from_columns(&[x_n, y_n, z_n]),
    ));
    let tilt = &geometry.axis_tilt;
    let front_in_base = Isometry3::from_parts(
        Translation3::from(chain.front_local),
        UnitQuaternion::from_rotation_matrix(
            &(stage_tilt(tilt[1]) * Rotation3::from_axis_angle(&Vector3::z_axis(), q[1])),
        ),
    );
    let back_rotation = UnitQuaternion::from_rotation_matrix(
        &(chain.roll * stage_tilt(tilt[4]) * Rotation3::from_axis_angle(&Vector3::z_axis(), q[4])),
    );
    Ok(NeedlePose {
        tip: Point3::from(chain.tip),
        direction: Unit::new_unchecked(z_n),
        needle: Isometry3::from_parts(Translation3::from(chain.tip), needle_rotation),
        front_effector: geometry.front_base * front_in_base,
        back_effector: Isometry3::from_parts(Translation3::from(chain.p_b), back_rotation),
    })
}

/// Inverse kinematics: tip `p_n` (mm, `Bb`) and needle direction `z_N` → joints, the
/// solution nearest `near` (wrapped to within π of it). Unreachable targets are an error.
///
/// `direction` need not be unit length (it is normalised) but must not be zero. The result
/// is checked by [`forward`]: its tip is within 1e-6 mm of `tip`.
pub fn inverse(
    geometry: &Geometry,
    tip: &Point3<f64>,
    direction: &Vector3<f64>,
    near: &Joints,
) -> Result<Joints, KinematicsError> {
    let length = check_inverse_inputs(&tip.coords.into(), &(*direction).into(), near)?;
    let z = direction / length;
    if geometry.axis_tilt != [[0.0; 2]; 5] {
        return inverse_tilted(geometry, tip, &z, near);
    }
    let p_r = tip.coords - geometry.l_n * z;

    // p_f: the needle line p_r + t·z meets the plane z = 0 of Bf.
    let to_front = geometry.front_base.inverse();
    let origin = to_front * Point3::from(p_r);
    let along = to_front.rotation * z;
    let t = front_plane_crossing(origin.z, along.z)?;
    let front_point = (origin.x + t * along.x, origin.y + t * along.y);
    let front = FiveBar::front(geometry)
        .inverse(front_point.0, front_point.1)
        .map_err(front_stage_unreachable)?;
    let p_f = p_r + t * z;

    let back_stage = FiveBar::back(geometry);
    let d = geometry.d_offset;
    let mut candidates = Candidates::new(near);
    for &v in roll::gimbal_plane_directions(&p_r.into(), &z.into(), d).iter() {
        let v = Vector3::from(v);
        let p_b = p_r + d * v;
        let radius = planar_length(p_b.y, p_b.z);
        if radius.is_nan() || radius <= 1e-9 {
            candidates.refuse(ON_ROLL_AXIS);
            continue;
        }
        let a_b = Vector3::new(0.0, -p_b.y / radius, -p_b.z / radius);
        // Forward kinematics picks the perpendicular foot with x_N·n > 0; keep only rolls
        // that agree with it.
        if v.cross(&z).dot(&a_b.cross(&(p_f - p_b))) <= 0.0 {
            candidates.refuse(WRONG_SIDE);
            continue;
        }
        let theta3 = (-p_b.z).atan2(-p_b.y);
        match back_stage.inverse(p_b.x, -radius) {
            Ok(back) => candidates.add(theta3, &back, &front),
            Err(reason) => candidates.refuse_back(reason),
        }
    }
    candidates.nearest(|q| reproduces(geometry, q, &tip.coords, &z))
}

/// Inverse kinematics with tilted joint axes (§4): the closed-form solution of the untilted
/// geometry, refined by Newton steps on the tip (3 equations) and the needle direction (its
/// components along two unit vectors perpendicular to the target direction `z`, unit).
fn inverse_tilted(
    geometry: &Geometry,
    tip: &Point3<f64>,
    z: &Vector3<f64>,
    near: &Joints,
) -> Result<Joints, KinematicsError> {
    let mut untilted = geometry.clone();
    untilted.axis_tilt = [[0.0; 2]; 5];
    let q = inverse(&untilted, tip, z, near)?;
    let across = z.cross(&Vector3::x());
    let first = if across.norm() > 0.1 {
        across.normalize()
    } else {
        z.cross(&Vector3::y()).normalize()
    };
    let second = z.cross(&first);
    let equations = |q: &Joints| -> Option<[f64; 5]> {
        let chain = needle_chain(geometry, q).ok()?;
        let d = chain.tip - tip.coords;
        let axis = chain.axes[2];
        Some([d.x, d.y, d.z, axis.dot(&first), axis.dot(&second)])
    };
    refine_tilted(q, equations, |q| reproduces(geometry, q, &tip.coords, z))
}

/// True when FK of `q` puts the tip within 1e-6 mm of `tip` and the needle along `z`.
fn reproduces(geometry: &Geometry, q: &Joints, tip: &Vector3<f64>, z: &Vector3<f64>) -> bool {
    match needle_chain(geometry, q) {
        Ok(chain) => {
            (chain.tip - tip).norm() <= IK_TIP_TOLERANCE_MM
                && (chain.axes[2] - z).norm() <= IK_DIRECTION_TOLERANCE
        }
        Err(_) => false,
    }
}
