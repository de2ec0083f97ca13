//! The biopsy model's own Jacobian: each parameter's [`Channel`] says how it acts on a
//! prediction, so most columns need no forward kinematics. The joint-map parameters go by
//! the chain rule through ∂r/∂q (five FK calls per observation for all of them), the marker
//! mountings are composed after FK, the needle length moves only the tip, `T_Bb_Bf` moves
//! the front marker rigidly; only the geometry takes forward differences of the kinematics.

use nalgebra::DMatrix;
use sabr_model::Geometry;

use crate::data::session::Observation;
use crate::model::biopsy::params::Channel;
use crate::model::biopsy::predict::{
    joint_angles, marker_poses, predict_at, raw_residual, Prediction,
};
use crate::model::biopsy::{BiopsyModel, TIP};
use crate::model::{Block, Problem, RobotModel};

/// Largest residual rows of one observation (front + back + tip).
const MAX_ROWS_PER_OBSERVATION: usize = 15;
/// Step (rad) of the finite differences with respect to the joint angles.
const JOINT_STEP: f64 = 1e-7;

/// A model with one parameter shifted by its finite-difference step.
struct Perturbed {
    channel: Channel,
    step: f64,
    model: BiopsyModel,
    geometry: Option<Geometry>,
}

/// Writes the whitened (unweighted) residuals of one observation's blocks (starting at
/// block index `first`) into `out`, consecutively in block order; returns the rows written.
fn observation_rows(
    problem: &Problem<'_, BiopsyModel>,
    prediction: &Prediction,
    obs: &Observation,
    group: &[Block],
    out: &mut [f64],
) -> usize {
    let mut k = 0;
    for block in group {
        let raw = raw_residual(prediction, obs, block.kind).unwrap_or([0.0; 6]);
        problem
            .noise
            .whiten(block, &raw, &mut out[k..k + block.dim]);
        k += block.dim;
    }
    k
}

/// Writes the rows of `local` (one observation, block order) to their stacked rows, scaled
/// by the square root of each block's weight.
fn scatter(
    problem: &Problem<'_, BiopsyModel>,
    first: usize,
    group: &[Block],
    local: &[f64],
    mut write: impl FnMut(usize, f64),
) {
    let mut k = 0;
    for (i, block) in group.iter().enumerate() {
        let scale = problem.weights[first + i].sqrt();
        for d in 0..block.dim {
            write(block.row + d, scale * local[k]);
            k += 1;
        }
    }
}

/// Forward difference of the rows of `shifted` against `r0`, into `column`.
fn finite_difference(
    problem: &Problem<'_, BiopsyModel>,
    shifted: &Prediction,
    obs: &Observation,
    group: &[Block],
    r0: &[f64],
    step: f64,
    column: &mut [f64],
) -> bool {
    let rows = observation_rows(problem, shifted, obs, group, column);
    for k in 0..rows {
        column[k] = (column[k] - r0[k]) / step;
    }
    true
}

/// The weighted Jacobian of `problem` at `model` (see the module docs).
pub fn channel_jacobian(model: &BiopsyModel, problem: &Problem<'_, BiopsyModel>) -> DMatrix<f64> {
    let n = problem.layout.len();
    let mut jacobian = DMatrix::zeros(problem.rows, n);
    let geometry = model.robot.effective_geometry();
    let perturbed: Vec<Perturbed> = problem
        .layout
        .ids
        .iter()
        .map(|id| {
            let step = id.step();
            let mut shifted = model.clone();
            shifted.set(*id, model.get(*id) + step);
            let geometry = matches!(id.channel(), Channel::Geometry | Channel::FrontBase)
                .then(|| shifted.robot.effective_geometry());
            Perturbed {
                channel: id.channel(),
                step,
                model: shifted,
                geometry,
            }
        })
        .collect();
    let needs_dq = perturbed.iter().any(|p| p.channel == Channel::JointMap);
    let mut r0 = [0.0; MAX_ROWS_PER_OBSERVATION];
    let mut r1 = [0.0; MAX_ROWS_PER_OBSERVATION];
    let mut dr_dq = [[0.0; MAX_ROWS_PER_OBSERVATION]; 5];
    let mut column = [0.0; MAX_ROWS_PER_OBSERVATION];
    for (first, group) in problem.groups() {
        let obs = &problem.observations[group[0].obs];
        let q0 = joint_angles(model, obs);
        let Ok(p0) = predict_at(&geometry, &model.robot.markers, q0) else {
            continue;
        };
        let rows = observation_rows(problem, &p0, obs, group, &mut r0);
        let sees_tip = group.iter().any(|b| b.kind == TIP);
        if needs_dq {
            for (j, derivative) in dr_dq.iter_mut().enumerate() {
                let mut q = q0;
                q[j] += JOINT_STEP;
                if let Ok(p) = predict_at(&geometry, &model.robot.markers, q) {
                    observation_rows(problem, &p, obs, group, &mut r1);
                    for k in 0..rows {
                        derivative[k] = (r1[k] - r0[k]) / JOINT_STEP;
                    }
                }
            }
        }
        for (col, p) in perturbed.iter().enumerate() {
            let ok = match p.channel {
                Channel::JointMap => {
                    let q = joint_angles(&p.model, obs);
                    column[..rows].fill(0.0);
                    for j in 0..5 {
                        let dq = (q[j] - q0[j]) / p.step;
                        if dq != 0.0 {
                            for k in 0..rows {
                                column[k] += dr_dq[j][k] * dq;
                            }
                        }
                    }
                    true
                }
                Channel::Mount => {
                    let (front_marker, back_marker) =
                        marker_poses(&p0.pose, &p.model.robot.markers);
                    let shifted = Prediction {
                        front_marker,
                        back_marker,
                        ..p0.clone()
                    };
                    finite_difference(problem, &shifted, obs, group, &r0, p.step, &mut column)
                }
                Channel::NeedleLength => {
                    let mut shifted = p0.clone();
                    shifted.pose.tip += shifted.pose.direction.into_inner() * p.step;
                    finite_difference(problem, &shifted, obs, group, &r0, p.step, &mut column)
                }
                Channel::FrontBase if !sees_tip => {
                    let motion = p.model.robot.geometry.front_base
                        * model.robot.geometry.front_base.inverse();
                    let shifted = Prediction {
                        front_marker: motion * p0.front_marker,
                        ..p0.clone()
                    };
                    finite_difference(problem, &shifted, obs, group, &r0, p.step, &mut column)
                }
                Channel::Geometry | Channel::FrontBase => {
                    let geometry = p.geometry.as_ref().unwrap_or(&geometry);
                    match predict_at(geometry, &p.model.robot.markers, q0) {
                        Ok(shifted) => finite_difference(
                            problem,
                            &shifted,
                            obs,
                            group,
                            &r0,
                            p.step,
                            &mut column,
                        ),
                        Err(_) => false,
                    }
                }
            };
            if ok {
                scatter(problem, first, group, &column, |row, value| {
                    jacobian[(row, col)] = value
                });
            }
        }
    }
    jacobian
}
