//! Pairs tracker frames with the encoder state at their exposure time.
//!
//! Each frame's exposure time is the frame clock line at its counter ([`crate::clock`]) minus
//! the tracker latency. The line is fitted through the frames' availability stamps
//! ([`TrackerFrame::available_t_ns`]: when the frame became available at the device, which is
//! what the latency is measured to), not through the arrival of the replies, which are later by
//! the wait for the next poll and one serial exchange; the encoder counts are interpolated there ([`crate::encoder_buffer`]).
//! A frame waits until the first encoder sample after its exposure has arrived, at most
//! [`MatcherConfig::match_timeout_ns`]. Frames are matched in arrival order.

use crate::clock::{ClockConfig, ClockEstimate, FrameClock, Observed, Restart};
use crate::encoder_buffer::{EncoderBuffer, Lookup, Pushed};
use crate::latency::Latency;
use sabr_msgs::{EncoderSample, MatchQuality, MatchedSample, TrackerFrame, JOINTS};
use std::collections::VecDeque;
use std::f64::consts::TAU;

/// Settings of the matcher.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatcherConfig {
    /// The frame clock fit.
    pub clock: ClockConfig,
    /// Encoder samples kept (≥ 2 s at 1 kHz).
    pub buffer_samples: usize,
    /// Largest time between the two encoder samples interpolated between, ns.
    pub max_span_ns: i64,
    /// Longest a frame waits for the encoder sample after its exposure, ns of host time.
    pub match_timeout_ns: i64,
    /// Frames are published only once the clock line's predicted uncertainty is at most
    /// this, ns (while the fit window fills after a start or restart); once locked, up to
    /// [`LOCK_HYSTERESIS`] times this, so the noise of the spread estimate does not make the
    /// output flicker.
    pub max_uncertainty_ns: f64,
}

/// Factor on [`MatcherConfig::max_uncertainty_ns`] above which a locked clock unlocks.
pub const LOCK_HYSTERESIS: f64 = 1.25;

impl Default for MatcherConfig {
    /// 3 s of 1 kHz samples, 5 ms span, 100 ms wait, 200 µs clock uncertainty (an error
    /// p99 ≤ 0.5 ms for Gaussian errors).
    fn default() -> Self {
        Self {
            clock: ClockConfig::default(),
            buffer_samples: 3000,
            max_span_ns: 5_000_000,
            match_timeout_ns: 100_000_000,
            max_uncertainty_ns: 200_000.0,
        }
    }
}

/// Why a frame was not matched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Unmatched {
    /// The frame counter repeated the previous frame's: the same frame again.
    Repeated,
    /// The clock fit has too few frames yet.
    Learning {
        /// Frames in the window.
        frames: usize,
        /// Set when this frame restarted the fit.
        restart: Option<Restart>,
    },
    /// The clock line is not yet known precisely enough.
    Converging {
        /// Predicted uncertainty of the line, ns.
        uncertainty_ns: f64,
        /// Frames in the window.
        frames: usize,
    },
    /// Neither a configured nor a calibrated latency is known.
    NoLatency,
    /// The exposure time lies before the oldest encoder sample kept.
    TooOld,
    /// The encoder samples around the exposure time are too far apart, ns.
    Gap {
        /// Time between them, ns.
        span_ns: i64,
    },
    /// No encoder sample after the exposure arrived in time.
    TimedOut,
}

/// Counters of what happened to the frames.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MatchStats {
    /// Tracker frames received.
    pub frames: u64,
    /// Frames matched and published.
    pub matched: u64,
    /// Frames repeating the previous frame counter.
    pub repeated: u64,
    /// Frames without a usable clock line yet (learning or converging).
    pub converging: u64,
    /// Frames without a latency.
    pub no_latency: u64,
    /// Frames whose exposure was older than the encoder buffer.
    pub too_old: u64,
    /// Frames inside a gap of the encoder stream.
    pub gaps: u64,
    /// Frames whose next encoder sample never came in time.
    pub timed_out: u64,
    /// Encoder samples lost (sequence gaps).
    pub encoder_lost: u64,
    /// Encoder samples refused (time stamp not after the previous one).
    pub encoder_refused: u64,
}

