//! The sensing chain as shipped: `launch/graphs/sim-sensing.toml` run by the launcher (same
//! code as `sabr launch`) in a fresh domain and run directory — rig (autoplay), encoders,
//! tracker on the rig's pseudo-terminal, sync, recorder. A probe node in the domain checks:
//! - every service carries samples at its rate, without lost encoder samples;
//! - the synchroniser's exposure times against the rig's truth: with the configured latency,
//!   and after a calibrated latency is announced on `sabr/calibrator/parameters` (taken from
//!   the truth of the frames before), the exposure-time error p99 is ≤ 0.5 ms;
//! - a waiting subscriber of the frames, and one of the matched samples, is pre-woken before
//!   the tracker's polls: woken without a message more often than with one;
//! - the recorder's recording passes the recording reader (`Recording::read`, as for
//!   `sabr sim record`) and holds every encoder sample and tracker frame of its time span;
//! - Ctrl-C stops the graph cleanly: no node process and no shared memory left.
//!
//! Needs the service binaries: `cargo build --workspace --bins` before the tests (release in
//! CI). Prints the measured figures (`--nocapture`).

use sabr_integration_tests::{median_interval_ns, process_alive, LaunchedGraph};
use sabr_launcher::steal::{CpuTimes, NOTABLE_STEAL};
use sabr_model::{CalibrationInfo, RobotParams};
use sabr_msgs::{
    services, CounterLatch, EncoderSample, FixedString, LatencySource, MatchedSample,
    ParameterSetAnnouncement, RigTruth, TrackerFrame,
};
use sabr_node::{monotonic_ns, NodeRuntime, Publisher, Subscriber};
use sabr_recording::{Recording, Tool};
use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::time::{Duration, Instant};

/// The launch file under test.
const LAUNCH_FILE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../launch/graphs/sim-sensing.toml"
);
/// Longest wait for every node to be ready.
const START_TIMEOUT: Duration = Duration::from_secs(30);
/// Longest wait for all the samples below.
const COLLECT_TIMEOUT: Duration = Duration::from_secs(40);
/// Matched samples with the configured latency before the calibrated latency is announced.
const CONFIGURED_SAMPLES: usize = 60;
/// Matched samples with the calibrated latency that are checked against the truth.
const CALIBRATED_SAMPLES: usize = 150;
/// Share of the nominal rate a stream must reach: debug builds of the 2 kHz rig loop and the
/// 1 kHz sampler skip many periods on a loaded 2-core machine, release builds a few. Demanded
/// only while the hypervisor takes less than [`NOTABLE_STEAL`] of the CPUs' time: a vCPU
/// descheduled for ms skips periods whatever the build (the streams' periods, the median
/// intervals, are checked regardless).
const RATE_FLOOR: f64 = if cfg!(debug_assertions) { 0.75 } else { 0.9 };
/// The goal: exposure-time error p99 against the rig's truth, ns.
const ERROR_P99_GOAL_NS: i64 = 500_000;

/// The probe's ports in the graph's domain.
struct Probe {
    /// The node the ports belong to, alive as long as the probe.
    _node: NodeRuntime,
    counters: Subscriber<CounterLatch>,
    encoders: Subscriber<EncoderSample>,
    frames: Subscriber<TrackerFrame>,
    truth: Subscriber<RigTruth>,
    matched: Subscriber<MatchedSample>,
    parameters: Publisher<ParameterSetAnnouncement>,
}

/// Everything the probe received.
#[derive(Default)]
struct Seen {
    counters: Vec<CounterLatch>,
    encoders: Vec<EncoderSample>,
    frames: Vec<TrackerFrame>,
    truth: HashMap<u32, i64>,
    matched: Vec<MatchedSample>,
}

