//! Model-free temporal calibration (in the spirit of the PLUS toolkit): the delay between the
//! exposure clock and the encoder stream that best explains the marker motion. For each
//! candidate delay the marker poses are regressed on a quadratic polynomial of the encoder
//! counts at the shifted times; the delay with the smallest residual wins (coarse grid, fine
//! grid, parabolic refinement). No robot parameters are needed, so it runs before any fit;
//! the joint fit refines the latency afterwards.

use nalgebra::{DMatrix, Vector3};

use crate::data::phases::Phase;
use crate::data::session::SessionData;
use crate::error::CalibrationError;
use crate::math::se3;

/// Searched delays (s): coarse grid.
const COARSE_FROM: f64 = -0.05;
const COARSE_TO: f64 = 0.30;
const COARSE_STEP: f64 = 0.005;
/// Fine grid step (s) around the coarse minimum.
const FINE_STEP: f64 = 0.0005;
/// Weight of a rotation residual (mm per rad) against a position residual.
const ROTATION_WEIGHT_MM: f64 = 100.0;
/// Fewest frames for the regression.
const MIN_FRAMES: usize = 50;
/// Regressors: 1, 5 linear, 15 quadratic.
const FEATURES: usize = 21;
/// Outputs: front and back marker position and rotation.
const OUTPUTS: usize = 12;
/// Longest encoder gap (ns) the search interpolates across. A frame takes part only if the
/// encoder stream covers it at every searched delay (a 350 ms window), and a live encoder
/// stream on a loaded 2-core machine misses a period or several every few hundred ms: with
/// the fit's own limit (a few ms) most frames would drop out. A quadratic regression over a
/// whole phase is insensitive to the interpolation error across a gap this long.
const SEARCH_MAX_GAP_NS: i64 = 25_000_000;

/// Result of the model-free latency search.
#[derive(Debug, Clone, PartialEq)]
pub struct LatencyEstimate {
    /// Delay (s) from the exposure clock line back to the exposure.
    pub latency_s: f64,
    /// Frames used.
    pub frames: usize,
    /// RMS regression residual at the optimum (mm-equivalent).
    pub rms: f64,
}

/// Estimates the delay from the excitation frames in which both markers are seen.
pub fn estimate(data: &SessionData) -> Result<LatencyEstimate, CalibrationError> {
    let coarse: Vec<f64> = grid(COARSE_FROM, COARSE_TO, COARSE_STEP);
    let selected: Vec<usize> = (0..data.frames.len())
        .filter(|&i| {
            let f = &data.frames[i];
            f.front.is_some()
                && f.back.is_some()
                && data.phases.at(data.exposure_ns(i, 0.05)) == Phase::Excitation
                && coarse.iter().all(|d| {
                    data.encoders
                        .counts_bridging(data.exposure_ns(i, *d), SEARCH_MAX_GAP_NS)
                        .is_some()
                })
        })
        .collect();
    if selected.len() < MIN_FRAMES {
        return Err(CalibrationError::InsufficientData {
            phase: "excitation",
            reason: format!(
                "{} frames with both markers seen and encoder data, need at least {MIN_FRAMES} \
                 for the latency estimate",
                selected.len()
            ),
        });
    }
    let outputs = marker_outputs(data, &selected);
    let scaling = count_scaling(data, &selected);
    let cost = |d: f64| regression_rss(data, &selected, &outputs, &scaling, d);
    let coarse_costs: Vec<f64> = coarse.iter().map(|d| cost(*d)).collect();
    let best = argmin(&coarse_costs);
    if best == 0 || best + 1 == coarse.len() {
        return Err(CalibrationError::TimeSync(format!(
            "the best delay lies at the edge of the searched range {:.0}..{:.0} ms: the motion \
             does not determine the tracker latency",
            COARSE_FROM * 1e3,
            COARSE_TO * 1e3
        )));
    }
    let fine = grid(
        coarse[best] - COARSE_STEP,
        coarse[best] + COARSE_STEP,
        FINE_STEP,
    );
    let fine_costs: Vec<f64> = fine.iter().map(|d| cost(*d)).collect();
    let k = argmin(&fine_costs).clamp(1, fine.len() - 2);
    let latency_s = fine[k] + parabola_vertex(&fine_costs[k - 1..=k + 1]) * FINE_STEP;
    let rms = (cost(latency_s) / (selected.len() * OUTPUTS) as f64).sqrt();
    Ok(LatencyEstimate {
        latency_s,
        frames: selected.len(),
        rms,
    })
}

fn grid(from: f64, to: f64, step: f64) -> Vec<f64> {
    let n = ((to - from) / step).round() as usize;
    (0..=n).map(|k| from + k as f64 * step).collect()
}

