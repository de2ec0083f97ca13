//! Held-out validation of the biopsy model. The validation phase is never fitted; its
//! static holds give
//!
//! - the tip error against the tip sphere, when the recording has tip data there;
//! - the marker-derived tip error: the needle tip computed from the hold's mean marker poses
//!   (IK of the markers with the calibrated mountings) against the tip predicted from the
//!   encoders (sensitive to everything but the needle length);
//! - the held-out marker residuals.
//!
//! Without tip data in the validation phase, the tip error is estimated by cross-validation
//! over the tip phase (`fit::validation`).

use nalgebra::{Isometry3, Point3};

use crate::data::phases::Phase;
use crate::data::session::Observation;
use crate::math::se3;
use crate::math::stats::ErrorSummary;
use crate::model::biopsy::marker_ik::joints_from_markers;
use crate::model::biopsy::predict::{joint_angles, predict};
use crate::model::biopsy::BiopsyModel;
use crate::model::NoiseModel;

/// Count rate (counts/s) below which a validation frame counts as static.
const STATIC_RATE: f64 = 5.0;
/// Fewest frames of a hold.
const MIN_HOLD_FRAMES: usize = 3;

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
pub fn tip_sphere_error(model: &BiopsyModel, holds: &[Hold]) -> Option<ErrorSummary> {
    let errors: Vec<f64> = holds
        .iter()
        .filter_map(|h| {
            let measured: Point3<f64> = h.observation.tip?;
            Some((measured - predict(model, &h.observation).ok()?.pose.tip).norm())
        })
        .collect();
    ErrorSummary::of(&errors)
}

/// Tip from the hold's markers (via IK with the model's mountings) against the tip from its
/// encoders, per hold (mm). Holds whose markers cannot be inverted are skipped.
pub fn marker_tip_errors(model: &BiopsyModel, holds: &[Hold], noise: &NoiseModel) -> Vec<f64> {
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
