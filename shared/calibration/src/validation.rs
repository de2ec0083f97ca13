//! Held-out validation. The validation phase is never fitted; its static holds give
//!
//! - the tip error against the tip sphere, when the recording has tip data there;
//! - the marker-derived tip error: the needle tip computed from the hold's mean marker poses
//!   (IK of the markers with the calibrated mountings) against the tip predicted from the
//!   encoders (sensitive to everything but the needle length);
//! - the held-out marker residuals.
//!
//! Without tip data in the validation phase, the tip error is estimated by cross-validation
//! over contiguous folds of the tip phase: each fold's tip readings are left out, the joint
//! solution is updated without them (one Gauss–Newton step from the full solution, exact to
//! first order) and the left-out tips are predicted.

use nalgebra::{DMatrix, Isometry3, Point3};

use crate::joint_fit::JointFit;
use crate::layout::CalibModel;
use crate::marker_ik::joints_from_markers;
use crate::noise::NoiseModel;
use crate::observations::{Observation, Phase};
use crate::residuals::{joint_angles, predict, raw_block_residuals, Block, Quantity};
use crate::{se3, stats};

/// Count rate (counts/s) below which a validation frame counts as static.
const STATIC_RATE: f64 = 5.0;
/// Fewest frames of a hold.
const MIN_HOLD_FRAMES: usize = 3;
/// Folds of the tip-phase cross-validation.
pub const CROSS_VALIDATION_FOLDS: usize = 5;

/// Tip error summary (mm).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TipError {
    /// RMS of the 3-D tip error (mm).
    pub rms_mm: f64,
    /// Largest 3-D tip error (mm).
    pub max_mm: f64,
    /// Number of poses or readings it is taken over.
    pub count: usize,
}

impl TipError {
    /// Summary of 3-D errors (mm); `None` when there are none.
    pub fn of(errors: &[f64]) -> Option<Self> {
        (!errors.is_empty()).then(|| TipError {
            rms_mm: stats::rms(errors.iter().copied()),
            max_mm: errors.iter().copied().fold(0.0, f64::max),
            count: errors.len(),
        })
    }
}

/// One static validation hold: mean counts and marker poses over its frames.
#[derive(Debug, Clone, PartialEq)]
pub struct Hold {
    /// A synthetic observation with the hold's mean counts and poses.
    pub observation: Observation,
    /// Frames averaged.
    pub frames: usize,
}

/// Groups the static validation frames into holds (consecutive static frames at the same
/// counts, both markers seen).
pub fn validation_holds(observations: &[Observation]) -> Vec<Hold> {
    let is_static = |o: &Observation| {
        o.phase == Phase::Validation && o.count_rates.iter().all(|r| r.abs() < STATIC_RATE)
    };
    let mut holds = Vec::new();
    let mut run: Vec<&Observation> = Vec::new();
    let mut flush = |run: &mut Vec<&Observation>| {
        if run.len() >= MIN_HOLD_FRAMES {
            holds.push(mean_hold(run));
        }
        run.clear();
    };
    for obs in observations {
        let same_pose = run.last().is_none_or(|last: &&Observation| {
            last.counts
                .iter()
                .zip(&obs.counts)
                .all(|(a, b)| (a - b).abs() < 1.0)
        });
        if !is_static(obs) || !same_pose {
            flush(&mut run);
        }
        // A frame that misses a marker neither ends a hold nor joins it.
        if is_static(obs) && obs.front.is_some() && obs.back.is_some() {
            run.push(obs);
        }
    }
    flush(&mut run);
    holds
}

fn mean_hold(run: &[&Observation]) -> Hold {
    let n = run.len() as f64;
    let counts = std::array::from_fn(|j| run.iter().map(|o| o.counts[j]).sum::<f64>() / n);
    let fronts: Vec<Isometry3<f64>> = run.iter().filter_map(|o| o.front).collect();
    let backs: Vec<Isometry3<f64>> = run.iter().filter_map(|o| o.back).collect();
    let tip = se3::mean_point(run.iter().filter_map(|o| o.tip));
    let mut observation = run[0].clone();
    observation.counts = counts;
    observation.count_rates = [0.0; 5];
    observation.front = se3::mean_isometry(&fronts);
    observation.back = se3::mean_isometry(&backs);
    observation.tip = tip;
    Hold {
        observation,
        frames: run.len(),
    }
}