impl Probe {
    fn join(graph: &LaunchedGraph) -> Self {
        let node = NodeRuntime::with_domain("probe", graph.domain.clone()).expect("probe node");
        Probe {
            counters: node.subscriber(services::RIG_COUNTERS).expect("counters"),
            encoders: node
                .subscriber(services::ENCODER_SAMPLES)
                .expect("encoders"),
            frames: node.subscriber(services::TRACKER_FRAMES).expect("frames"),
            truth: node.subscriber(services::RIG_TRUTH).expect("truth"),
            matched: node.subscriber(services::SYNC_MATCHED).expect("matched"),
            parameters: node
                .publisher(services::CALIBRATOR_PARAMETERS)
                .expect("parameters"),
            _node: node,
        }
    }

    fn poll(&self, seen: &mut Seen) {
        self.counters
            .drain(|s| seen.counters.push(s))
            .expect("receive");
        self.encoders
            .drain(|s| seen.encoders.push(s))
            .expect("receive");
        self.frames.drain(|s| seen.frames.push(s)).expect("receive");
        self.truth
            .drain(|s| {
                seen.truth.insert(s.frame_number, s.exposure_t_ns);
            })
            .expect("receive");
        self.matched
            .drain(|s| seen.matched.push(s))
            .expect("receive");
    }

    /// Polls until `done` or the timeout; panics with `what` on the timeout.
    fn until(&self, seen: &mut Seen, deadline: Instant, what: &str, done: impl Fn(&Seen) -> bool) {
        while !done(seen) {
            assert!(Instant::now() < deadline, "timed out waiting for {what}");
            std::thread::sleep(Duration::from_millis(2));
            self.poll(seen);
        }
    }
}

/// Exposure-time errors (estimate − truth, ns) of the matched samples from `source`.
fn errors(seen: &Seen, source: LatencySource) -> Vec<i64> {
    seen.matched
        .iter()
        .filter(|m| m.quality.latency_source == source)
        .filter_map(|m| seen.truth.get(&m.frame_number).map(|t| m.exposure_t_ns - t))
        .collect()
}

/// The `q` quantile of `values` (nearest rank).
fn quantile(values: &[i64], q: f64) -> i64 {
    let mut sorted = values.to_vec();
    sorted.sort_unstable();
    sorted[((sorted.len() as f64 * q).ceil() as usize).clamp(1, sorted.len()) - 1]
}

fn abs_quantile(values: &[i64], q: f64) -> i64 {
    quantile(&values.iter().map(|e| e.abs()).collect::<Vec<_>>(), q)
}

/// Messages per second between the first and last time stamp.
fn rate_hz(count: usize, first_ns: i64, last_ns: i64) -> f64 {
    (count as f64 - 1.0) / ((last_ns - first_ns) as f64 * 1e-9)
}

/// Writes a calibrated parameter set with `latency_ms` and announces it.
fn announce_latency(probe: &Probe, dir: &Path, latency_ms: f64) {
    let mut params = RobotParams::nominal();
    params.calibration = Some(CalibrationInfo {
        latency_ms: Some(latency_ms),
        source: Some("sensing_graph test: rig truth of the first matched frames".into()),
        ..Default::default()
    });
    let path = dir.join("params.toml");
    std::fs::write(&path, params.to_toml_string()).expect("write params.toml");
    let path = FixedString::new(path.to_str().expect("UTF-8 path")).expect("short path");
    probe
        .parameters
        .send(ParameterSetAnnouncement {
            version: 1,
            t_ns: monotonic_ns(),
            path,
        })
        .expect("announce");
}

/// How a waiting subscriber of a stream was woken over a window: with messages to read, and
/// without (a pre-wake).
#[derive(Debug, Default)]
struct Wakes {
    with_messages: usize,
    without: usize,
}

impl Wakes {
    /// One wake-up that found `read` messages.
    fn count(&mut self, read: usize) {
        match read {
            0 => self.without += 1,
            _ => self.with_messages += 1,
        }
    }
}

