//! Forward and inverse kinematics (docs/robot-model.md §3–§4). All poses in `Bb`, mm and rad.

use std::borrow::Cow;
use std::f64::consts::TAU;

use nalgebra::{
    Isometry3, Matrix3, Point3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3,
};

use crate::{Geometry, Joints, MarkerPoses, RobotParams};

mod roll;
mod stage;

use stage::FiveBar;

/// The home pose of docs/robot-model.md §3 (needle along +z, tip at (0, −90, 180) mm in `Bb`):
/// joint angles θ1..θ5 (rad). A good `near` for [`inverse`] when nothing better is known.
pub const HOME_JOINTS: Joints = [-2.368404, -0.777628, 0.0, -2.685073, -0.601543];

/// Largest tip error (mm) at which an IK candidate counts as reproducing the target.
const IK_TIP_TOLERANCE_MM: f64 = 1e-6;
/// Largest needle-direction error (unit vector difference) of an accepted IK candidate.
const IK_DIRECTION_TOLERANCE: f64 = 1e-8;

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

fn check_finite_joints(q: &Joints, what: &'static str) -> Result<(), KinematicsError> {
    if q.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(KinematicsError::NotFinite(what))
    }
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
    if distance.is_nan() || distance <= d {
        return Err(KinematicsError::Unreachable(format!(
            "the gimbal centres are {distance} mm apart, not more than d_offset = {d} mm"
        )));
    }
    let e = to_front / distance;
    let normal = a_b.cross(&e);
    let normal_norm = normal.norm();
    if normal_norm.is_nan() || normal_norm <= 1e-12 {
        return Err(KinematicsError::Unreachable(
            "the line between the gimbal centres is parallel to the back gimbal axis".into(),
        ));
    }
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

/// A joint-vector candidate of the inverse kinematics and its squared distance to `near`.
#[derive(Clone, Copy)]
struct Candidate {
    q: Joints,
    distance: f64,
}

/// Wraps `angle` (rad) to within π of `reference`.
fn wrap_near(angle: f64, reference: f64) -> f64 {
    angle - TAU * ((angle - reference) / TAU).round()
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
    if !tip.coords.iter().all(|v| v.is_finite()) {
        return Err(KinematicsError::NotFinite("tip"));
    }
    if !direction.iter().all(|v| v.is_finite()) {
        return Err(KinematicsError::NotFinite("needle direction"));
    }
    check_finite_joints(near, "near joints")?;
    let length = direction.norm();
    if length <= 1e-12 || length.is_infinite() {
        return Err(KinematicsError::Unreachable(format!(
            "the needle direction has no usable length ({length})"
        )));
    }
    let z = direction / length;
    if geometry.axis_tilt != [[0.0; 2]; 5] {
        return inverse_tilted(geometry, tip, &z, near);
    }
    let p_r = tip.coords - geometry.l_n * z;

    // p_f: the needle line p_r + t·z meets the plane z = 0 of Bf.
    let to_front = geometry.front_base.inverse();
    let origin = to_front * Point3::from(p_r);
    let along = to_front.rotation * z;
    if along.z.abs() < 1e-9 {
        return Err(KinematicsError::Unreachable(
            "the needle is parallel to the front stage plane".into(),
        ));
    }
    let t = -origin.z / along.z;
    if t.is_nan() || t <= 0.0 {
        return Err(KinematicsError::Unreachable(format!(
            "the needle line meets the front stage plane {:.3} mm behind p_r (it must be ahead)",
            -t
        )));
    }
    let front_point = (origin.x + t * along.x, origin.y + t * along.y);
    let front = FiveBar::front(geometry)
        .inverse(front_point.0, front_point.1)
        .map_err(|reason| KinematicsError::Unreachable(format!("front 5-bar: {reason}")))?;
    let p_f = p_r + t * z;

    let back_stage = FiveBar::back(geometry);
    let d = geometry.d_offset;
    let mut candidates = [Candidate {
        q: [0.0; 5],
        distance: f64::INFINITY,
    }; roll::MAX_ROOTS * 4];
    let mut count = 0;
    let mut last_failure: Cow<'static, str> =
        "no needle roll puts the back gimbal axis in the needle plane".into();
    for v in roll::gimbal_plane_directions(&p_r, &z, d).iter() {
        let p_b = p_r + d * v;
        let radius = p_b.y.hypot(p_b.z);
        if radius.is_nan() || radius <= 1e-9 {
            last_failure = "the back gimbal centre would lie on the θ3 axis".into();
            continue;
        }
        let a_b = Vector3::new(0.0, -p_b.y / radius, -p_b.z / radius);
        // Forward kinematics picks the perpendicular foot with x_N·n > 0; keep only rolls
        // that agree with it.
        if v.cross(&z).dot(&a_b.cross(&(p_f - p_b))) <= 0.0 {
            last_failure = "the needle lies on the wrong side of the back gimbal".into();
            continue;
        }
        let theta3 = (-p_b.z).atan2(-p_b.y);
        let back = match back_stage.inverse(p_b.x, -radius) {
            Ok(back) => back,
            Err(reason) => {
                last_failure = format!("back 5-bar: {reason}").into();
                continue;
            }
        };
        for &(theta4, theta5) in &back {
            for &(theta1, theta2) in &front {
                let raw = [theta1, theta2, theta3, theta4, theta5];
                let q: Joints = std::array::from_fn(|i| wrap_near(raw[i], near[i]));
                let distance = q.iter().zip(near).map(|(a, b)| (a - b) * (a - b)).sum();
                candidates[count] = Candidate { q, distance };
                count += 1;
            }
        }
    }
    let candidates = &mut candidates[..count];
    candidates.sort_unstable_by(|a, b| a.distance.total_cmp(&b.distance));
    for candidate in candidates.iter() {
        if reproduces(geometry, &candidate.q, &tip.coords, &z) {
            return Ok(candidate.q);
        }
    }
    if !candidates.is_empty() {
        last_failure = "no candidate solution reproduces the target (singular pose)".into();
    }
    Err(KinematicsError::Unreachable(last_failure.into_owned()))
}

