//! Helpers of the multi-process integration tests: run a launch file in a fresh domain and
//! watch it from outside.
//!
//! Binaries: `cargo test -p sabr-integration-tests` builds this package's `sabr-test-launch`
//! (the launcher, same code as `sabr launch`) and `sabr-test-node` next to each other, so the
//! launcher finds the node executable in its own directory.

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_msgs::{Lifecycle, LifecycleState};
use sabr_node::{Domain, GraphObserver};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// How long a dropped [`LaunchedGraph`]'s launcher gets to stop its graph before SIGKILL.
const DROP_STOP_GRACE: Duration = Duration::from_secs(10);

/// Path of a binary of this workspace's target directory (`target/<profile>/<name>`).
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // Test executables live in target/<profile>/deps/.
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile> directory");
    let path = profile_dir.join(name);
    assert!(
        path.is_file(),
        "{} is missing: run the tests with `cargo test -p sabr-integration-tests`",
        path.display()
    );
    path
}

/// The eight service binaries of the shipped graphs, `sabr-<name>`, by the node name each
/// gives itself.
pub const SERVICES: [&str; 8] = [
    "rig",
    "encoders",
    "tracker",
    "sync",
    "recorder",
    "ik",
    "calibrator",
    "motion",
];

/// The median interval between consecutive time stamps (ns; the upper middle of an even
/// count): a stream's period whether or not some instants were skipped.
pub fn median_interval_ns(stamps: &[i64]) -> i64 {
    let mut intervals: Vec<i64> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(!intervals.is_empty(), "fewer than two time stamps");
    intervals.sort_unstable();
    intervals[intervals.len() / 2]
}

/// Serialises the multi-process tests of one test executable: each holds the guard for its
/// whole run. Plain `cargo test` runs a test executable's tests on parallel threads (and test
/// executables one after another); live graphs with 1 kHz deadlines on 2 cores must not share
/// the machine, so every test of this crate starts with `let _alone = run_alone();`. Under
/// nextest each test is its own process and `.config/nextest.toml` runs them one at a time.
pub fn run_alone() -> std::sync::MutexGuard<'static, ()> {
    static ALONE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    // A test that panicked while holding the guard leaves nothing to repair.
    ALONE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A fresh domain for one test: `it-<test>-<pid>`.
pub fn test_domain(test: &str) -> Domain {
    Domain::new(&format!("it-{test}-{}", std::process::id())).expect("valid test domain")
}

/// True if a process with this pid exists.
pub fn process_alive(pid: u32) -> bool {
    kill(Pid::from_raw(pid as i32), None).is_ok()
}

/// A launcher process running a launch file in its own domain and temporary directory.
pub struct LaunchedGraph {
    /// The graph's domain.
    pub domain: Domain,
    /// Holds the launch file, the run directories and the launcher's output.
    pub dir: tempfile::TempDir,
    launcher: Child,
    observer: Option<GraphObserver>,
    seen: Vec<Lifecycle>,
}

impl LaunchedGraph {
    /// Writes `launch_toml` to `graph.toml` and starts the launcher on it with `extra_args`.
    /// With `observe`, a [`GraphObserver`] joins the domain first, so no announcement is missed.
    pub fn start(test: &str, launch_toml: &str, extra_args: &[&str], observe: bool) -> Self {
        let domain = test_domain(test);
        assert!(
            sabr_node::domain_files(&domain).is_empty(),
            "domain {domain} not fresh"
        );
        let dir = tempfile::tempdir().expect("temporary directory");
        let file = dir.path().join("graph.toml");
        std::fs::write(&file, launch_toml).expect("write launch file");
        let observer = observe.then(|| GraphObserver::new(&domain).expect("observer"));
        let output = std::fs::File::create(dir.path().join("launcher.out")).expect("output file");
        let launcher = Command::new(bin("sabr-test-launch"))
            .arg(&file)
            .arg("--run-dir")
            .arg(dir.path().join("runs"))
            .arg("--domain")
            .arg(domain.as_str())
            .args(extra_args)
            .stdin(Stdio::null())
            .stdout(output.try_clone().expect("output file"))
            .stderr(output)
            .spawn()
            .expect("start the launcher");
        Self {
            domain,
            dir,
            launcher,
            observer,
            seen: Vec::new(),
        }
    }

