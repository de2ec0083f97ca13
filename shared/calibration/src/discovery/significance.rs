//! Is what is left just noise? The tail probabilities the loop's tests need, and the test of
//! a fit's residual against the tracker noise measured with the robot at rest.
//!
//! The residual of each tested quantity kind is whitened by the noise measured at rest (for
//! the biopsy robot the static homing dwell), not by the noise re-estimated from the fit,
//! which would absorb any structure. Its variance
//! per degree of freedom, against 1, is an F ratio: both the residual and the reference
//! variance are estimates, with `dof` and `reference_dof` degrees of freedom. The test uses
//! `ln F ≈ N(0, 2/dof + 2/reference_dof)`.

use serde::Serialize;

use crate::fit::joint_fit::JointFit;
use crate::model::{NoiseModel, QuantityKind, RobotModel};

/// Upper tail `P(Z > z)` of the standard normal (erfc approximation, relative error below
/// 1.2e-7).
pub fn normal_tail(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let value = t * poly.exp();
    if x >= 0.0 {
        value
    } else {
        2.0 - value
    }
}

/// Upper tail `P(χ²_k > x)`: exact for k = 1 and 2, Wilson–Hilferty otherwise.
pub fn chi2_tail(x: f64, k: usize) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    match k {
        0 | 1 => return 2.0 * normal_tail(x.sqrt()),
        2 => return (-0.5 * x).exp(),
        _ => {}
    }
    let k = k as f64;
    let a = 2.0 / (9.0 * k);
    normal_tail(((x / k).cbrt() - (1.0 - a)) / a.sqrt())
}

/// The value `x` with `P(χ²_k > x) = p` (bisection on [`chi2_tail`]).
pub fn chi2_quantile(p: f64, k: usize) -> f64 {
    let (mut low, mut high) = (0.0, 1.0);
    while chi2_tail(high, k) > p {
        high *= 2.0;
    }
    for _ in 0..100 {
        let mid = 0.5 * (low + high);
        if chi2_tail(mid, k) > p {
            low = mid;
        } else {
            high = mid;
        }
    }
    0.5 * (low + high)
}

/// Significance level of the test against the tracker noise.
pub const NOISE_TEST_LEVEL: f64 = 1e-3;

/// The residual of one quantity kind against the noise at rest.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseTest {
    /// The quantity kind's name (e.g. `front`).
    pub tool: String,
    /// Residual variance per degree of freedom, whitened by the tracker noise at rest
    /// (1 = tracker noise only).
    pub variance_ratio: f64,
    /// Degrees of freedom of the residual (rows minus their share of the parameters).
    pub dof: f64,
    /// Degrees of freedom of the noise measured at rest.
    pub reference_dof: f64,
    /// One-sided probability of a ratio this large if the residual were tracker noise.
    pub p_value: f64,
    /// Whether the residual is consistent with tracker noise at [`NOISE_TEST_LEVEL`].
    pub is_noise: bool,
}

/// Tests the residuals of the pose kinds `kinds` of `fit` against `rest_noise`, measured on
/// `rest_frames` static frames (the reference has `6 · (rest_frames − 1)` degrees of
/// freedom).
pub fn noise_tests<M: RobotModel>(
    fit: &JointFit<M>,
    rest_noise: &NoiseModel,
    rest_frames: usize,
    kinds: &[QuantityKind],
) -> Vec<NoiseTest> {
    let raws = fit.problem().raw_residuals(&fit.model);
    let names = fit.model.quantities();
    let parameter_share = fit.layout.len() as f64 / fit.rows.max(1) as f64;
    let reference_dof = 6.0 * rest_frames.saturating_sub(1) as f64;
    kinds
        .iter()
        .map(|&kind| {
            let (mut sum, mut rows) = (0.0, 0.0);
            for ((block, raw), weight) in fit.blocks.iter().zip(&raws).zip(&fit.weights) {
                let Some(raw) = raw.filter(|_| block.kind == kind) else {
                    continue;
                };
                let mut white = [0.0; 6];
                rest_noise.of(kind).whiten(&raw, 6, &mut white);
                sum += weight * white.iter().map(|v| v * v).sum::<f64>();
                rows += weight * 6.0;
            }
            let dof = (rows * (1.0 - parameter_share)).max(1.0);
            let variance_ratio = sum / dof;
            let spread = (2.0 / dof + 2.0 / reference_dof.max(1.0)).sqrt();
            let p_value = normal_tail(variance_ratio.ln() / spread);
            NoiseTest {
                tool: names[kind.0].name.clone(),
                variance_ratio,
                dof,
                reference_dof,
                p_value,
                is_noise: p_value >= NOISE_TEST_LEVEL,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tails_match_known_values() {
        assert!((normal_tail(0.0) - 0.5).abs() < 1e-7);
        assert!((normal_tail(1.959_964) - 0.025).abs() < 1e-6);
        assert!((normal_tail(-1.0) - 0.841_344_7).abs() < 1e-6);
        // χ²_1 at 3.841 and χ²_3 at 7.815 are the 5 % points; χ²_2 is exact.
        assert!((chi2_tail(3.841_459, 1) - 0.05).abs() < 2e-3);
        assert!((chi2_tail(7.814_728, 3) - 0.05).abs() < 1e-3);
        assert!((chi2_tail(5.991_464_547, 2) - 0.05).abs() < 1e-9);
        assert!((chi2_quantile(0.05, 2) - 5.991_465).abs() < 1e-6);
        assert!((chi2_quantile(1e-3, 1) - 10.83).abs() < 0.2);
    }
}
