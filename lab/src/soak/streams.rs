//! Sequence-number and rate bookkeeping of one sample stream as a subscriber sees it.

/// Counts what arrived on a stream whose publisher numbers its samples `seq` = 1, 2, 3, …:
/// gaps (lost samples), restarts (a new publisher starting again), and the arrival rate inside
/// the measurement window.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SeqCheck {
    /// Samples received in all.
    pub received: u64,
    /// Samples missing inside sequence gaps (`seq` jumped forward by more than one).
    pub lost: u64,
    /// Number of sequence gaps.
    pub gaps: u64,
    /// Times `seq` did not increase: the publisher restarted (its samples in between are
    /// unaccounted for).
    pub restarts: u64,
    /// The first `seq` received.
    pub first_seq: Option<u64>,
    /// Samples received since [`SeqCheck::start_window`].
    pub window_received: u64,
    /// Longest time between consecutive samples' own time stamps since the window start, ns.
    pub window_max_interval_ns: i64,
    last_seq: Option<u64>,
    last_t_ns: Option<i64>,
    in_window: bool,
}

impl SeqCheck {
    /// Records one sample with its sequence number and time stamp (host `CLOCK_MONOTONIC`, ns);
    /// returns how many samples are missing right before it.
    pub fn push(&mut self, seq: u64, t_ns: i64) -> u64 {
        self.received += 1;
        self.first_seq.get_or_insert(seq);
        let mut missing = 0;
        match self.last_seq {
            Some(last) if seq == last.wrapping_add(1) => {}
            Some(last) if seq > last => {
                missing = seq - last - 1;
                self.lost += missing;
                self.gaps += 1;
            }
            Some(_) => self.restarts += 1,
            None => {}
        }
        if self.in_window {
            self.window_received += 1;
            if let Some(last_t) = self.last_t_ns {
                self.window_max_interval_ns = self.window_max_interval_ns.max(t_ns - last_t);
            }
        }
        self.last_seq = Some(seq);
        self.last_t_ns = Some(t_ns);
        missing
    }

    /// Starts counting [`SeqCheck::window_received`] and the longest interval from now on.
    pub fn start_window(&mut self) {
        self.in_window = true;
        self.window_received = 0;
        self.window_max_interval_ns = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    #[test]
    fn counts_gaps_and_restarts() {
        let mut check = SeqCheck::default();
        assert_eq!(check.push(5, 0), 0);
        assert_eq!(check.push(6, MS), 0);
        assert_eq!(check.push(9, 4 * MS), 2);
        assert_eq!(check.push(1, 5 * MS), 0);
        assert_eq!(check.push(2, 6 * MS), 0);
        assert_eq!(check.push(2, 7 * MS), 0);
        assert_eq!(check.received, 6);
        assert_eq!((check.lost, check.gaps, check.restarts), (2, 1, 2));
        assert_eq!(check.first_seq, Some(5));
    }

    #[test]
    fn window_counts_only_after_its_start() {
        let mut check = SeqCheck::default();
        check.push(1, 0);
        check.push(2, 50 * MS);
        check.start_window();
        check.push(3, 51 * MS);
        check.push(4, 54 * MS);
        check.push(5, 55 * MS);
        assert_eq!(check.window_received, 3);
        assert_eq!(check.window_max_interval_ns, 3 * MS);
        assert_eq!(check.received, 5);
    }
}