/// A frame waiting for the encoder sample after its exposure.
#[derive(Debug, Clone, Copy)]
struct Pending {
    frame: TrackerFrame,
    clock: ClockEstimate,
    latency: Latency,
    exposure_ns: i64,
    received_ns: i64,
}

impl Pending {
    /// `frame`, received at host time `received_ns`, dated by `clock` and `latency`: exposed
    /// at the clock line minus the latency.
    fn new(frame: TrackerFrame, clock: ClockEstimate, latency: Latency, received_ns: i64) -> Self {
        Self {
            frame,
            clock,
            latency,
            exposure_ns: clock.line_ns - latency.ns,
            received_ns,
        }
    }
}

/// The matcher: feed it encoder samples and tracker frames, poll it for matched samples.
#[derive(Debug, Clone)]
pub struct Matcher {
    config: MatcherConfig,
    clock: FrameClock,
    encoders: EncoderBuffer,
    pending: VecDeque<Pending>,
    counts_per_rev: [u32; JOINTS],
    seq: u64,
    stats: MatchStats,
    last_clock: Option<ClockEstimate>,
    /// The newest frame admitted (the template [`Matcher::warm`] matches).
    last_admitted: Option<Pending>,
    locked: bool,
}

impl Matcher {
    /// A matcher converting counts to angles with `counts_per_rev` (4 × CPT per joint).
    pub fn new(config: MatcherConfig, counts_per_rev: [u32; JOINTS]) -> Self {
        Self {
            config,
            clock: FrameClock::new(config.clock),
            encoders: EncoderBuffer::new(config.buffer_samples),
            pending: VecDeque::new(),
            counts_per_rev,
            seq: 0,
            stats: MatchStats::default(),
            last_clock: None,
            last_admitted: None,
            locked: false,
        }
    }

    /// Changes the counts per revolution used for the encoder angles (a new parameter set).
    pub fn set_counts_per_rev(&mut self, counts_per_rev: [u32; JOINTS]) {
        self.counts_per_rev = counts_per_rev;
    }

    /// What happened so far.
    pub fn stats(&self) -> MatchStats {
        self.stats
    }

    /// The clock line at the newest frame that had one.
    pub fn last_clock(&self) -> Option<ClockEstimate> {
        self.last_clock
    }

    /// Frames waiting for encoder data.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// Adds an encoder sample (in arrival order).
    pub fn push_encoder(&mut self, sample: EncoderSample) -> Pushed {
        let pushed = self.encoders.push(sample);
        match pushed {
            Pushed::AfterGap { lost } => self.stats.encoder_lost += lost,
            Pushed::NotAfter { .. } => self.stats.encoder_refused += 1,
            Pushed::InSequence | Pushed::SequenceRestarted => {}
        }
        pushed
    }

    /// Feeds a frame that arrived before this matcher started (publisher history replayed to
    /// a restarted node) to the clock fit only: its encoder samples are gone, so it is never
    /// matched, but it lets the clock lock without waiting for new frames. Returns what the
    /// frame did to the clock.
    pub fn learn_clock(&mut self, frame: TrackerFrame) -> Observed {
        let observed = self.clock.observe(frame.frame_number, frame.available_t_ns);
        if let Observed::Estimate(estimate) = observed {
            self.last_clock = Some(estimate);
        }
        observed
    }

    /// Adds a tracker frame received at host time `now_ns`, with the latency in use. On
    /// `Ok` the frame waits for [`Matcher::poll`]; on `Err` it is not matched, for the reason
    /// given.
    pub fn push_frame(
        &mut self,
        frame: TrackerFrame,
        latency: Option<Latency>,
        now_ns: i64,
    ) -> Result<(), Unmatched> {
        self.stats.frames += 1;
        let result = self.admit(frame, latency, now_ns);
        match result {
            Err(Unmatched::Repeated) => self.stats.repeated += 1,
            Err(Unmatched::Learning { .. } | Unmatched::Converging { .. }) => {
                self.stats.converging += 1
            }
            Err(Unmatched::NoLatency) => self.stats.no_latency += 1,
            _ => {}
        }
        result
    }

