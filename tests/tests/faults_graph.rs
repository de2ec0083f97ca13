//! Faults of the real sensing graph (`sabr-rig`, `sabr-encoders`, `sabr-tracker`, `sabr-sync`,
//! `sabr-recorder` under the launcher): a node killed with SIGKILL is restarted per its policy
//! and its data flows again within 2 s; the killed tracker reconnects to the rig's
//! pseudo-terminal; a required node dying stops the whole graph with failure; and no process
//! or shared memory of the domain is left afterwards.
//!
//! Needs the service binaries next to the test executable: `cargo build --workspace --bins`
//! (CI: `cargo build --release --workspace --bins` before `cargo test --release`).

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_integration_tests::{bin, process_alive, LaunchedGraph};
use sabr_msgs::{services, EncoderSample, MatchedSample, TrackerFrame};
use sabr_node::iceoryx2::node::{Node, NodeState};
use sabr_node::iceoryx2::prelude::CallbackProgression;
use sabr_node::{Domain, Doorbell, GraphObserver, Message, NodeRuntime, Subscriber};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The shipped launch file of the sensing graph.
const SHIPPED: &str = include_str!("../../launch/graphs/sim-sensing.toml");
/// The recovery goal: from SIGKILL to data flowing from the new process.
const RECOVERY: Duration = Duration::from_secs(2);
/// Longest wait for the whole graph to start or stop.
const LONG: Duration = Duration::from_secs(30);
/// The nodes of the sensing graph.
const NODES: [&str; 5] = ["rig", "encoders", "tracker", "sync", "recorder"];

/// The shipped launch file with the `[[node]]` sections of `nodes` made `required = false`.
fn with_optional(nodes: &[&str]) -> String {
    let mut sections: Vec<String> = SHIPPED.split("[[node]]").map(str::to_owned).collect();
    for node in nodes {
        let section = sections
            .iter_mut()
            .find(|s| s.contains(&format!("name = \"{node}\"")))
            .unwrap_or_else(|| panic!("no node {node} in sim-sensing.toml"));
        assert!(
            section.contains("required = true"),
            "node {node} of sim-sensing.toml is no longer `required = true`: {section}"
        );
        *section = section.replace("required = true", "required = false");
    }
    sections.join("[[node]]")
}

/// Starts a launch file of the sensing graph and waits until every node is ready.
fn start(test: &str, toml: &str) -> LaunchedGraph {
    for node in NODES {
        bin(&format!("sabr-{node}"));
    }
    let mut graph = LaunchedGraph::start(test, toml, &[], true);
    for node in NODES {
        if graph.wait_ready(node, None, LONG).is_none() {
            panic!("{node} not ready within {LONG:?}:\n{}", graph.output());
        }
    }
    graph
}

/// A test node in the graph's domain subscribed to the streams of the sensing graph.
struct Probe {
    encoders: Subscriber<EncoderSample>,
    frames: Subscriber<TrackerFrame>,
    matched: Subscriber<MatchedSample>,
    _rt: NodeRuntime,
}

impl Probe {
    fn new(graph: &LaunchedGraph) -> Self {
        let rt = NodeRuntime::with_domain("fault-probe", graph.domain.clone()).unwrap();
        Self {
            encoders: rt.subscriber(services::ENCODER_SAMPLES).unwrap(),
            frames: rt.subscriber(services::TRACKER_FRAMES).unwrap(),
            matched: rt.subscriber(services::SYNC_MATCHED).unwrap(),
            _rt: rt,
        }
    }
}

/// Waits up to `timeout` until `stream` delivers, then returns the newest sequence number.
fn flowing<T: Message>(stream: &Subscriber<T>, seq: fn(&T) -> u64, timeout: Duration) -> u64 {
    let start = Instant::now();
    let mut newest = None;
    while newest.is_none() && start.elapsed() < timeout {
        if let Some(first) = stream.recv_timeout(Duration::from_millis(50)).unwrap() {
            newest = Some(seq(&first));
            stream.drain(|s| newest = Some(seq(&s))).unwrap();
        }
    }
    newest.unwrap_or_else(|| panic!("no data on {} within {timeout:?}", stream.service()))
}

/// Waits until `deadline` for the first sample of a new publisher on `stream`: its sequence
/// number starts again, below the previous one. Returns when it arrived.
fn first_of_new_publisher<T: Message>(
    stream: &Subscriber<T>,
    seq: fn(&T) -> u64,
    mut previous: u64,
    deadline: Instant,
) -> Option<Instant> {
    while Instant::now() < deadline {
        let left = deadline.saturating_duration_since(Instant::now());
        let Some(sample) = stream
            .recv_timeout(left.min(Duration::from_millis(20)))
            .unwrap()
        else {
            continue;
        };
        if seq(&sample) <= previous {
            return Some(Instant::now());
        }
        previous = seq(&sample);
    }
    None
}

