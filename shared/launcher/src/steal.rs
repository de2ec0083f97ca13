//! CPU time the hypervisor took from this machine (`steal` in `/proc/stat`).
//!
//! On a virtual machine whose host is busy, a vCPU can be descheduled for tens of ms while
//! the guest looks idle: a node's 1 ms timer fires late, its sampling instants are skipped,
//! round trips grow. `sabr launch`, `sabr bench` and the timing tests report the share stolen
//! over their run, so that such figures are read as the host's doing, not the graph's.

use anyhow::{bail, Context};

/// Share of the CPUs' time stolen from which `sabr launch` warns that the run's timing was
/// the host's (a fraction, 0..1).
pub const NOTABLE_STEAL: f64 = 0.05;

/// The machine's cumulative CPU time counters, summed over all CPUs, in clock ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CpuTimes {
    /// Every state's ticks (user, nice, system, idle, iowait, irq, softirq, steal).
    pub total: u64,
    /// Ticks a runnable vCPU waited for the hypervisor.
    pub steal: u64,
}

impl CpuTimes {
    /// Reads the counters now from `/proc/stat`.
    pub fn now() -> anyhow::Result<Self> {
        let text = std::fs::read_to_string("/proc/stat").context("cannot read /proc/stat")?;
        parse(&text).context("/proc/stat: unexpected content")
    }

    /// The share of the CPUs' time stolen between `earlier` and `self` (0..1); `None` when no
    /// tick elapsed (or `earlier` is not earlier).
    pub fn steal_share_since(&self, earlier: &CpuTimes) -> Option<f64> {
        let total = self.total.checked_sub(earlier.total)?;
        let steal = self.steal.checked_sub(earlier.steal)?;
        (total > 0).then(|| steal as f64 / total as f64)
    }
}

/// The first line of `/proc/stat`: `cpu user nice system idle iowait irq softirq steal …`
/// (guest times are already counted in user and nice).
fn parse(stat: &str) -> anyhow::Result<CpuTimes> {
    let Some(line) = stat.lines().find(|line| line.starts_with("cpu ")) else {
        bail!("no `cpu` line");
    };
    let ticks = line
        .split_whitespace()
        .skip(1)
        .take(8)
        .map(|field| {
            field
                .parse::<u64>()
                .with_context(|| format!("`cpu` field {field:?} is not a tick count"))
        })
        .collect::<anyhow::Result<Vec<u64>>>()?;
    if ticks.len() < 8 {
        bail!(
            "the `cpu` line has {} fields, expected 8 or more",
            ticks.len()
        );
    }
    Ok(CpuTimes {
        total: ticks.iter().sum(),
        steal: ticks[7],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_summed_cpu_line_and_its_steal() {
        let stat = "cpu  10 1 20 300 4 0 5 60 0 0\ncpu0 5 0 10 150 2 0 2 30 0 0\nintr 1\n";
        let times = parse(stat).unwrap();
        assert_eq!(
            times,
            CpuTimes {
                total: 400,
                steal: 60
            }
        );
        let later = CpuTimes {
            total: 500,
            steal: 85,
        };
        assert_eq!(later.steal_share_since(&times), Some(0.25));
        assert_eq!(times.steal_share_since(&later), None);
        assert_eq!(times.steal_share_since(&times), None);
    }

    #[test]
    fn a_short_or_garbled_cpu_line_is_an_error_naming_it() {
        let short = parse("cpu  1 2 3 4\n").unwrap_err();
        assert!(short.to_string().contains("4 fields"), "{short}");
        let garbled = parse("cpu  1 2 x 4 5 6 7 8\n").unwrap_err();
        assert!(format!("{garbled:#}").contains("\"x\""), "{garbled:#}");
        assert!(parse("intr 1\n").is_err());
    }

    #[test]
    fn this_machine_has_counters_that_advance() {
        let first = CpuTimes::now().unwrap();
        assert!(first.steal <= first.total);
        let spin = std::time::Instant::now();
        while spin.elapsed() < std::time::Duration::from_millis(60) {}
        let later = CpuTimes::now().unwrap();
        assert!(later.total > first.total);
        assert!((0.0..=1.0).contains(&later.steal_share_since(&first).unwrap()));
    }
}
