//! When a tracker frame became available at the device, estimated from the polls around it.
//!
//! The device only answers when polled, so the host learns of a new frame at the first poll
//! whose reply carries its frame number. The frame became available at the device after the
//! previous poll was answered (that reply still carried an older frame number) and before this
//! poll was answered: between the send times of the two polls. [`AvailabilityEstimator`] takes
//! the midpoint of that bracket; the error is at most ± half the gap between the two polls
//! (± ½ ms at the driver's 1 ms poll interval, plus the time of one serial exchange), and on
//! average zero if frames become available at random instants between polls. Stamping the
//! frame on the arrival of the reply instead is late by about half a poll gap plus one
//! exchange, on average.
//!
//! The first frame has no earlier poll to bracket it: it is stamped with the send time of the
//! poll that saw it (and may have been available for any time before). A frame number skipped
//! between two polls changes nothing: the frame that is seen is bracketed the same way. Only
//! polls that were answered should be fed: a poll without a reply says nothing about the device.
//!
//! Every time here is host `CLOCK_MONOTONIC` in ns, passed in by the caller (no I/O).

/// When a frame became available at the device: the estimate and its bracket, host
/// `CLOCK_MONOTONIC` ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Availability {
    /// The estimate: the midpoint of `earliest_ns..=latest_ns`, ns.
    pub estimate_ns: i64,
    /// Send time of the last poll whose reply did not carry the frame yet, ns (for the first
    /// frame, the send time of the poll that saw it: no lower bound is known).
    pub earliest_ns: i64,
    /// Send time of the first poll whose reply carried the frame, ns.
    pub latest_ns: i64,
}

impl Availability {
    /// The bracket `earliest_ns..=latest_ns` and its midpoint.
    fn between(earliest_ns: i64, latest_ns: i64) -> Availability {
        Availability {
            estimate_ns: earliest_ns + (latest_ns - earliest_ns) / 2,
            earliest_ns,
            latest_ns,
        }
    }

    /// The error bound of the estimate: half the bracket's width, ns (0 for the first frame,
    /// whose bracket is unknown rather than exact).
    pub fn half_width_ns(&self) -> i64 {
        (self.latest_ns - self.earliest_ns) / 2
    }
}

/// Estimates when each frame became available at the device from the send times of the
/// polls that saw it and the one before (see the module documentation). Fed one answered
/// poll at a time, in sending order.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AvailabilityEstimator {
    /// Send time of the previous answered poll, ns.
    last_sent_ns: Option<i64>,
    /// The frame number of the previous poll's reply and its availability.
    current: Option<(Option<u32>, Availability)>,
}

impl AvailabilityEstimator {
    /// A fresh estimator: the next frame it is fed is a first frame.
    pub fn new() -> Self {
        AvailabilityEstimator::default()
    }

    /// Feeds one answered poll: sent at `sent_ns` (host `CLOCK_MONOTONIC` ns), its reply
    /// carrying frame number `frame` (`None`: no frame number). Returns the availability of
    /// that frame: a new bracket if the frame number differs from the previous poll's, else
    /// the one from when it was first seen.
    pub fn observe(&mut self, sent_ns: i64, frame: Option<u32>) -> Availability {
        let availability = match self.current {
            Some((seen, availability)) if seen == frame => availability,
            _ => Availability::between(self.last_sent_ns.unwrap_or(sent_ns), sent_ns),
        };
        self.current = Some((frame, availability));
        self.last_sent_ns = Some(sent_ns);
        availability
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    #[test]
    fn a_new_frame_is_stamped_midway_between_the_polls_around_it() {
        let mut estimator = AvailabilityEstimator::new();
        // The first frame: no earlier poll, the seeing poll's send time.
        let first = estimator.observe(10 * MS, Some(40));
        assert_eq!(first, Availability::between(10 * MS, 10 * MS));
        assert_eq!((first.estimate_ns, first.half_width_ns()), (10 * MS, 0));
        // Repeats of the same frame keep its bracket.
        assert_eq!(estimator.observe(11 * MS, Some(40)), first);
        assert_eq!(estimator.observe(12 * MS, Some(40)), first);
        // Frame 41 became available between the poll at 12 ms and the one at 13.2 ms.
        let next = estimator.observe(13 * MS + 200_000, Some(41));
        assert_eq!(
            next,
            Availability {
                estimate_ns: 12 * MS + 600_000,
                earliest_ns: 12 * MS,
                latest_ns: 13 * MS + 200_000,
            }
        );
        assert_eq!(next.half_width_ns(), 600_000);
        assert_eq!(estimator.observe(14 * MS, Some(41)), next);
    }

    #[test]
    fn a_frame_skipped_between_polls_brackets_the_one_seen() {
        let mut estimator = AvailabilityEstimator::new();
        estimator.observe(0, Some(7));
        estimator.observe(MS, Some(7));
        // Frames 8 and 9 both came after the poll at 1 ms; only 9 is seen, at 3 ms (a slow
        // exchange in between).
        let seen = estimator.observe(3 * MS, Some(9));
        assert_eq!(seen, Availability::between(MS, 3 * MS));
        assert_eq!((seen.estimate_ns, seen.half_width_ns()), (2 * MS, MS));
    }

    #[test]
    fn a_reply_without_frame_number_counts_as_a_frame_of_its_own() {
        let mut estimator = AvailabilityEstimator::new();
        estimator.observe(0, None);
        assert_eq!(estimator.observe(MS, None), Availability::between(0, 0));
        assert_eq!(
            estimator.observe(2 * MS, Some(1)),
            Availability::between(MS, 2 * MS)
        );
    }

    #[test]
    fn the_estimate_is_unbiased_over_uniform_availability() {
        // Frames every 50 ms, polls every 1 ms; the stamp error averages out to zero, where
        // the seeing poll's send time alone would be late by half a poll interval.
        let mut estimator = AvailabilityEstimator::new();
        let mut errors = Vec::new();
        let mut poll_ns = 0;
        for frame in 0..200_i64 {
            let available_ns = 1_000 + frame * 50 * MS + (frame * 7_919 * 1_000) % MS;
            while poll_ns < available_ns {
                estimator.observe(poll_ns, Some((frame - 1) as u32));
                poll_ns += MS;
            }
            let availability = estimator.observe(poll_ns, Some(frame as u32));
            poll_ns += MS;
            if frame > 0 {
                let error = availability.estimate_ns - available_ns;
                assert!(error.abs() <= availability.half_width_ns(), "{error}");
                errors.push(error);
            }
        }
        let mean = errors.iter().sum::<i64>() as f64 / errors.len() as f64;
        assert!(mean.abs() < 0.05 * MS as f64, "mean error {mean} ns");
    }
}
