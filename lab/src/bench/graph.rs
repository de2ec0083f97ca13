//! A live graph under measurement: a launch file written by the bench, run by `sabr launch`
//! (the `sabr` beside the node executables) as a child process in an iceoryx2 domain of its own, and the node
//! processes it started, learnt from their lifecycle announcements.

use super::cpu::CpuShare;
use super::stats::Measurement;
use anyhow::{bail, Context};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_launcher::placement::{Placement, Sched};
use sabr_launcher::spec;
use sabr_node::msgs::LifecycleState;
use sabr_node::{errln, Domain, GraphObserver};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Longest wait for the launcher to stop its graph after SIGINT (its stop ladder is at most
/// 5 s per node, nodes stopped one after the other).
const STOP_TIMEOUT: Duration = Duration::from_secs(60);

/// Lines of the launcher's output quoted when the graph fails.
const LOG_TAIL_LINES: usize = 15;

/// The launch file of the sensing graph the bench measures (`launch/graphs/bench-sensing.toml`).
pub const SENSING_LAUNCH_FILE: &str = include_str!("../../../launch/graphs/bench-sensing.toml");
/// The launch file of the setpoint graph (`launch/graphs/bench-setpoints.toml`).
pub const SETPOINTS_LAUNCH_FILE: &str = include_str!("../../../launch/graphs/bench-setpoints.toml");
/// The shipped main job (`launch/graphs/sim-calibration.toml`): the placement of every node,
/// the motion node included, which the bench graphs lack.
pub const SHIPPED_LAUNCH_FILE: &str = include_str!("../../../launch/graphs/sim-calibration.toml");

/// A directory holding an empty stand-in executable for every node executable the bench's
/// launch files name (the shipped main job's included), so that they parse in tests.
#[cfg(test)]
pub fn stand_in_bin_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for file in [
        SENSING_LAUNCH_FILE,
        SETPOINTS_LAUNCH_FILE,
        SHIPPED_LAUNCH_FILE,
    ] {
        let graph: toml::Table = file.parse().unwrap();
        for node in graph["node"].as_array().unwrap() {
            let exec = node["exec"].as_str().unwrap();
            std::fs::write(dir.path().join(exec), "").unwrap();
        }
    }
    dir
}

/// The placement `launch_file` gives `node` (executables looked up in `bin_dir`).
pub fn placement_of(launch_file: &str, node: &str, bin_dir: &Path) -> anyhow::Result<Placement> {
    Ok(node_of(launch_file, node, bin_dir)?.placement)
}

/// The phase (µs) `launch_file` gives the periodic loop of `node` (`phase_us`), if any.
pub fn loop_phase_of(launch_file: &str, node: &str, bin_dir: &Path) -> anyhow::Result<Option<u32>> {
    Ok(node_of(launch_file, node, bin_dir)?.loop_phase_us)
}

/// The node `node` of `launch_file` as the launcher reads it (executables looked up in
/// `bin_dir`).
fn node_of(launch_file: &str, node: &str, bin_dir: &Path) -> anyhow::Result<spec::NodeSpec> {
    let graph = spec::parse(Path::new("bench graph"), launch_file, bin_dir)?;
    graph
        .nodes
        .into_iter()
        .find(|n| n.name == node)
        .with_context(|| format!("the bench graph has no node {node}"))
}

/// The CPU wake-up latency bound (µs) `launch_file` holds while its graph runs, if any
/// (`[graph] cpu_wake_latency_us`; executables looked up in `bin_dir`).
pub fn wake_latency_of(launch_file: &str, bin_dir: &Path) -> anyhow::Result<Option<u32>> {
    let graph = spec::parse(Path::new("bench graph"), launch_file, bin_dir)?;
    Ok(graph.cpu_wake_latency.map(|(latency_us, _line)| latency_us))
}

/// Real-time priority of the bench's listening thread: above any the graphs' nodes use, so
/// it runs as soon as it is woken.
const PROBE_PRIORITY: u8 = 50;

/// The placement of the bench's listening thread in a live graph: the CPUs of the node whose
/// place it takes, at `SCHED_FIFO` priority [`PROBE_PRIORITY`] where the system allows it.
/// A hop is then the transport's time to a consumer that runs when woken, not the time the
/// nodes sharing its core spend on the same sample first (the sync, woken by the same
/// encoder sample, would otherwise run before the bench on that core). Also returns the note
/// printed under the tables.
pub fn probe_placement(mut placement: Placement) -> (Placement, String) {
    let wanted = Placement {
        sched: Some(Sched::Fifo(PROBE_PRIORITY)),
        ..placement.clone()
    };
    match wanted.probe() {
        Ok(()) => {
            placement = wanted;
            let note = format!(
                "the bench listened at {placement}: above the graph, so a hop is the \
                 transport's time to a consumer that runs when woken"
            );
            (placement, note)
        }
        Err(reason) => {
            let note = format!(
                "the bench listened at {placement} without a real-time priority ({reason}): \
                 a hop includes the time nodes on the same core spend on the sample first"
            );
            (placement, note)
        }
    }
}

