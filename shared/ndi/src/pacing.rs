//! When to start polling for the next frame.
//!
//! A tracker makes frames at a steady rate (a Polaris at 20 or 60 Hz) and only answers when
//! polled, so the driver learns of a new frame at the first poll that carries its number. To
//! know when a frame became available within a poll interval ([`crate::availability`]), the
//! polls just before and just after it must be one poll interval apart; the polls in the rest
//! of the frame period only find the previous frame again. Every one of them costs the host a
//! write, a read and two wake-ups, and the device an answer (at 20 Hz and a 1 ms interval,
//! about 49 of every 50 polls).
//!
//! [`PollPacer`] remembers the arrivals of the last few new frames and predicts the next one:
//! the frame period is the median interval between them (robust to a skipped frame and to a
//! late one), and each remembered arrival, carried forward by whole periods, predicts the
//! next; the earliest prediction counts, so one late frame does not make the next look
//! early. After a frame, polling pauses until a lead time before that prediction, and before
//! it by the longest recent exchange too (a poll sees a frame if it was *sent* after the frame
//! became available, but arrivals come an exchange later: on a real serial line at 115 200
//! baud a BX reply takes over 10 ms); from then on the driver polls every poll interval until
//! the frame is there, as without a pause. So the bracket of every frame is as narrow as
//! before.
//!
//! A frame that is there already at the first poll after a pause came sooner than predicted
//! (the device's rate went up, or a frame was earlier than the lead allows for): its bracket
//! is the pause, and the pacer forgets the arrivals, so that polling goes on without pauses
//! until it has learnt them again. A frame that is late only means more polls at the poll
//! interval.
//!
//! Times are [`Instant`]s passed in by the caller (no I/O).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// New frames remembered.
const ARRIVALS_REMEMBERED: usize = 9;
/// Arrivals needed before polling pauses after a frame (three intervals).
const ARRIVALS_NEEDED: usize = 4;

/// When to send the first poll for the next frame, from the arrivals of the frames before it
/// (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PollPacer {
    poll_interval: Duration,
    lead: Duration,
    /// The last new frames, newest last: each one's arrival, and the exchange of the poll that
    /// saw it (from starting the poll to its reply).
    frames: VecDeque<(Instant, Duration)>,
}

impl PollPacer {
    /// A pacer for polls `poll_interval` apart that resume `lead` before a frame is due.
    pub fn new(poll_interval: Duration, lead: Duration) -> Self {
        PollPacer {
            poll_interval,
            lead,
            frames: VecDeque::with_capacity(ARRIVALS_REMEMBERED),
        }
    }

    /// The frame period: the median interval between the remembered arrivals (`None` with
    /// fewer than [`ARRIVALS_NEEDED`]).
    pub fn period(&self) -> Option<Duration> {
        if self.frames.len() < ARRIVALS_NEEDED {
            return None;
        }
        let mut intervals = [Duration::ZERO; ARRIVALS_REMEMBERED - 1];
        let count = self.frames.len() - 1;
        for (interval, ((earlier, _), (later, _))) in intervals
            .iter_mut()
            .zip(self.frames.iter().zip(self.frames.iter().skip(1)))
        {
            *interval = later.saturating_duration_since(*earlier);
        }
        let intervals = &mut intervals[..count];
        intervals.sort_unstable();
        Some(intervals[count / 2])
    }

    /// How long after the last new frame polling resumes: `lead` plus the longest exchange
    /// remembered before the next frame is predicted, at least one poll interval (that alone
    /// before the first frame and until the period is known).
    pub fn pause(&self) -> Duration {
        let (Some(period), Some(&(last, _))) = (self.period(), self.frames.back()) else {
            return self.poll_interval;
        };
        if period.is_zero() {
            return self.poll_interval;
        }
        let predicted = self
            .frames
            .iter()
            .map(|&(arrival, _)| {
                let since = last.saturating_duration_since(arrival);
                let periods = (since.as_secs_f64() / period.as_secs_f64()).round() as u32 + 1;
                arrival + period * periods
            })
            .min()
            .unwrap_or(last + period);
        let exchange = self.frames.iter().map(|&(_, exchange)| exchange).max();
        predicted
            .saturating_duration_since(last)
            .saturating_sub(self.lead + exchange.unwrap_or_default())
            .max(self.poll_interval)
    }

    /// A new frame arrived at `arrival`, `exchange` after the poll that saw it was started,
    /// that poll being the first since the previous frame if `at_first_poll`. Returns true if
    /// that poll followed a pause longer than the poll interval: the frame came sooner than
    /// predicted, its bracket is the pause, and the frames before it are forgotten.
    pub fn frame_arrived(
        &mut self,
        arrival: Instant,
        exchange: Duration,
        at_first_poll: bool,
    ) -> bool {
        let early = at_first_poll && self.pause() > self.poll_interval;
        if early {
            self.frames.clear();
        }
        if self.frames.len() == ARRIVALS_REMEMBERED {
            self.frames.pop_front();
        }
        self.frames.push_back((arrival, exchange));
        early
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);
    /// Replies taken as instantaneous (on a pseudo-terminal they take tens of µs).
    const NO_EXCHANGE: Duration = Duration::ZERO;

