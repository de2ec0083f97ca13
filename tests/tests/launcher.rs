//! The launcher running real processes: dependency order and readiness, restart after
//! SIGKILL, required nodes, the stop ladder, the done signal, launch-file errors, placement,
//! the idle CPUs' polling, and a terminal whose reader left.

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_integration_tests::{process_alive, LaunchedGraph};
use sabr_launcher::placement::Placement;
use sabr_launcher::wake_latency::{IdleLoop, WakeLatencyBound, IDLE_POLL_THREAD_PREFIX};
use sabr_msgs::{services, EncoderSample, LifecycleState};
use sabr_node::iceoryx2::node::{Node, NodeState};
use sabr_node::iceoryx2::prelude::CallbackProgression;
use sabr_node::{Doorbell, NodeRuntime};
use std::time::{Duration, Instant};

const LONG: Duration = Duration::from_secs(15);

fn assert_all_gone(graph: &mut LaunchedGraph) {
    for pid in graph.node_pids() {
        assert!(!process_alive(pid), "node process {pid} still alive");
    }
    let left = graph.leftover_files();
    assert!(left.is_empty(), "iceoryx2 files left: {left:?}");
}

#[test]
fn starts_in_dependency_order_and_stops_cleanly() {
    let _alone = sabr_integration_tests::run_alone();
    // Written out of order: the launcher must start a, then b, then c.
    let toml = r#"
[[node]]
name = "c"
exec = "sabr-test-node"
depends_on = ["b"]

[[node]]
name = "a"
exec = "sabr-test-node"
args = ["--ready-delay-ms", "300"]

[[node]]
name = "b"
exec = "sabr-test-node"
depends_on = ["a"]
args = ["--ready-delay-ms", "100"]
"#;
    let mut graph = LaunchedGraph::start("order", toml, &[], true);
    let c = graph.wait_ready("c", None, LONG).expect("c ready");
    let seen = graph.seen().to_vec();
    let time_of = |node: &str, state: LifecycleState| {
        seen.iter()
            .find(|m| m.node.as_str() == node && m.state == state)
            .map(|m| m.t_ns)
            .unwrap_or_else(|| panic!("no {state:?} from {node}"))
    };
    assert!(time_of("b", LifecycleState::Starting) > time_of("a", LifecycleState::Ready));
    assert!(time_of("c", LifecycleState::Starting) > time_of("b", LifecycleState::Ready));
    assert!(c.t_ns > time_of("b", LifecycleState::Ready));

    let status = graph.interrupt(LONG).expect("launcher exits after Ctrl-C");
    assert!(status.success(), "{status:?}\n{}", graph.output());
    let output = graph.output();
    let stop_line = |node: &str| {
        output
            .find(&format!("] {node} stopped"))
            .unwrap_or_else(|| panic!("{node} not stopped:\n{output}"))
    };
    assert!(stop_line("c") < stop_line("b") && stop_line("b") < stop_line("a"));
    let runs = graph.run_dirs();
    assert_eq!(runs.len(), 1);
    for node in ["a", "b", "c"] {
        let log = std::fs::read_to_string(runs[0].join("logs").join(format!("{node}.log")))
            .expect("node log");
        assert!(log.contains("ready"), "{node}.log: {log}");
    }
    assert_all_gone(&mut graph);
}

#[test]
fn a_killed_node_is_restarted_and_data_flows_again_within_2_s() {
    let _alone = sabr_integration_tests::run_alone();
    let toml = r#"
[[node]]
name = "anchor"
exec = "sabr-test-node"

[[node]]
name = "worker"
exec = "sabr-test-node"
args = ["--rate-hz", "200"]
restart = "on-failure"
required = false
"#;
    let mut graph = LaunchedGraph::start("restart", toml, &[], true);
    let first = graph
        .wait_ready("worker", None, LONG)
        .expect("worker ready");
    graph
        .wait_ready("anchor", None, LONG)
        .expect("anchor ready");
    let probe = NodeRuntime::with_domain("probe", graph.domain.clone()).unwrap();
    let counter = probe
        .subscriber::<EncoderSample>(services::TEST_COUNTER)
        .unwrap();

    kill(Pid::from_raw(first.pid as i32), Signal::SIGKILL).unwrap();
    let killed = Instant::now();
    let second = graph
        .wait_ready("worker", Some(first.pid), Duration::from_secs(2))
        .unwrap_or_else(|| panic!("no restart within 2 s:\n{}", graph.output()));
    let mut fresh_sample = None;
    while fresh_sample.is_none() && killed.elapsed() < Duration::from_secs(2) {
        if let Some(s) = counter.recv_timeout(Duration::from_millis(50)).unwrap() {
            fresh_sample = (s.counts[0] == i64::from(second.pid)).then_some(s);
        }
    }
    let recovered = killed.elapsed();
    assert!(fresh_sample.is_some(), "no data from the restarted worker");
    assert!(
        recovered < Duration::from_secs(2),
        "recovered after {recovered:?}"
    );
    eprintln!("worker recovered {recovered:?} after SIGKILL");
    // The launcher removed the killed node's resources when it noticed the death.
    let mut dead = 0;
    Node::<Doorbell>::list(&graph.domain.iceoryx_config(), |state| {
        dead += usize::from(matches!(state, NodeState::Dead(_)));
        CallbackProgression::Continue
    })
    .unwrap();
    assert_eq!(dead, 0, "stale resources of the killed node remain");

    drop((counter, probe));
    let status = graph.interrupt(LONG).expect("launcher exits");
    assert!(status.success(), "{}", graph.output());
    assert!(
        graph.output().contains("killed by SIGKILL"),
        "{}",
        graph.output()
    );
    assert_all_gone(&mut graph);
}

