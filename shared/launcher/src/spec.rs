//! The launch file: parsing and validation into a [`GraphSpec`] in start order.
//!
//! ```toml
//! [graph]                      # optional
//! stop_grace_s = 3.0           # stop request (SIGINT) → SIGTERM
//! term_grace_s = 2.0           # SIGTERM → SIGKILL
//! cpu_wake_latency_us = 0      # optional: bound on the CPUs' wake-up latency while the graph
//!                              # runs (0: idle CPUs poll; see `wake_latency`)
//!
//! [[node]]
//! name = "encoders"            # 1..=32 of [A-Za-z0-9_-]; names the log file
//! exec = "sabr-encoders"       # a bare name is looked up next to the sabr executable;
//!                              # a path is relative to the launch file
//! args = ["--rate-hz", "1000"]
//! env = { RUST_LOG = "debug" }
//! depends_on = ["rig"]         # started only once these are ready
//! restart = "on-failure"       # never (default) | on-failure | always
//! max_restarts = 5             # default 5
//! restart_backoff_s = 0.1      # first delay, doubled per consecutive restart (max 5 s)
//! required = true              # default true: its end stops the whole graph
//! ready_timeout_s = 10.0       # default 10
//! heartbeat_timeout_s = 2.0    # optional: silent this long while ready → killed (and restarted)
//! console = true               # default false: its stdout lines are also shown on the
//!                              # launcher's terminal (prefixed with the node's name)
//! cpus = [0]                   # optional: the CPUs it may run on (sched_setaffinity)
//! sched = "fifo:40"            # optional: "fifo:N" | "rr:N" (N = 1..=99) | "other" | "idle"
//! phase_us = 200               # optional: its periodic loop's deadlines fall this many µs
//!                              # after each multiple of the loop's period on
//!                              # CLOCK_MONOTONIC (modulo the period; 0..=999999)
//! ```
//!
//! A placement (`cpus`, `sched`) is checked against the machine when the file is read and
//! tried before any node starts ([`check_placements`]); the launcher applies it in the child
//! before the node's executable runs.

use crate::placement::{self, Placement, Sched};
use crate::wake_latency::WakeLatencyBound;
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;
use toml::Spanned;

/// Longest restart delay after doubling.
pub const MAX_BACKOFF: Duration = Duration::from_secs(5);

/// A launch-file error with its position: `file:line:column: reason`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}:{line}:{column}: {reason}", file.display())]
pub struct LaunchFileError {
    /// The launch file.
    pub file: PathBuf,
    /// 1-based line of the offending text.
    pub line: usize,
    /// 1-based column of the offending text.
    pub column: usize,
    /// What is wrong.
    pub reason: String,
}

/// When a node that ended is started again.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartPolicy {
    /// Never restarted.
    #[default]
    Never,
    /// Restarted when it exits with a non-zero status or is killed by a signal.
    OnFailure,
    /// Restarted whenever it ends.
    Always,
}

/// One node of the graph, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSpec {
    /// Unique name (log file `logs/<name>.log`, env `SABR_NODE_NAME`).
    pub name: String,
    /// Resolved path of the executable.
    pub exec: PathBuf,
    /// Command-line arguments.
    pub args: Vec<String>,
    /// Extra environment variables.
    pub env: BTreeMap<String, String>,
    /// Names of the nodes that must be ready before this one starts.
    pub depends_on: Vec<String>,
    /// Restart policy.
    pub restart: RestartPolicy,
    /// Most restarts in a row before giving up.
    pub max_restarts: u32,
    /// Delay before the first restart, doubled per consecutive restart up to [`MAX_BACKOFF`].
    pub restart_backoff: Duration,
    /// If true, the node ending for good stops the whole graph.
    pub required: bool,
    /// Longest wait for the node's readiness announcement.
    pub ready_timeout: Duration,
    /// Longest silence (no heartbeat) of a ready node before it is killed; `None`: not watched.
    pub heartbeat_timeout: Option<Duration>,
    /// If true, the node's stdout lines also go to the launcher's terminal (progress, results).
    pub console: bool,
    /// CPU set and scheduling policy.
    pub placement: Placement,
    /// Line of the launch file where the placement (or, without one, the node) is given.
    pub placement_line: usize,
    /// Phase of the node's periodic loop on `CLOCK_MONOTONIC`, µs (env
    /// `SABR_LOOP_PHASE_US`); `None`: the loop's schedule starts with its first call.
    pub loop_phase_us: Option<u32>,
}

