//! The recent encoder samples and linear interpolation of their counts at any host time.

use sabr_msgs::{EncoderSample, JOINTS};
use std::collections::VecDeque;

/// What adding a sample found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pushed {
    /// The next sample in sequence.
    InSequence,
    /// `lost` samples are missing before this one (sequence gap).
    AfterGap {
        /// Samples missing.
        lost: u64,
    },
    /// The sequence number restarted (the encoders process restarted).
    SequenceRestarted,
    /// Refused: its time stamp is not after the newest sample's (ns).
    NotAfter {
        /// The previous newest time stamp.
        newest_ns: i64,
    },
}

/// Counts interpolated at a time, and how well that time was bracketed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interpolated {
    /// Counts of joints 1..5, linear between the bracketing samples (fractional).
    pub counts: [f64; JOINTS],
    /// Time between the two bracketing samples, ns.
    pub span_ns: i64,
    /// Distance from the time to the nearer bracketing sample, ns.
    pub nearest_ns: i64,
}

/// The result of a look-up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lookup {
    /// Bracketed by two samples.
    Found(Interpolated),
    /// No sample after the time has arrived yet: wait.
    NotYet,
    /// The time is before the oldest sample kept (or no sample was ever received).
    TooOld,
    /// The bracketing samples are further apart than allowed (samples were lost), ns.
    Gap {
        /// Time between the bracketing samples, ns.
        span_ns: i64,
    },
}

/// A ring buffer of the most recent encoder samples, oldest first, time stamps increasing.
#[derive(Debug, Clone)]
pub struct EncoderBuffer {
    samples: VecDeque<EncoderSample>,
    capacity: usize,
    last_seq: Option<u64>,
}

