//! The CPUs' wake-up latency while a graph runs (`[graph] cpu_wake_latency_us`).
//!
//! An idle CPU sleeps in an idle state, and waking it costs that state's exit latency; on a
//! virtual machine the idle state is a halt that hands the virtual CPU back to the
//! hypervisor, and a woken node then starts with cold caches. Measured on the 2-vCPU
//! development VM: the IK round trip at 1 kHz took p50 31–39 µs with the CPU halting between
//! requests and 13–14 µs with it polling. Real-time Linux systems bound the latency with the
//! kernel's PM QoS request `/dev/cpu_dma_latency` (cyclictest and tuned do the same): the
//! request holds while the file stays open, so the kernel drops it when the launcher ends,
//! however it ends, and two launchers' requests combine (the lowest wins). The price: with a
//! bound of 0 every idle CPU polls instead of sleeping (the host sees busy CPUs; the graph's
//! processes do not use more CPU time).
//!
//! The request is obeyed by the kernel's cpuidle driver. A kernel without one (`current_driver`
//! `none` in sysfs: a guest whose hypervisor gives no idle hint, such as the 2-vCPU Firecracker
//! VM of 2026-12-06) halts every idle CPU whatever the request says: there, a 1 kHz timer woke
//! its thread p50 24.9 µs and p99 1.3 ms late (`sabr bench`, `timer/encoders-tick`). For a
//! bound of 0 on such a kernel the holder polls the CPUs itself: one thread per CPU it may run
//! on, pinned there at `SCHED_IDLE`, spinning until the bound is dropped (what the kernel's
//! `idle=poll` does, from user space). Any other thread that wakes on the CPU preempts it at
//! once. Its CPU time is the CPU's idle time, not work: the bench and the soak leave the
//! threads named [`IDLE_POLL_THREAD_PREFIX`] out of a process's CPU use.

use crate::placement::{Placement, Sched};
use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;

/// The kernel's CPU latency QoS device.
pub const DEVICE: &str = "/dev/cpu_dma_latency";

/// The sysfs file naming the registered cpuidle driver (`none` without one).
const CPUIDLE_DRIVER: &str = "/sys/devices/system/cpu/cpuidle/current_driver";

/// Start of the name of each thread polling an idle CPU (`idle-poll-cpu1` polls CPU 1), as
/// `/proc/<pid>/task/<tid>/comm` shows it.
pub const IDLE_POLL_THREAD_PREFIX: &str = "idle-poll-cpu";

/// A held CPU wake-up latency bound; the kernel releases it when this is dropped, and the
/// polling threads (if any) stop.
#[derive(Debug)]
pub struct WakeLatencyBound {
    _device: File,
    /// The bound, µs.
    pub latency_us: u32,
    polling: Option<IdlePolling>,
}

impl WakeLatencyBound {
    /// Asks the kernel to keep every CPU's wake-up latency at most `latency_us` until the
    /// returned bound is dropped; where [`polls_idle_cpus_itself`], also polls the CPUs the
    /// process may run on.
    /// The error says what failed and how to allow it.
    pub fn hold(latency_us: u32) -> Result<Self, String> {
        let mut device = open_device()?;
        let value = i32::try_from(latency_us).map_err(|_| {
            format!(
                "cpu_wake_latency_us = {latency_us}: at most {} µs",
                i32::MAX
            )
        })?;
        device
            .write_all(&value.to_ne_bytes())
            .map_err(|e| format!("cannot write the latency bound to {DEVICE}: {e}"))?;
        let polling = match polls_idle_cpus_itself(latency_us) {
            true => Some(IdlePolling::start()?),
            false => None,
        };
        Ok(Self {
            _device: device,
            latency_us,
            polling,
        })
    }

    /// Checks that a bound could be held, without holding one.
    pub fn check() -> Result<(), String> {
        open_device().map(drop)
    }

    /// The CPUs this bound keeps polling with threads of its own, ascending; empty when the
    /// kernel obeys the bound by itself.
    pub fn polled_cpus(&self) -> &[usize] {
        self.polling.as_ref().map_or(&[], |p| &p.cpus)
    }
}

/// Whether a bound of `latency_us` held on this kernel polls the idle CPUs with threads of
/// its own: a bound of 0 where the idle loop would halt anyway.
pub fn polls_idle_cpus_itself(latency_us: u32) -> bool {
    latency_us == 0 && !IdleLoop::of_this_kernel().obeys_zero_bound()
}

