//! The motion executor process (`sabr-motion`): an out-of-limit plan is refused before any
//! setpoint is published, and a stalled encoder or tracker stream stops it within 50 ms of
//! the stream's deadline with the reason in its status.
//!
//! Needs the workspace binaries: `cargo build --workspace --bins` first.

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_integration_tests::{bin, test_domain};
use sabr_msgs::{services, EncoderSample, MotionState, MotionStatus, MotorSetpoint, TrackerFrame};
use sabr_node::{monotonic_ns, Domain, NodeRuntime, Subscriber};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const LONG: Duration = Duration::from_secs(20);
/// The goal: the robot is stopped at most this long after a stream's deadline passed.
const STOP_WITHIN_NS: i64 = 50_000_000;
/// Deadlines given to `sabr-motion` here: longer than its defaults (20 ms, 200 ms) so that a
/// loaded CI host does not stall a stream by accident; the goal is about the time after them.
const ENCODER_DEADLINE_NS: i64 = 100_000_000;
const TRACKER_DEADLINE_NS: i64 = 400_000_000;

/// A `sabr-motion` process; a test that fails stops it on drop (SIGINT, then SIGKILL).
struct Motion(Child);

impl Motion {
    /// Starts `sabr-motion` in `domain`, its stderr in `log`.
    fn start(domain: &Domain, log: &Path, args: &[&str]) -> Self {
        let child = Command::new(bin("sabr-motion"))
            .args(args)
            .env("SABR_DOMAIN", domain.as_str())
            .env("SABR_NODE_NAME", "motion")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(log).unwrap())
            .spawn()
            .expect("start sabr-motion");
        Self(child)
    }

    fn interrupt(&self) {
        let _ = kill(Pid::from_raw(self.0.id() as i32), Signal::SIGINT);
    }

    fn try_wait(&mut self) -> Option<ExitStatus> {
        self.0.try_wait().unwrap()
    }

    fn wait_exit(&mut self) -> ExitStatus {
        let start = Instant::now();
        loop {
            if let Some(status) = self.try_wait() {
                return status;
            }
            assert!(start.elapsed() < LONG, "sabr-motion did not exit");
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Motion {
    fn drop(&mut self) {
        if self.try_wait().is_none() {
            self.interrupt();
            let start = Instant::now();
            while self.try_wait().is_none() && start.elapsed() < Duration::from_secs(3) {
                std::thread::sleep(Duration::from_millis(10));
            }
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// What the test sees of the motion node.
struct Watch {
    setpoints: Subscriber<MotorSetpoint>,
    status: Subscriber<MotionStatus>,
    /// Owns the ports above (dropped last).
    _rt: NodeRuntime,
}

impl Watch {
    fn new(domain: &Domain) -> Self {
        let rt = NodeRuntime::with_domain("motion-test", domain.clone()).unwrap();
        Self {
            setpoints: rt.subscriber(services::MOTION_SETPOINTS).unwrap(),
            status: rt.subscriber(services::MOTION_STATUS).unwrap(),
            _rt: rt,
        }
    }
}

/// A stand-in for the rig and its sensors: publishes encoder samples at about 1 kHz whose
/// counts follow the latest motor setpoint (a perfect servo without stops, so homing keeps
/// moving) and, unless disabled, tracker frames at 20 Hz, each until its flag is cleared;
/// records the stamp of the last sample of each stream.
struct Feedback {
    encoders_on: Arc<AtomicBool>,
    tracker_on: Arc<AtomicBool>,
    last_encoder_ns: Arc<AtomicI64>,
    last_frame_ns: Arc<AtomicI64>,
    running: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Feedback {
    fn start(domain: &Domain, tracker: bool) -> Self {
        let encoders_on = Arc::new(AtomicBool::new(true));
        let tracker_on = Arc::new(AtomicBool::new(tracker));
        let last_encoder_ns = Arc::new(AtomicI64::new(0));
        let last_frame_ns = Arc::new(AtomicI64::new(0));
        let running = Arc::new(AtomicBool::new(true));
        let thread = {
            let (encoders_on, tracker_on) = (encoders_on.clone(), tracker_on.clone());
            let (last_encoder_ns, last_frame_ns) = (last_encoder_ns.clone(), last_frame_ns.clone());
            let running = running.clone();
            let domain = domain.clone();
            std::thread::spawn(move || {
                let rt = NodeRuntime::with_domain("feedback", domain).unwrap();
                let encoders = rt
                    .publisher::<EncoderSample>(services::ENCODER_SAMPLES)
                    .unwrap();
                let frames = rt
                    .publisher::<TrackerFrame>(services::TRACKER_FRAMES)
                    .unwrap();
                let setpoints = rt
                    .subscriber::<MotorSetpoint>(services::MOTION_SETPOINTS)
                    .unwrap();
                let mut counts = [10, -20, 30, -40, 50];
                let mut seq = 0;
                while running.load(Ordering::Relaxed) {
                    seq += 1;
                    if let Some(setpoint) = setpoints.latest().unwrap() {
                        counts = setpoint.target_counts.map(|c| c.round() as i64);
                    }
                    let t_ns = monotonic_ns();
                    if encoders_on.load(Ordering::Relaxed) {
                        encoders.send(EncoderSample { seq, t_ns, counts }).unwrap();
                        last_encoder_ns.store(t_ns, Ordering::Relaxed);
                    }
                    if seq % 50 == 0 && tracker_on.load(Ordering::Relaxed) {
                        frames
                            .send(TrackerFrame {
                                seq: seq / 50,
                                arrival_t_ns: t_ns,
                                available_t_ns: t_ns,
                                ..TrackerFrame::default()
                            })
                            .unwrap();
                        last_frame_ns.store(t_ns, Ordering::Relaxed);
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
            })
        };
        Self {
            encoders_on,
            tracker_on,
            last_encoder_ns,
            last_frame_ns,
            running,
            thread: Some(thread),
        }
    }
}

impl Drop for Feedback {
    fn drop(&mut self) {
        self.running.store(false, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn release(domain: &Domain) {
    let left = sabr_node::release_domain(domain);
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn motion_refuses_an_out_of_limit_plan_before_any_setpoint() {
    let _alone = sabr_integration_tests::run_alone();
    let domain = test_domain("motion-refuse");
    let dir = tempfile::tempdir().unwrap();
    let watch = Watch::new(&domain);
    let feedback = Feedback::start(&domain, true);
    // The calibration plan's excitation reaches 0.46 rad from the stops: a 0.3 rad range
    // cuts it; a 0.1 rad/s speed limit is below its moves.
    for (limit, reason) in [
        (["--joint-range", "0.3"], "limit"),
        (["--max-joint-speed", "0.1"], "speed limit"),
    ] {
        let log = dir.path().join("motion.log");
        let mut args = vec!["--session", "calibration", "--duration-scale", "0.02"];
        args.extend(limit);
        let mut motion = Motion::start(&domain, &log, &args);
        let start = Instant::now();
        let faulted = loop {
            assert!(start.elapsed() < LONG, "no Faulted status");
            let status = std::iter::from_fn(|| watch.status.try_recv().unwrap())
                .find(|s| s.state == MotionState::Faulted);
            if let Some(status) = status {
                break status;
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        assert!(
            faulted.reason.as_str().starts_with("plan refused"),
            "{faulted:?}"
        );
        assert!(faulted.reason.as_str().contains(reason), "{faulted:?}");
        // It holds, refusing, until stopped; then exits with a failure.
        std::thread::sleep(Duration::from_millis(200));
        assert_eq!(motion.try_wait(), None, "still there, faulted");
        motion.interrupt();
        assert!(!motion.wait_exit().success(), "a refused plan is a failure");
        let stderr = std::fs::read_to_string(&log).unwrap();
        assert!(stderr.contains("plan refused"), "{stderr}");
        assert_eq!(
            watch.setpoints.try_recv().unwrap(),
            None,
            "no setpoint was published"
        );
    }
    drop((feedback, watch));
    release(&domain);
}

/// Starts homing with live feedback, then stops one stream; returns the motion status that
/// reports the fault, the stamp of that stream's last sample, and the setpoints seen.
fn stall_one_stream(
    test: &str,
    stop_encoders: bool,
) -> (MotionStatus, i64, Vec<MotorSetpoint>, String) {
    let domain = test_domain(test);
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("motion.log");
    let watch = Watch::new(&domain);
    let feedback = Feedback::start(&domain, true);
    let mut motion = Motion::start(
        &domain,
        &log,
        &[
            "--session",
            "homing",
            "--duration-scale",
            "0.2",
            "--exit-on-fault",
            "--encoder-deadline-ms",
            "100",
            "--tracker-deadline-ms",
            "400",
        ],
    );
    let mut seen = Vec::new();
    let start = Instant::now();
    // Wait until it moves (homing setpoints flow), then let it run a little.
    while seen.len() < 300 {
        assert!(start.elapsed() < LONG, "no setpoints");
        watch.setpoints.drain(|s| seen.push(s)).unwrap();
        if let Some(early) = std::iter::from_fn(|| watch.status.try_recv().unwrap())
            .find(|s| s.state == MotionState::Faulted)
        {
            panic!("faulted before any stream stopped (host too loaded?): {early:?}");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    if stop_encoders {
        feedback.encoders_on.store(false, Ordering::Relaxed);
    } else {
        feedback.tracker_on.store(false, Ordering::Relaxed);
    }
    let faulted = loop {
        assert!(start.elapsed() < LONG, "no fault reported");
        watch.setpoints.drain(|s| seen.push(s)).unwrap();
        let status = std::iter::from_fn(|| watch.status.try_recv().unwrap())
            .find(|s| s.state == MotionState::Faulted);
        if let Some(status) = status {
            break status;
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    let exit = motion.wait_exit();
    assert!(!exit.success(), "--exit-on-fault exits with a failure");
    watch.setpoints.drain(|s| seen.push(s)).unwrap();
    let last = if stop_encoders {
        feedback.last_encoder_ns.load(Ordering::Relaxed)
    } else {
        feedback.last_frame_ns.load(Ordering::Relaxed)
    };
    let stderr = std::fs::read_to_string(&log).unwrap();
    drop((feedback, watch));
    release(&domain);
    (faulted, last, seen, stderr)
}

/// The robot holds: the fault's last setpoint repeats the one before it and goes out with
/// the fault status, and nothing follows it; before, homing was moving.
fn assert_holds(status: &MotionStatus, setpoints: &[MotorSetpoint]) {
    assert!(
        setpoints
            .windows(2)
            .any(|w| w[0].target_counts != w[1].target_counts),
        "homing moved"
    );
    let [.., before, hold] = setpoints else {
        panic!("setpoints before the fault");
    };
    assert_eq!(hold.seq, before.seq + 1);
    assert_eq!(
        hold.target_counts, before.target_counts,
        "holds the last setpoint"
    );
    assert_eq!(hold.t_ns, status.t_ns, "the hold goes out with the fault");
}

#[test]
fn a_stalled_encoder_stream_stops_motion_within_50_ms_of_its_deadline() {
    let _alone = sabr_integration_tests::run_alone();
    let (status, last_sample_ns, setpoints, stderr) = stall_one_stream("motion-enc", true);
    assert!(
        status.reason.as_str().starts_with("encoder feedback stale"),
        "{status:?}"
    );
    let deadline_ns = last_sample_ns + ENCODER_DEADLINE_NS;
    assert!(status.t_ns > deadline_ns, "not before the deadline");
    let late = status.t_ns - deadline_ns;
    println!(
        "encoder stall: stopped {:.1} ms after the deadline",
        late as f64 * 1e-6
    );
    assert!(
        late <= STOP_WITHIN_NS,
        "stopped {late} ns after the deadline"
    );
    assert_holds(&status, &setpoints);
    assert!(stderr.contains("encoder feedback stale"), "{stderr}");
}

#[test]
fn a_stalled_tracker_stream_stops_motion_within_50_ms_of_its_deadline() {
    let _alone = sabr_integration_tests::run_alone();
    let (status, last_frame_ns, setpoints, stderr) = stall_one_stream("motion-trk", false);
    assert!(
        status.reason.as_str().starts_with("tracker feedback stale"),
        "{status:?}"
    );
    let deadline_ns = last_frame_ns + TRACKER_DEADLINE_NS;
    assert!(status.t_ns > deadline_ns, "not before the deadline");
    let late = status.t_ns - deadline_ns;
    println!(
        "tracker stall: stopped {:.1} ms after the deadline",
        late as f64 * 1e-6
    );
    assert!(
        late <= STOP_WITHIN_NS,
        "stopped {late} ns after the deadline"
    );
    assert_holds(&status, &setpoints);
    assert!(stderr.contains("tracker feedback stale"), "{stderr}");
}
