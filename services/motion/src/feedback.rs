//! Staleness of a feedback stream (encoders, tracker), on explicit host times so that it can
//! be tested with injected time.

/// Watches when data last arrived on one stream.
#[derive(Debug, Clone, PartialEq)]
pub struct FeedbackWatch {
    name: &'static str,
    deadline_ns: i64,
    last_ns: Option<i64>,
}

impl FeedbackWatch {
    /// A watch of the stream `name` (e.g. "encoder") that is stale after `deadline_ns`
    /// without data.
    pub fn new(name: &'static str, deadline_ns: i64) -> Self {
        Self {
            name,
            deadline_ns,
            last_ns: None,
        }
    }

    /// Records data arriving at host time `now_ns`.
    pub fn feed(&mut self, now_ns: i64) {
        self.last_ns = Some(self.last_ns.map_or(now_ns, |last| last.max(now_ns)));
    }

    /// True once any data arrived.
    pub fn has_data(&self) -> bool {
        self.last_ns.is_some()
    }

    /// Why the stream is stale at `now_ns` (no data for longer than the deadline since the
    /// last data), or `None` while it is fresh or before any data arrived.
    pub fn stale(&self, now_ns: i64) -> Option<String> {
        let silence = now_ns - self.last_ns?;
        (silence > self.deadline_ns).then(|| {
            format!(
                "{} feedback stale: no data for {:.1} ms (deadline {:.1} ms)",
                self.name,
                silence as f64 * 1e-6,
                self.deadline_ns as f64 * 1e-6
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    #[test]
    fn stale_only_after_the_deadline_since_the_last_data() {
        let mut watch = FeedbackWatch::new("encoder", 20 * MS);
        assert!(!watch.has_data());
        assert_eq!(watch.stale(1_000 * MS), None, "never stale before data");
        watch.feed(100 * MS);
        assert_eq!(watch.stale(120 * MS), None);
        let reason = watch.stale(120 * MS + 1).unwrap();
        assert!(reason.starts_with("encoder feedback stale"), "{reason}");
        assert!(reason.contains("deadline 20.0 ms"), "{reason}");
        watch.feed(130 * MS);
        assert_eq!(watch.stale(149 * MS), None);
        // Data stamped out of order never moves the last arrival back.
        watch.feed(125 * MS);
        assert_eq!(watch.stale(150 * MS), None);
        assert!(watch.stale(151 * MS).unwrap().contains("21.0 ms"));
    }
}