/// How this kernel's idle loop idles a CPU.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum IdleLoop {
    /// A cpuidle driver (its name) picks the idle state, within the PM QoS bound.
    Cpuidle(String),
    /// Booted with `idle=poll`: idle CPUs always poll.
    Polls,
    /// No cpuidle driver: idle CPUs halt, whatever the PM QoS bound.
    Halts,
}

impl IdleLoop {
    /// This kernel's, from sysfs and the kernel command line.
    pub fn of_this_kernel() -> Self {
        let driver = std::fs::read_to_string(CPUIDLE_DRIVER).ok();
        let cmdline = std::fs::read_to_string("/proc/cmdline").unwrap_or_default();
        Self::from_driver_and_cmdline(driver.as_deref(), &cmdline)
    }

    /// From the content of `cpuidle/current_driver` (`None`: no cpuidle in sysfs) and of
    /// `/proc/cmdline`.
    pub fn from_driver_and_cmdline(driver: Option<&str>, cmdline: &str) -> Self {
        if cmdline.split_whitespace().any(|word| word == "idle=poll") {
            return IdleLoop::Polls;
        }
        match driver.map(str::trim) {
            Some(name) if !name.is_empty() && name != "none" => IdleLoop::Cpuidle(name.to_owned()),
            _ => IdleLoop::Halts,
        }
    }

    /// Whether idle CPUs poll under a bound of 0 without help.
    pub fn obeys_zero_bound(&self) -> bool {
        !matches!(self, IdleLoop::Halts)
    }
}

