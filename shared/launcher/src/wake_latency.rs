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

use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Write};

/// The kernel's CPU latency QoS device.
pub const DEVICE: &str = "/dev/cpu_dma_latency";

/// A held CPU wake-up latency bound; the kernel releases it when this is dropped.
#[derive(Debug)]
pub struct WakeLatencyBound {
    _device: File,
    /// The bound, µs.
    pub latency_us: u32,
}

impl WakeLatencyBound {
    /// Asks the kernel to keep every CPU's wake-up latency at most `latency_us` until the
    /// returned bound is dropped. The error says what failed and how to allow it.
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
        Ok(Self {
            _device: device,
            latency_us,
        })
    }

    /// Checks that a bound could be held, without holding one.
    pub fn check() -> Result<(), String> {
        open_device().map(drop)
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
            }
            Err(reason) => {
                assert!(reason.contains(DEVICE), "{reason}");
                assert_eq!(WakeLatencyBound::check(), Err(reason));
            }
        }
    }
}
