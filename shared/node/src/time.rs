//! The host clock every message time stamp uses, and the grid periodic loops keep on it.

use nix::time::{clock_gettime, ClockId};

/// Host `CLOCK_MONOTONIC` now, in nanoseconds (the `t_ns` of every message and recording).
pub fn monotonic_ns() -> i64 {
    // CLOCK_MONOTONIC cannot fail on Linux; 0 would only show up as an obviously wrong time.
    clock_gettime(ClockId::CLOCK_MONOTONIC)
        .map(|t| t.tv_sec() * 1_000_000_000 + t.tv_nsec())
        .unwrap_or(0)
}

/// Time (ns) from `now_ns` to the next instant `t ≥ now_ns` of `CLOCK_MONOTONIC` with
/// `t ≡ phase_ns (mod period_ns)`: where a loop of that period and phase has its next
/// deadline. The phase is taken modulo the period; a non-positive period gives 0.
pub fn delay_to_phase(now_ns: i64, period_ns: i64, phase_ns: i64) -> i64 {
    if period_ns <= 0 {
        return 0;
    }
    (phase_ns - now_ns).rem_euclid(period_ns)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_next_deadline_on_the_grid_is_never_in_the_past() {
        // Period 1 ms, phase 300 µs.
        assert_eq!(delay_to_phase(5_000_000, 1_000_000, 300_000), 300_000);
        assert_eq!(delay_to_phase(5_300_000, 1_000_000, 300_000), 0);
        assert_eq!(delay_to_phase(5_300_001, 1_000_000, 300_000), 999_999);
        assert_eq!(delay_to_phase(5_900_000, 1_000_000, 300_000), 400_000);
        // The phase modulo the period: 600 µs on a 500 µs grid is 100 µs.
        assert_eq!(delay_to_phase(1_000_000, 500_000, 600_000), 100_000);
        assert_eq!(delay_to_phase(1_000_000, 0, 600_000), 0);
    }

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
