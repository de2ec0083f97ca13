//! The exposure clock of the tracker: a robust line through the frame counter and the host
//! arrival stamps. The tracker latency is defined against this line (exposure = line −
//! latency).

use crate::error::CalibrationError;
use crate::math::stats::{huber_weight, median, robust_scale, weighted_line};

/// Fewest tracker frames for a clock fit.
const MIN_FRAMES: usize = 10;

/// Robust linear map from the tracker frame counter to host time (ns):
/// `arrival ≈ intercept + period · (counter − first counter)`. The exposure of a frame is
/// this line minus the latency.
#[derive(Debug, Clone, PartialEq)]
pub struct ClockFit {
    first_counter: i64,
    first_arrival_ns: i64,
    intercept_ns: f64,
    /// Host time per frame-counter tick (ns).
    pub period_ns: f64,
    /// Robust standard deviation of the arrival stamps about the line (ns, 1.4826 · MAD).
    pub jitter_ns: f64,
    /// Mean of `arrival − line` (ns): what the line leaves of the arrival delay.
    pub mean_residual_ns: f64,
}

/// Unwraps the 32-bit tracker frame counter into a strictly increasing sequence; errors
/// when the counter stalls or goes back.
pub fn unwrap_counters(counters: &[u32]) -> Result<Vec<i64>, CalibrationError> {
    let Some(&first) = counters.first() else {
        return Ok(Vec::new());
    };
    let mut out = Vec::with_capacity(counters.len());
    out.push(0);
    let (mut previous, mut ticks) = (first, 0i64);
    for &counter in &counters[1..] {
        let step = counter.wrapping_sub(previous);
        if step == 0 || step > u32::MAX / 2 {
            return Err(CalibrationError::TimeSync(format!(
                "tracker frame counter goes from {previous} to {counter}: it must increase"
            )));
        }
        ticks += i64::from(step);
        out.push(ticks);
        previous = counter;
    }
    Ok(out)
}

impl ClockFit {
    /// Fits the line through `(counter, arrival_ns)` pairs given in stream order: the slope
    /// starts at the median per-tick interval (robust to skipped frames and counter steps
    /// ≠ 1), the fit is then refined by iteratively reweighted least squares with a Huber
    /// loss (robust to jitter and late frames).
    pub fn fit(counters: &[u32], arrivals_ns: &[i64]) -> Result<Self, CalibrationError> {
        if counters.len() < MIN_FRAMES {
            return Err(CalibrationError::TimeSync(format!(
                "{} tracker frames with the base marker, need at least {MIN_FRAMES}",
                counters.len()
            )));
        }
        let ticks = unwrap_counters(counters)?;
        let first_arrival_ns = arrivals_ns[0];
        let x: Vec<f64> = ticks.iter().map(|&t| t as f64).collect();
        let y: Vec<f64> = arrivals_ns
            .iter()
            .map(|&t| (t - first_arrival_ns) as f64)
            .collect();
        let mut slopes: Vec<f64> = x
            .windows(2)
            .zip(y.windows(2))
            .map(|(dx, dy)| (dy[1] - dy[0]) / (dx[1] - dx[0]))
            .collect();
        let mut slope = median(&mut slopes);
        if !(slope.is_finite() && slope > 0.0) {
            return Err(CalibrationError::TimeSync(format!(
                "arrival stamps do not advance with the frame counter (median {slope} ns per tick)"
            )));
        }
        let mut residuals: Vec<f64> = x.iter().zip(&y).map(|(xi, yi)| yi - slope * xi).collect();
        let mut intercept = median(&mut residuals.clone());
        let mut scale = 0.0;
        for _ in 0..20 {
            for (r, (xi, yi)) in residuals.iter_mut().zip(x.iter().zip(&y)) {
                *r = yi - intercept - slope * xi;
            }
            scale = robust_scale(&residuals).max(1.0);
            let weights: Vec<f64> = residuals
                .iter()
                .map(|r| huber_weight(r / scale, 1.345))
                .collect();
            let (new_intercept, new_slope) = weighted_line(&x, &y, &weights);
            let converged =
                (new_slope - slope).abs() < 1e-9 * slope && (new_intercept - intercept).abs() < 1.0;
            intercept = new_intercept;
            slope = new_slope;
            if converged {
                break;
            }
        }
        let mean_residual_ns = x
            .iter()
            .zip(&y)
            .map(|(xi, yi)| yi - intercept - slope * xi)
            .sum::<f64>()
            / x.len() as f64;
        Ok(Self {
            first_counter: i64::from(counters[0]),
            first_arrival_ns,
            intercept_ns: intercept,
            period_ns: slope,
            jitter_ns: scale,
            mean_residual_ns,
        })
    }

    /// The line's host time (ns) of an unwrapped counter value (ticks since the first frame).
    pub fn line_ns(&self, tick: i64) -> f64 {
        self.first_arrival_ns as f64 + self.intercept_ns + self.period_ns * tick as f64
    }

    /// Counter value of the first frame of the fit.
    pub fn first_counter(&self) -> i64 {
        self.first_counter
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_fit_recovers_the_period_through_skips_steps_and_late_frames() {
        // counter steps by 3, every 7th frame skipped, arrival = exposure + 30 ms + jitter.
        let mut counters = Vec::new();
        let mut arrivals = Vec::new();
        let mut counter = 1_000u32;
        for k in 0..600 {
            counter += 3;
            if k % 7 == 3 {
                continue;
            }
            let exposure = 5e9 + f64::from(counter) * 16.66e6;
            let jitter = f64::from((k * 37) % 11) * 0.2e6 + if k % 50 == 0 { 40e6 } else { 0.0 };
            counters.push(counter);
            arrivals.push((exposure + 30e6 + jitter) as i64);
        }
        let fit = ClockFit::fit(&counters, &arrivals).unwrap();
        assert!((fit.period_ns - 16.66e6).abs() < 1e3, "{}", fit.period_ns);
        let tick = 300 * 3;
        let exposure = 5e9 + f64::from(counters[0] + tick as u32) * 16.66e6;
        let offset = fit.line_ns(i64::from(tick)) - exposure;
        assert!((offset - 31e6).abs() < 1e6, "line offset {offset}");
    }

    #[test]
    fn a_counter_that_goes_back_is_an_error() {
        let counters: Vec<u32> = (0..20).chain([5]).collect();
        let arrivals: Vec<i64> = (0..21).map(|k| k * 50_000_000).collect();
        let error = ClockFit::fit(&counters, &arrivals).unwrap_err();
        assert!(error.to_string().contains("must increase"), "{error}");
    }

    #[test]
    fn unwrap_crosses_the_32_bit_wrap() {
        let ticks = unwrap_counters(&[u32::MAX - 1, u32::MAX, 1]).unwrap();
        assert_eq!(ticks, vec![0, 1, 3]);
    }
}