#[test]
fn a_node_without_heartbeat_is_killed_and_restarted() {
    let _alone = sabr_integration_tests::run_alone();
    let toml = r#"
[[node]]
name = "anchor"
exec = "sabr-test-node"

[[node]]
name = "hanging"
exec = "sabr-test-node"
args = ["--hang-after-ms", "200"]
restart = "on-failure"
required = false
heartbeat_timeout_s = 0.5
"#;
    let mut graph = LaunchedGraph::start("heartbeat", toml, &[], true);
    let first = graph.wait_ready("hanging", None, LONG).expect("ready");
    let second = graph.wait_ready("hanging", Some(first.pid), LONG);
    assert!(second.is_some(), "not restarted:\n{}", graph.output());
    assert!(!process_alive(first.pid), "the hung process was not killed");
    let output = graph.output();
    assert!(
        output.contains("hanging silent for 0.5 s (no heartbeat); killing it"),
        "{output}"
    );
    let status = graph.interrupt(LONG).expect("launcher exits");
    assert!(status.success(), "{}", graph.output());
    assert_all_gone(&mut graph);
}

#[test]
fn a_required_node_ending_stops_the_graph_with_failure() {
    let _alone = sabr_integration_tests::run_alone();
    let toml = r#"
[[node]]
name = "steady"
exec = "sabr-test-node"

[[node]]
name = "fragile"
exec = "sabr-test-node"
args = ["--exit-after-ms", "300", "--exit-code", "3"]
required = true
"#;
    let started = Instant::now();
    let mut graph = LaunchedGraph::start("required", toml, &[], false);
    let status = graph.wait_exit(LONG).expect("launcher stops on its own");
    assert_eq!(status.code(), Some(1), "{}", graph.output());
    assert!(started.elapsed() < Duration::from_secs(10));
    let output = graph.output();
    assert!(
        output.contains("required node fragile ended: exit code 3"),
        "{output}"
    );
    assert!(output.contains("steady stopped"), "{output}");
    // The launcher itself released the domain: nothing left without any help.
    let left = sabr_node::domain_files(&graph.domain);
    assert!(left.is_empty(), "iceoryx2 files left: {left:?}");
}

#[test]
fn a_node_ignoring_stop_requests_is_killed_and_cleaned_up() {
    let _alone = sabr_integration_tests::run_alone();
    let toml = r#"
[graph]
stop_grace_s = 0.3
term_grace_s = 0.3

[[node]]
name = "stubborn"
exec = "sabr-test-node"
args = ["--ignore-stop"]
"#;
    let mut graph = LaunchedGraph::start("ladder", toml, &["--duration", "1.0"], false);
    let status = graph
        .wait_exit(LONG)
        .expect("launcher stops after the duration");
    let output = graph.output();
    assert!(status.success(), "{output}");
    assert!(output.contains("duration elapsed"), "{output}");
    assert!(output.contains("sending SIGTERM"), "{output}");
    assert!(output.contains("sending SIGKILL"), "{output}");
    assert!(
        output.contains("stubborn stopped (killed by SIGKILL)"),
        "{output}"
    );
    let left = sabr_node::domain_files(&graph.domain);
    assert!(
        left.is_empty(),
        "stale iceoryx2 files of the killed node: {left:?}"
    );
}

#[test]
fn a_node_announcing_done_ends_the_graph_with_success() {
    let _alone = sabr_integration_tests::run_alone();
    let toml = r#"
[[node]]
name = "idle"
exec = "sabr-test-node"

[[node]]
name = "session"
exec = "sabr-test-node"
args = ["--done-after-ms", "300"]
depends_on = ["idle"]
"#;
    let mut graph = LaunchedGraph::start("done", toml, &[], false);
    let status = graph.wait_exit(LONG).expect("launcher stops on done");
    let output = graph.output();
    assert!(status.success(), "{output}");
    assert!(
        output.contains("node session announced the job done"),
        "{output}"
    );
    assert!(sabr_node::domain_files(&graph.domain).is_empty());
}