/// Waits on subscribers of the tracker frames and the matched samples for `window` and counts
/// how each was woken.
fn wakes_of_frames_and_matched(graph: &LaunchedGraph, window: Duration) -> (Wakes, Wakes) {
    let mut rt = NodeRuntime::with_domain("waiter", graph.domain.clone()).expect("waiter node");
    let frames: Subscriber<TrackerFrame> = rt.subscriber(services::TRACKER_FRAMES).expect("frames");
    let matched: Subscriber<MatchedSample> =
        rt.subscriber(services::SYNC_MATCHED).expect("matched");
    let (mut frame_wakes, mut matched_wakes) = (Wakes::default(), Wakes::default());
    let started = Instant::now();
    rt.run_on_data(&[&frames, &matched], Duration::from_millis(100), |ctx| {
        if ctx.woke_on_data() && ctx.woken_by(&frames) {
            frame_wakes.count(frames.drain(|_| {})?);
        }
        if ctx.woke_on_data() && ctx.woken_by(&matched) {
            matched_wakes.count(matched.drain(|_| {})?);
        }
        if started.elapsed() >= window {
            ctx.stop();
        }
        Ok::<_, sabr_node::NodeError>(())
    })
    .expect("waiting on the frames and matched samples");
    (frame_wakes, matched_wakes)
}