    /// A pacer (1 ms polls, 5 ms lead) fed new frames arriving at `arrivals_ms` after `start`,
    /// none of them early.
    fn fed(start: Instant, arrivals_ms: &[u64]) -> PollPacer {
        let mut pacer = PollPacer::new(MS, 5 * MS);
        for &ms in arrivals_ms {
            assert!(
                !pacer.frame_arrived(start + Duration::from_millis(ms), NO_EXCHANGE, false),
                "{ms} ms"
            );
        }
        pacer
    }

    #[test]
    fn polling_pauses_until_the_lead_before_the_next_frame_once_three_intervals_are_known() {
        let start = Instant::now();
        assert_eq!(PollPacer::new(MS, 5 * MS).pause(), MS);
        let pacer = fed(start, &[0, 50, 100]);
        assert_eq!((pacer.period(), pacer.pause()), (None, MS));
        let pacer = fed(start, &[0, 50, 100, 150]);
        assert_eq!((pacer.period(), pacer.pause()), (Some(50 * MS), 45 * MS));
    }

    #[test]
    fn a_late_frame_does_not_move_the_next_one_and_a_skipped_one_does_not_change_the_period() {
        let start = Instant::now();
        // The frame due at 200 ms came 3 ms late: the next is still due at 250 ms.
        let pacer = fed(start, &[0, 50, 100, 150, 203]);
        assert_eq!(pacer.period(), Some(50 * MS));
        assert_eq!(pacer.pause(), 42 * MS, "first poll at 245 ms");
        // The frame due at 200 ms never came.
        let pacer = fed(start, &[0, 50, 100, 150, 250]);
        assert_eq!(pacer.period(), Some(50 * MS));
        assert_eq!(pacer.pause(), 45 * MS, "first poll at 295 ms");
        // Only the last nine arrivals count: the late one has left.
        let later: Vec<u64> = (5..=13).map(|n| 50 * n).collect();
        let pacer = fed(start, &[[0, 50, 100, 150, 203].as_slice(), &later].concat());
        assert_eq!(pacer.pause(), 45 * MS, "first poll at 695 ms");
    }

    #[test]
    fn polling_resumes_earlier_by_the_longest_recent_exchange() {
        // A real serial line: a BX reply takes 13 ms, once 14 ms.
        let mut pacer = PollPacer::new(MS, 5 * MS);
        let start = Instant::now();
        for (n, exchange_ms) in [13, 14, 13, 13].into_iter().enumerate() {
            let arrival = start + 50 * MS * n as u32;
            assert!(!pacer.frame_arrived(arrival, exchange_ms * MS, false));
        }
        assert_eq!(pacer.pause(), 31 * MS, "first poll at 181 ms");
    }

    #[test]
    fn a_frame_there_at_the_first_poll_after_a_pause_makes_polling_start_over() {
        let start = Instant::now();
        let mut pacer = fed(start, &[0, 50, 100, 150]);
        // The device's period shortened to 40 ms: the first poll, 45 ms after the last frame,
        // finds the next one there already.
        assert!(pacer.frame_arrived(start + 195 * MS, NO_EXCHANGE, true));
        assert_eq!((pacer.period(), pacer.pause()), (None, MS));
        // Relearnt from polls every millisecond.
        for ms in [235, 275, 315] {
            assert!(!pacer.frame_arrived(start + Duration::from_millis(ms), NO_EXCHANGE, false));
        }
        assert_eq!(pacer.period(), Some(40 * MS));
        assert_eq!(pacer.pause(), 35 * MS, "first poll at 350 ms");
    }

    #[test]
    fn without_a_pause_a_frame_at_every_poll_is_not_early() {
        // A device faster than the poll interval: every first poll sees a new frame.
        let mut pacer = PollPacer::new(5 * MS, 5 * MS);
        let mut at = Instant::now();
        for _ in 0..20 {
            assert!(!pacer.frame_arrived(at, NO_EXCHANGE, true));
            at += 5 * MS;
        }
        assert_eq!(pacer.pause(), 5 * MS);
    }

    #[test]
    fn a_lead_as_long_as_the_period_never_pauses() {
        let mut pacer = PollPacer::new(MS, 60 * MS);
        let start = Instant::now();
        for n in 0..10_u32 {
            assert!(!pacer.frame_arrived(start + n * 50 * MS, NO_EXCHANGE, true));
        }
        assert_eq!(pacer.pause(), MS);
    }
}