#[test]
fn a_launcher_whose_reader_left_still_runs_and_stops_its_graph() {
    // `sabr launch FILE 2>&1 | head -1`: every line after the first meets a closed pipe. The
    // supervisor must not die of it, and must still stop its nodes and clean up.
    let domain = sabr_integration_tests::test_domain("reader-left");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("graph.toml");
    std::fs::write(&file, "[[node]]\nname = \"a\"\nexec = \"sabr-test-node\"\n").unwrap();
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let status = std::process::Command::new(sabr_integration_tests::bin("sabr-test-launch"))
        .arg(&file)
        .arg("--run-dir")
        .arg(dir.path().join("runs"))
        .arg("--domain")
        .arg(domain.as_str())
        .args(["--duration", "1"])
        .stdin(std::process::Stdio::null())
        .stdout(writer.try_clone().unwrap())
        .stderr(writer)
        .status()
        .unwrap();
    assert!(status.success(), "{status}");
    // The node ran and logged.
    let runs: Vec<_> = std::fs::read_dir(dir.path().join("runs"))
        .unwrap()
        .map(|run| run.unwrap().path().join("logs/a.log"))
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
    let log = std::fs::read_to_string(&runs[0]).unwrap();
    assert!(!log.is_empty(), "{}", runs[0].display());
    assert!(
        sabr_node::domain_files(&domain).is_empty(),
        "iceoryx2 files of {domain} left behind"
    );
}

#[test]
fn a_malformed_launch_file_is_rejected_with_file_line_and_reason() {
    let _alone = sabr_integration_tests::run_alone();
    let toml = "[[node]]\nname = \"a\"\nexec = \"sabr-test-node\"\ndepends_on = [\"nowhere\"]\n";
    let mut graph = LaunchedGraph::start("malformed", toml, &[], false);
    let status = graph.wait_exit(LONG).expect("launcher exits");
    assert!(!status.success());
    let output = graph.output();
    assert!(
        output.contains("graph.toml:4:15: node \"a\" depends on unknown node \"nowhere\""),
        "{output}"
    );
    assert!(
        graph.run_dirs().is_empty(),
        "a run directory was created: {output}"
    );
}

/// `Cpus_allowed_list` and the scheduling policy and real-time priority (`/proc/<pid>/stat`
/// fields 41 and 40) of a process.
fn placement_of(pid: u32) -> (String, u32, u32) {
    placement_of_task(pid, pid)
}

/// [`placement_of`] one thread `tid` of process `pid`.
fn placement_of_task(pid: u32, tid: u32) -> (String, u32, u32) {
    let task = format!("/proc/{pid}/task/{tid}");
    let status = std::fs::read_to_string(format!("{task}/status")).unwrap();
    let cpus = status
        .lines()
        .find_map(|line| line.strip_prefix("Cpus_allowed_list:"))
        .unwrap()
        .trim()
        .to_owned();
    let stat = std::fs::read_to_string(format!("{task}/stat")).unwrap();
    // Fields after the command name, which ends with the last ')': field 3 is first.
    let fields: Vec<&str> = stat[stat.rfind(')').unwrap() + 2..].split(' ').collect();
    let field = |n: usize| fields[n - 3].parse::<u32>().unwrap();
    (cpus, field(41), field(40))
}

/// The `SABR_LOOP_PHASE_US` a process was started with, if any.
fn loop_phase_of(pid: u32) -> Option<String> {
    let environ = std::fs::read(format!("/proc/{pid}/environ")).unwrap();
    environ.split(|&b| b == 0).find_map(|entry| {
        let entry = std::str::from_utf8(entry).ok()?;
        entry
            .strip_prefix(&format!("{}=", sabr_node::LOOP_PHASE_ENV))
            .map(str::to_owned)
    })
}

#[test]
fn nodes_run_with_their_cpu_set_and_scheduling_policy() {
    let toml = r#"
[[node]]
name = "pinned"
exec = "sabr-test-node"
cpus = [0]
sched = "rr:3"
phase_us = 250

[[node]]
name = "free"
exec = "sabr-test-node"
"#;
    let mut graph = LaunchedGraph::start("placement", toml, &[], true);
    let pinned = graph
        .wait_ready("pinned", None, LONG)
        .expect("pinned ready");
    let free = graph.wait_ready("free", None, LONG).expect("free ready");
    // SCHED_RR is policy 2, SCHED_OTHER 0.
    assert_eq!(placement_of(pinned.pid), ("0".to_owned(), 2, 3));
    let (cpus, policy, priority) = placement_of(free.pid);
    assert_eq!((policy, priority), (0, 0));
    assert_eq!(cpus, placement_of(std::process::id()).0);
    // The loop phase reaches the node's runtime through its environment, only where given.
    assert_eq!(loop_phase_of(pinned.pid).as_deref(), Some("250"));
    assert_eq!(loop_phase_of(free.pid), None);
    let status = graph.interrupt(LONG).expect("launcher exits");
    assert!(status.success(), "{}", graph.output());
    assert_all_gone(&mut graph);
}

