//! Starting, watching, restarting and stopping the node processes of a graph.

use crate::placement::Prepared;
use crate::progress::Progress;
use crate::run_dir::RunDir;
use crate::spec::{GraphSpec, NodeSpec, RestartPolicy, MAX_BACKOFF};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_node::msgs::LifecycleState;
use sabr_node::{Domain, GraphObserver, DOMAIN_ENV, LOOP_PHASE_ENV, NODE_NAME_ENV, RUN_DIR_ENV};
use std::io::{BufRead, Write};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::process::{Child, ChildStdout, Command, ExitStatus, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How often the supervisor looks at its children and the lifecycle messages.
const POLL: Duration = Duration::from_millis(10);
/// A node ready this long gets its restart count and backoff reset.
const STABLE_AFTER: Duration = Duration::from_secs(10);
/// Longest wait, once a console node has exited, for its last stdout lines to be shown.
const ECHO_DRAIN: Duration = Duration::from_secs(1);

/// Why the graph stops.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StopReason {
    /// SIGINT/SIGTERM to the launcher (Ctrl-C).
    Signal,
    /// The `--duration` elapsed.
    Duration,
    /// A node announced that the graph's job is done.
    Done(String),
    /// A required node ended for good (or could not be started).
    RequiredEnded {
        /// The node.
        node: String,
        /// How it ended.
        detail: String,
    },
}

impl StopReason {
    /// True if the graph ends successfully.
    pub fn is_success(&self) -> bool {
        !matches!(self, StopReason::RequiredEnded { .. })
    }
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::Signal => write!(f, "stop requested"),
            StopReason::Duration => write!(f, "duration elapsed"),
            StopReason::Done(node) => write!(f, "node {node} announced the job done"),
            StopReason::RequiredEnded { node, detail } => {
                write!(f, "required node {node} ended: {detail}")
            }
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    NotStarted,
    Starting { since: Instant },
    Ready { since: Instant },
    Backoff { until: Instant },
    Ended,
}

struct Proc {
    spec: NodeSpec,
    child: Option<Child>,
    phase: Phase,
    starts: u32,
    restarts_in_a_row: u32,
    last_seen: Instant,
    announced_done: bool,
    /// Copies the stdout of a `console` node to the log and the terminal.
    echo: Option<JoinHandle<()>>,
}

/// The running graph.
pub struct Supervisor<'a> {
    graph: &'a GraphSpec,
    run: &'a RunDir,
    domain: Domain,
    observer: GraphObserver,
    procs: Vec<Proc>,
    t0: Instant,
    stop_at: Option<Instant>,
    done: Option<String>,
    /// The spinner with the session's latest news (on a terminal only).
    progress: Progress,
}

impl<'a> Supervisor<'a> {
    /// Joins the domain (removing stale resources of dead nodes) without starting anything.
    pub fn new(
        graph: &'a GraphSpec,
        run: &'a RunDir,
        domain: Domain,
        duration: Option<Duration>,
    ) -> anyhow::Result<Self> {
        let observer = GraphObserver::new(&domain)?;
        let t0 = Instant::now();
        let procs = graph
            .nodes
            .iter()
            .map(|spec| Proc {
                spec: spec.clone(),
                child: None,
                phase: Phase::NotStarted,
                starts: 0,
                restarts_in_a_row: 0,
                last_seen: t0,
                announced_done: false,
                echo: None,
            })
            .collect();
        Ok(Self {
            graph,
            run,
            domain,
            observer,
            procs,
            t0,
            stop_at: duration.map(|d| t0 + d),
            done: None,
            progress: Progress::spinner(),
        })
    }

    /// Starts the nodes in order, each once its dependencies are ready, then supervises until
    /// the graph has to stop; returns why.
    pub fn run(&mut self) -> StopReason {
        for i in 0..self.procs.len() {
            if let Err(reason) = self.spawn(i) {
                return reason;
            }
            while matches!(
                self.procs[i].phase,
                Phase::Starting { .. } | Phase::Backoff { .. }
            ) {
                if let Err(reason) = self.tick() {
                    return reason;
                }
            }
        }
        self.say(format_args!("all {} nodes started", self.procs.len()));
        loop {
            if let Err(reason) = self.tick() {
                return reason;
            }
        }
    }