    fn admit(
        &mut self,
        frame: TrackerFrame,
        latency: Option<Latency>,
        now_ns: i64,
    ) -> Result<(), Unmatched> {
        let clock = match self
            .clock
            .observe_deferred(frame.frame_number, frame.available_t_ns)
        {
            Observed::Repeated => return Err(Unmatched::Repeated),
            Observed::Learning { frames, restart } => {
                self.locked = false;
                return Err(Unmatched::Learning { frames, restart });
            }
            Observed::Estimate(estimate) => estimate,
        };
        self.last_clock = Some(clock);
        let limit = match self.locked {
            true => self.config.max_uncertainty_ns * LOCK_HYSTERESIS,
            false => self.config.max_uncertainty_ns,
        };
        self.locked = clock.uncertainty_ns <= limit;
        if !self.locked {
            return Err(Unmatched::Converging {
                uncertainty_ns: clock.uncertainty_ns,
                frames: clock.frames,
            });
        }
        let latency = latency.ok_or(Unmatched::NoLatency)?;
        let pending = Pending::new(frame, clock, latency, now_ns);
        self.pending.push_back(pending);
        self.last_admitted = Some(pending);
        Ok(())
    }

    /// Matches the frame due next without it and without changing anything: its counter
    /// one after the newest admitted frame's, its clock line where the current line puts that
    /// counter, the encoder counts at its exposure (with `latency`) and the sample built, as
    /// [`Matcher::poll`] would. Returns that sample, or `None` while no frame was admitted,
    /// there is no latency or the encoder samples after the exposure have not arrived.
    ///
    /// Between two frames (50 ms at 20 Hz) the core's other work evicts what matching a frame
    /// reads; a caller that knows a frame is due (the sync, pre-woken by the tracker before a
    /// poll) calls this so that the frame is admitted and matched from the cache.
    pub fn warm(&self, latency: Option<Latency>) -> Option<MatchedSample> {
        let last = self.last_admitted?;
        let latency = latency?;
        let frame_number = last.frame.frame_number.wrapping_add(1);
        let frame = TrackerFrame {
            frame_number,
            ..last.frame
        };
        let pending = Pending::new(
            frame,
            self.clock.next_estimate()?,
            latency,
            last.received_ns,
        );
        match self
            .encoders
            .at(pending.exposure_ns, self.config.max_span_ns)
        {
            Lookup::Found(found) => Some(self.matched(&pending, found, self.seq + 1)),
            _ => None,
        }
    }

    /// Matches every waiting frame whose encoder data is complete, in order, at host time
    /// `now_ns`; hands each result to `out` (a matched sample, or the frame's counter and
    /// why it was given up). Then, with the results out, refits the frame clock over the
    /// frames added since its last fit (admitting a frame only extends the line).
    pub fn poll(&mut self, now_ns: i64, out: impl FnMut(Result<MatchedSample, (u32, Unmatched)>)) {
        self.match_pending(now_ns, out);
        self.clock.refit();
    }

    fn match_pending(
        &mut self,
        now_ns: i64,
        mut out: impl FnMut(Result<MatchedSample, (u32, Unmatched)>),
    ) {
        while let Some(pending) = self.pending.front().copied() {
            let result = match self
                .encoders
                .at(pending.exposure_ns, self.config.max_span_ns)
            {
                Lookup::Found(found) => {
                    self.seq += 1;
                    Ok(self.matched(&pending, found, self.seq))
                }
                Lookup::NotYet if now_ns - pending.received_ns <= self.config.match_timeout_ns => {
                    return;
                }
                Lookup::NotYet => Err(Unmatched::TimedOut),
                Lookup::TooOld => Err(Unmatched::TooOld),
                Lookup::Gap { span_ns } => Err(Unmatched::Gap { span_ns }),
            };
            self.pending.pop_front();
            match &result {
                Ok(_) => self.stats.matched += 1,
                Err(Unmatched::TimedOut) => self.stats.timed_out += 1,
                Err(Unmatched::TooOld) => self.stats.too_old += 1,
                Err(Unmatched::Gap { .. }) => self.stats.gaps += 1,
                Err(_) => {}
            }
            out(result.map_err(|reason| (pending.frame.frame_number, reason)));
        }
    }