impl EncoderBuffer {
    /// A buffer keeping the newest `capacity` samples (at least 2).
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(2);
        Self {
            samples: VecDeque::with_capacity(capacity),
            capacity,
            last_seq: None,
        }
    }

    /// Adds the newest sample, dropping the oldest beyond the capacity. A sample whose time
    /// stamp is not after the newest one is refused (the buffer must stay sorted).
    pub fn push(&mut self, sample: EncoderSample) -> Pushed {
        if let Some(newest) = self.samples.back() {
            if sample.t_ns <= newest.t_ns {
                return Pushed::NotAfter {
                    newest_ns: newest.t_ns,
                };
            }
        }
        let pushed = match self.last_seq {
            Some(last) if sample.seq == last.wrapping_add(1) => Pushed::InSequence,
            Some(last) if sample.seq > last => Pushed::AfterGap {
                lost: sample.seq - last - 1,
            },
            Some(_) => Pushed::SequenceRestarted,
            None => Pushed::InSequence,
        };
        self.last_seq = Some(sample.seq);
        if self.samples.len() == self.capacity {
            self.samples.pop_front();
        }
        self.samples.push_back(sample);
        pushed
    }

    /// Number of samples kept.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True if no sample was kept yet.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Time stamp of the newest sample, ns.
    pub fn newest_ns(&self) -> Option<i64> {
        self.samples.back().map(|s| s.t_ns)
    }

    /// Counts at host time `t_ns`, linear between the last sample at or before it and the
    /// first sample after it; refused if those are more than `max_span_ns` apart.
    pub fn at(&self, t_ns: i64, max_span_ns: i64) -> Lookup {
        let after = self.samples.partition_point(|s| s.t_ns <= t_ns);
        if after == self.samples.len() {
            return if self.samples.is_empty() {
                Lookup::TooOld
            } else {
                Lookup::NotYet
            };
        }
        if after == 0 {
            return Lookup::TooOld;
        }
        let (a, b) = (&self.samples[after - 1], &self.samples[after]);
        let span_ns = b.t_ns - a.t_ns;
        if span_ns > max_span_ns {
            return Lookup::Gap { span_ns };
        }
        let fraction = (t_ns - a.t_ns) as f64 / span_ns as f64;
        let counts = std::array::from_fn(|j| {
            a.counts[j] as f64 + fraction * (b.counts[j] - a.counts[j]) as f64
        });
        Lookup::Found(Interpolated {
            counts,
            span_ns,
            nearest_ns: (t_ns - a.t_ns).min(b.t_ns - t_ns),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_streams::{encoder_samples, true_counts};

    fn sample(seq: u64, t_ns: i64, c: i64) -> EncoderSample {
        EncoderSample {
            seq,
            t_ns,
            counts: [c, -c, 2 * c, 0, 7],
        }
    }

    #[test]
    fn interpolates_linearly_between_the_bracketing_samples() {
        let mut buffer = EncoderBuffer::new(10);
        buffer.push(sample(1, 1_000_000, 10));
        buffer.push(sample(2, 2_000_000, 20));
        let Lookup::Found(i) = buffer.at(1_250_000, 5_000_000) else {
            panic!()
        };
        assert_eq!(i.counts, [12.5, -12.5, 25.0, 0.0, 7.0]);
        assert_eq!(i.span_ns, 1_000_000);
        assert_eq!(i.nearest_ns, 250_000);
        // Exactly on a sample: that sample's counts.
        let Lookup::Found(i) = buffer.at(1_000_000, 5_000_000) else {
            panic!()
        };
        assert_eq!(i.counts[0], 10.0);
        assert_eq!(buffer.at(2_000_000, 5_000_000), Lookup::NotYet);
        assert_eq!(buffer.at(999_999, 5_000_000), Lookup::TooOld);
    }

    #[test]
    fn waits_for_the_sample_after_and_refuses_gaps() {
        let mut buffer = EncoderBuffer::new(10);
        assert_eq!(buffer.at(0, 1), Lookup::TooOld);
        buffer.push(sample(1, 1_000_000, 1));
        assert_eq!(buffer.at(1_500_000, 5_000_000), Lookup::NotYet);
        assert_eq!(
            buffer.push(sample(9, 9_000_000, 9)),
            Pushed::AfterGap { lost: 7 }
        );
        assert_eq!(
            buffer.at(1_500_000, 5_000_000),
            Lookup::Gap { span_ns: 8_000_000 }
        );
    }

    #[test]
    fn sequence_and_time_checks() {
        let mut buffer = EncoderBuffer::new(3);
        assert_eq!(buffer.push(sample(5, 10, 0)), Pushed::InSequence);
        assert_eq!(buffer.push(sample(6, 20, 0)), Pushed::InSequence);
        assert_eq!(
            buffer.push(sample(7, 20, 0)),
            Pushed::NotAfter { newest_ns: 20 }
        );
        assert_eq!(buffer.push(sample(1, 30, 0)), Pushed::SequenceRestarted);
        assert_eq!(buffer.push(sample(2, 40, 0)), Pushed::InSequence);
        assert_eq!(buffer.len(), 3, "capacity");
        assert_eq!(buffer.at(15, 100), Lookup::TooOld, "oldest dropped");
        assert_eq!(buffer.newest_ns(), Some(40));
    }

    #[test]
    fn interpolation_error_on_a_jittered_1khz_stream_is_below_a_count() {
        let mut buffer = EncoderBuffer::new(3000);
        for s in encoder_samples(1_000_000_000, 1_000_000, 3000, 20_000) {
            assert_eq!(buffer.push(s), Pushed::InSequence);
        }
        for k in 0..500 {
            let t = 1_100_000_000 + k * 3_700_123;
            let Lookup::Found(i) = buffer.at(t, 5_000_000) else {
                panic!("{t}")
            };
            let truth = true_counts(t);
            for (j, (got, want)) in i.counts.iter().zip(truth).enumerate() {
                assert!(
                    (got - want).abs() < 1.0,
                    "joint {j} at {t}: {got} vs {want}"
                );
            }
            assert!(i.span_ns <= 1_040_000 && i.nearest_ns <= i.span_ns / 2);
        }
    }
}