    /// Stops every running node in reverse start order (SIGINT → grace → SIGTERM → grace →
    /// SIGKILL) and removes the resources of nodes that did not exit cleanly.
    pub fn stop_all(mut self) {
        for i in (0..self.procs.len()).rev() {
            self.procs[i].phase = Phase::Ended;
            let Some(mut child) = self.procs[i].child.take() else {
                continue;
            };
            let name = self.procs[i].spec.name.clone();
            let ladder = [
                (Signal::SIGINT, self.graph.stop_grace),
                (Signal::SIGTERM, self.graph.term_grace),
                (Signal::SIGKILL, Duration::from_secs(5)),
            ];
            let mut status = child.try_wait().ok().flatten();
            for (signal, grace) in ladder {
                if status.is_some() {
                    break;
                }
                if signal != Signal::SIGINT {
                    self.say(format_args!("{name} still running; sending {signal}"));
                }
                let _ = kill(Pid::from_raw(child.id() as i32), signal);
                status = wait_exit(&mut child, grace);
            }
            if status.is_some() {
                drain_echo(self.procs[i].echo.take());
            }
            match status {
                Some(status) => self.say(format_args!("{name} stopped ({})", describe(status))),
                None => self.say(format_args!(
                    "{name} could not be stopped (pid {})",
                    child.id()
                )),
            }
        }
        let removed = self.observer.cleanup_dead_nodes();
        if removed > 0 {
            self.say(format_args!(
                "removed the resources of {removed} dead node(s)"
            ));
        }
        self.progress.finish();
    }

    /// Prints a progress line with the time since launch.
    pub fn say(&self, message: std::fmt::Arguments<'_>) {
        self.progress.line(format_args!(
            "[{:8.3}] {message}",
            self.t0.elapsed().as_secs_f64()
        ));
    }

    /// One supervision step: wait a little, read lifecycle messages, look after every node.
    fn tick(&mut self) -> Result<(), StopReason> {
        if !self.observer.wait(POLL) {
            self.say(format_args!("stop requested"));
            return Err(StopReason::Signal);
        }
        self.read_lifecycle();
        if let Some(node) = self.done.clone() {
            return Err(StopReason::Done(node));
        }
        if self.stop_at.is_some_and(|at| Instant::now() >= at) {
            self.say(format_args!("duration elapsed"));
            return Err(StopReason::Duration);
        }
        for i in 0..self.procs.len() {
            self.look_after(i)?;
        }
        Ok(())
    }

    fn read_lifecycle(&mut self) {
        let mut messages = Vec::new();
        if let Err(error) = self.observer.poll(|m| messages.push(m)) {
            self.say(format_args!("cannot read lifecycle messages: {error}"));
        }
        for message in messages {
            let Some(i) = self.procs.iter().position(|p| {
                p.spec.name == message.node.as_str()
                    && p.child.as_ref().is_some_and(|c| c.id() == message.pid)
            }) else {
                continue;
            };
            self.procs[i].last_seen = Instant::now();
            match message.state {
                LifecycleState::Ready => {
                    if let Phase::Starting { since } = self.procs[i].phase {
                        self.procs[i].phase = Phase::Ready {
                            since: Instant::now(),
                        };
                        self.say(format_args!(
                            "{} ready (pid {}, {:.0} ms)",
                            self.procs[i].spec.name,
                            message.pid,
                            since.elapsed().as_secs_f64() * 1e3
                        ));
                    }
                }
                LifecycleState::Done => {
                    self.procs[i].announced_done = true;
                    self.say(format_args!(
                        "{} announced the job done",
                        self.procs[i].spec.name
                    ));
                    self.done
                        .get_or_insert_with(|| message.node.as_str().to_owned());
                }
                LifecycleState::Starting | LifecycleState::Stopping => {}
            }
        }
    }