fn argmin(values: &[f64]) -> usize {
    values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(i, _)| i)
}

/// Offset (in grid steps, within ±1) of the vertex of the parabola through three equally
/// spaced values.
pub fn parabola_vertex(y: &[f64]) -> f64 {
    let curvature = y[0] - 2.0 * y[1] + y[2];
    if curvature <= 0.0 {
        return 0.0;
    }
    (0.5 * (y[0] - y[2]) / curvature).clamp(-1.0, 1.0)
}

/// Centred marker outputs (mm, rotations scaled to mm) of the selected frames.
fn marker_outputs(data: &SessionData, selected: &[usize]) -> DMatrix<f64> {
    let first = &data.frames[selected[0]];
    let (front_ref, back_ref) = (
        first.front.unwrap_or_default(),
        first.back.unwrap_or_default(),
    );
    let mut y = DMatrix::zeros(selected.len(), OUTPUTS);
    for (row, &i) in selected.iter().enumerate() {
        let frame = &data.frames[i];
        for (tool, (pose, reference)) in [(frame.front, front_ref), (frame.back, back_ref)]
            .into_iter()
            .enumerate()
        {
            let pose = pose.unwrap_or_default();
            let rotation: Vector3<f64> =
                se3::rotation_log(&(pose.rotation * reference.rotation.inverse()))
                    * ROTATION_WEIGHT_MM;
            for a in 0..3 {
                y[(row, 6 * tool + a)] = pose.translation.vector[a];
                y[(row, 6 * tool + 3 + a)] = rotation[a];
            }
        }
    }
    for mut column in y.column_iter_mut() {
        let mean = column.mean();
        column.add_scalar_mut(-mean);
    }
    y
}

/// Mean and standard deviation of each joint's counts (at zero delay) for conditioning.
fn count_scaling(data: &SessionData, selected: &[usize]) -> [(f64, f64); 5] {
    let counts: Vec<[f64; 5]> = selected
        .iter()
        .filter_map(|&i| {
            data.encoders
                .counts_bridging(data.exposure_ns(i, 0.0), SEARCH_MAX_GAP_NS)
        })
        .collect();
    std::array::from_fn(|j| {
        let n = counts.len().max(1) as f64;
        let mean = counts.iter().map(|c| c[j]).sum::<f64>() / n;
        let var = counts.iter().map(|c| (c[j] - mean).powi(2)).sum::<f64>() / n;
        (mean, var.sqrt().max(1.0))
    })
}

/// Residual sum of squares of the quadratic regression of the outputs on the counts at
/// delay `d`; infinite when a frame has no encoder data or the regression is singular.
fn regression_rss(
    data: &SessionData,
    selected: &[usize],
    outputs: &DMatrix<f64>,
    scaling: &[(f64, f64); 5],
    d: f64,
) -> f64 {
    let mut xtx = DMatrix::<f64>::zeros(FEATURES, FEATURES);
    let mut xty = DMatrix::<f64>::zeros(FEATURES, OUTPUTS);
    let mut features = [0.0; FEATURES];
    for (row, &i) in selected.iter().enumerate() {
        let Some(counts) = data
            .encoders
            .counts_bridging(data.exposure_ns(i, d), SEARCH_MAX_GAP_NS)
        else {
            return f64::INFINITY;
        };
        let z: [f64; 5] = std::array::from_fn(|j| (counts[j] - scaling[j].0) / scaling[j].1);
        features[0] = 1.0;
        features[1..6].copy_from_slice(&z);
        let mut k = 6;
        for a in 0..5 {
            for b in a..5 {
                features[k] = z[a] * z[b];
                k += 1;
            }
        }
        for a in 0..FEATURES {
            for b in a..FEATURES {
                xtx[(a, b)] += features[a] * features[b];
            }
            for o in 0..OUTPUTS {
                xty[(a, o)] += features[a] * outputs[(row, o)];
            }
        }
    }
    for a in 0..FEATURES {
        for b in 0..a {
            xtx[(a, b)] = xtx[(b, a)];
        }
    }
    let Some(cholesky) = xtx.cholesky() else {
        return f64::INFINITY;
    };
    let beta = cholesky.solve(&xty);
    outputs.norm_squared() - beta.component_mul(&xty).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parabola_vertex_of_a_shifted_parabola() {
        let f = |x: f64| (x - 0.3).powi(2) + 2.0;
        let v = parabola_vertex(&[f(-1.0), f(0.0), f(1.0)]);
        assert!((v - 0.3).abs() < 1e-12);
    }
}
