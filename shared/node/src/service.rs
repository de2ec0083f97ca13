//! The one shape of every SABR service process, so that eight binaries differ only in what
//! their loop body does:
//!
//! 1. [`service_main`] parses the command line (clap), sets up logging, starts the node on the
//!    graph's transport and runs the service's function, which sets up its ports and runs one
//!    of the runtime's loops ([`crate::NodeRuntime::run_loop`] at a fixed rate,
//!    [`crate::NodeRuntime::run_on_data`] woken by its inputs);
//! 2. the outcome maps to one exit convention: any [`Exit`] is success (exit status 0), an
//!    error is logged with its whole chain of causes (and printed on stdout as
//!    `<service>: FAILED: <causes>`) and is a failure (exit status 1); a bad command line is
//!    clap's usage error (exit status 2). Standard output goes through [`crate::console`]: a
//!    service whose output failed (its reader left, its log's disk is full) goes on working,
//!    and logs the failure as it leaves instead of panicking.
//!
//! The helpers every service needed a copy of live here once: [`in_run_dir`] (where a file
//! goes when no flag names it), [`StatusTimer`] (the status line every [`STATUS_PERIOD`]) and
//! [`StallWatch`] (input streams that went silent, and came back).

use crate::{run_dir, Deadline, Exit, NodeRuntime, RUN_DIR_ENV};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Period of every service's status line in its log.
pub const STATUS_PERIOD: Duration = Duration::from_secs(10);

/// Runs a service process: parses `A` from the command line, starts logging and the node (its
/// name from [`crate::NODE_NAME_ENV`], else `default_name`), calls `run` and maps its outcome
/// to the exit status (see the module documentation).
pub fn service_main<A: clap::Parser>(
    default_name: &str,
    run: impl FnOnce(&A, &mut NodeRuntime) -> anyhow::Result<Exit>,
) -> ExitCode {
    let args = A::parse();
    crate::init_tracing();
    let outcome = NodeRuntime::start(default_name)
        .map_err(anyhow::Error::from)
        .and_then(|mut rt| run(&args, &mut rt));
    exit_code(default_name, outcome)
}

/// The exit status of a service's outcome; an error is logged first, and a standard output
/// that failed on the way (its last line included) is logged last.
fn exit_code(service: &str, outcome: anyhow::Result<Exit>) -> ExitCode {
    let code = match outcome {
        Ok(exit) => {
            tracing::debug!(service, ?exit, "leaving");
            ExitCode::SUCCESS
        }
        Err(error) => {
            tracing::error!(service, "{error:#}");
            // Also on stdout, which the launcher shows for a node marked `console`.
            crate::outln!("{service}: FAILED: {error:#}");
            ExitCode::FAILURE
        }
    };
    if let Err(error) = crate::console::finish() {
        tracing::warn!(service, "{error:#}");
    }
    code
}

/// The path of a service's file or directory: `given` (from the flag `flag`) if set, else
/// `name` in the run directory the launcher sets ([`RUN_DIR_ENV`]); an error names both ways
/// when neither exists.
pub fn in_run_dir(given: Option<&Path>, name: &str, flag: &str) -> anyhow::Result<PathBuf> {
    match (given, run_dir()) {
        (Some(path), _) => Ok(path.to_path_buf()),
        (None, Some(run)) => Ok(run.join(name)),
        (None, None) => anyhow::bail!(
            "no {flag} given and {RUN_DIR_ENV} is unset: give {flag}, or run under `sabr launch`"
        ),
    }
}

/// Says when the next status line is due: every [`STATUS_PERIOD`] from its creation.
#[derive(Debug, Clone)]
pub struct StatusTimer {
    last: Instant,
}

impl StatusTimer {
    /// A timer whose first line is due one period from now.
    pub fn new() -> Self {
        Self {
            last: Instant::now(),
        }
    }

    /// True once per [`STATUS_PERIOD`]: the caller logs its status line now.
    pub fn due(&mut self) -> bool {
        if self.last.elapsed() < STATUS_PERIOD {
            return false;
        }
        self.last = Instant::now();
        true
    }
}

impl Default for StatusTimer {
    fn default() -> Self {
        Self::new()
    }
}

/// Input streams of a process, each with a [`Deadline`]: logs a warning when one falls silent
/// for longer than its limit and a note when it flows again (once per transition).
#[derive(Debug)]
pub struct StallWatch<const N: usize> {
    streams: [(&'static str, Deadline, bool); N],
}

impl<const N: usize> StallWatch<N> {
    /// Watches the streams named `names`, each stalled after `limit` of silence.
    pub fn new(names: [&'static str; N], limit: Duration) -> Self {
        Self {
            streams: names.map(|name| (name, Deadline::new(limit), false)),
        }
    }

    /// Stream `index` (in the order of [`StallWatch::new`]) delivered data now.
    pub fn feed(&mut self, index: usize) {
        self.streams[index].1.feed();
    }

    /// Which streams are silent beyond their limit, in order.
    pub fn stalled(&self) -> [bool; N] {
        self.streams
            .each_ref()
            .map(|(_, deadline, _)| deadline.expired())
    }

    /// Logs the streams that stalled or recovered since the last call.
    pub fn check(&mut self) {
        for (name, deadline, stalled) in &mut self.streams {
            let expired = deadline.expired();
            if expired == *stalled {
                continue;
            }
            *stalled = expired;
            if expired {
                tracing::warn!(
                    silent_ms = deadline.silence().as_millis() as u64,
                    "no {name} data"
                );
            } else {
                tracing::info!("{name} data flowing again");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stream_is_stalled_only_while_silent_beyond_its_limit() {
        let mut watch = StallWatch::new(["encoder", "tracker"], Duration::from_millis(20));
        watch.feed(0);
        watch.feed(1);
        assert_eq!(watch.stalled(), [false, false]);
        std::thread::sleep(Duration::from_millis(30));
        watch.feed(1);
        assert_eq!(watch.stalled(), [true, false]);
        watch.check();
        watch.feed(0);
        assert_eq!(watch.stalled(), [false, false]);
    }

    #[test]
    fn a_given_path_wins_and_no_path_at_all_is_an_error_naming_the_flag() {
        let given = Path::new("/tmp/somewhere");
        assert_eq!(in_run_dir(Some(given), "x", "--out").unwrap(), given);
        if run_dir().is_none() {
            let error = in_run_dir(None, "recording", "--out").unwrap_err();
            assert!(error.to_string().contains("--out"), "{error}");
        }
    }

    #[test]
    fn an_error_is_a_failure_and_every_exit_a_success() {
        for exit in [Exit::Signal, Exit::Stopped, Exit::Done] {
            assert_eq!(exit_code("test", Ok(exit)), ExitCode::SUCCESS);
        }
        let failed = exit_code("test", Err(anyhow::anyhow!("broken")));
        assert_eq!(failed, ExitCode::FAILURE);
    }
}