    /// The launcher's process id.
    pub fn launcher_pid(&self) -> u32 {
        self.launcher.id()
    }

    /// Every lifecycle announcement seen so far (needs `observe`).
    pub fn seen(&mut self) -> &[Lifecycle] {
        if let Some(observer) = &self.observer {
            let seen = &mut self.seen;
            observer.poll(|m| seen.push(m)).expect("poll lifecycle");
        }
        &self.seen
    }

    /// Waits up to `timeout` until `found` picks something out of the announcements seen.
    pub fn wait_for<T>(
        &mut self,
        timeout: Duration,
        mut found: impl FnMut(&[Lifecycle]) -> Option<T>,
    ) -> Option<T> {
        let start = Instant::now();
        loop {
            if let Some(value) = found(self.seen()) {
                return Some(value);
            }
            if start.elapsed() >= timeout {
                return None;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Waits for a `Ready` of `node` from a process other than `not_pid`; returns its pid and
    /// its announcement.
    pub fn wait_ready(
        &mut self,
        node: &str,
        not_pid: Option<u32>,
        timeout: Duration,
    ) -> Option<Lifecycle> {
        self.wait_for(timeout, |seen| {
            seen.iter()
                .find(|m| {
                    m.node.as_str() == node
                        && m.state == LifecycleState::Ready
                        && Some(m.pid) != not_pid
                })
                .copied()
        })
    }

    /// Distinct pids of node processes that announced anything (not the test's own).
    pub fn node_pids(&mut self) -> Vec<u32> {
        let own = std::process::id();
        let mut pids: Vec<u32> = self
            .seen()
            .iter()
            .map(|m| m.pid)
            .filter(|&pid| pid != own)
            .collect();
        pids.sort_unstable();
        pids.dedup();
        pids
    }

    /// Sends SIGINT to the launcher (Ctrl-C) and waits for it to exit.
    pub fn interrupt(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let _ = kill(Pid::from_raw(self.launcher.id() as i32), Signal::SIGINT);
        self.wait_exit(timeout)
    }

    /// Waits up to `timeout` for the launcher to exit.
    pub fn wait_exit(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let start = Instant::now();
        loop {
            if let Ok(Some(status)) = self.launcher.try_wait() {
                return Some(status);
            }
            if start.elapsed() >= timeout {
                return None;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// What the launcher printed.
    pub fn output(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("launcher.out")).unwrap_or_default()
    }

    /// The run directories the launcher created.
    pub fn run_dirs(&self) -> Vec<PathBuf> {
        std::fs::read_dir(self.dir.path().join("runs"))
            .map(|entries| entries.flatten().map(|e| e.path()).collect())
            .unwrap_or_default()
    }

    /// Leaves the domain and returns the domain's files still left once no node exists.
    pub fn leftover_files(&mut self) -> Vec<PathBuf> {
        self.observer = None;
        sabr_node::release_domain(&self.domain)
    }
}

impl Drop for LaunchedGraph {
    fn drop(&mut self) {
        // A failed test must not leave a graph running nor its shared memory behind: ask the
        // launcher to stop (its stop ladder cleans up), kill it only if it does not, then sweep
        // what dead nodes left and release the domain.
        if matches!(self.launcher.try_wait(), Ok(None)) && self.interrupt(DROP_STOP_GRACE).is_none()
        {
            let _ = self.launcher.kill();
            let _ = self.launcher.wait();
        }
        let observer = self
            .observer
            .take()
            .or_else(|| GraphObserver::new(&self.domain).ok());
        if let Some(observer) = observer {
            observer.cleanup_dead_nodes();
        }
        sabr_node::release_domain(&self.domain);
    }
}
