//! The scalar steps of the kinematics that the nalgebra and the glam paths share: input and
//! gimbal checks, the front-plane crossing, collecting and choosing the candidate joint
//! vectors of the inverse kinematics, and the Newton refinement of a tilted chain. Lengths in
//! mm, angles in rad.

use std::borrow::Cow;
use std::f64::consts::TAU;

use super::roll::MAX_ROOTS;
use super::KinematicsError;
use crate::Joints;

/// Largest tip error (mm) at which an IK candidate counts as reproducing the target.
pub(super) const IK_TIP_TOLERANCE_MM: f64 = 1e-6;
/// Largest needle-direction error (unit vector difference) of an accepted IK candidate.
pub(super) const IK_DIRECTION_TOLERANCE: f64 = 1e-8;
/// Newton steps of the inverse kinematics with tilted joint axes.
const TILTED_IK_ITERATIONS: usize = 30;
/// Joint step (rad) of the finite differences of the tilted inverse kinematics.
const TILTED_IK_STEP: f64 = 1e-7;
/// Largest residual (tip mm; needle-direction components) at which the Newton refinement of
/// the tilted inverse kinematics stops: far below the acceptance tolerances, so that two
/// implementations whose rounding differs (the real-time one and this) stop at the same
/// root, not one step apart as when each stopped once its candidate was accepted.
const TILTED_IK_CONVERGED: f64 = 1e-10;

/// Refusal of a needle roll whose back gimbal centre lies on the θ3 axis.
pub(super) const ON_ROLL_AXIS: &str = "the back gimbal centre would lie on the θ3 axis";
/// Refusal of a needle roll that forward kinematics would not pick (x_N·n ≤ 0).
pub(super) const WRONG_SIDE: &str = "the needle lies on the wrong side of the back gimbal";

/// An error unless every joint angle (rad) is finite; `what` names the input.
pub(super) fn check_finite_joints(q: &Joints, what: &'static str) -> Result<(), KinematicsError> {
    if q.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(KinematicsError::NotFinite(what))
    }
}

/// An error unless the gimbal centres are more than `d_offset` (mm) apart (`distance`, mm).
pub(super) fn check_gimbal_distance(distance: f64, d_offset: f64) -> Result<(), KinematicsError> {
    if distance.is_nan() || distance <= d_offset {
        return Err(KinematicsError::Unreachable(format!(
            "the gimbal centres are {distance} mm apart, not more than d_offset = {d_offset} mm"
        )));
    }
    Ok(())
}

/// An error unless the line between the gimbal centres is off the back gimbal axis: `norm` is
/// the length of the cross product of their unit directions.
pub(super) fn check_gimbal_normal(norm: f64) -> Result<(), KinematicsError> {
    if norm.is_nan() || norm <= 1e-12 {
        return Err(KinematicsError::Unreachable(
            "the line between the gimbal centres is parallel to the back gimbal axis".into(),
        ));
    }
    Ok(())
}

/// The refusal of a point (in `Bf`) out of the front 5-bar's reach, with its reason.
pub(super) fn front_stage_unreachable(reason: String) -> KinematicsError {
    KinematicsError::Unreachable(format!("front 5-bar: {reason}"))
}

/// Checks the inputs of the inverse kinematics (tip in mm, direction and near joints in
/// rad) and returns the length of `direction`, which must be usable for normalising.
pub(super) fn check_inverse_inputs(
    tip: &[f64; 3],
    direction: &[f64; 3],
    near: &Joints,
) -> Result<f64, KinematicsError> {
    if !tip.iter().all(|v| v.is_finite()) {
        return Err(KinematicsError::NotFinite("tip"));
    }
    if !direction.iter().all(|v| v.is_finite()) {
        return Err(KinematicsError::NotFinite("needle direction"));
    }
    check_finite_joints(near, "near joints")?;
    let length =
        (direction[0] * direction[0] + direction[1] * direction[1] + direction[2] * direction[2])
            .sqrt();
    if length <= 1e-12 || length.is_infinite() {
        return Err(KinematicsError::Unreachable(format!(
            "the needle direction has no usable length ({length})"
        )));
    }
    Ok(length)
}

/// The parameter `t` (mm along the unit needle direction) at which the needle line through
/// `p_r` meets the plane z = 0 of `Bf`, from the z components (in `Bf`) of `p_r` (`origin_z`,
/// mm) and of the direction (`along_z`). The plane must lie ahead of `p_r`.
pub(super) fn front_plane_crossing(origin_z: f64, along_z: f64) -> Result<f64, KinematicsError> {
    if along_z.abs() < 1e-9 {
        return Err(KinematicsError::Unreachable(
            "the needle is parallel to the front stage plane".into(),
        ));
    }
    let t = -origin_z / along_z;
    if t.is_nan() || t <= 0.0 {
        return Err(KinematicsError::Unreachable(format!(
            "the needle line meets the front stage plane {:.3} mm behind p_r (it must be ahead)",
            -t
        )));
    }
    Ok(t)
}

