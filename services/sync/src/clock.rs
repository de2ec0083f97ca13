//! The tracker's exposure clock, estimated online: a robust line through the tracker's frame
//! counter and the host stamps of the most recent frames (the matcher feeds the estimated time
//! each frame became available at the device; "arrival" below means that stamp).
//!
//! The line is the engine's [`ClockLine`], the one the calibrator fits offline over a whole
//! recording (`sabr_calibration::data::clock::ClockFit`): the slope starts at the median
//! per-tick interval (robust to skipped frames and counter increments ≠ 1), then iteratively
//! reweighted least squares with a Huber loss on the MAD scale refine it (robust to jitter and
//! to late frames, which only ever arrive late). The tracker latency is defined against this
//! central line, so `exposure = line − latency` with either a configured or a calibrated
//! latency. Here the fit runs over a sliding window and is evaluated at the newest frame,
//! warm-started from the previous fit; this module adds only the window, the counter
//! unwrapping with restarts, and the line's uncertainty at the newest frame.

use sabr_calibration::data::clock::ClockLine;
use sabr_calibration::math::stats::median;
use std::collections::VecDeque;

/// Iterations stop when the line moves less than this at both ends of the window (ns): far
/// below the jitter of any tracker.
const CONVERGED_NS: f64 = 50.0;

/// Settings of the online clock fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockConfig {
    /// Most frames in the fit window; the oldest leave first.
    pub window: usize,
    /// Fewest frames before a line is fitted (at least 3).
    pub min_frames: usize,
    /// A frame arriving further than this from where the line puts its counter (ns) means
    /// the counter jumped (tracker restarted): the fit starts over from that frame.
    pub restart_after_ns: i64,
}

impl Default for ClockConfig {
    /// 60 s of a 20 Hz tracker, at least 40 frames (2 s: the robust scale of fewer is too
    /// noisy to judge the line by), restart beyond 250 ms.
    fn default() -> Self {
        Self {
            window: 1200,
            min_frames: 40,
            restart_after_ns: 250_000_000,
        }
    }
}

/// The clock line at one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockEstimate {
    /// Host time of the arrival line at this frame's counter, ns; the exposure is this minus
    /// the latency.
    pub line_ns: i64,
    /// This frame's arrival minus the line, ns (large and positive: a late frame).
    pub residual_ns: i64,
    /// Robust spread (1.4826 · MAD) of the arrivals about the line over the window, ns.
    pub spread_ns: f64,
    /// Standard uncertainty of `line_ns` predicted from the spread and the window, ns.
    pub uncertainty_ns: f64,
    /// Host time per frame-counter tick, ns.
    pub period_ns: f64,
    /// Frames in the fit window.
    pub frames: usize,
}

/// Why the fit started over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Restart {
    /// The frame counter went back (from, to).
    CounterWentBack(u32, u32),
    /// The counter advanced by `ticks`, which does not fit the time since the previous frame.
    CounterJumped {
        /// Counter increment.
        ticks: u32,
        /// Arrival minus where the line expected it, ns.
        off_by_ns: i64,
    },
}

impl std::fmt::Display for Restart {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Restart::CounterWentBack(from, to) => {
                write!(f, "the frame counter went back from {from} to {to}")
            }
            Restart::CounterJumped { ticks, off_by_ns } => write!(
                f,
                "the frame counter advanced by {ticks} but the frame arrived {:.1} ms off the \
                 clock line",
                *off_by_ns as f64 * 1e-6
            ),
        }
    }
}

/// What one frame did to the clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Observed {
    /// The frame's counter equals the previous one: the same frame again, ignored.
    Repeated,
    /// Too few frames for a line yet (after a start or a restart).
    Learning {
        /// Frames in the window so far.
        frames: usize,
        /// Set when this frame started the fit over.
        restart: Option<Restart>,
    },
    /// The line at this frame.
    Estimate(ClockEstimate),
}

/// One frame in the window: unwrapped counter and arrival stamp.
#[derive(Debug, Clone, Copy)]
struct Point {
    tick: i64,
    arrival_ns: i64,
}

