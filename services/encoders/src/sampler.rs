//! The sampling logic of `encoders`, apart from the process: the newest latch of the rig's
//! counter register, read at the sampler's instants, published only while it is fresh.

use sabr_msgs::{CounterLatch, EncoderSample};

/// What one sampling instant yields.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reading {
    /// A fresh sample to publish.
    Sample(EncoderSample),
    /// The register's newest latch is older than the limit: the rig is stalled or dead.
    Stale {
        /// Age of the newest latch, ns.
        age_ns: i64,
        /// Its sequence number.
        latch_seq: u64,
    },
    /// No latch was ever read.
    NoData,
}

/// Reads the counter register and numbers the samples.
#[derive(Debug, Clone)]
pub struct Sampler {
    register: Option<CounterLatch>,
    stale_after_ns: i64,
    seq: u64,
}

impl Sampler {
    /// A sampler that treats a latch older than `stale_after_ns` as stale.
    pub fn new(stale_after_ns: i64) -> Self {
        Sampler {
            register: None,
            stale_after_ns,
            seq: 0,
        }
    }

    /// Takes a latch from the rig; an older one than the register holds is ignored.
    pub fn latch(&mut self, latch: CounterLatch) {
        if self
            .register
            .is_none_or(|held| latch.latch_t_ns >= held.latch_t_ns)
        {
            self.register = Some(latch);
        }
    }

    /// The register read at host time `now_ns`: a sample stamped `now_ns` with the next
    /// sequence number, unless the newest latch is stale.
    pub fn read(&mut self, now_ns: i64) -> Reading {
        let Some(latch) = self.register else {
            return Reading::NoData;
        };
        let age_ns = now_ns - latch.latch_t_ns;
        if age_ns > self.stale_after_ns {
            return Reading::Stale {
                age_ns,
                latch_seq: latch.seq,
            };
        }
        self.seq += 1;
        Reading::Sample(EncoderSample {
            seq: self.seq,
            t_ns: now_ns,
            counts: latch.counts,
        })
    }

    /// Age of the newest latch at `now_ns`, if any.
    pub fn age_ns(&self, now_ns: i64) -> Option<i64> {
        self.register.map(|latch| now_ns - latch.latch_t_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn latch(seq: u64, t: i64, c: i64) -> CounterLatch {
        CounterLatch {
            seq,
            latch_t_ns: t,
            counts: [c, -c, 2 * c, 0, 7],
        }
    }

    #[test]
    fn samples_carry_the_newest_counts_and_contiguous_numbers() {
        let mut sampler = Sampler::new(10_000_000);
        assert_eq!(sampler.read(0), Reading::NoData);
        sampler.latch(latch(1, 1_000, 5));
        sampler.latch(latch(2, 1_500, 6));
        let Reading::Sample(first) = sampler.read(1_700) else {
            panic!("no sample");
        };
        assert_eq!(
            (first.seq, first.t_ns, first.counts),
            (1, 1_700, latch(2, 0, 6).counts)
        );
        // A late, older latch does not roll the register back.
        sampler.latch(latch(1, 1_000, 5));
        let Reading::Sample(second) = sampler.read(2_700) else {
            panic!("no sample");
        };
        assert_eq!((second.seq, second.counts), (2, latch(2, 0, 6).counts));
        assert_eq!(sampler.age_ns(2_700), Some(1_200));
    }

    #[test]
    fn stale_register_yields_no_sample_until_fresh_again() {
        let mut sampler = Sampler::new(10_000_000);
        sampler.latch(latch(1, 0, 1));
        assert!(matches!(sampler.read(10_000_000), Reading::Sample(_)));
        assert_eq!(
            sampler.read(10_000_001),
            Reading::Stale {
                age_ns: 10_000_001,
                latch_seq: 1
            }
        );
        sampler.latch(latch(2, 20_000_000, 3));
        let Reading::Sample(sample) = sampler.read(20_500_000) else {
            panic!("no sample");
        };
        // Numbering continues: a stale instant is not a lost sample.
        assert_eq!((sample.seq, sample.counts[0]), (2, 3));
    }
}