/// A validated graph: nodes in start order (every node after its dependencies).
#[derive(Debug, Clone, PartialEq)]
pub struct GraphSpec {
    /// The launch file.
    pub file: PathBuf,
    /// Nodes in start order; stop order is the reverse.
    pub nodes: Vec<NodeSpec>,
    /// Time between the stop request (SIGINT) and SIGTERM.
    pub stop_grace: Duration,
    /// Time between SIGTERM and SIGKILL.
    pub term_grace: Duration,
    /// Bound on the CPUs' wake-up latency while the graph runs (µs), and the line giving it.
    pub cpu_wake_latency: Option<(u32, usize)>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileToml {
    #[serde(default)]
    graph: GraphToml,
    #[serde(default)]
    node: Vec<Spanned<NodeToml>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct GraphToml {
    stop_grace_s: Option<Spanned<f64>>,
    term_grace_s: Option<Spanned<f64>>,
    cpu_wake_latency_us: Option<Spanned<u32>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NodeToml {
    name: Spanned<String>,
    exec: Spanned<String>,
    #[serde(default)]
    args: Vec<String>,
    #[serde(default)]
    env: BTreeMap<String, String>,
    #[serde(default)]
    depends_on: Vec<Spanned<String>>,
    #[serde(default)]
    restart: RestartPolicy,
    #[serde(default = "default_max_restarts")]
    max_restarts: u32,
    restart_backoff_s: Option<Spanned<f64>>,
    #[serde(default = "default_required")]
    required: bool,
    ready_timeout_s: Option<Spanned<f64>>,
    heartbeat_timeout_s: Option<Spanned<f64>>,
    #[serde(default)]
    console: bool,
    cpus: Option<Spanned<Vec<usize>>>,
    sched: Option<Spanned<String>>,
    phase_us: Option<Spanned<u32>>,
}

fn default_max_restarts() -> u32 {
    5
}

fn default_required() -> bool {
    true
}

/// Reads and validates a launch file; bare executable names are resolved in `bin_dir`.
pub fn load(file: &Path, bin_dir: &Path) -> Result<GraphSpec, LaunchFileError> {
    let text = std::fs::read_to_string(file).map_err(|e| LaunchFileError {
        file: file.to_owned(),
        line: 1,
        column: 1,
        reason: format!("cannot read the launch file: {e}"),
    })?;
    parse(file, &text, bin_dir)
}

/// Validates launch-file text (`file` names it in errors and anchors relative exec paths).
pub fn parse(file: &Path, text: &str, bin_dir: &Path) -> Result<GraphSpec, LaunchFileError> {
    let at = |span: Range<usize>, reason: String| {
        let (line, column) = line_column(text, span.start);
        LaunchFileError {
            file: file.to_owned(),
            line,
            column,
            reason,
        }
    };
    let parsed: FileToml =
        toml::from_str(text).map_err(|e| at(e.span().unwrap_or(0..0), clean(e.message())))?;
    if parsed.node.is_empty() {
        return Err(at(0..0, "no [[node]] in the launch file".to_owned()));
    }
    let stop_grace = seconds(&parsed.graph.stop_grace_s, 3.0, "stop_grace_s", &at)?;
    let term_grace = seconds(&parsed.graph.term_grace_s, 2.0, "term_grace_s", &at)?;

    let mut nodes = Vec::with_capacity(parsed.node.len());
    let mut index: HashMap<String, usize> = HashMap::new();
    for entry in &parsed.node {
        let node = entry.get_ref();
        let name = node.name.get_ref();
        sabr_node::validate_node_name(name).map_err(|e| at(node.name.span(), e.to_string()))?;
        if index.insert(name.clone(), nodes.len()).is_some() {
            return Err(at(
                node.name.span(),
                format!("duplicate node name {name:?}"),
            ));
        }
        let exec = resolve_exec(file, bin_dir, node.exec.get_ref())
            .map_err(|reason| at(node.exec.span(), reason))?;
        let heartbeat_timeout = match &node.heartbeat_timeout_s {
            Some(_) => Some(seconds(
                &node.heartbeat_timeout_s,
                0.0,
                "heartbeat_timeout_s",
                &at,
            )?),
            None => None,
        };
        let (placement, placement_line) = node_placement(node, text, &at)?;
        let loop_phase_us = match &node.phase_us {
            Some(phase) if *phase.get_ref() > sabr_node::MAX_LOOP_PHASE_US => {
                return Err(at(
                    phase.span(),
                    format!(
                        "phase_us = {}: must be below one second (at most {})",
                        phase.get_ref(),
                        sabr_node::MAX_LOOP_PHASE_US
                    ),
                ));
            }
            phase => phase.as_ref().map(|phase| *phase.get_ref()),
        };
        nodes.push(NodeSpec {
            name: name.clone(),
            exec,
            args: node.args.clone(),
            env: node.env.clone(),
            depends_on: node
                .depends_on
                .iter()
                .map(|d| d.get_ref().clone())
                .collect(),
            restart: node.restart,
            max_restarts: node.max_restarts,
            restart_backoff: seconds(&node.restart_backoff_s, 0.1, "restart_backoff_s", &at)?,
            required: node.required,
            ready_timeout: seconds(&node.ready_timeout_s, 10.0, "ready_timeout_s", &at)?,
            heartbeat_timeout,
            console: node.console,
            placement,
            placement_line,
            loop_phase_us,
        });
    }
    for entry in &parsed.node {
        let node = entry.get_ref();
        for dep in &node.depends_on {
            if !index.contains_key(dep.get_ref()) {
                return Err(at(
                    dep.span(),
                    format!(
                        "node {:?} depends on unknown node {:?}",
                        node.name.get_ref(),
                        dep.get_ref()
                    ),
                ));
            }
            if dep.get_ref() == node.name.get_ref() {
                return Err(at(
                    dep.span(),
                    format!("node {:?} depends on itself", dep.get_ref()),
                ));
            }
        }
    }
    let order = start_order(&nodes).map_err(|cycle| {
        let first = &parsed.node[index[&cycle[0]]];
        at(
            first.get_ref().name.span(),
            format!("dependency cycle: {}", cycle.join(" → ")),
        )
    })?;
    let mut slots: Vec<Option<NodeSpec>> = nodes.into_iter().map(Some).collect();
    let nodes = order.into_iter().filter_map(|i| slots[i].take()).collect();
    Ok(GraphSpec {
        file: file.to_owned(),
        nodes,
        stop_grace,
        term_grace,
        cpu_wake_latency: parsed
            .graph
            .cpu_wake_latency_us
            .as_ref()
            .map(|bound| (*bound.get_ref(), line_column(text, bound.span().start).0)),
    })
}

/// The node's placement and the line it is given on.
fn node_placement(
    node: &NodeToml,
    text: &str,
    at: &impl Fn(Range<usize>, String) -> LaunchFileError,
) -> Result<(Placement, usize), LaunchFileError> {
    let mut line = line_column(text, node.name.span().start).0;
    let cpus = match &node.cpus {
        None => None,
        Some(cpus) => {
            placement::check_cpus(cpus.get_ref()).map_err(|reason| at(cpus.span(), reason))?;
            line = line_column(text, cpus.span().start).0;
            Some(cpus.get_ref().clone())
        }
    };
    let sched = match &node.sched {
        None => None,
        Some(sched) => {
            let parsed =
                Sched::parse(sched.get_ref()).map_err(|reason| at(sched.span(), reason))?;
            line = line_column(text, sched.span().start).0;
            Some(parsed)
        }
    };
    Ok((Placement { cpus, sched }, line))
}

impl GraphSpec {
    /// Leaves every node's placement, loop phase and the CPUs' wake-up latency to the system.
    pub fn remove_placement(&mut self) {
        self.cpu_wake_latency = None;
        for node in &mut self.nodes {
            node.placement = Placement::default();
            node.loop_phase_us = None;
        }
    }
}

/// Tries every node's placement, and the graph's CPU wake-up latency bound, on this machine
/// before anything starts; the error names the node, the launch-file line, what failed and
/// how to allow it.
pub fn check_placements(graph: &GraphSpec) -> Result<(), LaunchFileError> {
    if let Some((_, line)) = graph.cpu_wake_latency {
        WakeLatencyBound::check().map_err(|reason| LaunchFileError {
            file: graph.file.clone(),
            line,
            column: 1,
            reason,
        })?;
    }
    for node in graph.nodes.iter().filter(|n| !n.placement.is_default()) {
        node.placement.probe().map_err(|reason| LaunchFileError {
            file: graph.file.clone(),
            line: node.placement_line,
            column: 1,
            reason: format!("node {:?}: {reason}", node.name),
        })?;
    }
    Ok(())
}

/// Start order by Kahn's algorithm, ties in file order; on a cycle, the names along it.
fn start_order(nodes: &[NodeSpec]) -> Result<Vec<usize>, Vec<String>> {
    let position: HashMap<&str, usize> = nodes
        .iter()
        .enumerate()
        .map(|(i, n)| (n.name.as_str(), i))
        .collect();
    let mut started = vec![false; nodes.len()];
    let mut order = Vec::with_capacity(nodes.len());
    while order.len() < nodes.len() {
        let next = (0..nodes.len()).find(|&i| {
            !started[i]
                && nodes[i]
                    .depends_on
                    .iter()
                    .all(|d| started[position[d.as_str()]])
        });
        match next {
            Some(i) => {
                started[i] = true;
                order.push(i);
            }
            None => return Err(find_cycle(nodes, &position, &started)),
        }
    }
    Ok(order)
}

/// Follows unstarted dependencies from the first blocked node until a name repeats.
fn find_cycle(
    nodes: &[NodeSpec],
    position: &HashMap<&str, usize>,
    started: &[bool],
) -> Vec<String> {
    let mut path: Vec<usize> = Vec::new();
    let mut current = (0..nodes.len()).find(|&i| !started[i]).unwrap_or(0);
    loop {
        if let Some(at) = path.iter().position(|&p| p == current) {
            let mut names: Vec<String> =
                path[at..].iter().map(|&i| nodes[i].name.clone()).collect();
            names.push(nodes[current].name.clone());
            return names;
        }
        path.push(current);
        current = nodes[current]
            .depends_on
            .iter()
            .map(|d| position[d.as_str()])
            .find(|&d| !started[d])
            .unwrap_or(current);
    }
}

fn resolve_exec(file: &Path, bin_dir: &Path, exec: &str) -> Result<PathBuf, String> {
    if exec.is_empty() {
        return Err("exec is empty".to_owned());
    }
    let path = if exec.contains('/') {
        file.parent().unwrap_or(Path::new(".")).join(exec)
    } else {
        bin_dir.join(exec)
    };
    if path.is_file() {
        Ok(path)
    } else {
        Err(format!(
            "executable {:?} not found at {} (build the service binaries: cargo build --workspace --bins)",
            exec,
            path.display()
        ))
    }
}

fn seconds(
    value: &Option<Spanned<f64>>,
    default: f64,
    key: &str,
    at: &impl Fn(Range<usize>, String) -> LaunchFileError,
) -> Result<Duration, LaunchFileError> {
    match value {
        None => Ok(Duration::from_secs_f64(default)),
        Some(v) => {
            let s = *v.get_ref();
            if s.is_finite() && (0.0..=86_400.0).contains(&s) {
                Ok(Duration::from_secs_f64(s))
            } else {
                Err(at(
                    v.span(),
                    format!("{key} must be between 0 and 86400 s, got {s}"),
                ))
            }
        }
    }
}

/// 1-based line and column of a byte offset.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

fn clean(message: &str) -> String {
    message.trim().replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bin dir holding fake executables `a` … `d`.
    fn bin_dir() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a", "b", "c", "d"] {
            std::fs::write(dir.path().join(name), "").unwrap();
        }
        dir
    }

    fn check(text: &str) -> Result<GraphSpec, LaunchFileError> {
        let bins = bin_dir();
        parse(Path::new("g.toml"), text, bins.path())
    }

    fn error(text: &str) -> LaunchFileError {
        check(text).unwrap_err()
    }

    #[test]
    fn orders_nodes_after_their_dependencies() {
        let spec = check(
            r#"
[[node]]
name = "sync"
exec = "c"
depends_on = ["enc", "rig"]
[[node]]
name = "enc"
exec = "b"
depends_on = ["rig"]
restart = "on-failure"
required = false
[[node]]
name = "rig"
exec = "a"
"#,
        )
        .unwrap();
        let names: Vec<&str> = spec.nodes.iter().map(|n| n.name.as_str()).collect();
        assert_eq!(names, ["rig", "enc", "sync"]);
        assert_eq!(spec.nodes[1].restart, RestartPolicy::OnFailure);
        assert!(!spec.nodes[1].required);
        assert!(spec.nodes[0].required);
        assert!(spec.nodes[0].exec.ends_with("a"));
    }

    #[test]
    fn unknown_key_is_reported_at_its_line() {
        let e = error("[[node]]\nname = \"x\"\nexec = \"a\"\nrestarts = 3\n");
        assert_eq!((e.line, e.file.as_path()), (4, Path::new("g.toml")));
        assert!(e.reason.contains("restarts"), "{e}");
    }

    #[test]
    fn cycle_is_reported_with_its_path() {
        let e = error(
            "[[node]]\nname = \"x\"\nexec = \"a\"\ndepends_on = [\"y\"]\n\
             [[node]]\nname = \"y\"\nexec = \"b\"\ndepends_on = [\"x\"]\n",
        );
        assert!(e.reason.contains("cycle: x → y → x"), "{e}");
        assert_eq!(e.line, 2);
    }

    #[test]
    fn unknown_dependency_and_duplicate_names_are_errors() {
        let e = error("[[node]]\nname = \"x\"\nexec = \"a\"\ndepends_on = [\"ghost\"]\n");
        assert_eq!(e.line, 4);
        assert!(e.reason.contains("unknown node \"ghost\""), "{e}");

        let e =
            error("[[node]]\nname = \"x\"\nexec = \"a\"\n[[node]]\nname = \"x\"\nexec = \"b\"\n");
        assert_eq!(e.line, 5);
        assert!(e.reason.contains("duplicate"), "{e}");
    }

    #[test]
    fn bad_values_are_errors() {
        let e = error("[[node]]\nname = \"x\"\nexec = \"a\"\nrestart = \"sometimes\"\n");
        assert_eq!(e.line, 4);
        assert!(e.reason.contains("sometimes"), "{e}");

        let e = error("[[node]]\nname = \"x\"\nexec = \"a\"\nready_timeout_s = -1.0\n");
        assert_eq!((e.line, e.column), (4, 19));

        let e = error("[[node]]\nname = \"x y\"\nexec = \"a\"\n");
        assert_eq!(e.line, 2);

        let e = error("[[node]]\nname = \"x\"\nexec = \"missing\"\n");
        assert!(e.reason.contains("not found"), "{e}");

        let e = error("[graph]\nstop_grace_s = 1.0\n");
        assert!(e.reason.contains("no [[node]]"), "{e}");

        let e = error("[[node]]\nname = \"x\"\n");
        assert!(e.reason.contains("exec"), "{e}");
    }

    #[test]
    fn the_cpu_wake_latency_bound_is_parsed_with_its_line() {
        let node = "[[node]]\nname = \"x\"\nexec = \"a\"\n";
        let spec = check(&format!("[graph]\ncpu_wake_latency_us = 0\n{node}")).unwrap();
        assert_eq!(spec.cpu_wake_latency, Some((0, 2)));
        assert_eq!(check(node).unwrap().cpu_wake_latency, None);
        let e = error(&format!("[graph]\ncpu_wake_latency_us = -5\n{node}"));
        assert_eq!(e.line, 2);
    }

    #[test]
    fn a_graph_without_its_placement_is_left_to_the_system() {
        let mut spec = check(
            "[graph]\ncpu_wake_latency_us = 0\n[[node]]\nname = \"x\"\nexec = \"a\"\n\
             cpus = [0]\nsched = \"fifo:40\"\nphase_us = 300\n",
        )
        .unwrap();
        assert_eq!(spec.nodes[0].loop_phase_us, Some(300));
        spec.remove_placement();
        assert_eq!(spec.cpu_wake_latency, None);
        assert!(spec.nodes[0].placement.is_default());
        assert_eq!(spec.nodes[0].loop_phase_us, None);
        assert_eq!(check_placements(&spec), Ok(()));
    }

    #[test]
    fn placement_is_parsed_and_checked() {
        let spec = check(
            "[[node]]\nname = \"x\"\nexec = \"a\"\ncpus = [0]\nsched = \"rr:5\"\n\
             [[node]]\nname = \"y\"\nexec = \"b\"\n",
        )
        .unwrap();
        assert_eq!(spec.nodes[0].placement.cpus, Some(vec![0]));
        assert_eq!(spec.nodes[0].placement.sched, Some(Sched::RoundRobin(5)));
        assert_eq!(spec.nodes[0].placement_line, 5);
        assert!(spec.nodes[1].placement.is_default());
        assert_eq!(spec.nodes[1].placement_line, 7);

        let e = error("[[node]]\nname = \"x\"\nexec = \"a\"\ncpus = [0, 4096]\n");
        assert_eq!(e.line, 4);
        assert!(e.reason.contains("CPU 4096 does not exist"), "{e}");
        let e = error("[[node]]\nname = \"x\"\nexec = \"a\"\nsched = \"fifo:200\"\n");
        assert_eq!((e.line, e.column), (4, 9));
        assert!(e.reason.contains("fifo:200"), "{e}");
        let e = error("[[node]]\nname = \"x\"\nexec = \"a\"\ncpus = [-1]\n");
        assert_eq!(e.line, 4);
    }

    #[test]
    fn a_loop_phase_is_whole_microseconds_below_one_second() {
        let node = "[[node]]\nname = \"x\"\nexec = \"a\"\n";
        assert_eq!(check(node).unwrap().nodes[0].loop_phase_us, None);
        let spec = check(&format!("{node}phase_us = 999999\n")).unwrap();
        assert_eq!(spec.nodes[0].loop_phase_us, Some(999_999));
        let e = error(&format!("{node}phase_us = 1000000\n"));
        assert_eq!((e.line, e.column), (4, 12));
        assert!(e.reason.contains("below one second"), "{e}");
        let e = error(&format!("{node}phase_us = 2.5\n"));
        assert_eq!(e.line, 4);
    }

    #[test]
    fn a_placement_the_system_refuses_names_the_node_and_line() {
        // Root may take any real-time policy here, so the refusal is a CPU set the kernel
        // rejects (a CPU that is not online: EINVAL), past the parse-time check.
        let mut spec = check("[[node]]\nname = \"x\"\nexec = \"a\"\ncpus = [0]\n").unwrap();
        spec.nodes[0].placement.cpus = Some(vec![placement::online_cpus() + 7]);
        let e = check_placements(&spec).unwrap_err();
        assert_eq!(e.line, 4);
        assert!(e.reason.starts_with("node \"x\": "), "{e}");
        assert!(e.reason.contains("cannot apply the placement"), "{e}");
    }

    #[test]
    fn syntax_errors_carry_a_position() {
        let e = error("[[node]]\nname = \"x\nexec = \"a\"\n");
        assert_eq!(e.line, 2);
    }

    #[test]
    fn shipped_graphs_are_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../launch/graphs");
        let mut checked = 0;
        for entry in std::fs::read_dir(&dir).unwrap().flatten() {
            let file = entry.path();
            if file.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let text = std::fs::read_to_string(&file).unwrap();
            // Fake executables for every exec, so only the file itself is judged.
            let bins = tempfile::tempdir().unwrap();
            let table: toml::Table = toml::from_str(&text).unwrap();
            for node in table["node"].as_array().unwrap() {
                let exec = node["exec"].as_str().unwrap();
                std::fs::write(bins.path().join(exec), "").unwrap();
            }
            let spec = parse(&file, &text, bins.path()).unwrap_or_else(|e| panic!("{e}"));
            for (i, node) in spec.nodes.iter().enumerate() {
                for dep in &node.depends_on {
                    assert!(spec.nodes[..i].iter().any(|n| &n.name == dep), "{dep}");
                }
            }
            checked += 1;
        }
        assert!(checked >= 1, "no launch files in {}", dir.display());
    }
}