    fn look_after(&mut self, i: usize) -> Result<(), StopReason> {
        let name = self.procs[i].spec.name.clone();
        match self.procs[i].phase {
            Phase::Backoff { until } if Instant::now() >= until => return self.spawn(i),
            Phase::Starting { since } if since.elapsed() > self.procs[i].spec.ready_timeout => {
                self.say(format_args!(
                    "{name} not ready within {:.1} s; killing it",
                    self.procs[i].spec.ready_timeout.as_secs_f64()
                ));
                self.kill_now(i);
            }
            Phase::Ready { .. } => {
                if let Some(limit) = self.procs[i].spec.heartbeat_timeout {
                    if self.procs[i].last_seen.elapsed() > limit {
                        self.say(format_args!(
                            "{name} silent for {:.1} s (no heartbeat); killing it",
                            limit.as_secs_f64()
                        ));
                        self.kill_now(i);
                    }
                }
            }
            _ => {}
        }
        let status = match self.procs[i].child.as_mut().map(Child::try_wait) {
            Some(Ok(Some(status))) => status,
            _ => return Ok(()),
        };
        self.procs[i].child = None;
        self.ended(i, &describe(status), !status.success())
    }

    /// Handles the end of a node's process: restart per policy, or give up.
    fn ended(&mut self, i: usize, detail: &str, failed: bool) -> Result<(), StopReason> {
        // A last "done" sent just before the exit must count.
        self.read_lifecycle();
        let removed = self.observer.cleanup_dead_nodes();
        let proc = &mut self.procs[i];
        let name = proc.spec.name.clone();
        if let Phase::Ready { since } = proc.phase {
            if since.elapsed() >= STABLE_AFTER {
                proc.restarts_in_a_row = 0;
            }
        }
        let wanted = match proc.spec.restart {
            RestartPolicy::Never => false,
            RestartPolicy::OnFailure => failed,
            RestartPolicy::Always => true,
        };
        let cleaned = if removed > 0 {
            "; removed its stale resources".to_owned()
        } else {
            String::new()
        };
        if wanted && proc.restarts_in_a_row < proc.spec.max_restarts {
            let delay = proc
                .spec
                .restart_backoff
                .saturating_mul(1 << proc.restarts_in_a_row.min(16))
                .min(MAX_BACKOFF);
            proc.restarts_in_a_row += 1;
            proc.phase = Phase::Backoff {
                until: Instant::now() + delay,
            };
            let attempt = format!("{}/{}", proc.restarts_in_a_row, proc.spec.max_restarts);
            self.say(format_args!(
                "{name} ended ({detail}){cleaned}; restart {attempt} in {:.2} s",
                delay.as_secs_f64()
            ));
            return Ok(());
        }
        proc.phase = Phase::Ended;
        let required = proc.spec.required;
        let done = proc.announced_done;
        let why = if wanted {
            "restart limit reached"
        } else {
            "not restarted"
        };
        self.say(format_args!("{name} ended ({detail}){cleaned}; {why}"));
        if required && !done {
            return Err(StopReason::RequiredEnded {
                node: name,
                detail: detail.to_owned(),
            });
        }
        Ok(())
    }