#[test]
fn sim_sensing_graph_matches_to_truth_records_and_stops_cleanly() {
    let _alone = sabr_integration_tests::run_alone();
    let launch = std::fs::read_to_string(LAUNCH_FILE).expect("read the launch file");
    let mut graph = LaunchedGraph::start("sensing", &launch, &[], true);
    for node in ["rig", "encoders", "tracker", "sync", "recorder"] {
        let ready = graph.wait_ready(node, None, START_TIMEOUT);
        assert!(ready.is_some(), "{node} not ready:\n{}", graph.output());
    }
    let probe = Probe::join(&graph);
    let mut seen = Seen::default();
    let cpu_at_start = CpuTimes::now().expect("CPU times");
    let deadline = Instant::now() + COLLECT_TIMEOUT;

    // Phase 1: the configured latency.
    probe.until(&mut seen, deadline, "matched samples", |s| {
        errors(s, LatencySource::Configured).len() >= CONFIGURED_SAMPLES
    });
    let configured = errors(&seen, LatencySource::Configured);
    let configured_latency_ns = seen.matched[0].quality.latency_ns;
    let bias_ns = quantile(&configured, 0.5);
    let centred: Vec<i64> = configured.iter().map(|e| e - bias_ns).collect();

    // Phase 2: announce the latency the truth of phase 1 calls for, then check new frames.
    let calibrated_ns = configured_latency_ns + bias_ns;
    announce_latency(&probe, graph.dir.path(), calibrated_ns as f64 * 1e-6);
    probe.until(
        &mut seen,
        deadline,
        "matched samples with the calibrated latency",
        |s| errors(s, LatencySource::Calibrated).len() >= CALIBRATED_SAMPLES,
    );
    let calibrated = errors(&seen, LatencySource::Calibrated);
    let first_calibrated = seen
        .matched
        .iter()
        .find(|m| m.quality.latency_source == LatencySource::Calibrated)
        .expect("a calibrated sample");
    // The sync's own rounding of ms → ns.
    assert!((first_calibrated.quality.latency_ns - calibrated_ns).abs() <= 1);

    // Rates and continuity of every stream over the whole collection.
    let steal = CpuTimes::now()
        .expect("CPU times")
        .steal_share_since(&cpu_at_start)
        .expect("clock ticks elapsed");
    let floor = if steal < NOTABLE_STEAL {
        RATE_FLOOR
    } else {
        0.0
    };
    let enc = &seen.encoders;
    let encoder_rate = rate_hz(enc.len(), enc[0].t_ns, enc[enc.len() - 1].t_ns);
    let lost = (enc[enc.len() - 1].seq - enc[0].seq + 1) as usize - enc.len();
    let cnt = &seen.counters;
    let counter_rate = rate_hz(cnt.len(), cnt[0].latch_t_ns, cnt[cnt.len() - 1].latch_t_ns);
    let frames = &seen.frames;
    let frame_rate = rate_hz(
        frames.len(),
        frames[0].arrival_t_ns,
        frames[frames.len() - 1].arrival_t_ns,
    );
    let matched_frames: HashSet<u32> = seen.matched.iter().map(|m| m.frame_number).collect();
    let since_lock: Vec<&TrackerFrame> = frames
        .iter()
        .filter(|f| f.arrival_t_ns >= seen.matched[0].arrival_t_ns)
        .collect();
    let unmatched = since_lock
        .iter()
        .filter(|f| !matched_frames.contains(&f.frame_number))
        .count();
    println!(
        "sensing graph: counters {counter_rate:.0} Hz, encoders {encoder_rate:.1} Hz ({lost} lost), \
         tracker {frame_rate:.2} Hz ({} frames, {} truths), matched {} ({unmatched} of {} frames \
         since lock unmatched); the hypervisor took {:.1} % of the CPUs' time",
        frames.len(),
        seen.truth.len(),
        seen.matched.len(),
        since_lock.len(),
        steal * 100.0
    );
    println!(
        "exposure error vs truth, configured latency {:.3} ms ({} frames): median {:.3} ms, \
         p99 |e| {:.3} ms, p99 |e − median| {:.3} ms",
        configured_latency_ns as f64 * 1e-6,
        configured.len(),
        bias_ns as f64 * 1e-6,
        abs_quantile(&configured, 0.99) as f64 * 1e-6,
        abs_quantile(&centred, 0.99) as f64 * 1e-6
    );
    println!(
        "exposure error vs truth, calibrated latency {:.3} ms ({} frames): median {:.3} ms, \
         p50 |e| {:.3} ms, p99 |e| {:.3} ms, max |e| {:.3} ms",
        calibrated_ns as f64 * 1e-6,
        calibrated.len(),
        quantile(&calibrated, 0.5) as f64 * 1e-6,
        abs_quantile(&calibrated, 0.5) as f64 * 1e-6,
        abs_quantile(&calibrated, 0.99) as f64 * 1e-6,
        abs_quantile(&calibrated, 1.0) as f64 * 1e-6
    );
    let in_rate = |rate: f64, nominal: f64| (floor * nominal..1.02 * nominal).contains(&rate);
    let median_period_s = |times: Vec<i64>| median_interval_ns(&times) as f64 * 1e-9;
    let encoder_period = median_period_s(enc.iter().map(|s| s.t_ns).collect());
    let counter_period = median_period_s(cnt.iter().map(|s| s.latch_t_ns).collect());
    assert!(
        in_rate(encoder_rate, 1000.0) && (0.9e-3..1.1e-3).contains(&encoder_period),
        "encoders at {encoder_rate} Hz, median interval {encoder_period} s, {:.1} % steal",
        steal * 100.0
    );
    assert_eq!(lost, 0, "encoder samples lost");
    assert!(
        in_rate(counter_rate, 2000.0) && (0.45e-3..0.55e-3).contains(&counter_period),
        "counters at {counter_rate} Hz, median interval {counter_period} s, {:.1} % steal",
        steal * 100.0
    );
    // The tracker's clock is within 50 ppm of 20 Hz; 0.5 % of its frames are dropped.
    assert!(
        (19.0..20.1).contains(&frame_rate),
        "tracker at {frame_rate} Hz"
    );
    assert!(seen.truth.len() >= frames.len(), "a truth per exposure");
    // Frames inside an encoder gap longer than 5 ms are not matched (the encoder sampler
    // skips periods when the 2-core machine is loaded).
    let sync_log = || {
        let runs = graph.run_dirs();
        std::fs::read_to_string(runs[0].join("logs/sync.log")).unwrap_or_default()
    };
    assert!(
        (since_lock.len() - unmatched) as f64 >= (floor - 0.1) * since_lock.len() as f64,
        "{unmatched} of {} frames unmatched after the lock:\n{}",
        since_lock.len(),
        sync_log()
    );
    let p99 = abs_quantile(&calibrated, 0.99);
    assert!(
        p99 <= ERROR_P99_GOAL_NS,
        "exposure-time error p99 {p99} ns > {ERROR_P99_GOAL_NS} ns"
    );

    // Before every BX poll the tracker pre-wakes the frames' subscribers, and the sync passes
    // that on to the matched samples' (several polls per frame, so more pre-wakes than
    // messages).
    let (frame_wakes, matched_wakes) = wakes_of_frames_and_matched(&graph, Duration::from_secs(2));
    println!(
        "waiting subscribers woken: frames {frame_wakes:?}, matched samples {matched_wakes:?}"
    );
    for (stream, wakes) in [
        ("frames", &frame_wakes),
        ("matched samples", &matched_wakes),
    ] {
        assert!(
            wakes.with_messages >= 30 && wakes.without >= wakes.with_messages,
            "{stream}: {wakes:?} in 2 s"
        );
    }

    // Ctrl-C: the graph stops cleanly and leaves nothing behind.
    drop(probe);
    let status = graph
        .interrupt(Duration::from_secs(20))
        .expect("launcher exits");
    assert!(status.success(), "{status:?}\n{}", graph.output());
    for pid in graph.node_pids() {
        assert!(!process_alive(pid), "node process {pid} still alive");
    }
    let left = graph.leftover_files();
    assert!(left.is_empty(), "iceoryx2 files left: {left:?}");

    // The recording: readable, and complete over its span.
    let runs = graph.run_dirs();
    assert_eq!(runs.len(), 1);
    let sync_log = std::fs::read_to_string(runs[0].join("logs/sync.log")).expect("sync log");
    let sync_stats = sync_log.lines().find(|l| l.contains("sync stopped"));
    println!("{}", sync_stats.expect("the sync stopped cleanly"));
    let log = std::fs::read_to_string(runs[0].join("logs/recorder.log")).expect("recorder log");
    assert!(log.contains("recording finished"), "{log}");
    let recording = Recording::read(&runs[0].join("recording")).expect("recording reads");
    RobotParams::from_toml_str(&recording.robot_toml).expect("robot.toml parses");
    let (first, last) = (
        recording.encoders[0].t_ns,
        recording.encoders[recording.encoders.len() - 1].t_ns,
    );
    let recorded: HashSet<i64> = recording.encoders.iter().map(|r| r.t_ns).collect();
    let expected: Vec<i64> = seen
        .encoders
        .iter()
        .map(|s| s.t_ns)
        .filter(|t| (first..=last).contains(t))
        .collect();
    assert!(
        expected.len() > 5000,
        "{} samples overlap the recording",
        expected.len()
    );
    let missing = expected.iter().filter(|t| !recorded.contains(t)).count();
    assert_eq!(missing, 0, "encoder samples seen live but not recorded");
    let recorded_frames: HashSet<u32> = recording.tracker.iter().map(|r| r.frame).collect();
    assert_eq!(
        recording.tracker.len(),
        4 * recorded_frames.len(),
        "4 tools per frame"
    );
    assert!(recording
        .tracker
        .chunks(4)
        .all(|tools| tools.iter().map(|r| r.tool).eq(Tool::ALL)));
    let span_s = (last - first) as f64 * 1e-9;
    let frames_expected = seen
        .frames
        .iter()
        .filter(|f| (first..=last).contains(&f.arrival_t_ns))
        .filter(|f| !recorded_frames.contains(&f.frame_number))
        .count();
    assert_eq!(
        frames_expected, 0,
        "tracker frames seen live but not recorded"
    );
    assert!(
        recorded_frames.len() as f64 >= 18.0 * span_s,
        "{} frames in {span_s:.1} s",
        recorded_frames.len()
    );
    assert!(
        !recording.phases.is_empty(),
        "the homing phase ended and was recorded"
    );
    println!(
        "recording: {span_s:.1} s, {} encoder rows, {} tracker frames, phases {:?}",
        recording.encoders.len(),
        recorded_frames.len(),
        recording
            .phases
            .iter()
            .map(|p| p.phase.as_str())
            .collect::<Vec<_>>()
    );
}

