//! CPU use of a process over a time window, from `/proc/<pid>/stat` (user + system time of
//! all its threads), e.g. to check that an idle node does not spin.

use crate::procfs::{cpu_ticks, ticks_per_second};
use std::time::{Duration, Instant};

/// CPU use of one process over a window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CpuShare {
    /// CPU time used divided by wall time: 1.0 = one core fully busy.
    pub cores: f64,
    /// Smallest step of `cores` this window can show (one clock tick / window).
    pub resolution: f64,
    /// Wall time the use was measured over.
    pub window: Duration,
}

/// The CPU use of process `pid` over the next `window` (this call sleeps that long).
pub fn measure_cpu_share(pid: u32, window: Duration) -> anyhow::Result<CpuShare> {
    let shares = measure_cpu_shares(&[pid], window)?;
    Ok(shares[0])
}

/// The CPU use of each of `pids` over the same next `window`, in the order given (this call
/// sleeps that long).
pub fn measure_cpu_shares(pids: &[u32], window: Duration) -> anyhow::Result<Vec<CpuShare>> {
    let ticks_per_second = ticks_per_second()? as f64;
    let before = pids
        .iter()
        .map(|&pid| cpu_ticks(pid))
        .collect::<anyhow::Result<Vec<u64>>>()?;
    let started = Instant::now();
    std::thread::sleep(window);
    let after = pids
        .iter()
        .map(|&pid| cpu_ticks(pid))
        .collect::<anyhow::Result<Vec<u64>>>()?;
    let elapsed = started.elapsed();
    let seconds = elapsed.as_secs_f64();
    Ok(before
        .iter()
        .zip(&after)
        .map(|(before, after)| CpuShare {
            cores: after.saturating_sub(*before) as f64 / ticks_per_second / seconds,
            resolution: 1.0 / ticks_per_second / seconds,
            window: elapsed,
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    /// A thread of this process keeping one core busy until stopped.
    struct Spinner {
        stop: Arc<AtomicBool>,
        thread: std::thread::JoinHandle<()>,
    }

    impl Spinner {
        fn start() -> Self {
            let stop = Arc::new(AtomicBool::new(false));
            let thread = {
                let stop = stop.clone();
                std::thread::spawn(move || {
                    while !stop.load(Ordering::Relaxed) {
                        std::hint::spin_loop();
                    }
                })
            };
            Self { stop, thread }
        }

        fn stop(self) {
            self.stop.store(true, Ordering::Relaxed);
            self.thread.join().unwrap();
        }
    }

    #[test]
    fn one_window_serves_several_processes_in_order() {
        let mut sleeper = std::process::Command::new("sleep")
            .arg("5")
            .spawn()
            .unwrap();
        let spinner = Spinner::start();
        let shares = measure_cpu_shares(
            &[sleeper.id(), std::process::id()],
            Duration::from_millis(300),
        );
        spinner.stop();
        let _ = sleeper.kill();
        let _ = sleeper.wait();
        let shares = shares.unwrap();
        assert_eq!(shares.len(), 2);
        assert_eq!(shares[0].window, shares[1].window);
        // The sleeping process uses at most one clock tick; the spinning one more.
        assert!(shares[0].cores <= shares[0].resolution, "{shares:?}");
        assert!(shares[1].cores > shares[0].cores, "{shares:?}");
    }

    #[test]
    fn a_missing_process_is_an_error_naming_its_file() {
        // Pid 0 never has a /proc entry.
        let error = measure_cpu_shares(&[0], Duration::ZERO).unwrap_err();
        assert!(format!("{error:#}").contains("/proc/0/stat"), "{error:#}");
    }

    #[test]
    fn a_spinning_thread_shows_up_and_stays_within_the_machine() {
        let spinner = Spinner::start();
        let share = measure_cpu_share(std::process::id(), Duration::from_millis(300)).unwrap();
        spinner.stop();
        let cores = std::thread::available_parallelism().unwrap().get() as f64;
        assert!(share.cores > 0.0, "{share:?}");
        assert!(share.cores <= cores + share.resolution, "{share:?}");
        assert!(
            share.resolution > 0.0 && share.resolution < 0.1,
            "{share:?}"
        );
    }
}
