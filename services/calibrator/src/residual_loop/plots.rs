//! The data of the report's residual plots: the residual of every frame expressed as joint
//! errors (the joint angles that best explain it) against the joint angles, and the
//! histogram of the residual whitened by the tracker noise at rest.

use nalgebra::{DMatrix, Matrix5, Vector5};

use crate::joint_fit::JointFit;
use crate::noise::NoiseModel;
use crate::residuals::{joint_angles, raw_block_residuals};

/// Most points kept per scatter plot.
const MAX_POINTS: usize = 800;
/// Histogram range (in units of the tracker noise) and bin width.
pub const HISTOGRAM_LOW: f64 = -6.0;
/// Bin width of the histogram.
pub const HISTOGRAM_BIN: f64 = 0.25;
const HISTOGRAM_BINS: usize = 48;

/// The residual of one model, ready to plot.
#[derive(Debug, Clone, PartialEq)]
pub struct ResidualPicture {
    /// Model label.
    pub label: String,
    /// Per joint: `(joint angle rad, joint error mrad)` of each plotted frame, where the
    /// joint error is the least-squares joint change that would explain the frame's
    /// residual (both markers seen).
    pub joint_errors: [Vec<(f64, f64)>; 5],
    /// Density of the whitened residual components in each bin from [`HISTOGRAM_LOW`].
    pub density: Vec<f64>,
    /// Share of components outside the histogram range.
    pub outside: f64,
    /// RMS of the whitened residual components (1 = tracker noise).
    pub whitened_rms: f64,
}

/// The pictures before (paper model) and after (final model) the loop.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plots {
    /// The paper model.
    pub before: Option<ResidualPicture>,
    /// The final model (only when effects were added).
    pub after: Option<ResidualPicture>,
}

/// The picture of `fit`, with `joint_derivatives` (`∂r/∂q_j` of every row) and the tracker
/// noise at rest.
pub fn picture(
    label: &str,
    fit: &JointFit,
    joint_derivatives: &DMatrix<f64>,
    rest_noise: &NoiseModel,
) -> ResidualPicture {
    let mut joint_errors: [Vec<(f64, f64)>; 5] = Default::default();
    let groups: Vec<_> = fit.blocks.chunk_by(|a, b| a.obs == b.obs).collect();
    let stride = groups.len().div_ceil(MAX_POINTS).max(1);
    for group in groups.iter().step_by(stride) {
        if group.len() < 2 {
            continue;
        }
        let mut normal = Matrix5::zeros();
        let mut product = Vector5::zeros();
        for block in *group {
            for row in block.row..block.row + block.quantity.dim() {
                let d = Vector5::from_fn(|j, _| joint_derivatives[(row, j)]);
                normal += d * d.transpose();
                product += d * fit.residual[row];
            }
        }
        let Some(solved) = normal.cholesky().map(|c| c.solve(&product)) else {
            continue;
        };
        let q = joint_angles(&fit.model, &fit.observations[group[0].obs]);
        for (j, points) in joint_errors.iter_mut().enumerate() {
            points.push((q[j], -solved[j] * 1e3));
        }
    }
    let raws = raw_block_residuals(&fit.model, &fit.observations, &fit.blocks);
    let mut counts = vec![0usize; HISTOGRAM_BINS];
    let (mut total, mut outside, mut sum) = (0usize, 0usize, 0.0);
    for (block, raw) in fit.blocks.iter().zip(&raws) {
        let Some(raw) = raw else { continue };
        let dim = block.quantity.dim();
        let mut white = [0.0; 6];
        rest_noise.of(block.quantity).whiten(raw, dim, &mut white);
        for v in &white[..dim] {
            total += 1;
            sum += v * v;
            let bin = ((v - HISTOGRAM_LOW) / HISTOGRAM_BIN).floor();
            if bin >= 0.0 && (bin as usize) < HISTOGRAM_BINS {
                counts[bin as usize] += 1;
            } else {
                outside += 1;
            }
        }
    }
    let n = total.max(1) as f64;
    ResidualPicture {
        label: label.into(),
        joint_errors,
        density: counts
            .iter()
            .map(|c| *c as f64 / (n * HISTOGRAM_BIN))
            .collect(),
        outside: outside as f64 / n,
        whitened_rms: (sum / n).sqrt(),
    }
}