    /// The matched sample number `seq` of a frame and the encoder counts at its exposure.
    fn matched(
        &self,
        pending: &Pending,
        found: crate::encoder_buffer::Interpolated,
        seq: u64,
    ) -> MatchedSample {
        let cpr = self.counts_per_rev;
        MatchedSample {
            seq,
            exposure_t_ns: pending.exposure_ns,
            arrival_t_ns: pending.frame.arrival_t_ns,
            available_t_ns: pending.frame.available_t_ns,
            frame_sent_t_ns: pending.frame.sent_t_ns,
            frame_received_t_ns: pending.received_ns,
            // Stamped by the caller right before its send.
            sent_t_ns: 0,
            frame_number: pending.frame.frame_number,
            counts: found.counts,
            encoder_angle_rad: std::array::from_fn(|j| TAU * found.counts[j] / f64::from(cpr[j])),
            tools: pending.frame.tools,
            quality: MatchQuality {
                interpolation_span_ns: found.span_ns,
                nearest_sample_ns: found.nearest_ns,
                latency_ns: pending.latency.ns,
                latency_source: pending.latency.source,
                clock_residual_ns: pending.clock.residual_ns,
                clock_spread_ns: pending.clock.spread_ns.round() as i64,
                clock_frames: pending.clock.frames as u32,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_streams::{encoder_samples, true_counts, TrackerStream};
    use sabr_msgs::LatencySource;

    /// A matcher configuration whose clock locks after three frames and that accepts any
    /// uncertainty: the tests' timing, not the defaults' caution.
    fn quickly_locking_config() -> MatcherConfig {
        MatcherConfig {
            clock: ClockConfig {
                min_frames: 3,
                ..ClockConfig::default()
            },
            max_uncertainty_ns: f64::INFINITY,
            ..MatcherConfig::default()
        }
    }

    const LATENCY: Latency = Latency {
        ns: 35_000_000,
        source: LatencySource::Configured,
    };

    /// Wait of a reply for the next poll plus one serial exchange in the synthetic frames, ns:
    /// the arrival stamp is this much later than the availability stamp.
    const REPLY_DELAY_NS: i64 = 700_000;

    /// The tracker's work on a synthetic frame from its arrival to its send, ns.
    const TRACKER_WORK_NS: i64 = 2_000;

    /// A frame that became available at the device at `available_ns` (the synthetic streams'
    /// `arrival_ns`, drawn from exposure + latency + jitter) and arrived [`REPLY_DELAY_NS`]
    /// later.
    fn frame(counter: u32, available_ns: i64) -> TrackerFrame {
        TrackerFrame {
            seq: 0,
            arrival_t_ns: available_ns + REPLY_DELAY_NS,
            available_t_ns: available_ns,
            sent_t_ns: available_ns + REPLY_DELAY_NS + TRACKER_WORK_NS,
            frame_number: counter,
            tools: Default::default(),
        }
    }

    /// Runs a synthetic session: 1 kHz encoders, 20 Hz tracker with the given counter
    /// increment; returns the matched samples with their true exposure times.
    fn session(increment: u32, seconds: i64) -> (Vec<(MatchedSample, i64)>, MatchStats) {
        let mut matcher = Matcher::new(MatcherConfig::default(), [2000, 2000, 4000, 2000, 2000]);
        let encoders = encoder_samples(
            4_900_000_000,
            1_000_000,
            (seconds * 1000) as usize + 200,
            20_000,
        );
        let mut stream = TrackerStream::new(3, 50_000_000.0, increment, LATENCY.ns);
        let mut frames = Vec::new();
        while let Some(f) = stream.next_frame().or_else(|| stream.next_frame()) {
            if f.arrival_ns > 4_900_000_000 + seconds * 1_000_000_000 {
                break;
            }
            frames.push(f);
        }
        // Deliver both streams in host time order, polling as a node would.
        let mut out = Vec::new();
        let mut next_frame = 0;
        for sample in encoders {
            while next_frame < frames.len() && frames[next_frame].arrival_ns <= sample.t_ns {
                let f = frames[next_frame];
                let _ =
                    matcher.push_frame(frame(f.counter, f.arrival_ns), Some(LATENCY), f.arrival_ns);
                next_frame += 1;
            }
            matcher.push_encoder(sample);
            matcher.poll(sample.t_ns, |r| {
                let m = r.expect("matched");
                let truth = frames.iter().find(|f| f.counter == m.frame_number).unwrap();
                out.push((m, truth.exposure_ns));
            });
        }
        (out, matcher.stats())
    }

    #[test]
    fn matches_a_jittery_stream_with_drops_and_counter_steps_of_3() {
        let (matched, stats) = session(3, 60);
        assert!(matched.len() > 900, "{stats:?}");
        assert_eq!(stats.matched as usize, matched.len());
        assert_eq!(stats.timed_out + stats.gaps + stats.too_old, 0, "{stats:?}");
        let mut errors: Vec<i64> = matched
            .iter()
            .map(|(m, truth)| (m.exposure_t_ns - truth).abs())
            .collect();
        errors.sort_unstable();
        let p99 = errors[errors.len() * 99 / 100];
        assert!(p99 <= 500_000, "exposure error p99 {p99} ns");
        for (m, _) in &matched {
            assert_eq!(m.frame_sent_t_ns, m.arrival_t_ns + TRACKER_WORK_NS);
            // The session pushes each frame at its stream's arrival, the frame's availability.
            assert_eq!(m.frame_received_t_ns, m.available_t_ns);
            assert_eq!(m.sent_t_ns, 0, "stamped by the node right before its send");
            assert_eq!(m.quality.latency_ns, LATENCY.ns);
            assert!(m.quality.interpolation_span_ns <= 1_040_000);
            let spread = m.quality.clock_spread_ns;
            assert!(
                (500_000..1_500_000).contains(&spread),
                "spread {spread} ns: {m:?}"
            );
            // The counts are those at the estimated exposure, within a count.
            let expected = true_counts(m.exposure_t_ns);
            assert!((m.counts[0] - expected[0]).abs() < 1.0);
            assert!((m.encoder_angle_rad[0] - TAU * m.counts[0] / 2000.0).abs() < 1e-12);
        }
        let seqs: Vec<u64> = matched.iter().map(|(m, _)| m.seq).collect();
        assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1));
    }

    #[test]
    fn warming_predicts_the_next_frames_match_and_changes_nothing() {
        // Two matchers fed the same exact stream; one is warmed before every frame, as the
        // sync is when the tracker pre-wakes it. Its outputs must be the other's, and each
        // warm-up must have matched the frame that came next as it came.
        let mut stream = TrackerStream::new(4, 50_000_000.0, 1, LATENCY.ns);
        stream.jitter_ns = 0.0;
        stream.late_probability = 0.0;
        stream.drop_probability = 0.0;
        let frames: Vec<_> = std::iter::from_fn(|| stream.next_frame())
            .take_while(|f| f.arrival_ns < 7_000_000_000)
            .collect();
        let cpr = [2000, 2000, 4000, 2000, 2000];
        let mut warmed = Matcher::new(quickly_locking_config(), cpr);
        let mut plain = Matcher::new(quickly_locking_config(), cpr);
        let (mut warmed_out, mut plain_out) = (Vec::new(), Vec::new());
        let (mut predicted, mut predictions_checked) = (None, 0);
        let mut next_frame = 0;
        for sample in encoder_samples(4_900_000_000, 1_000_000, 2_200, 20_000) {
            while next_frame < frames.len() && frames[next_frame].arrival_ns <= sample.t_ns {
                let f = frames[next_frame];
                predicted = warmed.warm(Some(LATENCY));
                for matcher in [&mut warmed, &mut plain] {
                    let _ = matcher.push_frame(
                        frame(f.counter, f.arrival_ns),
                        Some(LATENCY),
                        f.arrival_ns,
                    );
                }
                next_frame += 1;
            }
            for (matcher, out) in [(&mut warmed, &mut warmed_out), (&mut plain, &mut plain_out)] {
                matcher.push_encoder(sample);
                matcher.poll(sample.t_ns, |r| out.push(r.expect("matched")));
            }
            if let (Some(mut guess), Some(actual)) = (predicted, warmed_out.last()) {
                if actual.frame_number != guess.frame_number {
                    continue;
                }
                // The frame's own stamps and its distance from the line are what it brings.
                guess.arrival_t_ns = actual.arrival_t_ns;
                guess.available_t_ns = actual.available_t_ns;
                guess.frame_sent_t_ns = actual.frame_sent_t_ns;
                guess.frame_received_t_ns = actual.frame_received_t_ns;
                assert!(actual.quality.clock_residual_ns.abs() <= 1, "{actual:?}");
                guess.quality.clock_residual_ns = actual.quality.clock_residual_ns;
                assert_eq!(&guess, actual);
                predictions_checked += 1;
                predicted = None;
            }
        }
        assert!(
            predictions_checked > 30,
            "{predictions_checked} predictions checked"
        );
        assert_eq!(warmed_out, plain_out);
        assert_eq!(warmed.stats(), plain.stats());
    }

    #[test]
    fn the_clock_line_runs_through_the_availability_stamps_not_the_arrivals() {
        // Every frame arrives REPLY_DELAY_NS after it became available; the latency is
        // measured to availability, so the exposures carry no bias of that size.
        let (matched, _) = session(3, 60);
        let mean_error = matched
            .iter()
            .map(|(m, truth)| (m.exposure_t_ns - truth) as f64)
            .sum::<f64>()
            / matched.len() as f64;
        assert!(
            mean_error.abs() < 0.2 * REPLY_DELAY_NS as f64,
            "mean exposure error {mean_error} ns"
        );
        for (m, _) in &matched {
            assert_eq!(m.arrival_t_ns - m.available_t_ns, REPLY_DELAY_NS);
        }
        // The same frames with other arrival stamps (up to 5 ms late, varying) match at the
        // same exposures: the arrival stamp takes no part in the timing.
        let exposures = |late_ns: fn(u32) -> i64| {
            let config = quickly_locking_config();
            let mut matcher = Matcher::new(config, [2000; 5]);
            for sample in encoder_samples(0, 1_000_000, 700, 0) {
                matcher.push_encoder(sample);
            }
            let mut exposures = Vec::new();
            for k in 0..12u32 {
                let available = 60_000_000 + 50_000_000 * i64::from(k) + 1_000 * i64::from(k % 3);
                let mut frame = frame(k, available);
                frame.arrival_t_ns = available + late_ns(k);
                let _ = matcher.push_frame(frame, Some(LATENCY), frame.arrival_t_ns);
                matcher.poll(700_000_000, |r| {
                    if let Ok(m) = r {
                        exposures.push((m.frame_number, m.exposure_t_ns, m.available_t_ns));
                    }
                });
            }
            exposures
        };
        let on_time = exposures(|_| 0);
        assert_eq!(on_time.len(), 10, "{on_time:?}");
        assert_eq!(
            on_time,
            exposures(|k| 100_000 + 450_000 * i64::from(k % 11))
        );
    }

    #[test]
    fn nothing_is_published_before_the_clock_converges() {
        // With 1 ms of jitter the line needs ~100 frames for 200 µs of predicted uncertainty.
        let (matched, stats) = session(1, 20);
        let first = matched.first().expect("matched after convergence").0;
        assert!(first.quality.clock_frames >= 70, "{first:?}");
        // Every frame before the first match was held back, none after it (the lock holds).
        assert_eq!(
            stats.converging + 1,
            u64::from(first.quality.clock_frames),
            "{stats:?}"
        );
        assert_eq!(stats.matched + stats.converging, stats.frames);
        assert_eq!(stats.matched as usize, matched.len());
    }

    #[test]
    fn a_matcher_warm_started_from_frame_history_matches_the_first_live_frame() {
        // A restarted sync: 10 s of frames it missed (history, no encoder data), then live.
        let restart_ns = 15_000_000_000;
        let mut matcher = Matcher::new(MatcherConfig::default(), [2000, 2000, 4000, 2000, 2000]);
        let mut stream = TrackerStream::new(5, 50_000_000.0, 3, LATENCY.ns);
        let mut live = Vec::new();
        while live.len() < 10 {
            let Some(f) = stream.next_frame() else {
                continue;
            };
            if f.arrival_ns < restart_ns {
                matcher.learn_clock(frame(f.counter, f.arrival_ns));
            } else {
                live.push(f);
            }
        }
        assert_eq!(
            matcher.stats().frames,
            0,
            "history is not counted as received"
        );
        let encoders = encoder_samples(restart_ns, 1_000_000, 600, 20_000);
        let mut matched = Vec::new();
        let mut next_frame = 0;
        for sample in encoders {
            while next_frame < live.len() && live[next_frame].arrival_ns <= sample.t_ns {
                let f = live[next_frame];
                let pushed =
                    matcher.push_frame(frame(f.counter, f.arrival_ns), Some(LATENCY), f.arrival_ns);
                assert_eq!(pushed, Ok(()), "live frame {next_frame} held back");
                next_frame += 1;
            }
            matcher.push_encoder(sample);
            matcher.poll(sample.t_ns, |r| {
                if let Ok(m) = r {
                    matched.push(m);
                }
            });
        }
        // Only a frame exposed before the first encoder sample can be refused (too old).
        let stats = matcher.stats();
        assert!(stats.too_old <= 1, "{stats:?}");
        assert!(matched.len() >= live.len() - 2, "{stats:?}");
        for m in &matched {
            let truth = live.iter().find(|f| f.counter == m.frame_number).unwrap();
            let error = (m.exposure_t_ns - truth.exposure_ns).abs();
            assert!(error <= 500_000, "exposure error {error} ns: {m:?}");
            assert!(m.quality.clock_frames >= 150, "{m:?}");
        }
    }

    #[test]
    fn a_frame_waits_for_the_sample_after_its_exposure_then_times_out() {
        let config = quickly_locking_config();
        let mut matcher = Matcher::new(config, [2000; 5]);
        let latency = Latency {
            ns: 0,
            source: LatencySource::Calibrated,
        };
        for k in 0..3 {
            matcher.push_encoder(EncoderSample {
                seq: k + 1,
                t_ns: 1_000_000 * k as i64,
                counts: [k as i64; 5],
            });
        }
        for k in 0..3u32 {
            let arrival = 1_000_000 + 50_000_000 * i64::from(k);
            let _ = matcher.push_frame(frame(k, arrival), Some(latency), arrival);
        }
        // Frame 2's exposure (101 ms) is after the newest sample (2 ms): it waits.
        let mut results = Vec::new();
        matcher.poll(101_000_000, |r| results.push(r));
        assert!(results.is_empty());
        assert_eq!(matcher.pending(), 1);
        matcher.poll(250_000_000, |r| results.push(r));
        assert_eq!(results, vec![Err((2, Unmatched::TimedOut))]);
        assert_eq!(matcher.stats().timed_out, 1);
        // Without any latency nothing is queued.
        assert_eq!(
            matcher.push_frame(frame(3, 151_000_000), None, 0),
            Err(Unmatched::NoLatency)
        );
    }

    #[test]
    fn lost_encoder_samples_are_counted_and_gaps_refused() {
        let config = quickly_locking_config();
        let mut matcher = Matcher::new(config, [2000; 5]);
        for (seq, t) in [
            (1u64, 0i64),
            (2, 1_000_000),
            (12, 11_000_000),
            (13, 12_000_000),
        ] {
            matcher.push_encoder(EncoderSample {
                seq,
                t_ns: t,
                counts: [0; 5],
            });
        }
        assert_eq!(matcher.stats().encoder_lost, 9);
        let latency = Some(Latency {
            ns: 40_000_000,
            source: LatencySource::Configured,
        });
        let mut results = Vec::new();
        // The first two frames only start the clock; the third's exposure is before the
        // oldest sample.
        for k in 0..6u32 {
            let exposure = 500_000 + (i64::from(k) - 3) * 5_000_000;
            let _ = matcher.push_frame(frame(k, exposure + 40_000_000), latency, 0);
        }
        matcher.poll(0, |r| results.push(r.map(|m| m.frame_number)));
        assert_eq!(
            results,
            vec![
                Err((2, Unmatched::TooOld)),
                Ok(3),
                Err((
                    4,
                    Unmatched::Gap {
                        span_ns: 10_000_000
                    }
                )),
                Err((
                    5,
                    Unmatched::Gap {
                        span_ns: 10_000_000
                    }
                ))
            ]
        );
        assert_eq!(matcher.stats().gaps, 2);
        assert_eq!(matcher.stats().too_old, 1);
    }
}
