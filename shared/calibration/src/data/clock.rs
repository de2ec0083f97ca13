//! The exposure clock of the tracker: a robust line through the frame counter and the frames'
//! host stamps (when each frame became available at the tracker: `tracker.csv`'s `t_ns`, the
//! live `TrackerFrame::available_t_ns`; "arrival" below means that stamp). The tracker latency is defined against this line (exposure = line −
//! latency).
//!
//! [`ClockLine`] is the one fit of that line: the engine runs it once over a whole recording
//! ([`ClockFit`]), the live synchroniser `sabr-sync` over a sliding window at every frame,
//! warm-started from its previous line. Both therefore define the latency the same way.

use crate::error::CalibrationError;
use crate::math::stats::{huber_weight, median, robust_scale, weighted_line, HUBER_K};

/// Fewest tracker frames for a clock fit.
const MIN_FRAMES: usize = 10;
/// Most reweighting iterations of a line fit.
const MAX_ITERATIONS: usize = 20;
/// Smallest robust scale used for the weights (ns), so noise-free input stays well defined.
const MIN_SCALE_NS: f64 = 1.0;
/// The offline fit stops when the line moves less than this at both ends of the session (ns).
const OFFLINE_CONVERGED_NS: f64 = 1.0;

/// A robust clock line `y ≈ intercept + slope · x` through host-time offsets `y` (ns) against
/// unwrapped counter ticks `x`, with the robust spread of `y` about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockLine {
    /// `y` of the line at `x = 0` (ns).
    pub intercept_ns: f64,
    /// Host time per counter tick (ns).
    pub slope_ns: f64,
    /// Robust standard deviation of `y` about the line (ns, 1.4826 · MAD, at least 1 ns).
    pub spread_ns: f64,
}

impl ClockLine {
    /// The starting line `(intercept, slope)`: the median per-tick interval between
    /// consecutive points (robust to skipped frames and counter steps ≠ 1), then the median
    /// offset. `None` when no consecutive pair advances in `x`.
    pub fn start(x: &[f64], y: &[f64]) -> Option<(f64, f64)> {
        let mut slopes: Vec<f64> = x
            .windows(2)
            .zip(y.windows(2))
            .filter(|(dx, _)| dx[1] > dx[0])
            .map(|(dx, dy)| (dy[1] - dy[0]) / (dx[1] - dx[0]))
            .collect();
        if slopes.is_empty() {
            return None;
        }
        let slope = median(&mut slopes);
        let mut offsets: Vec<f64> = x.iter().zip(y).map(|(xi, yi)| yi - slope * xi).collect();
        Some((median(&mut offsets), slope))
    }

    /// Refines the line `start = (intercept, slope)` by iteratively reweighted least squares
    /// with a Huber loss on the MAD scale (robust to jitter and to late frames), until it
    /// moves less than `converged_ns` at both ends of `x` (at most 20 iterations).
    pub fn refine(x: &[f64], y: &[f64], start: (f64, f64), converged_ns: f64) -> Self {
        let (mut intercept, mut slope) = start;
        let low = x.iter().copied().fold(f64::INFINITY, f64::min);
        let high = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mut residuals = vec![0.0; x.len()];
        let mut weights = vec![1.0; x.len()];
        let mut scale = MIN_SCALE_NS;
        for _ in 0..MAX_ITERATIONS {
            for (r, (xi, yi)) in residuals.iter_mut().zip(x.iter().zip(y)) {
                *r = yi - intercept - slope * xi;
            }
            scale = robust_scale(&residuals).max(MIN_SCALE_NS);
            for (w, r) in weights.iter_mut().zip(&residuals) {
                *w = huber_weight(r / scale, HUBER_K);
            }
            let Some((new_intercept, new_slope)) = weighted_line(x, y, &weights) else {
                break;
            };
            let moved_at =
                |at: f64| (new_intercept + new_slope * at - (intercept + slope * at)).abs();
            let moved = moved_at(low).max(moved_at(high));
            intercept = new_intercept;
            slope = new_slope;
            if moved < converged_ns {
                break;
            }
        }
        Self {
            intercept_ns: intercept,
            slope_ns: slope,
            spread_ns: scale,
        }
    }

    /// `y` of the line at `x` (ns).
    pub fn at(&self, x: f64) -> f64 {
        self.intercept_ns + self.slope_ns * x
    }
}

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
    /// Fits the [`ClockLine`] through `(counter, arrival_ns)` pairs given in stream order,
    /// over the whole recording.
    pub fn fit(counters: &[u32], arrivals_ns: &[i64]) -> Result<Self, CalibrationError> {
        if counters.len() < MIN_FRAMES {
            return Err(CalibrationError::TimeSync(format!(
                "{} tracker frames with the base marker, need at least {MIN_FRAMES}",
                counters.len()
            )));
        }
        if arrivals_ns.len() != counters.len() {
            return Err(CalibrationError::TimeSync(format!(
                "{} frame counters but {} arrival stamps",
                counters.len(),
                arrivals_ns.len()
            )));
        }
        let ticks = unwrap_counters(counters)?;
        let first_arrival_ns = arrivals_ns[0];
        let x: Vec<f64> = ticks.iter().map(|&t| t as f64).collect();
        let y: Vec<f64> = arrivals_ns
            .iter()
            .map(|&t| (t - first_arrival_ns) as f64)
            .collect();
        let start = ClockLine::start(&x, &y)
            .filter(|(_, slope)| slope.is_finite() && *slope > 0.0)
            .ok_or_else(|| {
                CalibrationError::TimeSync(
                    "arrival stamps do not advance with the frame counter".into(),
                )
            })?;
        let line = ClockLine::refine(&x, &y, start, OFFLINE_CONVERGED_NS);
        let mean_residual_ns = x
            .iter()
            .zip(&y)
            .map(|(xi, yi)| yi - line.at(*xi))
            .sum::<f64>()
            / x.len() as f64;
        Ok(Self {
            first_counter: i64::from(counters[0]),
            first_arrival_ns,
            intercept_ns: line.intercept_ns,
            period_ns: line.slope_ns,
            jitter_ns: line.spread_ns,
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
    fn stamps_that_do_not_advance_are_an_error() {
        let counters: Vec<u32> = (0..20).collect();
        let arrivals = vec![1_000_000_000i64; 20];
        let error = ClockFit::fit(&counters, &arrivals).unwrap_err();
        assert!(error.to_string().contains("do not advance"), "{error}");
    }

    #[test]
    fn refine_from_a_poor_start_reaches_the_exact_line() {
        let x: Vec<f64> = (0..50).map(|k| f64::from(k) * 2.0).collect();
        let y: Vec<f64> = x.iter().map(|xi| 7.0e6 + 5.0e7 * xi).collect();
        let line = ClockLine::refine(&x, &y, (0.0, 4.0e7), 1.0);
        assert!((line.slope_ns - 5.0e7).abs() < 1e-3, "{line:?}");
        assert!((line.at(0.0) - 7.0e6).abs() < 1.0, "{line:?}");
        assert_eq!(line.spread_ns, 1.0);
    }

    #[test]
    fn unwrap_crosses_the_32_bit_wrap() {
        let ticks = unwrap_counters(&[u32::MAX - 1, u32::MAX, 1]).unwrap();
        assert_eq!(ticks, vec![0, 1, 3]);
    }
}