/// Runs `run` on a thread of its own placed as `placement` says (affinity and policy are per
/// thread on Linux, so the rest of the bench is not moved).
pub fn placed<R: Send>(
    placement: &Placement,
    run: impl FnOnce() -> anyhow::Result<R> + Send,
) -> anyhow::Result<R> {
    let prepared = placement.prepare().map_err(anyhow::Error::msg)?;
    std::thread::scope(|scope| {
        scope
            .spawn(move || {
                prepared
                    .apply()
                    .with_context(|| format!("cannot place the bench's thread: {placement}"))?;
                run()
            })
            .join()
            .map_err(|_| anyhow::anyhow!("the bench's placed thread panicked"))?
    })
}

/// The iceoryx2 domain `name`, which must not be in use (no files of it exist).
pub fn fresh_domain(name: &str) -> anyhow::Result<Domain> {
    let domain = Domain::new(name)?;
    let files = sabr_node::domain_files(&domain);
    if let Some(first) = files.first() {
        bail!(
            "domain {domain} is in use: {} iceoryx2 files such as {}",
            files.len(),
            first.display()
        );
    }
    Ok(domain)
}

/// What the measurement of one live graph produced.
pub struct GraphMeasured {
    /// Hop latencies and errors (ns), named after [`super::hops::HOPS`].
    pub measurements: Vec<Measurement>,
    /// CPU use of each process of the graph, labelled `<graph>/<node>`.
    pub idle: Vec<(String, CpuShare)>,
    /// Remarks printed under the tables.
    pub notes: Vec<String>,
}

/// A graph started by the bench; stopped by [`LiveGraph::stop`] or when dropped.
pub struct LiveGraph {
    name: String,
    launcher: Option<Child>,
    launcher_log: PathBuf,
    observer: Option<GraphObserver>,
    ready: BTreeMap<String, u32>,
}