/// The pid of the running process of `node`.
fn pid_of(graph: &mut LaunchedGraph, node: &str) -> u32 {
    graph
        .wait_ready(node, None, LONG)
        .unwrap_or_else(|| panic!("{node} never ready"))
        .pid
}

/// Nodes of `domain` whose process died and whose resources are still there once the
/// domain's dead nodes were cleaned up (as the launcher does after every node's end).
fn dead_nodes(domain: &Domain) -> usize {
    GraphObserver::new(domain).unwrap().cleanup_dead_nodes();
    let mut dead = 0;
    Node::<Doorbell>::list(&domain.iceoryx_config(), |state| {
        dead += usize::from(matches!(state, NodeState::Dead(_)));
        CallbackProgression::Continue
    })
    .unwrap();
    dead
}

fn sigkill(pid: u32) -> Instant {
    kill(Pid::from_raw(pid as i32), Signal::SIGKILL).unwrap();
    Instant::now()
}

/// Stops the graph with Ctrl-C and checks that it stopped with success, that no node process
/// is alive and that no iceoryx2 file of the domain is left.
fn stop_cleanly(mut graph: LaunchedGraph, probe: Probe) {
    drop(probe);
    let status = graph
        .interrupt(LONG)
        .unwrap_or_else(|| panic!("the launcher did not stop:\n{}", graph.output()));
    assert!(status.success(), "{status:?}\n{}", graph.output());
    assert_nothing_left(&mut graph);
}

fn assert_nothing_left(graph: &mut LaunchedGraph) {
    for pid in graph.node_pids() {
        assert!(!process_alive(pid), "node process {pid} still alive");
    }
    let left = graph.leftover_files();
    assert!(left.is_empty(), "iceoryx2 files left: {left:?}");
}

/// Recording directories of the run (`recording`, `recording-2`, …), sorted.
fn recordings(graph: &LaunchedGraph) -> Vec<PathBuf> {
    let runs = graph.run_dirs();
    assert_eq!(runs.len(), 1, "{runs:?}");
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&runs[0])
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("recording"))
        })
        .collect();
    dirs.sort();
    dirs
}

/// Data rows of a recording CSV (lines after the header).
fn rows(file: &Path) -> usize {
    std::fs::read_to_string(file)
        .map(|text| text.lines().count().saturating_sub(1))
        .unwrap_or(0)
}

#[test]
fn killed_sync_is_restarted_and_matched_samples_flow_again_within_2_s() {
    let _alone = sabr_integration_tests::run_alone();
    let mut graph = start("fault-sync", &with_optional(&["sync", "recorder"]));
    let probe = Probe::new(&graph);
    let last = flowing(&probe.matched, |m| m.seq, LONG);
    let victim = pid_of(&mut graph, "sync");

    let killed = sigkill(victim);
    // Waits past the goal to report how long the recovery actually took.
    let fresh = first_of_new_publisher(&probe.matched, |m| m.seq, last, killed + LONG);
    let restarted = graph.wait_ready("sync", Some(victim), Duration::ZERO);
    assert!(
        restarted.is_some(),
        "sync not restarted:\n{}",
        graph.output()
    );
    let recovered = fresh.map(|t| t - killed);
    eprintln!("sync recovered {recovered:?} after SIGKILL");
    assert!(
        recovered.is_some_and(|r| r < RECOVERY),
        "the restarted sync published its first matched sample {recovered:?} after SIGKILL \
         (goal {RECOVERY:?}):\n{}",
        graph.output()
    );
    assert!(!process_alive(victim));
    assert_eq!(
        dead_nodes(&graph.domain),
        0,
        "stale resources of the killed node remain"
    );
    stop_cleanly(graph, probe);
}

