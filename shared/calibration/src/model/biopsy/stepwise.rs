//! The paper's stepwise calibration, as a robust baseline. Each step solves one block of
//! parameters with the others held, and the blocks are iterated to a fixed point:
//!
//! 1. joint angles of every excitation frame from the measured marker poses (IK);
//! 2. gear ratios by linear least squares of those joints on the motor angles (paper
//!    eq. 15, θ = GR·θ_enc + θ_off, Huber-reweighted);
//! 3. joint offsets from the homing dwell, via IK of the dwell's marker poses;
//! 4. marker mountings: the mean of `T_Bb_E(q)⁻¹ · T_Bb_T` over the excitation;
//! 5. the front/back base transform `T_Bb_Bf` (paper eqs. 16–17): rigid registration of the
//!    front marker as predicted in `Bf` onto its measured positions in `Bb` (rotation about
//!    z held at 0);
//!
//! then the needle length from the tip sphere, `l_n = (p_tip − p_r)·z_N` (robust mean).
//!
//! The blocks are coupled through the marker IK (the measured joint angles absorb mounting
//! errors), so plain block iteration does not converge to the least-squares optimum and can
//! drift; the passes therefore continue only while the whitened marker residual of the
//! excitation decreases, and the best pass is kept.

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::data::session::Observation;
use crate::error::CalibrationError;
use crate::math::se3;
use crate::math::stats::{median, robust_line};
use crate::model::biopsy::marker_ik::joints_from_markers;
use crate::model::biopsy::predict::{joint_angles, predict, raw_residual};
use crate::model::biopsy::{BiopsyModel, BACK, FRONT};
use crate::model::NoiseModel;

const MAX_PASSES: usize = 10;
/// Stop when a pass lowers the marker cost by less than this fraction.
const COST_TOLERANCE: f64 = 1e-4;
const STAGE: &str = "stepwise method";

/// The observations the stepwise method uses.
#[derive(Debug, Clone, Default)]
pub struct FitSets<'a> {
    /// Excitation frames with both markers seen.
    pub excitation: Vec<&'a Observation>,
    /// Homing-dwell frames with both markers seen.
    pub dwell: Vec<&'a Observation>,
    /// Tip-phase frames with the tip sphere seen.
    pub tip: Vec<&'a Observation>,
}

/// Runs the stepwise method from `start` (nominal parameters with homing offsets).
pub fn stepwise(
    start: &BiopsyModel,
    sets: &FitSets<'_>,
    noise: &NoiseModel,
) -> Result<BiopsyModel, CalibrationError> {
    let mut best = start.clone();
    let mut best_cost = marker_cost(&best, &sets.excitation, noise);
    let mut model = start.clone();
    for _ in 0..MAX_PASSES {
        fit_gear_ratios(&mut model, &sets.excitation, noise)?;
        fit_offsets_from_dwell(&mut model, &sets.dwell, noise)?;
        fit_mounts(&mut model, &sets.excitation)?;
        fit_front_base(&mut model, &sets.excitation)?;
        let cost = marker_cost(&model, &sets.excitation, noise);
        if cost.is_nan() || cost >= best_cost {
            break;
        }
        let gain = (best_cost - cost) / best_cost;
        best = model.clone();
        best_cost = cost;
        if gain < COST_TOLERANCE {
            break;
        }
    }
    let mut model = best;
    fit_needle_length(&mut model, &sets.tip)?;
    Ok(model)
}

fn failure(reason: String) -> CalibrationError {
    CalibrationError::Fit {
        stage: STAGE,
        reason,
    }
}

/// Whitened sum of squares of the marker residuals over `frames` (infinite if the
/// kinematics fail anywhere).
fn marker_cost(model: &BiopsyModel, frames: &[&Observation], noise: &NoiseModel) -> f64 {
    let mut cost = 0.0;
    let mut white = [0.0; 6];
    for obs in frames {
        let Ok(p) = predict(model, obs) else {
            return f64::INFINITY;
        };
        for kind in [FRONT, BACK] {
            if let Some(raw) = raw_residual(&p, obs, kind) {
                noise.of(kind).whiten(&raw, 6, &mut white);
                cost += white.iter().map(|v| v * v).sum::<f64>();
            }
        }
    }
    cost
}

