//! The graph under soak: `sabr launch` as a child process, stopped like Ctrl-C would.

use anyhow::Context;
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use std::ffi::OsString;
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// Longest wait for the launcher to stop its graph after SIGINT (its stop ladder).
pub const STOP_TIMEOUT: Duration = Duration::from_secs(60);

/// A running `sabr launch`; stopped (SIGINT, then SIGKILL) when dropped.
pub struct LauncherChild {
    child: Child,
}

impl LauncherChild {
    /// Starts `sabr launch` (the `sabr` executable in `bin_dir`) with `args`, its output going
    /// to `log`.
    pub fn spawn(bin_dir: &Path, args: &[OsString], log: &Path) -> anyhow::Result<Self> {
        let exe = bin_dir.join("sabr");
        let output = std::fs::File::create(log)
            .with_context(|| format!("cannot create {}", log.display()))?;
        let child = Command::new(&exe)
            .arg("launch")
            .args(args)
            .stdin(Stdio::null())
            .stdout(output.try_clone()?)
            .stderr(output)
            .spawn()
            .with_context(|| format!("cannot start {} launch", exe.display()))?;
        Ok(Self { child })
    }

    /// The launcher's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// How it exited, if it has.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        self.child.try_wait().ok().flatten()
    }

    /// Asks the launcher to stop the graph (SIGINT, as Ctrl-C) and waits up to `timeout`;
    /// `None` if it is still running then (it is killed).
    pub fn stop(&mut self, timeout: Duration) -> Option<ExitStatus> {
        if let Some(status) = self.exited() {
            return Some(status);
        }
        let _ = kill(Pid::from_raw(self.child.id() as i32), Signal::SIGINT);
        let start = Instant::now();
        while start.elapsed() < timeout {
            if let Some(status) = self.exited() {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        None
    }
}

impl Drop for LauncherChild {
    fn drop(&mut self) {
        self.stop(STOP_TIMEOUT);
    }
}
