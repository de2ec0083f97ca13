//! Memory and CPU time of a process from `/proc/<pid>/status` and `/proc/<pid>/stat`, for the
//! bench's idle-CPU windows and the soak's memory and CPU trends.

use anyhow::{bail, Context};
use nix::unistd::{sysconf, SysconfVar};
use sabr_launcher::wake_latency::IDLE_POLL_THREAD_PREFIX;

/// One reading of a process's resident memory and CPU time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProcReading {
    /// Resident set size (`VmRSS`), KiB.
    pub rss_kib: u64,
    /// User + system CPU time of its threads so far, clock ticks, as [`cpu_ticks`] counts it.
    pub cpu_ticks: u64,
}

/// Reads [`ProcReading`] of `pid`; an error once the process is gone (or a zombie: no `VmRSS`).
pub fn read(pid: u32) -> anyhow::Result<ProcReading> {
    let status_path = format!("/proc/{pid}/status");
    let status = std::fs::read_to_string(&status_path)
        .with_context(|| format!("cannot read {status_path}"))?;
    Ok(ProcReading {
        rss_kib: parse_vm_rss_kib(&status).with_context(|| status_path.clone())?,
        cpu_ticks: cpu_ticks(pid)?,
    })
}

/// User + system CPU time of process `pid` so far, in clock ticks (`sysconf(CLK_TCK)` per s),
/// without its threads polling idle CPUs for a held wake-up latency bound
/// ([`IDLE_POLL_THREAD_PREFIX`]): their time is the CPUs' idle time, not the process's work.
pub fn cpu_ticks(pid: u32) -> anyhow::Result<u64> {
    let path = format!("/proc/{pid}/stat");
    let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {path}"))?;
    let ticks = parse_cpu_ticks(&text).with_context(|| format!("{path}: unexpected content"))?;
    Ok(ticks.saturating_sub(idle_polling_ticks(pid)))
}

/// User + system CPU time of the threads of `pid` named [`IDLE_POLL_THREAD_PREFIX`]…, clock
/// ticks (0 without any; a thread that ends while it is read is not counted).
pub fn idle_polling_ticks(pid: u32) -> u64 {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return 0;
    };
    tasks
        .filter_map(Result::ok)
        .filter(|task| {
            std::fs::read_to_string(task.path().join("comm"))
                .is_ok_and(|name| name.starts_with(IDLE_POLL_THREAD_PREFIX))
        })
        .filter_map(|task| std::fs::read_to_string(task.path().join("stat")).ok())
        .filter_map(|stat| parse_cpu_ticks(&stat).ok())
        .sum()
}

/// Clock ticks per second of the `/proc` CPU times (`sysconf(CLK_TCK)`).
pub fn ticks_per_second() -> anyhow::Result<u64> {
    match sysconf(SysconfVar::CLK_TCK) {
        Ok(Some(ticks)) if ticks > 0 => Ok(ticks as u64),
        other => bail!("sysconf(CLK_TCK) gave {other:?}"),
    }
}

/// The `VmRSS:   1234 kB` line of `/proc/<pid>/status`, in KiB.
fn parse_vm_rss_kib(status: &str) -> anyhow::Result<u64> {
    let line = status
        .lines()
        .find_map(|line| line.strip_prefix("VmRSS:"))
        .context("no VmRSS line (the process has exited)")?;
    let value = line
        .trim()
        .strip_suffix("kB")
        .with_context(|| format!("VmRSS {:?} is not in kB", line.trim()))?;
    value
        .trim()
        .parse()
        .with_context(|| format!("VmRSS {:?} is not a number", value.trim()))
}

/// `utime + stime` (fields 14 and 15) of `/proc/<pid>/stat`. The command name (field 2) is in
/// parentheses and may hold spaces and `)`, so fields are counted after the last `)`.
fn parse_cpu_ticks(stat: &str) -> anyhow::Result<u64> {
    let Some((_, after_name)) = stat.rsplit_once(')') else {
        bail!("no ')' closing the command name");
    };
    // After the name come fields 3 (state), 4, …: utime (14) is the 12th of them.
    let fields: Vec<&str> = after_name.split_whitespace().collect();
    let field = |number: usize| -> anyhow::Result<u64> {
        let text = fields
            .get(number - 3)
            .with_context(|| format!("field {number} is missing"))?;
        text.parse()
            .with_context(|| format!("field {number} ({text:?}) is not a tick count"))
    };
    Ok(field(14)? + field(15)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_rss_and_cpu_of_odd_command_names() {
        let status = "Name:\tsabr-rig\nVmPeak:\t  9000 kB\nVmRSS:\t    5120 kB\nThreads:\t3\n";
        assert_eq!(parse_vm_rss_kib(status).unwrap(), 5120);
        let stat = "42 (a) b) S 1 42 42 0 -1 4194560 100 0 0 0 17 5 0 0 20 0 3 0 1234 0 0";
        assert_eq!(parse_cpu_ticks(stat).unwrap(), 22);
    }

    #[test]
    fn rejects_exited_and_malformed_processes() {
        let zombie = "Name:\tx\nState:\tZ (zombie)\n";
        let error = parse_vm_rss_kib(zombie).unwrap_err().to_string();
        assert!(error.contains("no VmRSS"), "{error}");
        assert!(parse_vm_rss_kib("VmRSS:\t12 MB\n").is_err());
        assert!(parse_cpu_ticks("42 (x S 1").is_err());
        assert!(parse_cpu_ticks("42 (x) S 1 2").is_err());
        assert!(parse_cpu_ticks("4242 x S 1 2 3 4 5 6 7 8 9 10 11 12 13").is_err());
        let error = parse_cpu_ticks("1 (x) S 1 1 1 0 -1 0 0 0 0 0 u 5 0").unwrap_err();
        assert!(format!("{error:#}").contains("field 14"), "{error:#}");
    }

    #[test]
    fn threads_polling_idle_cpus_are_left_out_of_the_cpu_time() {
        let pid = std::process::id();
        let total = || parse_cpu_ticks(&std::fs::read_to_string("/proc/self/stat").unwrap());
        let (spun_tx, spun_rx) = std::sync::mpsc::channel();
        let (end_tx, end_rx) = std::sync::mpsc::channel::<()>();
        let poller = std::thread::Builder::new()
            .name(format!("{IDLE_POLL_THREAD_PREFIX}0"))
            .spawn(move || {
                // Spin until this thread has used some ticks, then hold them still.
                let started = std::time::Instant::now();
                while idle_polling_ticks(pid) < 5 && started.elapsed().as_secs() < 20 {
                    std::hint::spin_loop();
                }
                spun_tx.send(()).unwrap();
                let _ = end_rx.recv();
            })
            .unwrap();
        spun_rx.recv().unwrap();
        let polling = idle_polling_ticks(pid);
        assert!(polling >= 5, "the polling thread used {polling} ticks");
        let before = total().unwrap();
        let work = cpu_ticks(pid).unwrap();
        let after = total().unwrap();
        assert!(
            (before..=after).contains(&(work + polling)),
            "work {work} + polling {polling} outside the process's {before}..={after} ticks"
        );
        assert_eq!(idle_polling_ticks(u32::MAX), 0);
        end_tx.send(()).unwrap();
        poller.join().unwrap();
    }

    #[test]
    fn reads_this_process() {
        let reading = read(std::process::id()).unwrap();
        assert!(reading.rss_kib > 100, "{reading:?}");
        assert!(ticks_per_second().unwrap() >= 1);
    }
}