/// Steps 1–2: IK of the excitation's marker poses, then eq. 15 per joint (the slope).
fn fit_gear_ratios(
    model: &mut BiopsyModel,
    frames: &[&Observation],
    noise: &NoiseModel,
) -> Result<(), CalibrationError> {
    let geometry = model.robot.effective_geometry();
    let mut motor: Vec<[f64; 5]> = Vec::with_capacity(frames.len());
    let mut joints: Vec<[f64; 5]> = Vec::with_capacity(frames.len());
    for obs in frames {
        let (Some(front), Some(back)) = (obs.front, obs.back) else {
            continue;
        };
        let start = joint_angles(model, obs);
        if let Some(p) =
            joints_from_markers(&geometry, &model.robot.markers, noise, &front, &back, start)
        {
            motor.push(
                model
                    .robot
                    .motor_angles_fractional(&obs.counts_at_latency(model.latency_s)),
            );
            joints.push(p.joints);
        }
    }
    if joints.len() < frames.len() / 2 || joints.len() < 10 {
        return Err(failure(format!(
            "the marker poses of only {} of {} excitation frames could be turned into joint \
             angles",
            joints.len(),
            frames.len()
        )));
    }
    for j in 0..5 {
        let x: Vec<f64> = motor.iter().map(|m| m[j]).collect();
        let y: Vec<f64> = joints.iter().map(|q| q[j]).collect();
        let slope = robust_line(&x, &y).map_or(f64::NAN, |(_, slope)| slope);
        if !slope.is_finite() || slope == 0.0 {
            return Err(failure(format!(
                "gear ratio of joint {} is not determined",
                j + 1
            )));
        }
        model.robot.joints.gear_ratio[j] = slope;
    }
    Ok(())
}

/// Step 3: offsets from the homing dwell via IK of its marker poses.
fn fit_offsets_from_dwell(
    model: &mut BiopsyModel,
    dwell: &[&Observation],
    noise: &NoiseModel,
) -> Result<(), CalibrationError> {
    let geometry = model.robot.effective_geometry();
    let mut samples: [Vec<f64>; 5] = Default::default();
    for obs in dwell {
        let (Some(front), Some(back)) = (obs.front, obs.back) else {
            continue;
        };
        let start = joint_angles(model, obs);
        let Some(p) =
            joints_from_markers(&geometry, &model.robot.markers, noise, &front, &back, start)
        else {
            continue;
        };
        let motor = model
            .robot
            .motor_angles_fractional(&obs.counts_at_latency(model.latency_s));
        for j in 0..5 {
            samples[j].push(p.joints[j] - model.robot.joints.gear_ratio[j] * motor[j]);
        }
    }
    if samples[0].is_empty() {
        return Err(failure(
            "no homing-dwell frame could be turned into joint angles".into(),
        ));
    }
    let offsets: [f64; 5] = std::array::from_fn(|j| median(&mut samples[j]));
    model.robot.joints.offset = Some(offsets);
    Ok(())
}

/// Step 4: marker mountings as the mean of `T_Bb_E(q)⁻¹ · T_Bb_T`.
fn fit_mounts(model: &mut BiopsyModel, frames: &[&Observation]) -> Result<(), CalibrationError> {
    let mut front = Vec::with_capacity(frames.len());
    let mut back = Vec::with_capacity(frames.len());
    for obs in frames {
        let Ok(p) = predict(model, obs) else { continue };
        if let Some(measured) = obs.front {
            front.push(p.pose.front_effector.inverse() * measured);
        }
        if let Some(measured) = obs.back {
            back.push(p.pose.back_effector.inverse() * measured);
        }
    }
    let (Some(front), Some(back)) = (se3::mean_isometry(&front), se3::mean_isometry(&back)) else {
        return Err(failure(
            "no excitation frame for the marker mountings".into(),
        ));
    };
    model.robot.markers.front_mount = front;
    model.robot.markers.back_mount = back;
    Ok(())
}