/// Newton steps of the inverse kinematics with tilted joint axes.
const TILTED_IK_ITERATIONS: usize = 30;
/// Joint step (rad) of the finite differences of the tilted inverse kinematics.
const TILTED_IK_STEP: f64 = 1e-7;

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
    let mut q = inverse(&untilted, tip, z, near)?;
    let across = z.cross(&Vector3::x());
    let first = if across.norm() > 0.1 {
        across.normalize()
    } else {
        z.cross(&Vector3::y()).normalize()
    };
    let second = z.cross(&first);
    let equations = |q: &Joints| -> Option<nalgebra::Vector5<f64>> {
        let chain = needle_chain(geometry, q).ok()?;
        let d = chain.tip - tip.coords;
        let axis = chain.axes[2];
        Some(nalgebra::Vector5::new(
            d.x,
            d.y,
            d.z,
            axis.dot(&first),
            axis.dot(&second),
        ))
    };
    for _ in 0..TILTED_IK_ITERATIONS {
        if reproduces(geometry, &q, &tip.coords, z) {
            return Ok(q);
        }
        let f = equations(&q).ok_or_else(|| {
            KinematicsError::Unreachable("the tilted chain leaves its workspace".into())
        })?;
        let mut jacobian = nalgebra::Matrix5::zeros();
        for j in 0..5 {
            let mut moved = q;
            moved[j] += TILTED_IK_STEP;
            let g = equations(&moved).ok_or_else(|| {
                KinematicsError::Unreachable("the tilted chain leaves its workspace".into())
            })?;
            jacobian.set_column(j, &((g - f) / TILTED_IK_STEP));
        }
        let step = jacobian.lu().solve(&(-f)).ok_or_else(|| {
            KinematicsError::Unreachable("singular pose of the tilted chain".into())
        })?;
        for (value, delta) in q.iter_mut().zip(step.iter()) {
            *value += delta;
        }
    }
    if reproduces(geometry, &q, &tip.coords, z) {
        Ok(q)
    } else {
        Err(KinematicsError::Unreachable(format!(
            "no joint vector of the tilted chain reproduces the target within              {TILTED_IK_ITERATIONS} Newton steps"
        )))
    }
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