/// A fitted line `arrival ≈ origin_ns + intercept + slope · (tick − origin_tick)`.
#[derive(Debug, Clone, Copy)]
struct Line {
    origin_tick: i64,
    origin_ns: i64,
    intercept: f64,
    slope: f64,
}

impl Line {
    fn at(&self, tick: i64) -> f64 {
        (self.origin_ns as f64) + self.intercept + self.slope * (tick - self.origin_tick) as f64
    }

    /// The estimate of this line at `tick` for a frame that arrived at `arrival_ns` (host ns), with
    /// `frames` in the window and the spread and uncertainty of `fit` (the line's own fit).
    fn estimate(
        &self,
        tick: i64,
        arrival_ns: f64,
        frames: usize,
        fit: ClockEstimate,
    ) -> ClockEstimate {
        let line_ns = self.at(tick);
        ClockEstimate {
            line_ns: line_ns.round() as i64,
            residual_ns: (arrival_ns - line_ns).round() as i64,
            period_ns: self.slope,
            frames,
            ..fit
        }
    }
}

/// The online clock estimator; feed it every tracker frame in arrival order.
#[derive(Debug, Clone)]
pub struct FrameClock {
    config: ClockConfig,
    points: VecDeque<Point>,
    last_counter: Option<u32>,
    line: Option<Line>,
    restarts: u64,
    /// The estimate of the last full fit.
    last_fit: Option<ClockEstimate>,
    /// Frames were added since the last full fit (see [`FrameClock::observe_deferred`]).
    stale: bool,
    /// The current call extends the line instead of refitting it.
    deferring: bool,
}

impl FrameClock {
    /// An empty clock.
    pub fn new(config: ClockConfig) -> Self {
        Self {
            config: ClockConfig {
                min_frames: config.min_frames.max(3),
                window: config.window.max(config.min_frames.max(3)),
                ..config
            },
            points: VecDeque::new(),
            last_counter: None,
            line: None,
            restarts: 0,
            last_fit: None,
            stale: false,
            deferring: false,
        }
    }

    /// Like [`FrameClock::observe`], but once a line exists it is extended to the new frame
    /// (the line of the frames before it, evaluated at its counter) instead of refitted: a few
    /// nanoseconds instead of a robust fit over the window, for a caller that must answer at
    /// once. It then calls [`FrameClock::refit`] when the answer is out. Over a window of
    /// hundreds of frames one frame moves the line by a small fraction of its uncertainty.
    pub fn observe_deferred(&mut self, frame_number: u32, arrival_ns: i64) -> Observed {
        self.deferring = true;
        let observed = self.observe(frame_number, arrival_ns);
        self.deferring = false;
        observed
    }

    /// Refits the line over the window if frames were added by
    /// [`FrameClock::observe_deferred`] since the last fit.
    pub fn refit(&mut self) {
        if self.stale {
            self.stale = false;
            self.fit();
        }
    }

    /// The estimate [`FrameClock::observe_deferred`] would give a frame with the counter after
    /// the newest frame's, arriving on the line; `None` before the first line. Changes nothing.
    pub fn next_estimate(&self) -> Option<ClockEstimate> {
        let newest = self.points.back()?;
        let (line, last_fit) = (self.line.as_ref()?, self.last_fit?);
        let tick = newest.tick + 1;
        let frames = (self.points.len() + 1).min(self.config.window);
        Some(line.estimate(tick, line.at(tick), frames, last_fit))
    }

