//! Joint angles from measured marker poses: the joints whose predicted front and back
//! marker poses best match the measured ones (whitened Gauss–Newton on five joints). This is
//! the paper's "IK of the measured marker poses", used by the stepwise method and to turn a
//! validation pose's markers into a measured needle tip.

use nalgebra::{Isometry3, SMatrix, SVector};
use sabr_model::{Geometry, Joints, MarkerMounts};

use crate::math::se3::pose_residual;
use crate::model::biopsy::predict::{predict_at, Prediction};
use crate::model::biopsy::{BACK, FRONT};
use crate::model::NoiseModel;

const MAX_ITERATIONS: usize = 20;
const STEP: f64 = 1e-7;
const CONVERGED_RAD: f64 = 1e-10;

type Residual = SVector<f64, 12>;

fn residual(
    geometry: &Geometry,
    mounts: &MarkerMounts,
    noise: &NoiseModel,
    measured: (&Isometry3<f64>, &Isometry3<f64>),
    q: Joints,
) -> Option<(Residual, Prediction)> {
    let prediction = predict_at(geometry, mounts, q).ok()?;
    let mut r = Residual::zeros();
    let front = pose_residual(measured.0, &prediction.front_marker);
    let back = pose_residual(measured.1, &prediction.back_marker);
    noise
        .of(FRONT)
        .whiten(&front, 6, &mut r.as_mut_slice()[..6]);
    noise.of(BACK).whiten(&back, 6, &mut r.as_mut_slice()[6..]);
    Some((r, prediction))
}

/// The joints (rad) that best explain measured `T_Bb_Tf`, `T_Bb_Tb`, starting from `start`;
/// `None` when the kinematics fail or the iteration does not settle.
pub fn joints_from_markers(
    geometry: &Geometry,
    mounts: &MarkerMounts,
    noise: &NoiseModel,
    front: &Isometry3<f64>,
    back: &Isometry3<f64>,
    start: Joints,
) -> Option<Prediction> {
    let measured = (front, back);
    let mut q = start;
    let (mut r, mut prediction) = residual(geometry, mounts, noise, measured, q)?;
    for _ in 0..MAX_ITERATIONS {
        let mut jacobian = SMatrix::<f64, 12, 5>::zeros();
        for j in 0..5 {
            let mut shifted = q;
            shifted[j] += STEP;
            let (rj, _) = residual(geometry, mounts, noise, measured, shifted)?;
            jacobian.set_column(j, &((rj - r) / STEP));
        }
        let normal = jacobian.transpose() * jacobian;
        let step = normal.cholesky()?.solve(&(-jacobian.transpose() * r));
        let candidate: Joints = std::array::from_fn(|j| q[j] + step[j]);
        let (rc, pc) = residual(geometry, mounts, noise, measured, candidate)?;
        q = candidate;
        r = rc;
        prediction = pc;
        if step.amax() < CONVERGED_RAD {
            return Some(prediction);
        }
    }
    (r.norm().is_finite()).then_some(prediction)
}