/// Tip error against the tip sphere at the holds that saw it; `None` without tip data.
pub fn tip_sphere_error(model: &CalibModel, holds: &[Hold]) -> Option<TipError> {
    let errors: Vec<f64> = holds
        .iter()
        .filter_map(|h| {
            let measured: Point3<f64> = h.observation.tip?;
            Some((measured - predict(model, &h.observation).ok()?.pose.tip).norm())
        })
        .collect();
    TipError::of(&errors)
}

/// Tip from the hold's markers (via IK with the model's mountings) against the tip from its
/// encoders, per hold (mm). Holds whose markers cannot be inverted are skipped.
pub fn marker_tip_errors(model: &CalibModel, holds: &[Hold], noise: &NoiseModel) -> Vec<f64> {
    let geometry = model.robot.effective_geometry();
    holds
        .iter()
        .filter_map(|h| {
            let obs = &h.observation;
            let predicted = predict(model, obs).ok()?;
            let from_markers = joints_from_markers(
                &geometry,
                &model.robot.markers,
                noise,
                obs.front.as_ref()?,
                obs.back.as_ref()?,
                joint_angles(model, obs),
            )?;
            Some((from_markers.pose.tip - predicted.pose.tip).norm())
        })
        .collect()
}

/// Cross-validated tip error over contiguous folds of the tip phase (see the module docs);
/// `None` without at least one tip reading per fold.
pub fn cross_validated_tip(fit: &JointFit) -> Option<TipError> {
    let tip_blocks: Vec<usize> = (0..fit.blocks.len())
        .filter(|&i| fit.blocks[i].quantity == Quantity::Tip && fit.weights[i] > 0.0)
        .collect();
    if tip_blocks.len() < CROSS_VALIDATION_FOLDS {
        return None;
    }
    let j = &fit.jacobian;
    let r = &fit.residual;
    let normal = j.transpose() * j;
    let x = fit.layout.values(&fit.model);
    let fold_len = tip_blocks.len().div_ceil(CROSS_VALIDATION_FOLDS);
    let mut errors = Vec::with_capacity(tip_blocks.len());
    for fold in tip_blocks.chunks(fold_len) {
        let rows: Vec<usize> = fold
            .iter()
            .flat_map(|&b| (0..3).map(move |k| fit.blocks[b].row + k))
            .collect();
        let j_fold = DMatrix::from_fn(rows.len(), j.ncols(), |a, c| j[(rows[a], c)]);
        let r_fold = nalgebra::DVector::from_fn(rows.len(), |a, _| r[rows[a]]);
        let reduced = &normal - j_fold.transpose() * &j_fold;
        let step = reduced.cholesky()?.solve(&(j_fold.transpose() * r_fold));
        let mut model = fit.model.clone();
        fit.layout.apply(&mut model, &(&x + step));
        let blocks: Vec<Block> = fold.iter().map(|&b| fit.blocks[b]).collect();
        for raw in raw_block_residuals(&model, &fit.observations, &blocks)
            .into_iter()
            .flatten()
        {
            errors.push((raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2]).sqrt());
        }
    }
    TipError::of(&errors)
}

/// Standard deviation (RMS over the 3 axes ×√3, i.e. of the 3-D error, mm) of the tip
/// predicted at each hold, from the joint fit's parameter covariance.
pub fn predicted_tip_std(fit: &JointFit, holds: &[Hold]) -> Vec<f64> {
    let ids = &fit.layout.ids;
    let n = ids.len();
    let sigma = &fit.analysis.std_devs;
    if sigma.iter().any(|s| !s.is_finite()) {
        return Vec::new();
    }
    let covariance = DMatrix::from_fn(n, n, |a, b| {
        fit.analysis.correlation[(a, b)] * sigma[a] * sigma[b]
    });
    holds
        .iter()
        .filter_map(|h| {
            let base = predict(&fit.model, &h.observation).ok()?.pose.tip;
            let mut jacobian = DMatrix::<f64>::zeros(3, n);
            for (k, id) in ids.iter().enumerate() {
                let mut shifted = fit.model.clone();
                id.set(&mut shifted, id.get(&fit.model) + id.step());
                let tip = predict(&shifted, &h.observation).ok()?.pose.tip;
                let d = (tip - base) / id.step();
                jacobian.set_column(k, &d);
            }
            Some(
                (&jacobian * &covariance * jacobian.transpose())
                    .trace()
                    .max(0.0)
                    .sqrt(),
            )
        })
        .collect()
}