    /// How often the fit started over because the counter went back or jumped.
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// Adds a frame (its counter and host time stamp, `CLOCK_MONOTONIC` ns: the matcher passes
    /// its availability stamp) and returns the line at it.
    pub fn observe(&mut self, frame_number: u32, arrival_ns: i64) -> Observed {
        let mut restart = None;
        let tick = match (self.last_counter, self.points.back()) {
            (Some(last), Some(previous)) => {
                let step = frame_number.wrapping_sub(last);
                if step == 0 {
                    return Observed::Repeated;
                }
                if step > u32::MAX / 2 {
                    restart = Some(Restart::CounterWentBack(last, frame_number));
                    0
                } else {
                    let tick = previous.tick + i64::from(step);
                    match self.expected_arrival(tick, previous) {
                        Some(expected)
                            if (arrival_ns as f64 - expected).abs()
                                > self.config.restart_after_ns as f64 =>
                        {
                            restart = Some(Restart::CounterJumped {
                                ticks: step,
                                off_by_ns: (arrival_ns as f64 - expected) as i64,
                            });
                            0
                        }
                        _ => tick,
                    }
                }
            }
            _ => 0,
        };
        if restart.is_some() {
            self.points.clear();
            self.line = None;
            self.last_fit = None;
            self.restarts += 1;
        }
        self.last_counter = Some(frame_number);
        self.points.push_back(Point { tick, arrival_ns });
        while self.points.len() > self.config.window {
            self.points.pop_front();
        }
        if self.points.len() < self.config.min_frames {
            return Observed::Learning {
                frames: self.points.len(),
                restart,
            };
        }
        match (
            self.deferring && restart.is_none(),
            self.line,
            self.last_fit,
        ) {
            (true, Some(line), Some(last_fit)) => Observed::Estimate(self.extend(line, last_fit)),
            _ => Observed::Estimate(self.fit()),
        }
    }

    /// The estimate at the newest frame from `line` (fitted before it), with the spread and
    /// uncertainty of that fit; the window is refitted later ([`FrameClock::refit`]).
    fn extend(&mut self, line: Line, last_fit: ClockEstimate) -> ClockEstimate {
        self.stale = true;
        let newest = *self.points.back().expect("the window is not empty");
        let arrival_ns = newest.arrival_ns as f64;
        line.estimate(newest.tick, arrival_ns, self.points.len(), last_fit)
    }

    /// Where the current line (or, while learning, the median interval) puts `tick`.
    fn expected_arrival(&self, tick: i64, previous: &Point) -> Option<f64> {
        if let Some(line) = &self.line {
            return Some(line.at(tick));
        }
        let mut slopes = consecutive_slopes(&self.points);
        if slopes.is_empty() {
            return None;
        }
        let slope = median(&mut slopes);
        Some(previous.arrival_ns as f64 + slope * (tick - previous.tick) as f64)
    }

    /// Refits the line over the window and evaluates it at the newest frame.
    fn fit(&mut self) -> ClockEstimate {
        let newest = *self.points.back().expect("the window is not empty");
        let x: Vec<f64> = self
            .points
            .iter()
            .map(|p| (p.tick - newest.tick) as f64)
            .collect();
        let y: Vec<f64> = self
            .points
            .iter()
            .map(|p| (p.arrival_ns - newest.arrival_ns) as f64)
            .collect();
        let start = match &self.line {
            // Warm start: the previous line moved to the new origin.
            Some(line) => (line.at(newest.tick) - newest.arrival_ns as f64, line.slope),
            None => ClockLine::start(&x, &y)
                .expect("the window holds at least 3 frames with strictly increasing ticks"),
        };
        let fitted = ClockLine::refine(&x, &y, start, CONVERGED_NS);
        let (intercept, slope, scale) = (fitted.intercept_ns, fitted.slope_ns, fitted.spread_ns);
        self.line = Some(Line {
            origin_tick: newest.tick,
            origin_ns: newest.arrival_ns,
            intercept,
            slope,
        });
        let line_ns = newest.arrival_ns as f64 + intercept;
        let estimate = ClockEstimate {
            line_ns: line_ns.round() as i64,
            residual_ns: (newest.arrival_ns as f64 - line_ns).round() as i64,
            spread_ns: scale,
            uncertainty_ns: scale * extrapolation_factor(&x),
            period_ns: slope,
            frames: x.len(),
        };
        self.last_fit = Some(estimate);
        estimate
    }
}

/// Slopes (ns per tick) between consecutive frames of the window.
fn consecutive_slopes(points: &VecDeque<Point>) -> Vec<f64> {
    points
        .iter()
        .zip(points.iter().skip(1))
        .filter(|(a, b)| b.tick > a.tick)
        .map(|(a, b)| (b.arrival_ns - a.arrival_ns) as f64 / (b.tick - a.tick) as f64)
        .collect()
}