/// One polling thread per CPU, stopped and joined on drop.
#[derive(Debug)]
struct IdlePolling {
    cpus: Vec<usize>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl IdlePolling {
    /// Starts polling every CPU the process's main thread may run on; an error (and nothing
    /// left running) if a thread cannot be started or placed.
    fn start() -> Result<Self, String> {
        let allowed = Placement::unplaced()?
            .cpus
            .expect("the unplaced placement lists the process's CPUs");
        let mut polling = IdlePolling {
            cpus: Vec::with_capacity(allowed.len()),
            stop: Arc::new(AtomicBool::new(false)),
            threads: Vec::with_capacity(allowed.len()),
        };
        for cpu in allowed {
            let placement = Placement {
                cpus: Some(vec![cpu]),
                sched: Some(Sched::Idle),
            }
            .prepare()?;
            let stop = Arc::clone(&polling.stop);
            let (placed_tx, placed_rx) = mpsc::channel();
            let thread = std::thread::Builder::new()
                .name(format!("{IDLE_POLL_THREAD_PREFIX}{cpu}"))
                .spawn(move || {
                    let placed = placement.apply();
                    let ok = placed.is_ok();
                    let _ = placed_tx.send(placed);
                    while ok && !stop.load(Ordering::Relaxed) {
                        std::hint::spin_loop();
                    }
                })
                .map_err(|e| format!("cannot start a thread to poll idle CPU {cpu}: {e}"))?;
            polling.threads.push(thread);
            match placed_rx.recv() {
                Ok(Ok(())) => polling.cpus.push(cpu),
                Ok(Err(error)) => {
                    return Err(format!(
                        "cannot place the thread polling idle CPU {cpu} (SCHED_IDLE on that \
                         CPU): {error}"
                    ))
                }
                Err(_) => return Err(format!("the thread polling idle CPU {cpu} ended")),
            }
        }
        Ok(polling)
    }
}

impl Drop for IdlePolling {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

fn open_device() -> Result<File, String> {
    OpenOptions::new()
        .write(true)
        .open(DEVICE)
        .map_err(|error| match error.kind() {
            ErrorKind::PermissionDenied => format!(
                "cpu_wake_latency_us needs write access to {DEVICE} ({error}): run the launcher \
                 as root, or grant its group the device (a udev rule `KERNEL==\"cpu_dma_latency\", \
                 GROUP=\"<group>\", MODE=\"0660\"`); or remove cpu_wake_latency_us"
            ),
            ErrorKind::NotFound => format!(
                "cpu_wake_latency_us: this kernel has no {DEVICE} (CPU latency PM QoS): remove \
                 cpu_wake_latency_us"
            ),
            _ => format!("cannot open {DEVICE}: {error}"),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether the idle states of CPU 0 with an exit latency above zero are in use (their
    /// `usage` counters move) over a short window; `None` without cpuidle in sysfs.
    fn sleeping_idle_states_used() -> Option<bool> {
        let states = std::fs::read_dir("/sys/devices/system/cpu/cpu0/cpuidle").ok()?;
        let sleeping: Vec<_> = states
            .filter_map(Result::ok)
            .map(|state| state.path())
            .filter(|path| {
                std::fs::read_to_string(path.join("latency"))
                    .ok()
                    .and_then(|l| l.trim().parse::<u64>().ok())
                    .is_some_and(|l| l > 0)
            })
            .collect();
        if sleeping.is_empty() {
            return None;
        }
        let usage = || -> u64 {
            sleeping
                .iter()
                .filter_map(|p| std::fs::read_to_string(p.join("usage")).ok())
                .filter_map(|u| u.trim().parse::<u64>().ok())
                .sum()
        };
        let before = usage();
        std::thread::sleep(std::time::Duration::from_millis(300));
        Some(usage() > before)
    }

    /// The names of the threads of this process polling idle CPUs, sorted (their placement
    /// is checked on the launcher's, in the launcher's integration tests).
    fn polling_threads() -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir("/proc/self/task")
            .unwrap()
            .filter_map(Result::ok)
            .filter_map(|task| std::fs::read_to_string(task.path().join("comm")).ok())
            .map(|name| name.trim().to_owned())
            .filter(|name| name.starts_with(IDLE_POLL_THREAD_PREFIX))
            .collect();
        names.sort();
        names
    }

    #[test]
    fn idle_loops_are_told_apart_by_the_cpuidle_driver_and_the_command_line() {
        let idle = IdleLoop::from_driver_and_cmdline;
        assert_eq!(idle(Some("none\n"), "console=ttyS0 quiet"), IdleLoop::Halts);
        assert_eq!(idle(None, ""), IdleLoop::Halts);
        assert_eq!(
            idle(Some("intel_idle\n"), "quiet"),
            IdleLoop::Cpuidle("intel_idle".to_owned())
        );
        assert_eq!(idle(Some("none"), "quiet idle=poll"), IdleLoop::Polls);
        assert!(!IdleLoop::Halts.obeys_zero_bound());
        assert!(IdleLoop::Polls.obeys_zero_bound());
        assert!(IdleLoop::Cpuidle("haltpoll".to_owned()).obeys_zero_bound());
    }

    #[test]
    fn a_held_bound_of_zero_keeps_the_cpus_out_of_sleeping_idle_states_or_says_why_not() {
        match WakeLatencyBound::hold(0) {
            Ok(bound) => {
                assert_eq!(bound.latency_us, 0);
                if let Some(used) = sleeping_idle_states_used() {
                    assert!(
                        !used,
                        "a CPU slept in an idle state with the bound of 0 held"
                    );
                }
                assert_eq!(WakeLatencyBound::check(), Ok(()));
                // Where the kernel would halt idle CPUs anyway, a thread polls each CPU of
                // the process until the bound ends.
                let expected: Vec<usize> = match IdleLoop::of_this_kernel().obeys_zero_bound() {
                    true => Vec::new(),
                    false => Placement::unplaced().unwrap().cpus.unwrap(),
                };
                assert_eq!(bound.polled_cpus(), expected.as_slice());
                let mut names: Vec<String> = expected
                    .iter()
                    .map(|cpu| format!("{IDLE_POLL_THREAD_PREFIX}{cpu}"))
                    .collect();
                names.sort();
                assert_eq!(polling_threads(), names);
                drop(bound);
                // Joined threads leave /proc/self/task once the kernel has reaped them, a
                // moment after the join returns.
                let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
                while !polling_threads().is_empty() && std::time::Instant::now() < deadline {
                    std::thread::sleep(std::time::Duration::from_millis(1));
                }
                assert_eq!(polling_threads(), Vec::<String>::new());
            }
            Err(reason) => {
                assert!(reason.contains(DEVICE), "{reason}");
                assert_eq!(WakeLatencyBound::check(), Err(reason));
            }
        }
    }

    #[test]
    fn a_bound_above_zero_polls_no_cpu_itself() {
        if let Ok(bound) = WakeLatencyBound::hold(100) {
            assert_eq!(bound.polled_cpus(), &[] as &[usize]);
        }
    }
}
