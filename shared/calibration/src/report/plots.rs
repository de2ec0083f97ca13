//! The data of the report's residual plots: the residual of every frame expressed as joint
//! errors (the joint angles that best explain it) against the joint angles, and the
//! histogram of the residual whitened by the tracker noise at rest.

use nalgebra::{DMatrix, Matrix5, Vector5};

use crate::fit::joint_fit::JointFit;
use crate::model::biopsy::candidates::joint_derivatives;
use crate::model::biopsy::predict::joint_angles;
use crate::model::biopsy::BiopsyModel;
use crate::model::NoiseModel;
use crate::report::hysteresis::{HysteresisDiagnostic, MotionSample};

/// Most points kept per scatter plot.
const MAX_POINTS: usize = 800;
/// Bins of the binned means along each joint angle.
const MEAN_BINS: usize = 16;
/// Fewest frames for a binned mean.
const MIN_BIN_FRAMES: usize = 5;
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
    /// Per joint: the plotted frames (a subsample), where the joint error is the
    /// least-squares joint change that would explain the frame's residual (both markers
    /// seen).
    pub joint_errors: [Vec<JointErrorPoint>; 5],
    /// Per joint and direction of motion ([`JointErrorPoint::class`]): the mean joint error
    /// (mrad) in bins of the joint angle (rad), over all frames.
    pub binned_means: [[Vec<(f64, f64)>; 3]; 5],
    /// Density of the whitened residual components in each bin from [`HISTOGRAM_LOW`].
    pub density: Vec<f64>,
    /// Share of components outside the histogram range.
    pub outside: f64,
    /// RMS of the whitened residual components (1 = tracker noise).
    pub whitened_rms: f64,
    /// Per joint: the joint errors per direction of motion and along the travel since the
    /// last reversal.
    pub hysteresis: [HysteresisDiagnostic; 5],
}

/// One frame in a joint-error plot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointErrorPoint {
    /// Joint angle (rad).
    pub angle: f64,
    /// Joint error (mrad).
    pub error_mrad: f64,
    /// Direction of motion of the joint: 0 moving down, 1 moving up, 2 unknown.
    pub class: usize,
}

fn direction_class(direction: f64) -> usize {
    if direction < 0.0 {
        0
    } else if direction > 0.0 {
        1
    } else {
        2
    }
}

/// Means of `points` in [`MEAN_BINS`] equal bins of the angle, per direction class; bins
/// with fewer than [`MIN_BIN_FRAMES`] frames are left out.
fn binned_means(points: &[JointErrorPoint]) -> [Vec<(f64, f64)>; 3] {
    let (low, high) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.angle), b.max(p.angle))
        });
    let width = (high - low) / MEAN_BINS as f64;
    std::array::from_fn(|class| {
        if width.is_nan() || width <= 0.0 {
            return Vec::new();
        }
        let mut sums = [(0.0, 0.0, 0usize); MEAN_BINS];
        for p in points.iter().filter(|p| p.class == class) {
            let bin = (((p.angle - low) / width) as usize).min(MEAN_BINS - 1);
            sums[bin].0 += p.angle;
            sums[bin].1 += p.error_mrad;
            sums[bin].2 += 1;
        }
        sums.iter()
            .filter(|s| s.2 >= MIN_BIN_FRAMES)
            .map(|s| (s.0 / s.2 as f64, s.1 / s.2 as f64))
            .collect()
    })
}

/// The pictures before (paper model) and after (final model) the loop.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plots {
    /// The paper model.
    pub before: Option<ResidualPicture>,
    /// The final model (only when effects were added).
    pub after: Option<ResidualPicture>,
}

/// The picture of `fit` (labelled `label`) against the tracker noise at rest.
pub fn picture(
    label: &str,
    fit: &JointFit<BiopsyModel>,
    rest_noise: &NoiseModel,
) -> ResidualPicture {
    let joint_derivatives: DMatrix<f64> = joint_derivatives(&fit.model, &fit.problem());
    let mut all: [Vec<JointErrorPoint>; 5] = Default::default();
    let mut motion_samples: [Vec<MotionSample>; 5] = Default::default();
    let scale = fit.model.robot.encoder_scale();
    for group in fit.blocks.chunk_by(|a, b| a.obs == b.obs) {
        if group.len() < 2 {
            continue;
        }
        let mut normal = Matrix5::zeros();
        let mut product = Vector5::zeros();
        for block in group {
            for row in block.row..block.row + block.dim {
                let d = Vector5::from_fn(|j, _| joint_derivatives[(row, j)]);
                normal += d * d.transpose();
                product += d * fit.residual[row];
            }
        }
        let Some(solved) = normal.cholesky().map(|c| c.solve(&product)) else {
            continue;
        };
        let obs = &fit.observations[group[0].obs];
        let q = joint_angles(&fit.model, obs);
        let counts = obs.counts_at_latency(fit.model.latency_s);
        for (j, points) in all.iter_mut().enumerate() {
            points.push(JointErrorPoint {
                angle: q[j],
                error_mrad: -solved[j] * 1e3,
                class: direction_class(obs.motion.direction[j]),
            });
            let joint_per_count = scale.gear_ratio[j].abs() * scale.motor_rad_per_count[j];
            motion_samples[j].push(MotionSample {
                error_mrad: -solved[j] * 1e3,
                direction: obs.motion.direction[j],
                travel_mrad: obs
                    .motion
                    .travel_since_turn(j, counts[j])
                    .map(|c| c * joint_per_count * 1e3),
            });
        }
    }
    let binned_means = std::array::from_fn(|j| binned_means(&all[j]));
    let stride = all[0].len().div_ceil(MAX_POINTS).max(1);
    let joint_errors = all.map(|points| points.into_iter().step_by(stride).collect());
    let raws = fit.problem().raw_residuals(&fit.model);
    let mut counts = vec![0usize; HISTOGRAM_BINS];
    let (mut total, mut outside, mut sum) = (0usize, 0usize, 0.0);
    for (block, raw) in fit.blocks.iter().zip(&raws) {
        let Some(raw) = raw else { continue };
        let dim = block.dim;
        let mut white = [0.0; 6];
        rest_noise.of(block.kind).whiten(raw, dim, &mut white);
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
        binned_means,
        density: counts
            .iter()
            .map(|c| *c as f64 / (n * HISTOGRAM_BIN))
            .collect(),
        outside: outside as f64 / n,
        whitened_rms: (sum / n).sqrt(),
        hysteresis: std::array::from_fn(|j| HysteresisDiagnostic::of(j, &motion_samples[j])),
    }
}
