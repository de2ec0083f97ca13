//! Deadlines on incoming data, so a waiting node notices a dead or stalled peer.

use std::time::{Duration, Instant};

/// Tracks when data last arrived on a stream and whether it is overdue.
///
/// ```
/// use sabr_node::Deadline;
/// use std::time::Duration;
/// let mut encoders = Deadline::new(Duration::from_millis(20));
/// encoders.feed(); // on every sample
/// assert!(!encoders.expired());
/// ```
#[derive(Debug, Clone)]
pub struct Deadline {
    limit: Duration,
    last: Instant,
    fed: bool,
}

impl Deadline {
    /// A deadline of `limit` between samples; the first period starts now.
    pub fn new(limit: Duration) -> Self {
        Self {
            limit,
            last: Instant::now(),
            fed: false,
        }
    }

    /// Records that data arrived now.
    pub fn feed(&mut self) {
        self.last = Instant::now();
        self.fed = true;
    }

    /// True if no data arrived within the limit (counting from creation before the first).
    pub fn expired(&self) -> bool {
        self.last.elapsed() > self.limit
    }

    /// How long ago the last data arrived (or the deadline was created).
    pub fn silence(&self) -> Duration {
        self.last.elapsed()
    }

    /// Time left before the deadline expires (zero once expired): the longest a wait may block.
    pub fn remaining(&self) -> Duration {
        self.limit.saturating_sub(self.last.elapsed())
    }

    /// True once any data has arrived.
    pub fn has_data(&self) -> bool {
        self.fed
    }

    /// The configured limit.
    pub fn limit(&self) -> Duration {
        self.limit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expires_without_data_and_recovers_when_fed() {
        let mut deadline = Deadline::new(Duration::from_millis(10));
        assert!(!deadline.expired());
        assert!(!deadline.has_data());
        std::thread::sleep(Duration::from_millis(15));
        assert!(deadline.expired());
        assert_eq!(deadline.remaining(), Duration::ZERO);
        deadline.feed();
        assert!(!deadline.expired());
        assert!(deadline.has_data());
        assert!(deadline.remaining() > Duration::ZERO);
    }
}
