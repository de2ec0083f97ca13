//! Small robust statistics: median, MAD scale, Huber weights and a robust line fit. The
//! tracker clock line (offline in the engine, live in `sabr-sync`) is built on these.

/// Huber threshold in units of the robust scale: 95 % efficiency for Gaussian noise.
pub const HUBER_K: f64 = 1.345;

/// Median absolute deviation to standard deviation, for Gaussian data.
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// Huber weight of a standardised residual `u` with threshold `k`.
pub fn huber_weight(u: f64, k: f64) -> f64 {
    let a = u.abs();
    if a <= k {
        1.0
    } else {
        k / a
    }
}

/// Median of `values` (reorders them, in linear time); NaN when empty.
pub fn median(values: &mut [f64]) -> f64 {
    let n = values.len();
    if n == 0 {
        return f64::NAN;
    }
    let (lower_half, upper, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    let upper = *upper;
    if n % 2 == 1 {
        return upper;
    }
    let lower = lower_half
        .iter()
        .copied()
        .max_by(f64::total_cmp)
        .unwrap_or(upper);
    0.5 * (lower + upper)
}

/// Robust standard deviation: 1.4826 · median absolute deviation from the median.
pub fn robust_scale(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    let m = median(&mut v);
    let mut deviations: Vec<f64> = values.iter().map(|x| (x - m).abs()).collect();
    MAD_TO_SIGMA * median(&mut deviations)
}

/// Weighted least-squares line `y ≈ intercept + slope · x`; returns `(intercept, slope)`, or
/// `None` when the weighted `x` do not vary.
pub fn weighted_line(x: &[f64], y: &[f64], w: &[f64]) -> Option<(f64, f64)> {
    let sw: f64 = w.iter().sum();
    let mx = x.iter().zip(w).map(|(a, b)| a * b).sum::<f64>() / sw;
    let my = y.iter().zip(w).map(|(a, b)| a * b).sum::<f64>() / sw;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for ((xi, yi), wi) in x.iter().zip(y).zip(w) {
        sxy += wi * (xi - mx) * (yi - my);
        sxx += wi * (xi - mx) * (xi - mx);
    }
    (sxx > 0.0).then(|| {
        let slope = sxy / sxx;
        (my - slope * mx, slope)
    })
}

/// Line fit robust to outliers: least squares, then Huber-reweighted iterations with the
/// MAD scale of the residuals. Returns `(intercept, slope)`, or `None` when `x` does not vary.
pub fn robust_line(x: &[f64], y: &[f64]) -> Option<(f64, f64)> {
    let mut weights = vec![1.0; x.len()];
    let mut line = weighted_line(x, y, &weights)?;
    for _ in 0..10 {
        let residuals: Vec<f64> = x
            .iter()
            .zip(y)
            .map(|(a, b)| b - line.0 - line.1 * a)
            .collect();
        let scale = robust_scale(&residuals);
        if scale.is_nan() || scale <= 0.0 {
            break;
        }
        for (w, r) in weights.iter_mut().zip(&residuals) {
            *w = huber_weight(r / scale, HUBER_K);
        }
        match weighted_line(x, y, &weights) {
            Some(refined) => line = refined,
            None => break,
        }
    }
    Some(line)
}

/// Root mean square; 0 for an empty slice.
pub fn rms(values: impl IntoIterator<Item = f64>) -> f64 {
    let (sum, n) = values
        .into_iter()
        .fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 {
        0.0
    } else {
        (sum / n as f64).sqrt()
    }
}

/// Summary of error magnitudes (mm): RMS, largest and how many.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ErrorSummary {
    /// RMS of the errors (mm).
    pub rms_mm: f64,
    /// Largest error (mm).
    pub max_mm: f64,
    /// Number of errors it is taken over.
    pub count: usize,
}

impl ErrorSummary {
    /// Summary of errors (mm); `None` when there are none.
    pub fn of(errors: &[f64]) -> Option<Self> {
        (!errors.is_empty()).then(|| ErrorSummary {
            rms_mm: rms(errors.iter().copied()),
            max_mm: errors.iter().copied().fold(0.0, f64::max),
            count: errors.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_line_ignores_a_few_gross_outliers() {
        let x: Vec<f64> = (0..100).map(f64::from).collect();
        let mut y: Vec<f64> = x
            .iter()
            .map(|v| 2.0 + 0.5 * v + 0.01 * (v * 7.0).sin())
            .collect();
        y[10] += 50.0;
        y[60] -= 80.0;
        let (a, b) = robust_line(&x, &y).unwrap();
        assert!((a - 2.0).abs() < 0.02 && (b - 0.5).abs() < 1e-3, "{a} {b}");
    }

    #[test]
    fn median_and_scale() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&mut []).is_nan());
        assert!((robust_scale(&[1.0, 2.0, 3.0, 4.0, 100.0]) - 1.4826).abs() < 1e-12);
    }

    #[test]
    fn a_line_needs_varying_x() {
        assert_eq!(weighted_line(&[2.0, 2.0], &[1.0, 3.0], &[1.0, 1.0]), None);
        assert_eq!(robust_line(&[2.0, 2.0, 2.0], &[1.0, 3.0, 4.0]), None);
    }
}