/// Step 5: `T_Bb_Bf` by registering the front marker positions predicted in `Bf` onto the
/// measured ones (Kabsch), rotation about z set to 0.
fn fit_front_base(
    model: &mut BiopsyModel,
    frames: &[&Observation],
) -> Result<(), CalibrationError> {
    let base_inverse = model.robot.geometry.front_base.inverse();
    let mut pairs: Vec<(Point3<f64>, Point3<f64>)> = Vec::with_capacity(frames.len());
    for obs in frames {
        let (Ok(p), Some(measured)) = (predict(model, obs), obs.front) else {
            continue;
        };
        let in_front_base = base_inverse * p.front_marker;
        pairs.push((
            Point3::from(in_front_base.translation.vector),
            Point3::from(measured.translation.vector),
        ));
    }
    let registration = register_points(&pairs)
        .ok_or_else(|| failure("the front marker positions do not determine T_Bb_Bf".into()))?;
    let mut rotation_vector = se3::rotation_log(&registration.rotation);
    rotation_vector.z = 0.0;
    let rotation = UnitQuaternion::from_scaled_axis(rotation_vector);
    let (ca, cb) = centroids(&pairs);
    let translation = cb.coords - rotation * ca.coords;
    model.robot.geometry.front_base =
        Isometry3::from_parts(Translation3::from(translation), rotation);
    Ok(())
}

fn centroids(pairs: &[(Point3<f64>, Point3<f64>)]) -> (Point3<f64>, Point3<f64>) {
    let a = se3::mean_point(pairs.iter().map(|p| p.0)).unwrap_or_else(Point3::origin);
    let b = se3::mean_point(pairs.iter().map(|p| p.1)).unwrap_or_else(Point3::origin);
    (a, b)
}

/// The rigid motion `T` minimising `Σ |T·a − b|²` (Kabsch); `None` for fewer than three
/// pairs or a degenerate (collinear) set.
pub fn register_points(pairs: &[(Point3<f64>, Point3<f64>)]) -> Option<Isometry3<f64>> {
    if pairs.len() < 3 {
        return None;
    }
    let (ca, cb) = centroids(pairs);
    let h: Matrix3<f64> = pairs
        .iter()
        .map(|(a, b)| (a - ca) * (b - cb).transpose())
        .sum();
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut sorted = svd.singular_values;
    sorted.as_mut_slice().sort_by(|x, y| y.total_cmp(x));
    if sorted[1] <= 1e-9 * sorted[0] {
        return None;
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rotation = UnitQuaternion::from_matrix(&r);
    let translation = cb.coords - rotation * ca.coords;
    Some(Isometry3::from_parts(
        Translation3::from(translation),
        rotation,
    ))
}

/// The needle length from the tip sphere: the robust mean of `(p_tip − p_r)·z_N`.
fn fit_needle_length(
    model: &mut BiopsyModel,
    tip: &[&Observation],
) -> Result<(), CalibrationError> {
    let l_n = model.robot.geometry.l_n;
    let mut lengths: Vec<f64> = tip
        .iter()
        .filter_map(|obs| {
            let measured = obs.tip?;
            let p = predict(model, obs).ok()?;
            let z = p.pose.direction.into_inner();
            let p_r = p.pose.tip - z * l_n;
            Some((measured - p_r).dot(&z))
        })
        .collect();
    if lengths.is_empty() {
        return Err(failure("no tip-phase frame for the needle length".into()));
    }
    model.robot.geometry.l_n = median(&mut lengths);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registration_recovers_a_known_motion_of_a_planar_set() {
        let truth = se3::isometry(
            Vector3::new(1.0, -2.0, 100.0),
            Vector3::new(0.01, -0.02, 0.3),
        );
        let pairs: Vec<_> = (0..20)
            .map(|k| {
                let a = Point3::new(
                    f64::from(k).cos() * 40.0,
                    f64::from(k * 3).sin() * 30.0,
                    15.0,
                );
                (a, truth * a)
            })
            .collect();
        let found = register_points(&pairs).unwrap();
        assert!((found.translation.vector - truth.translation.vector).norm() < 1e-9);
        assert!(found.rotation.angle_to(&truth.rotation) < 1e-12);
    }
}
