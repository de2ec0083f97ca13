//! An encoder stall in the real graph during a motion: the `sabr-encoders` process is frozen
//! with SIGSTOP while `sabr-motion` homes the simulated robot (`sabr-rig` following its
//! setpoints). The motion executor must report the fault with its reason within 50 ms of the
//! encoder deadline, and the robot itself (the rig's counter register, which keeps being
//! published) must come to rest. `tests/tests/motion.rs` checks the executor against a
//! synthetic feedback stream; this test checks the whole chain with real processes.
//!
//! Needs the service binaries next to the test executable: `cargo build --workspace --bins`.

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_integration_tests::{bin, process_alive, LaunchedGraph};
use sabr_msgs::{services, CounterLatch, EncoderSample, MotionState, MotionStatus, JOINTS};
use sabr_node::{NodeRuntime, Subscriber};
use std::time::{Duration, Instant};

/// The graph: the rig follows motion's setpoints; motion homes the robot.
const GRAPH: &str = r#"
[graph]
stop_grace_s = 2.0
term_grace_s = 1.0

[[node]]
name = "rig"
exec = "sabr-rig"

[[node]]
name = "encoders"
exec = "sabr-encoders"
depends_on = ["rig"]

[[node]]
name = "tracker"
exec = "sabr-tracker"
depends_on = ["rig"]
ready_timeout_s = 15.0

[[node]]
name = "motion"
exec = "sabr-motion"
depends_on = ["encoders", "tracker"]
args = ["--session", "homing", "--encoder-deadline-ms", "20"]
"#;
/// Motion's encoder deadline in [`GRAPH`], ns.
const DEADLINE_NS: i64 = 20_000_000;
/// The goal: stopped at most this long after the deadline passed, ns.
const STOP_WITHIN_NS: i64 = 50_000_000;
const LONG: Duration = Duration::from_secs(30);

/// Largest change of any joint's count over a stretch of counter latches.
fn travel(latches: &[CounterLatch]) -> i64 {
    (0..JOINTS)
        .map(|j| {
            let counts = latches.iter().map(|l| l.counts[j]);
            counts.clone().max().unwrap_or(0) - counts.min().unwrap_or(0)
        })
        .max()
        .unwrap_or(0)
}

/// Everything arriving on `stream` for `duration`.
fn collect<T: sabr_node::Message>(stream: &Subscriber<T>, duration: Duration) -> Vec<T> {
    let until = Instant::now() + duration;
    let mut seen = Vec::new();
    while Instant::now() < until {
        if let Some(first) = stream.recv_timeout(Duration::from_millis(5)).unwrap() {
            seen.push(first);
            stream.drain(|s| seen.push(s)).unwrap();
        }
    }
    seen
}

#[test]
fn frozen_encoders_stop_the_motion_within_50_ms_of_the_deadline_and_the_robot_rests() {
    let _alone = sabr_integration_tests::run_alone();
    for node in ["rig", "encoders", "tracker", "motion"] {
        bin(&format!("sabr-{node}"));
    }
    let mut graph = LaunchedGraph::start("fault-motion", GRAPH, &[], true);
    let probe = NodeRuntime::with_domain("fault-probe", graph.domain.clone()).unwrap();
    let encoders: Subscriber<EncoderSample> = probe.subscriber(services::ENCODER_SAMPLES).unwrap();
    let status: Subscriber<MotionStatus> = probe.subscriber(services::MOTION_STATUS).unwrap();
    let counters: Subscriber<CounterLatch> = probe.subscriber(services::RIG_COUNTERS).unwrap();
    let victim = graph
        .wait_ready("encoders", None, LONG)
        .expect("encoders ready")
        .pid;
    if graph.wait_ready("motion", None, LONG).is_none() {
        panic!("motion not ready:\n{}", graph.output());
    }

    // The robot is moving: the rig's counts change under motion's setpoints.
    let start = Instant::now();
    let moving = loop {
        assert!(
            start.elapsed() < LONG,
            "the robot never moved:\n{}",
            graph.output()
        );
        let moved = travel(&collect(&counters, Duration::from_millis(200)));
        if moved > 5 {
            break moved;
        }
    };
    let statuses_before: Vec<MotionStatus> =
        std::iter::from_fn(|| status.try_recv().unwrap()).collect();
    assert!(
        statuses_before
            .iter()
            .all(|s| s.state != MotionState::Faulted),
        "faulted before the stall: {statuses_before:?}"
    );

    let mut last_sample_ns = None;
    encoders.drain(|s| last_sample_ns = Some(s.t_ns)).unwrap();
    kill(Pid::from_raw(victim as i32), Signal::SIGSTOP).unwrap();
    let stopped = Instant::now();
    let faulted = loop {
        assert!(
            stopped.elapsed() < Duration::from_secs(5),
            "no fault reported:\n{}",
            graph.output()
        );
        encoders.drain(|s| last_sample_ns = Some(s.t_ns)).unwrap();
        if let Some(s) = std::iter::from_fn(|| status.try_recv().unwrap())
            .find(|s| s.state == MotionState::Faulted)
        {
            break s;
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    let after_fault = collect(&counters, Duration::from_millis(400));
    let _ = kill(Pid::from_raw(victim as i32), Signal::SIGCONT);

    assert!(
        faulted
            .reason
            .as_str()
            .starts_with("encoder feedback stale"),
        "{faulted:?}"
    );
    let last_sample_ns = last_sample_ns.expect("encoder samples before the stall");
    let late_ns = faulted.t_ns - (last_sample_ns + DEADLINE_NS);
    eprintln!(
        "motion faulted {:.1} ms after the encoder deadline: {}",
        late_ns as f64 * 1e-6,
        faulted.reason.as_str()
    );
    assert!(
        (0..=STOP_WITHIN_NS).contains(&late_ns),
        "fault {:.1} ms after the deadline (goal ≤ 50 ms)",
        late_ns as f64 * 1e-6
    );
    // The robot comes to rest: 100 ms after the fault its counts no longer change.
    let settle_ns = faulted.t_ns + 100_000_000;
    let resting: Vec<CounterLatch> = after_fault
        .into_iter()
        .filter(|l| l.latch_t_ns >= settle_ns)
        .collect();
    assert!(
        resting.len() > 100,
        "{} latches after settling",
        resting.len()
    );
    eprintln!(
        "robot travel: {moving} counts in 200 ms while homing, {} counts in {} latches after the fault",
        travel(&resting),
        resting.len()
    );
    assert!(
        travel(&resting) <= 1,
        "the robot still moves after the fault: {} counts",
        travel(&resting)
    );

    drop((encoders, status, counters, probe));
    let exit = graph
        .interrupt(LONG)
        .unwrap_or_else(|| panic!("the launcher did not stop:\n{}", graph.output()));
    assert!(exit.success(), "{}", graph.output());
    for pid in graph.node_pids() {
        assert!(!process_alive(pid), "node process {pid} still alive");
    }
    let left = graph.leftover_files();
    assert!(left.is_empty(), "iceoryx2 files left: {left:?}");
}