#[test]
fn a_killed_recorder_leaves_a_readable_recording_and_its_restart_records_anew() {
    let _alone = sabr_integration_tests::run_alone();
    use nix::sys::signal::{kill, Signal};
    use nix::unistd::Pid;

    let launch = std::fs::read_to_string(LAUNCH_FILE).expect("read the launch file");
    let mut graph = LaunchedGraph::start("sensing-kill", &launch, &[], true);
    let first = graph
        .wait_ready("recorder", None, START_TIMEOUT)
        .unwrap_or_else(|| panic!("recorder not ready:\n{}", graph.output()));
    let probe = Probe::join(&graph);
    let mut seen = Seen::default();
    let start = Instant::now();
    probe.until(
        &mut seen,
        start + COLLECT_TIMEOUT,
        "3 s of encoder samples",
        |s| {
            s.encoders.len() > 1
                && s.encoders[s.encoders.len() - 1].t_ns - s.encoders[0].t_ns > 3e9 as i64
        },
    );
    let killed_at_ns = monotonic_ns();
    kill(Pid::from_raw(first.pid as i32), Signal::SIGKILL).expect("SIGKILL the recorder");
    let second = graph
        .wait_ready("recorder", Some(first.pid), Duration::from_secs(10))
        .unwrap_or_else(|| panic!("recorder not restarted:\n{}", graph.output()));
    let restart_deadline = Instant::now() + Duration::from_secs(2);
    probe.until(
        &mut seen,
        restart_deadline + COLLECT_TIMEOUT,
        "2 s more",
        |_| Instant::now() >= restart_deadline,
    );
    drop(probe);
    let status = graph
        .interrupt(Duration::from_secs(20))
        .expect("launcher exits");
    assert!(status.success(), "{status:?}\n{}", graph.output());
    assert!(!process_alive(first.pid) && !process_alive(second.pid));
    let left = graph.leftover_files();
    assert!(left.is_empty(), "iceoryx2 files left: {left:?}");

    let run = &graph.run_dirs()[0];
    // The killed recorder's files: every complete row is readable; nothing it had handed to
    // the operating system (all rows older than the flush interval) is lost.
    let salvage = Recording::read_salvage(&run.join("recording")).expect("salvaged recording");
    let killed = salvage.recording;
    let recorded: HashSet<i64> = killed.encoders.iter().map(|r| r.t_ns).collect();
    let flushed_before = killed_at_ns - 200_000_000;
    let must_have: Vec<i64> = seen
        .encoders
        .iter()
        .map(|s| s.t_ns)
        .filter(|&t| t >= killed.encoders[0].t_ns && t <= flushed_before)
        .collect();
    assert!(
        must_have.len() > 2500,
        "{} samples to check",
        must_have.len()
    );
    let missing = must_have.iter().filter(|t| !recorded.contains(t)).count();
    assert_eq!(
        missing, 0,
        "samples older than the flush interval lost by SIGKILL"
    );
    // The restarted recorder wrote a new recording next to it, closed cleanly on Ctrl-C.
    let restarted = Recording::read(&run.join("recording-2")).expect("second recording reads");
    assert!(
        restarted.encoders.len() > 1000,
        "{}",
        restarted.encoders.len()
    );
    assert!(restarted.encoders[0].t_ns > killed.encoders[killed.encoders.len() - 1].t_ns);
    println!(
        "SIGKILL: first recording {} encoder rows ({} dropped tail lines), restart {} rows",
        killed.encoders.len(),
        salvage.dropped.len(),
        restarted.encoders.len()
    );
}