impl LiveGraph {
    /// Writes `launch_toml` to `<dir>/<name>.toml`, checks it (every executable must exist in
    /// `bin_dir`) and starts `sabr launch` on it in `domain` (see [`fresh_domain`]), logs under
    /// `<dir>/runs`. The launcher stops the graph by itself after `backstop` should this
    /// process die.
    pub fn start(
        name: &str,
        launch_toml: &str,
        dir: &Path,
        bin_dir: &Path,
        domain: Domain,
        backstop: Duration,
    ) -> anyhow::Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let file = dir.join(format!("{name}.toml"));
        std::fs::write(&file, launch_toml)
            .with_context(|| format!("cannot write {}", file.display()))?;
        spec::load(&file, bin_dir)
            .with_context(|| format!("the {name} graph cannot be launched"))?;
        // Joins the domain before any node does, so no announcement is missed.
        let observer = GraphObserver::new(&domain)?;
        let launcher_log = dir.join(format!("{name}-launcher.log"));
        let output = std::fs::File::create(&launcher_log)
            .with_context(|| format!("cannot create {}", launcher_log.display()))?;
        let exe = bin_dir.join("sabr");
        let mut command = Command::new(&exe);
        // The bench starts graphs from its measuring thread, placed above the graph: the
        // launcher, and the nodes without a policy of their own, must not inherit that.
        Placement::unplaced()
            .and_then(|unplaced| unplaced.prepare())
            .map_err(anyhow::Error::msg)
            .context("cannot place the launcher")?
            .apply_in_child(&mut command);
        let launcher = command
            .arg("launch")
            .arg(&file)
            .arg("--run-dir")
            .arg(dir.join("runs"))
            .args(["--domain", domain.as_str()])
            .args(["--duration", &format!("{:.0}", backstop.as_secs_f64())])
            .arg("--bin-dir")
            .arg(bin_dir)
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(output.try_clone()?)
            .stderr(output)
            .spawn()
            .with_context(|| format!("cannot start {} launch", exe.display()))?;
        Ok(Self {
            name: name.to_owned(),
            launcher: Some(launcher),
            launcher_log,
            observer: Some(observer),
            ready: BTreeMap::new(),
        })
    }

    /// Where the launcher writes the run directory with each node's log (`<run id>/logs/`).
    pub fn runs_dir(&self) -> PathBuf {
        self.launcher_log
            .parent()
            .map_or(PathBuf::from("runs"), |dir| dir.join("runs"))
    }

    /// Waits up to `timeout` until every node of `nodes` announced readiness.
    pub fn wait_ready(&mut self, nodes: &[&str], timeout: Duration) -> anyhow::Result<()> {
        let started = Instant::now();
        loop {
            self.poll_lifecycle()?;
            if nodes.iter().all(|node| self.ready.contains_key(*node)) {
                return Ok(());
            }
            self.check_running()?;
            if started.elapsed() > timeout {
                let missing: Vec<&str> = nodes
                    .iter()
                    .copied()
                    .filter(|node| !self.ready.contains_key(*node))
                    .collect();
                bail!(
                    "{} graph: {missing:?} not ready within {timeout:?}{}",
                    self.name,
                    self.log_tail()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Fails if the launcher ended or a ready node announced that it is stopping.
    pub fn check_running(&mut self) -> anyhow::Result<()> {
        self.poll_lifecycle()?;
        if let Some(launcher) = &mut self.launcher {
            if let Some(status) = launcher.try_wait()? {
                bail!(
                    "{} graph: the launcher ended early ({status}){}",
                    self.name,
                    self.log_tail()
                );
            }
        }
        Ok(())
    }

    /// `(label, pid)` of every ready node, then of the launcher.
    pub fn processes(&self) -> Vec<(String, u32)> {
        let mut processes: Vec<(String, u32)> = self
            .ready
            .iter()
            .map(|(node, pid)| (node.clone(), *pid))
            .collect();
        if let Some(launcher) = &self.launcher {
            processes.push(("launcher".to_owned(), launcher.id()));
        }
        processes
    }

    /// Stops the graph like Ctrl-C would and waits for the launcher (which removes the
    /// domain's files once no node of it is left: the bench's own nodes should be gone by
    /// now).
    pub fn stop(mut self) -> anyhow::Result<()> {
        self.stop_launcher()
    }

    fn stop_launcher(&mut self) -> anyhow::Result<()> {
        // The observer is a node of the domain: leave first, so the domain can be released.
        self.observer = None;
        let Some(mut launcher) = self.launcher.take() else {
            return Ok(());
        };
        if launcher.try_wait()?.is_none() {
            let _ = kill(Pid::from_raw(launcher.id() as i32), Signal::SIGINT);
        }
        let started = Instant::now();
        let status = loop {
            if let Some(status) = launcher.try_wait()? {
                break Some(status);
            }
            if started.elapsed() > STOP_TIMEOUT {
                let _ = launcher.kill();
                let _ = launcher.wait();
                break None;
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        match status {
            None => bail!(
                "{} graph: the launcher did not stop within {STOP_TIMEOUT:?} (killed){}",
                self.name,
                self.log_tail()
            ),
            Some(status) if !status.success() => bail!(
                "{} graph: the launcher stopped with {status}{}",
                self.name,
                self.log_tail()
            ),
            Some(_) => Ok(()),
        }
    }

    fn poll_lifecycle(&mut self) -> anyhow::Result<()> {
        let Some(observer) = &self.observer else {
            return Ok(());
        };
        let own = std::process::id();
        let mut announcements = Vec::new();
        observer.poll(|m| announcements.push(m))?;
        for message in announcements.into_iter().filter(|m| m.pid != own) {
            let node = message.node.as_str().to_owned();
            match message.state {
                LifecycleState::Ready => {
                    self.ready.insert(node, message.pid);
                }
                LifecycleState::Stopping | LifecycleState::Done
                    if self.ready.get(&node) == Some(&message.pid) =>
                {
                    bail!(
                        "{} graph: node {node} (pid {}) announced {:?} during the measurement{}",
                        self.name,
                        message.pid,
                        message.state,
                        self.log_tail()
                    );
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The end of the launcher's output, for error messages.
    fn log_tail(&self) -> String {
        let text = std::fs::read_to_string(&self.launcher_log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        let tail = lines[lines.len().saturating_sub(LOG_TAIL_LINES)..].join("\n  ");
        format!(
            "; launcher output ({}, node logs under {}):\n  {tail}",
            self.launcher_log.display(),
            self.runs_dir().display()
        )
    }
}

impl Drop for LiveGraph {
    fn drop(&mut self) {
        if self.launcher.is_some() {
            if let Err(error) = self.stop_launcher() {
                errln!("sabr bench: {error:#}");
            }
        }
    }
}