/// `sqrt(1/n + (x₀ − x̄)² / Sxx)` at `x₀ = 0`: the standard error of a least-squares line at
/// the newest frame per unit of noise.
fn extrapolation_factor(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let sxx: f64 = x.iter().map(|xi| (xi - mean).powi(2)).sum();
    if sxx <= 0.0 {
        return f64::INFINITY;
    }
    (1.0 / n + mean * mean / sxx).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_streams::TrackerStream;
    use rand::{Rng, SeedableRng};

    /// Feeds `stream` and returns (frame index, estimate error vs. the true line, ns) for
    /// every frame with an estimate.
    fn errors(clock: &mut FrameClock, stream: &mut TrackerStream, frames: usize) -> Vec<f64> {
        let mut out = Vec::new();
        for _ in 0..frames {
            let Some(frame) = stream.next_frame() else {
                continue;
            };
            if let Observed::Estimate(estimate) = clock.observe(frame.counter, frame.arrival_ns) {
                let truth = frame.exposure_ns + stream.latency_ns;
                out.push((estimate.line_ns - truth) as f64);
            }
        }
        out
    }

    fn p99_abs(errors: &[f64]) -> f64 {
        let mut a: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
        a.sort_by(f64::total_cmp);
        a[((a.len() as f64 * 0.99) as usize).min(a.len() - 1)]
    }

    #[test]
    fn a_deferred_fit_answers_with_the_previous_line_and_refits_to_the_same_clock() {
        // Two clocks fed the same jittered stream with late frames: one refits at every
        // frame, the other extends its line and refits after answering.
        let config = ClockConfig {
            window: 400,
            ..ClockConfig::default()
        };
        let (mut full, mut deferred) = (FrameClock::new(config), FrameClock::new(config));
        let mut stream = TrackerStream::new(5, 50_000_000.0 * (1.0 - 25e-6), 1, 40_000_000);
        let mut compared = 0;
        let mut gaps = 0.0;
        for _ in 0..900 {
            let Some(frame) = stream.next_frame() else {
                continue;
            };
            let a = full.observe(frame.counter, frame.arrival_ns);
            let b = deferred.observe_deferred(frame.counter, frame.arrival_ns);
            deferred.refit();
            // One frame moves the line most while the window is short.
            if let (Observed::Estimate(a), Observed::Estimate(b)) = (a, b) {
                if a.frames < 100 {
                    continue;
                }
                compared += 1;
                let gap = (a.line_ns - b.line_ns).abs() as f64;
                gaps += gap / a.uncertainty_ns;
                assert!(
                    gap <= 0.5 * a.uncertainty_ns.max(1_000.0),
                    "frame {}: full {} ns, deferred {} ns, uncertainty {} ns",
                    frame.counter,
                    a.line_ns,
                    b.line_ns,
                    a.uncertainty_ns
                );
            }
        }
        assert!(compared > 750, "{compared} estimates compared");
        let mean_gap = gaps / f64::from(compared);
        assert!(mean_gap < 0.15, "mean gap {mean_gap} uncertainties");
        assert_eq!(full.line.map(|l| l.slope), deferred.line.map(|l| l.slope));
    }

    #[test]
    fn exact_stream_gives_the_exact_line() {
        let mut stream = TrackerStream::new(1, 50_000_000.0, 1, 30_000_000);
        stream.jitter_ns = 0.0;
        stream.late_probability = 0.0;
        stream.drop_probability = 0.0;
        let mut clock = FrameClock::new(ClockConfig::default());
        let errors = errors(&mut clock, &mut stream, 100);
        assert_eq!(errors.len(), 100 - 39);
        assert!(errors.iter().all(|e| e.abs() <= 1.0), "{errors:?}");
    }

    #[test]
    fn jitter_late_frames_drops_and_steps_of_3() {
        // 1 ms Gaussian jitter, 2 % late frames (2–15 ms), 1 % dropped, counter +3 per frame,
        // a tracker clock 40 ppm fast: the line at the newest frame stays well within 0.5 ms.
        // The window is 400 frames (20 s) to keep the test fast in debug builds.
        let mut stream = TrackerStream::new(7, 50_000_000.0 * (1.0 + 40e-6), 3, 42_000_000);
        let config = ClockConfig {
            window: 400,
            ..ClockConfig::default()
        };
        let mut clock = FrameClock::new(config);
        let errors = errors(&mut clock, &mut stream, 1000);
        let settled = &errors[200..];
        let p99 = p99_abs(settled);
        assert!(p99 < 400_000.0, "p99 {p99} ns");
        let mean = settled.iter().sum::<f64>() / settled.len() as f64;
        // Late frames pull the Huber line up by about their share × 1.345 σ (the calibrator's
        // line has the same bias, so it is part of the latency's definition).
        assert!(mean.abs() < 100_000.0, "bias {mean} ns");
        assert_eq!(clock.restarts(), 0);
    }

    #[test]
    fn uncertainty_predicts_the_error() {
        let mut stream = TrackerStream::new(11, 50_000_000.0, 1, 25_000_000);
        stream.late_probability = 0.0;
        let mut clock = FrameClock::new(ClockConfig::default());
        let mut pairs = Vec::new();
        for _ in 0..600 {
            let Some(frame) = stream.next_frame() else {
                continue;
            };
            if let Observed::Estimate(e) = clock.observe(frame.counter, frame.arrival_ns) {
                let error = (e.line_ns - frame.exposure_ns - stream.latency_ns) as f64;
                pairs.push((error, e.uncertainty_ns, e.spread_ns));
            }
        }
        // Normalised errors over the last 300 frames: about unit variance.
        let z: Vec<f64> = pairs[pairs.len() - 300..]
            .iter()
            .map(|(e, u, _)| e / u)
            .collect();
        let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
        assert!((0.3..2.0).contains(&rms), "normalised rms {rms}");
        let spread = pairs.last().unwrap().2;
        assert!(
            (0.8e6..1.2e6).contains(&spread),
            "spread {spread} ns for 1 ms jitter"
        );
    }

    #[test]
    fn repeated_frames_are_ignored_and_a_counter_reset_restarts_the_fit() {
        let mut clock = FrameClock::new(ClockConfig::default());
        let mut t = 1_000_000_000i64;
        for k in 0..20u32 {
            t += 50_000_000;
            clock.observe(500 + k, t);
        }
        assert_eq!(clock.observe(519, t + 1_000_000), Observed::Repeated);
        t += 50_000_000;
        match clock.observe(3, t) {
            Observed::Learning {
                frames: 1,
                restart: Some(Restart::CounterWentBack(519, 3)),
            } => {}
            other => panic!("{other:?}"),
        }
        for k in 4..13u32 {
            t += 50_000_000;
            clock.observe(k, t);
        }
        // A jump forward that the elapsed time does not explain.
        t += 50_000_000;
        match clock.observe(10_000, t) {
            Observed::Learning {
                restart: Some(Restart::CounterJumped { ticks, .. }),
                ..
            } => assert_eq!(ticks, 10_000 - 12),
            other => panic!("{other:?}"),
        }
        assert_eq!(clock.restarts(), 2);
    }

    #[test]
    fn the_counter_wraps_around_without_a_restart() {
        let mut clock = FrameClock::new(ClockConfig::default());
        let mut counter = u32::MAX - 30;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut last = None;
        for k in 0..60i64 {
            counter = counter.wrapping_add(1);
            let arrival = 2_000_000_000 + k * 50_000_000 + rng.random_range(0..100_000);
            last = Some(clock.observe(counter, arrival));
        }
        assert_eq!(clock.restarts(), 0);
        let Some(Observed::Estimate(e)) = last else {
            panic!("{last:?}")
        };
        assert!(
            (e.period_ns - 50_000_000.0).abs() < 5_000.0,
            "{}",
            e.period_ns
        );
    }
}