    fn kill_now(&mut self, i: usize) {
        if let Some(child) = self.procs[i].child.as_mut() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Starts node `i`; a failure to start counts as a failed run of the node.
    fn spawn(&mut self, i: usize) -> Result<(), StopReason> {
        self.procs[i].starts += 1;
        let starts = self.procs[i].starts;
        let label = if starts == 1 {
            "starting"
        } else {
            "restarting"
        };
        match self.start_process(&self.procs[i].spec, label, starts) {
            Ok((child, echo)) => {
                drain_echo(std::mem::replace(&mut self.procs[i].echo, echo));
                self.say(format_args!(
                    "{label} {} (pid {})",
                    self.procs[i].spec.name,
                    child.id()
                ));
                let proc = &mut self.procs[i];
                proc.child = Some(child);
                proc.phase = Phase::Starting {
                    since: Instant::now(),
                };
                proc.last_seen = Instant::now();
                Ok(())
            }
            Err(error) => {
                self.say(format_args!(
                    "cannot start {}: {error:#}",
                    self.procs[i].spec.name
                ));
                self.procs[i].phase = Phase::Starting {
                    since: Instant::now(),
                };
                self.ended(i, "could not be started", true)
            }
        }
    }

    fn start_process(
        &self,
        spec: &NodeSpec,
        label: &str,
        starts: u32,
    ) -> anyhow::Result<(Child, Option<JoinHandle<()>>)> {
        let mut log = self.run.open_log(&spec.name)?;
        writeln!(
            log,
            "=== sabr launch: {label} {} (start #{starts}) ===",
            spec.name
        )?;
        let mut command = Command::new(&spec.exec);
        command
            .args(&spec.args)
            .envs(&spec.env)
            .env(DOMAIN_ENV, self.domain.as_str())
            .env(NODE_NAME_ENV, &spec.name)
            .env(RUN_DIR_ENV, self.run.path())
            .envs(
                spec.loop_phase_us
                    .map(|phase| (LOOP_PHASE_ENV, phase.to_string())),
            )
            .stdin(Stdio::null())
            .stdout(if spec.console {
                Stdio::piped()
            } else {
                log.try_clone()?.into()
            })
            .stderr(log.try_clone()?)
            // Own process group: a terminal's Ctrl-C reaches only the launcher, which then
            // stops the nodes in reverse order.
            .process_group(0);
        let placement = spec
            .placement
            .prepare()
            .map_err(|reason| anyhow::anyhow!("placement of {}: {reason}", spec.name))?;
        prepare_child(&mut command, placement);
        let mut child = command.spawn()?;
        let echo = child
            .stdout
            .take()
            .map(|out| echo_lines(out, log, spec.name.clone(), self.t0, self.progress.clone()));
        Ok((child, echo))
    }
}

/// Copies a console node's stdout line by line to its log and to the launcher's terminal
/// (`[time] node: line`), until the node closes it. Its latest line is also the progress
/// display's message (the calibrator's phase and session lines, for example).
fn echo_lines(
    out: ChildStdout,
    mut log: std::fs::File,
    node: String,
    t0: Instant,
    progress: Progress,
) -> JoinHandle<()> {
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(out).lines() {
            let Ok(line) = line else { break };
            let _ = writeln!(log, "{line}");
            progress.line(format_args!(
                "[{:8.3}] {node}: {line}",
                t0.elapsed().as_secs_f64()
            ));
            progress.set_message(format_args!("{node}: {line}"));
        }
    })
}

/// Lets the echo of an exited console node show its last lines (bounded wait).
fn drain_echo(echo: Option<JoinHandle<()>>) {
    let Some(echo) = echo else { return };
    let start = Instant::now();
    while !echo.is_finished() && start.elapsed() < ECHO_DRAIN {
        std::thread::sleep(Duration::from_millis(5));
    }
    if echo.is_finished() {
        let _ = echo.join();
    }
}

/// In the child before exec: makes the kernel send SIGTERM to the child when the launcher
/// dies (so no node outlives it), then applies the node's CPU set and scheduling policy
/// (the steps run in the order they were added).
#[allow(unsafe_code)]
fn prepare_child(command: &mut Command, placement: Prepared) {
    let launcher = nix::unistd::getpid();
    // SAFETY: the closure runs in the child between fork and exec; it only makes the
    // async-signal-safe system calls prctl and getppid and does not allocate.
    unsafe {
        command.pre_exec(move || {
            nix::sys::prctl::set_pdeathsig(Signal::SIGTERM)?;
            if nix::unistd::getppid() != launcher {
                return Err(nix::errno::Errno::ESRCH.into());
            }
            Ok(())
        });
    }
    placement.apply_in_child(command);
}

/// Waits up to `grace` for the child to exit.
fn wait_exit(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    let start = Instant::now();
    loop {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        if start.elapsed() >= grace {
            return None;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// "exit code 3" or "killed by SIGKILL".
pub fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exit code {code}"),
        (None, Some(signal)) => match Signal::try_from(signal) {
            Ok(signal) => format!("killed by {signal}"),
            Err(_) => format!("killed by signal {signal}"),
        },
        (None, None) => "ended".to_owned(),
    }
}
