//! The host clock every message time stamp uses.

use nix::time::{clock_gettime, ClockId};

/// Host `CLOCK_MONOTONIC` now, in nanoseconds (the `t_ns` of every message and recording).
pub fn monotonic_ns() -> i64 {
    // CLOCK_MONOTONIC cannot fail on Linux; 0 would only show up as an obviously wrong time.
    clock_gettime(ClockId::CLOCK_MONOTONIC)
        .map(|t| t.tv_sec() * 1_000_000_000 + t.tv_nsec())
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn is_monotonic_and_advances_with_std_clock() {
        let std_start = std::time::Instant::now();
        let a = monotonic_ns();
        std::thread::sleep(std::time::Duration::from_millis(5));
        let b = monotonic_ns();
        let std_elapsed = std_start.elapsed().as_nanos() as i64;
        assert!(b - a >= 5_000_000, "advanced only {} ns", b - a);
        assert!(
            b - a <= std_elapsed,
            "{} ns > std's {std_elapsed} ns",
            b - a
        );
    }
}