#[test]
fn killed_recorder_is_restarted_and_records_again_within_2_s() {
    let _alone = sabr_integration_tests::run_alone();
    let mut graph = start("fault-rec", &with_optional(&["sync", "recorder"]));
    let probe = Probe::new(&graph);
    flowing(&probe.encoders, |s| s.seq, LONG);
    let first = recordings(&graph);
    assert_eq!(first.len(), 1, "{first:?}");
    let first_encoders = first[0].join("encoders.csv");
    let start = Instant::now();
    while rows(&first_encoders) == 0 {
        assert!(
            start.elapsed() < LONG,
            "the recorder writes no encoder rows"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let victim = pid_of(&mut graph, "recorder");
    let rows_before = rows(&first_encoders);

    let killed = sigkill(victim);
    let mut recovered = None;
    while recovered.is_none() && killed.elapsed() < RECOVERY {
        let dirs = recordings(&graph);
        if dirs.len() == 2 && rows(&dirs[1].join("encoders.csv")) > 0 {
            recovered = Some(killed.elapsed());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let recovered = recovered.unwrap_or_else(|| {
        panic!(
            "the restarted recorder wrote no encoder row within {RECOVERY:?} ({:?}):\n{}",
            recordings(&graph),
            graph.output()
        )
    });
    eprintln!("recorder recovered {recovered:?} after SIGKILL");
    // The killed recorder's recording is kept with every row it had written.
    assert!(rows(&first_encoders) >= rows_before);
    assert_eq!(
        dead_nodes(&graph.domain),
        0,
        "stale resources of the killed node remain"
    );
    stop_cleanly(graph, probe);
}

#[test]
fn killed_encoders_are_restarted_and_samples_flow_again_within_2_s() {
    let _alone = sabr_integration_tests::run_alone();
    let mut graph = start("fault-enc", SHIPPED);
    let probe = Probe::new(&graph);
    let last = flowing(&probe.encoders, |s| s.seq, LONG);
    let victim = pid_of(&mut graph, "encoders");

    let killed = sigkill(victim);
    let fresh = first_of_new_publisher(&probe.encoders, |s| s.seq, last, killed + RECOVERY);
    let fresh = fresh.unwrap_or_else(|| {
        panic!(
            "no encoder sample from the restarted encoders within {RECOVERY:?}:\n{}",
            graph.output()
        )
    });
    eprintln!("encoders recovered {:?} after SIGKILL", fresh - killed);
    let restarted = graph
        .wait_ready("encoders", Some(victim), LONG)
        .expect("ready")
        .pid;
    // The new process's samples follow each other without a gap.
    let mut check = probe
        .encoders
        .recv_timeout(LONG)
        .unwrap()
        .expect("a sample")
        .seq;
    let until = Instant::now() + Duration::from_millis(500);
    while Instant::now() < until {
        if let Some(sample) = probe
            .encoders
            .recv_timeout(Duration::from_millis(20))
            .unwrap()
        {
            assert_eq!(sample.seq, check + 1, "gap after the restart");
            check = sample.seq;
        }
    }
    // Only the killed node was restarted.
    for node in NODES {
        let pids: Vec<u32> = graph
            .seen()
            .iter()
            .filter(|m| m.node.as_str() == node)
            .map(|m| m.pid)
            .collect();
        let expected: &[u32] = if node == "encoders" {
            &[victim, restarted]
        } else {
            &pids[..1]
        };
        assert!(
            pids.iter().all(|p| expected.contains(p)),
            "{node} restarted: {pids:?}"
        );
    }
    assert_eq!(
        dead_nodes(&graph.domain),
        0,
        "stale resources of the killed node remain"
    );
    stop_cleanly(graph, probe);
}

#[test]
fn killed_tracker_reconnects_to_the_rig_and_frames_flow_again_within_2_s() {
    let _alone = sabr_integration_tests::run_alone();
    let mut graph = start("fault-trk", SHIPPED);
    let probe = Probe::new(&graph);
    let last = flowing(&probe.frames, |f| f.seq, LONG);
    let victim = pid_of(&mut graph, "tracker");

    let killed = sigkill(victim);
    // A reconnect needs the NDI start-up sequence (reset, INIT, COMM, port handles, TSTART)
    // on the rig's pseudo-terminal before the first frame.
    let fresh = first_of_new_publisher(&probe.frames, |f| f.seq, last, killed + RECOVERY);
    let fresh = fresh.unwrap_or_else(|| {
        panic!(
            "no frame from the restarted tracker within {RECOVERY:?}:\n{}",
            graph.output()
        )
    });
    eprintln!("tracker recovered {:?} after SIGKILL", fresh - killed);
    assert!(graph.wait_ready("tracker", Some(victim), LONG).is_some());
    let rig = pid_of(&mut graph, "rig");
    assert!(process_alive(rig), "the rig died with the tracker");
    assert_eq!(
        dead_nodes(&graph.domain),
        0,
        "stale resources of the killed node remain"
    );
    stop_cleanly(graph, probe);
}

#[test]
fn a_required_node_dying_stops_the_graph_cleanly_with_failure() {
    let _alone = sabr_integration_tests::run_alone();
    let mut graph = start("fault-req", SHIPPED);
    let pids: Vec<u32> = NODES.iter().map(|n| pid_of(&mut graph, n)).collect();
    let killed = sigkill(pids[0]);
    let status = graph
        .wait_exit(LONG)
        .unwrap_or_else(|| panic!("the launcher did not stop:\n{}", graph.output()));
    eprintln!(
        "graph stopped {:?} after the rig was killed",
        killed.elapsed()
    );
    let output = graph.output();
    assert_eq!(status.code(), Some(1), "{output}");
    assert!(
        output.contains("required node rig ended: killed by SIGKILL"),
        "{output}"
    );
    for (node, pid) in NODES.iter().zip(&pids) {
        assert!(!process_alive(*pid), "{node} (pid {pid}) still alive");
    }
    assert_nothing_left(&mut graph);
}
