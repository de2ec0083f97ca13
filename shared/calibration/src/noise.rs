//! The tracker noise of the robot tools (relative to the base marker, in `Bb`): estimated
//! from the static homing dwell, re-estimated from the fit residuals, used to whiten them.

use nalgebra::{Matrix3, Vector3};

use crate::observations::Observation;
use crate::residuals::Quantity;
use crate::se3;

/// Noise of one tool: position covariance (mm², in `Bb`) and rotation noise (rad per axis).
#[derive(Debug, Clone, PartialEq)]
pub struct ToolNoise {
    /// Position covariance (mm²).
    pub position_covariance: Matrix3<f64>,
    /// Rotation noise, standard deviation per axis (rad).
    pub rotation_sigma: f64,
    whitener: Matrix3<f64>,
}

/// Smallest position standard deviation (mm) and rotation standard deviation (rad) a noise
/// model accepts (keeps the whitening finite on perfect synthetic data).
const MIN_POSITION_SIGMA: f64 = 1e-3;
const MIN_ROTATION_SIGMA: f64 = 1e-5;

impl ToolNoise {
    /// Isotropic noise: `position_sigma` mm, `rotation_sigma` rad.
    pub fn isotropic(position_sigma: f64, rotation_sigma: f64) -> Self {
        Self::new(Matrix3::identity() * position_sigma.powi(2), rotation_sigma)
    }

    /// Noise with a full position covariance (mm²); regularised to stay positive definite.
    pub fn new(position_covariance: Matrix3<f64>, rotation_sigma: f64) -> Self {
        let floor = Matrix3::identity() * MIN_POSITION_SIGMA.powi(2);
        let symmetric = (position_covariance + position_covariance.transpose()) * 0.5 + floor;
        let whitener = symmetric
            .cholesky()
            .and_then(|c| c.l().try_inverse())
            .unwrap_or_else(|| Matrix3::identity() / MIN_POSITION_SIGMA);
        Self {
            position_covariance: symmetric,
            rotation_sigma: rotation_sigma.max(MIN_ROTATION_SIGMA),
            whitener,
        }
    }

    /// RMS position noise per axis (mm).
    pub fn position_sigma(&self) -> f64 {
        (self.position_covariance.trace() / 3.0).sqrt()
    }

    /// Whitens a raw residual in place (first `dim` entries).
    pub fn whiten(&self, raw: &[f64; 6], dim: usize, out: &mut [f64]) {
        let p = self.whitener * Vector3::new(raw[0], raw[1], raw[2]);
        out[..3].copy_from_slice(p.as_slice());
        if dim == 6 {
            for k in 0..3 {
                out[3 + k] = raw[3 + k] / self.rotation_sigma;
            }
        }
    }
}

/// Tracker noise of the three robot tools, measured relative to the base marker.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseModel {
    /// Front marker.
    pub front: ToolNoise,
    /// Back marker.
    pub back: ToolNoise,
    /// Tip sphere (position only).
    pub tip: ToolNoise,
}

impl NoiseModel {
    /// A Polaris Vicra-like default: 0.25 mm per axis on each tool and the base marker
    /// (hence √2 · 0.25 relative), 0.1° rotation noise per tool.
    pub fn vicra_default() -> Self {
        let relative = 0.25 * std::f64::consts::SQRT_2;
        let rotation = (0.1f64).to_radians() * std::f64::consts::SQRT_2;
        Self {
            front: ToolNoise::isotropic(relative, rotation),
            back: ToolNoise::isotropic(relative, rotation),
            tip: ToolNoise::isotropic(relative, rotation),
        }
    }

    /// The noise of a quantity.
    pub fn of(&self, quantity: Quantity) -> &ToolNoise {
        match quantity {
            Quantity::Front => &self.front,
            Quantity::Back => &self.back,
            Quantity::Tip => &self.tip,
        }
    }
}

/// Fewest static frames for a noise estimate.
const MIN_STATIC_FRAMES: usize = 5;

impl NoiseModel {
    /// Noise from frames taken with the robot at rest (e.g. the homing dwell): the scatter of
    /// each marker pose. The tip sphere (not seen at rest) gets the front marker's noise.
    /// `None` with fewer than 5 frames seeing both markers.
    pub fn from_static(frames: &[&Observation]) -> Option<Self> {
        let both: Vec<_> = frames
            .iter()
            .filter_map(|o| Some((o.front?, o.back?)))
            .collect();
        if both.len() < MIN_STATIC_FRAMES {
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
            Some(ToolNoise::new(se3::covariance(&positions)?, rotation_sigma))
        };
        let front = tool(both.iter().map(|(f, _)| *f).collect())?;
        let back = tool(both.iter().map(|(_, b)| *b).collect())?;
        Some(Self {
            tip: front.clone(),
            front,
            back,
        })
    }

    /// Re-estimates each quantity's noise from raw residuals `(quantity, raw, weight)` (the
    /// weighted second moment); a quantity with fewer than 5 residuals keeps its noise.
    pub fn from_residuals<'a>(
        &self,
        residuals: impl Iterator<Item = (Quantity, &'a [f64; 6], f64)>,
    ) -> Self {
        let mut sums = [(Matrix3::zeros(), 0.0, 0.0, 0usize); 3];
        for (quantity, raw, weight) in residuals {
            let slot = &mut sums[quantity as usize];
            let p = Vector3::new(raw[0], raw[1], raw[2]);
            slot.0 += p * p.transpose() * weight;
            slot.1 += (raw[3] * raw[3] + raw[4] * raw[4] + raw[5] * raw[5]) * weight / 3.0;
            slot.2 += weight;
            slot.3 += 1;
        }
        let update = |quantity: Quantity, old: &ToolNoise| {
            let (covariance, rotation, weight, count) = sums[quantity as usize];
            if count < MIN_STATIC_FRAMES || weight <= 0.0 {
                return old.clone();
            }
            let rotation_sigma = if quantity == Quantity::Tip {
                old.rotation_sigma
            } else {
                (rotation / weight).sqrt()
            };
            ToolNoise::new(covariance / weight, rotation_sigma)
        };
        Self {
            front: update(Quantity::Front, &self.front),
            back: update(Quantity::Back, &self.back),
            tip: update(Quantity::Tip, &self.tip),
        }
    }
}
