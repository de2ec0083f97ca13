//! The host's timer at the graph's clock rate: how late a thread placed like the encoders
//! wakes from a sleep until an absolute deadline every millisecond (the measurement
//! `cyclictest` makes). Every periodic node starts its cycle with such a wake-up, and on a
//! virtual machine the timer interrupt passes through the hypervisor: a late wake-up tells of
//! a host that was busy elsewhere at that moment, and the caches the node finds then are
//! colder too. This row is the host's, not the graph's; it has no goal, it tells how far the
//! hop tails of a run are the machine's.

use super::stats::Measurement;
use anyhow::Context;
use rustix::thread::{clock_nanosleep_absolute, ClockId, Timespec};
use sabr_node::{delay_to_phase, monotonic_ns};
use std::time::Duration;

/// Lateness of each wake-up after its deadline (ns), the thread placed as the encoders.
pub const TIMER_LATENESS: &str = "timer/encoders-tick";

/// Sleeps until `ticks` deadlines `period` apart (`CLOCK_MONOTONIC`, the clock of every
/// message's `t_ns`) from the calling thread, recording how late each wake-up came. A
/// wake-up later than a whole period skips the deadlines it missed, as the nodes' loops do.
pub fn lateness(ticks: u64, period: Duration) -> anyhow::Result<Measurement> {
    let period_ns = i64::try_from(period.as_nanos()).context("timer period too long")?;
    let mut measured = Measurement::new(TIMER_LATENESS, "ns");
    let mut due = monotonic_ns() + period_ns;
    for _ in 0..ticks {
        sleep_until(due)?;
        let woke = monotonic_ns();
        measured.record(u64::try_from(woke - due).unwrap_or(0))?;
        due = next_deadline(due, woke, period_ns);
    }
    Ok(measured)
}

/// Sleeps until `due_ns` on `CLOCK_MONOTONIC` (at once if it has passed).
pub(super) fn sleep_until(due_ns: i64) -> anyhow::Result<()> {
    let deadline = Timespec {
        tv_sec: due_ns.div_euclid(1_000_000_000),
        tv_nsec: due_ns.rem_euclid(1_000_000_000),
    };
    loop {
        match clock_nanosleep_absolute(ClockId::Monotonic, &deadline) {
            Ok(()) => return Ok(()),
            Err(rustix::io::Errno::INTR) => continue,
            Err(error) => return Err(error).context("clock_nanosleep on CLOCK_MONOTONIC"),
        }
    }
}

/// The deadline after `due_ns` for a wake-up at `woke_ns`: the first one on the grid of
/// `due_ns` still ahead (one period on, or more when the wake-up came a whole period late).
fn next_deadline(due_ns: i64, woke_ns: i64, period_ns: i64) -> i64 {
    let after = woke_ns + 1;
    after + delay_to_phase(after, period_ns, due_ns)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_late_wake_up_skips_the_deadlines_it_missed() {
        assert_eq!(next_deadline(0, 200, 1_000), 1_000);
        assert_eq!(next_deadline(0, 999, 1_000), 1_000);
        assert_eq!(next_deadline(0, 1_000, 1_000), 2_000);
        assert_eq!(next_deadline(0, 2_500, 1_000), 3_000);
    }

    #[test]
    fn every_tick_is_recorded_after_its_deadline() {
        let period = Duration::from_millis(1);
        let start = monotonic_ns();
        let measured = lateness(20, period).unwrap();
        let elapsed = monotonic_ns() - start;
        let summary = measured.summary();
        assert_eq!(summary.count, 20);
        // Twenty deadlines a millisecond apart, the first one period after the start: the
        // loop cannot have finished before the last of them.
        assert!(elapsed >= 20 * 1_000_000, "{elapsed} ns");
        assert!(summary.max < elapsed as u64, "{summary:?}");
    }
}
