//! The measurement noise of each quantity kind: it whitens the residuals, and the fits
//! re-estimate it from them.

use nalgebra::{Matrix3, Vector3};

use crate::model::blocks::{Block, QuantityKind};

/// Noise of one quantity kind: position covariance (mm², in the frame the residuals are
/// expressed in) and rotation noise (rad per axis; unused for points).
#[derive(Debug, Clone, PartialEq)]
pub struct QuantityNoise {
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

impl QuantityNoise {
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

/// The noise of every quantity kind of a model, indexed by [`QuantityKind`].
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseModel {
    /// Noise per kind.
    pub kinds: Vec<QuantityNoise>,
}

/// Fewest residuals of a kind for its noise to be re-estimated.
pub const MIN_RESIDUALS: usize = 5;

impl NoiseModel {
    /// The noise of a kind.
    pub fn of(&self, kind: QuantityKind) -> &QuantityNoise {
        &self.kinds[kind.0]
    }

    /// Whitens the raw residual of `block` into `out[..block.dim]`: by the block's own
    /// standard deviations when it has them, else by the noise of its kind.
    pub fn whiten(&self, block: &Block, raw: &[f64; 6], out: &mut [f64]) {
        match &block.sigma {
            Some(sigma) => {
                for k in 0..block.dim {
                    out[k] = raw[k] / sigma[k];
                }
            }
            None => self.of(block.kind).whiten(raw, block.dim, out),
        }
    }

    /// Re-estimates each kind's noise from raw residuals `(block, raw, weight)` (the
    /// weighted second moment); a kind with fewer than [`MIN_RESIDUALS`] residuals keeps its
    /// noise, and a point kind keeps its rotation noise.
    pub fn from_residuals<'a>(
        &self,
        residuals: impl Iterator<Item = (&'a Block, &'a [f64; 6], f64)>,
    ) -> Self {
        let mut sums = vec![(Matrix3::zeros(), 0.0, 0.0, 0usize, 6usize); self.kinds.len()];
        for (block, raw, weight) in residuals {
            let slot = &mut sums[block.kind.0];
            let p = Vector3::new(raw[0], raw[1], raw[2]);
            slot.0 += p * p.transpose() * weight;
            slot.1 += (raw[3] * raw[3] + raw[4] * raw[4] + raw[5] * raw[5]) * weight / 3.0;
            slot.2 += weight;
            slot.3 += 1;
            slot.4 = block.dim;
        }
        let kinds = self
            .kinds
            .iter()
            .zip(&sums)
            .map(|(old, &(covariance, rotation, weight, count, dim))| {
                if count < MIN_RESIDUALS || weight <= 0.0 {
                    return old.clone();
                }
                let rotation_sigma = if dim == 6 {
                    (rotation / weight).sqrt()
                } else {
                    old.rotation_sigma
                };
                QuantityNoise::new(covariance / weight, rotation_sigma)
            })
            .collect();
        Self { kinds }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(kind: usize, dim: usize, sigma: Option<[f64; 6]>) -> Block {
        Block {
            obs: 0,
            kind: QuantityKind(kind),
            dim,
            row: 0,
            sigma,
        }
    }

    #[test]
    fn per_measurement_sigmas_override_the_noise_of_the_kind() {
        let noise = NoiseModel {
            kinds: vec![QuantityNoise::isotropic(0.5, 0.01)],
        };
        let raw = [1.0, -2.0, 0.5, 0.02, 0.0, -0.01];
        let mut out = [0.0; 6];
        noise.whiten(&block(0, 6, None), &raw, &mut out);
        assert!((out[0] - 2.0).abs() < 1e-3 && (out[3] - 2.0).abs() < 1e-9);
        let own = [0.1, 0.2, 0.25, 0.01, 0.01, 0.02];
        noise.whiten(&block(0, 3, Some(own)), &raw, &mut out);
        assert_eq!(out[..3], [10.0, -10.0, 2.0]);
    }

    #[test]
    fn noise_is_re_estimated_per_kind_from_weighted_residuals() {
        let noise = NoiseModel {
            kinds: vec![
                QuantityNoise::isotropic(1.0, 0.1),
                QuantityNoise::isotropic(1.0, 0.1),
            ],
        };
        let pose = block(0, 6, None);
        let point = block(1, 3, None);
        let raws: Vec<[f64; 6]> = (0..40)
            .map(|k| {
                let s: f64 = if k % 2 == 0 { 0.2 } else { -0.2 };
                [s, -s, s, 0.003 * s.signum(), 0.003, -0.003]
            })
            .collect();
        let items = raws
            .iter()
            .map(|r| (&pose, r, 1.0))
            .chain(raws.iter().take(3).map(|r| (&point, r, 1.0)));
        let updated = noise.from_residuals(items);
        assert!((updated.kinds[0].position_sigma() - 0.2).abs() < 1e-3);
        assert!((updated.kinds[0].rotation_sigma - 0.003).abs() < 1e-9);
        assert_eq!(updated.kinds[1], noise.kinds[1], "too few point residuals");
    }
}