/// The CPUs the threads of `pid` polling idle CPUs are named after, ascending, each checked
/// to be confined to that CPU at `SCHED_IDLE` (policy 5).
fn idle_polled_cpus(pid: u32) -> Vec<usize> {
    let mut cpus = Vec::new();
    for task in std::fs::read_dir(format!("/proc/{pid}/task")).unwrap() {
        let task = task.unwrap().path();
        let name = std::fs::read_to_string(task.join("comm")).unwrap();
        let Some(cpu) = name.trim().strip_prefix(IDLE_POLL_THREAD_PREFIX) else {
            continue;
        };
        let tid: u32 = task.file_name().unwrap().to_str().unwrap().parse().unwrap();
        let (allowed, policy, _) = placement_of_task(pid, tid);
        assert_eq!(
            (allowed.as_str(), policy),
            (cpu, 5),
            "thread {}",
            name.trim()
        );
        cpus.push(cpu.parse().unwrap());
    }
    cpus.sort_unstable();
    cpus
}

#[test]
fn idle_cpus_are_polled_by_the_launcher_where_the_kernel_would_halt_them() {
    let toml =
        "[graph]\ncpu_wake_latency_us = 0\n\n[[node]]\nname = \"a\"\nexec = \"sabr-test-node\"\n";
    let mut graph = LaunchedGraph::start("idle-poll", toml, &[], true);
    if let Err(reason) = WakeLatencyBound::check() {
        // Refused before any node starts, naming the device and the way out.
        let status = graph.wait_exit(LONG).expect("launcher exits");
        assert!(!status.success());
        let output = graph.output();
        assert!(
            output.contains(&reason) && output.contains("--unplaced"),
            "{output}"
        );
        return;
    }
    graph.wait_ready("a", None, LONG).expect("a ready");
    let expected = match IdleLoop::of_this_kernel().obeys_zero_bound() {
        true => Vec::new(),
        false => Placement::unplaced().unwrap().cpus.unwrap(),
    };
    assert_eq!(idle_polled_cpus(graph.launcher_pid()), expected);
    let status = graph.interrupt(LONG).expect("launcher exits");
    assert!(status.success(), "{}", graph.output());
    assert_eq!(
        graph.output().contains("polling idle CPUs"),
        !expected.is_empty(),
        "{}",
        graph.output()
    );
    assert_all_gone(&mut graph);
}

#[test]
fn a_shipped_graph_checks_with_its_placement_and_without_it() {
    let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../launch/graphs/sim-calibration.toml");
    let bin_dir = sabr_integration_tests::bin("sabr");
    let bin_dir = bin_dir.parent().unwrap();
    let check = |extra: &[&str]| {
        let output = std::process::Command::new(sabr_integration_tests::bin("sabr"))
            .arg("launch")
            .arg("--check")
            .arg("--bin-dir")
            .arg(bin_dir)
            .args(extra)
            .arg(&file)
            .output()
            .unwrap();
        (
            output.status.success(),
            String::from_utf8_lossy(&output.stdout).into_owned(),
            String::from_utf8_lossy(&output.stderr).into_owned(),
        )
    };
    let (ok, stdout, stderr) = check(&["--unplaced"]);
    assert!(ok, "{stdout}{stderr}");
    assert!(stdout.contains("  motion ("), "{stdout}");
    assert!(
        !stdout.contains("cpus =")
            && !stdout.contains("sched =")
            && !stdout.contains("phase_us")
            && !stdout.contains("latency"),
        "--unplaced kept a placement: {stdout}"
    );
    // With its placement the graph either checks and shows it, or is refused with the way
    // out named (a machine without real-time privileges).
    let (ok, stdout, stderr) = check(&[]);
    if ok {
        assert!(
            stdout.contains("rig (") && stdout.contains("sched = \"fifo:30\""),
            "{stdout}"
        );
        assert!(stdout.contains("ik (") && stdout.contains("sched = \"fifo:45\""));
        let motion = stdout.lines().find(|l| l.contains("motion (")).unwrap();
        assert!(motion.ends_with(", phase_us = 700)"), "{motion}");
        assert!(
            stdout.contains("CPU wake-up latency held at ≤ 0 µs"),
            "{stdout}"
        );
        assert_eq!(
            stdout.contains("the launcher polls idle CPUs itself"),
            !IdleLoop::of_this_kernel().obeys_zero_bound(),
            "{stdout}"
        );
    } else {
        assert!(stderr.contains("--unplaced"), "{stderr}");
    }
}