/// `√(a² + b²)` of two millimetre-scale components (mm): far from overflow and underflow,
/// so not `f64::hypot`, which guards against both in a library call several times slower.
pub(super) fn planar_length(a: f64, b: f64) -> f64 {
    (a * a + b * b).sqrt()
}

/// Wraps `angle` (rad) to within π of `reference`.
fn wrap_near(angle: f64, reference: f64) -> f64 {
    let turns = (angle - reference) / TAU;
    // Within half a turn already (the usual case): `round` would give 0, and it is a
    // library call on the baseline x86-64 target.
    if turns.abs() < 0.5 {
        angle
    } else {
        angle - TAU * turns.round()
    }
}

/// A joint-vector candidate of the inverse kinematics and its squared distance to `near`.
#[derive(Clone, Copy)]
struct Candidate {
    q: Joints,
    distance: f64,
}

/// The candidate joint vectors of one closed-form solve (every needle roll times both
/// solutions of each stage), wrapped near `near`, and why the last roll was refused.
pub(super) struct Candidates {
    near: Joints,
    items: [Candidate; MAX_ROOTS * 4],
    count: usize,
    last_failure: Cow<'static, str>,
}

impl Candidates {
    /// No candidates yet, for joints near `near` (rad).
    pub(super) fn new(near: &Joints) -> Self {
        Self {
            near: *near,
            items: [Candidate {
                q: [0.0; 5],
                distance: f64::INFINITY,
            }; MAX_ROOTS * 4],
            count: 0,
            last_failure: "no needle roll puts the back gimbal axis in the needle plane".into(),
        }
    }

    /// Records why a needle roll gives no candidate.
    pub(super) fn refuse(&mut self, reason: impl Into<Cow<'static, str>>) {
        self.last_failure = reason.into();
    }

    /// Records why the back 5-bar cannot reach a roll's gimbal centre.
    pub(super) fn refuse_back(&mut self, reason: String) {
        self.refuse(format!("back 5-bar: {reason}"));
    }

    /// Adds the candidates of one needle roll θ3: both back solutions (θ4, θ5) with both
    /// front solutions (θ1, θ2), each angle wrapped to within π of `near`.
    pub(super) fn add(&mut self, theta3: f64, back: &[(f64, f64); 2], front: &[(f64, f64); 2]) {
        for &(theta4, theta5) in back {
            for &(theta1, theta2) in front {
                let raw = [theta1, theta2, theta3, theta4, theta5];
                let q: Joints = std::array::from_fn(|i| wrap_near(raw[i], self.near[i]));
                let distance = q
                    .iter()
                    .zip(&self.near)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum();
                self.items[self.count] = Candidate { q, distance };
                self.count += 1;
            }
        }
    }

    /// The candidate nearest `near` that `reproduces` the target, or why there is none.
    pub(super) fn nearest(
        mut self,
        reproduces: impl Fn(&Joints) -> bool,
    ) -> Result<Joints, KinematicsError> {
        let candidates = &mut self.items[..self.count];
        candidates.sort_unstable_by(|a, b| a.distance.total_cmp(&b.distance));
        for candidate in candidates.iter() {
            if reproduces(&candidate.q) {
                return Ok(candidate.q);
            }
        }
        if !candidates.is_empty() {
            self.last_failure =
                "no candidate solution reproduces the target (singular pose)".into();
        }
        Err(KinematicsError::Unreachable(self.last_failure.into_owned()))
    }
}

/// Newton refinement of the tilted chain (§4) from the untilted solution `q` (rad):
/// `equations` are the tip error (mm, 3 components) and the needle direction's components
/// along two unit vectors perpendicular to the target direction (`None` outside the
/// workspace); `reproduces` is the acceptance test of the inverse kinematics.
pub(super) fn refine_tilted(
    mut q: Joints,
    equations: impl Fn(&Joints) -> Option<[f64; 5]>,
    reproduces: impl Fn(&Joints) -> bool,
) -> Result<Joints, KinematicsError> {
    let evaluate = |q: &Joints| {
        equations(q).map(nalgebra::Vector5::from).ok_or_else(|| {
            KinematicsError::Unreachable("the tilted chain leaves its workspace".into())
        })
    };
    for _ in 0..TILTED_IK_ITERATIONS {
        let f = evaluate(&q)?;
        if f.amax() <= TILTED_IK_CONVERGED {
            break;
        }
        let mut jacobian = nalgebra::Matrix5::zeros();
        for j in 0..5 {
            let mut moved = q;
            moved[j] += TILTED_IK_STEP;
            let g = evaluate(&moved)?;
            jacobian.set_column(j, &((g - f) / TILTED_IK_STEP));
        }
        let step = jacobian.lu().solve(&(-f)).ok_or_else(|| {
            KinematicsError::Unreachable("singular pose of the tilted chain".into())
        })?;
        for (value, delta) in q.iter_mut().zip(step.iter()) {
            *value += delta;
        }
    }
    if reproduces(&q) {
        Ok(q)
    } else {
        Err(KinematicsError::Unreachable(format!(
            "no joint vector of the tilted chain reproduces the target within \
             {TILTED_IK_ITERATIONS} Newton steps"
        )))
    }
}
