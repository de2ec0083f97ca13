//! The tracker noise of the robot tools (relative to the base marker, in `Bb`): a Polaris
//! Vicra-like default, and the scatter measured with the robot at rest.

use nalgebra::Vector3;

use crate::data::session::Observation;
use crate::math::se3;
use crate::model::noise::MIN_RESIDUALS;
use crate::model::{NoiseModel, QuantityNoise};

/// A Polaris Vicra-like default for front, back and tip: 0.25 mm per axis on each tool and
/// the base marker (hence √2 · 0.25 relative), 0.1° rotation noise per tool.
pub fn vicra_default() -> NoiseModel {
    let relative = 0.25 * std::f64::consts::SQRT_2;
    let rotation = (0.1f64).to_radians() * std::f64::consts::SQRT_2;
    NoiseModel {
        kinds: vec![QuantityNoise::isotropic(relative, rotation); 3],
    }
}

/// Noise from frames taken with the robot at rest (e.g. the homing dwell): the scatter of
/// each marker pose. The tip sphere (not seen at rest) gets the front marker's noise.
/// `None` with fewer than 5 frames seeing both markers.
pub fn from_static(frames: &[&Observation]) -> Option<NoiseModel> {
    let both: Vec<_> = frames
        .iter()
        .filter_map(|o| Some((o.front?, o.back?)))
        .collect();
    if both.len() < MIN_RESIDUALS {
        return None;
    }
    let tool = |poses: Vec<nalgebra::Isometry3<f64>>| {
        let mean = se3::mean_isometry(&poses)?;
        let positions: Vec<Vector3<f64>> = poses.iter().map(|p| p.translation.vector).collect();
        let rotations: Vec<f64> = poses
            .iter()
            .map(|p| se3::rotation_log(&(p.rotation * mean.rotation.inverse())).norm_squared())
            .collect();
        let rotation_sigma =
            (rotations.iter().sum::<f64>() / (3.0 * (poses.len() - 1) as f64)).sqrt();
        Some(QuantityNoise::new(
            se3::covariance(&positions)?,
            rotation_sigma,
        ))
    };
    let front = tool(both.iter().map(|(f, _)| *f).collect())?;
    let back = tool(both.iter().map(|(_, b)| *b).collect())?;
    Some(NoiseModel {
        kinds: vec![front.clone(), back, front],
    })
}
