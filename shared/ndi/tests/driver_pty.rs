//! End to end: the host driver against the simulated device on a real pseudo-terminal.

use sabr_ndi::{
    Baud, Command, DeviceError, DriverConfig, DriverError, HandleStatus, NdiDriver, NdiServer, Pty,
    ServeStats, ServerMode, SimFrame, SimReading, Transform,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What the rig would report at frame `frame`: a fixed base, a moving front tool, a back tool
/// seen every other frame, and the tip sphere.
fn readings(frame: u32) -> Vec<SimReading> {
    let f = frame as f32;
    let pose = |x: f32| {
        SimReading::Pose(Transform {
            q: [0.5, -0.5, 0.5, 0.5],
            t: [x, 20.5, -1800.0],
            rms: 0.25,
        })
    };
    vec![
        pose(-100.0),
        pose(0.5 * f),
        if (frame / 3) % 2 == 1 {
            SimReading::Missing
        } else {
            pose(-f)
        },
        SimReading::Point {
            position: [0.25 * f, 1.0, -1500.0],
            rms: 0.125,
        },
    ]
}

/// A camera at 100 Hz whose counter advances by 3 per frame, like the real log.
fn camera() -> impl FnMut() -> Option<SimFrame> + Send {
    let start = Instant::now();
    move || {
        let frame = 30 + 3 * (start.elapsed().as_millis() / 10) as u32;
        Some(SimFrame {
            frame,
            readings: readings(frame),
        })
    }
}

struct Rig<S> {
    path: String,
    stop: Arc<AtomicBool>,
    thread: JoinHandle<(NdiServer<S>, ServeStats)>,
}

fn serve<S: sabr_ndi::FrameSource + Send + 'static>(source: S) -> Rig<S> {
    let mut pty = Pty::open().unwrap();
    let path = pty.slave_path().to_str().unwrap().to_owned();
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let thread = std::thread::spawn(move || {
        let mut server = NdiServer::new(4, source);
        let stats = pty.serve(&mut server, &flag).unwrap();
        (server, stats)
    });
    Rig { path, stop, thread }
}

impl<S> Rig<S> {
    fn shut_down(self) -> (NdiServer<S>, ServeStats) {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

/// Generous deadlines: the CI machine may be busy.
fn config(path: &str) -> DriverConfig {
    DriverConfig {
        reply_timeout: Duration::from_secs(1),
        slow_timeout: Duration::from_secs(2),
        stall_timeout: Duration::from_secs(1),
        ..DriverConfig::new(path)
    }
}

/// Short deadlines, for the tests where running into them is the point.
fn impatient(path: &str) -> DriverConfig {
    DriverConfig {
        reply_timeout: Duration::from_millis(200),
        slow_timeout: Duration::from_millis(500),
        stall_timeout: Duration::from_millis(200),
        ..DriverConfig::new(path)
    }
}

#[test]
fn driver_tracks_the_simulated_device_on_a_pty() {
    let rig = serve(camera());
    let mut driver = NdiDriver::connect(config(&rig.path)).unwrap();
    assert!(
        driver.version().contains("SABR simulated Polaris"),
        "{}",
        driver.version()
    );
    let handles: Vec<(u8, u16)> = driver
        .handles()
        .iter()
        .map(|h| (h.handle, h.status))
        .collect();
    assert_eq!(
        handles,
        vec![(1, 0x031), (2, 0x031), (3, 0x031), (4, 0x031)]
    );

    let mut previous: Option<sabr_ndi::Stamped> = None;
    for _ in 0..15 {
        let stamped = driver.next_frame().unwrap();
        let reply = &stamped.reply;
        let frame = reply.frame().unwrap();
        let expected = readings(frame);
        for (reading, want) in reply.handles.iter().zip(&expected) {
            assert_eq!(reading.frame, Some(frame));
            match *want {
                SimReading::Missing => assert_eq!(reading.status, HandleStatus::Missing),
                SimReading::Pose(t) => assert_eq!(reading.transform, Some(t)),
                SimReading::Point { position, rms } => {
                    assert_eq!(
                        reading.transform,
                        Some(Transform {
                            q: [1.0, 0.0, 0.0, 0.0],
                            t: position,
                            rms
                        })
                    );
                }
            }
        }
        if let Some(previous) = &previous {
            let step = frame - previous.reply.frame().unwrap();
            assert!(step >= 3 && step.is_multiple_of(3), "frame step {step}");
            assert!(stamped.arrival > previous.arrival);
            assert!(stamped.arrival_ns > previous.arrival_ns);
            // Bracketed by the previous poll (which did not see this frame) and this one.
            assert!(stamped.available_ns > previous.available_ns);
            assert!(stamped.available_half_width_ns > 0);
        } else {
            assert_eq!(stamped.available_half_width_ns, 0);
        }
        assert!(stamped.available_ns + stamped.available_half_width_ns < stamped.arrival_ns);
        previous = Some(stamped);
    }
    let stats = driver.stats();
    assert_eq!(stats.frames, 15);
    assert!(stats.polls >= 15);
    assert_eq!(
        (
            stats.framing.bad_replies,
            stats.timeouts,
            stats.device_errors
        ),
        (0, 0, 0)
    );

    // The device refuses set-up commands while tracking, and the driver says so.
    match driver.command(&Command::Pinit(1), Duration::from_secs(1)) {
        Err(DriverError::Device { command, error }) => {
            assert_eq!(error, DeviceError::WRONG_MODE);
            assert_eq!(command, "PINIT:01");
        }
        other => panic!("expected ERROR0C, got {other:?}"),
    }
    driver.stop().unwrap();

    // A second session (a restarted tracker process) opens the same terminal again.
    let mut again = NdiDriver::connect(DriverConfig {
        baud: Baud::B9600,
        ..config(&rig.path)
    })
    .unwrap();
    let frame = again.next_frame().unwrap().reply.frame().unwrap();
    assert!(again.next_frame().unwrap().reply.frame().unwrap() > frame);
    // A caller can prepare for the frame before every BX poll, one call per poll sent.
    let polls_before = again.stats().polls;
    let mut before_polls = 0;
    let mut previous = frame;
    for _ in 0..5 {
        let stamped = again.next_frame_with(|| before_polls += 1).unwrap();
        let next = stamped.reply.frame().unwrap();
        assert!(next > previous);
        previous = next;
    }
    assert!(before_polls >= 5);
    assert_eq!(before_polls, again.stats().polls - polls_before);
    drop(again); // TSTOP on drop

    let (server, serve_stats) = rig.shut_down();
    assert_eq!(
        server.mode(),
        ServerMode::Setup,
        "the dropped driver left tracking mode"
    );
    assert_eq!(serve_stats.dropped_replies, 0);
    assert!(server.stats().tracking_replies >= 17);
    assert_eq!(server.stats().errors, 1, "only the refused PINIT");
}

#[test]
fn a_new_frame_is_not_polled_for_within_a_poll_interval_of_the_last() {
    // A device with a new frame at every poll: only the driver's pacing spaces the frames.
    let mut frame = 30;
    let rig = serve(move || {
        frame += 3;
        Some(SimFrame {
            frame,
            readings: readings(frame),
        })
    });
    let poll_interval = Duration::from_millis(5);
    let mut driver = NdiDriver::connect(DriverConfig {
        poll_interval,
        ..config(&rig.path)
    })
    .unwrap();
    let mut previous = driver.next_frame().unwrap().arrival;
    for _ in 0..10 {
        let stamped = driver.next_frame().unwrap();
        let gap = stamped.arrival.duration_since(previous);
        assert!(gap >= poll_interval, "frames {gap:?} apart");
        previous = stamped.arrival;
    }
    // One poll per frame: none was spent finding the last frame again.
    assert_eq!(driver.stats().polls, 11);
    drop(driver);
    rig.shut_down();
}

#[test]
fn polling_pauses_between_frames_and_still_brackets_each_frame_within_a_poll_interval() {
    // A camera at 20 Hz, polled every millisecond: without pauses about 50 polls per frame.
    let start = Instant::now();
    let rig = serve(move || {
        let frame = 100 + (start.elapsed().as_millis() / 50) as u32;
        Some(SimFrame {
            frame,
            readings: readings(frame),
        })
    });
    let config = config(&rig.path);
    let (poll_interval, lead) = (config.poll_interval, config.poll_lead);
    assert_eq!(
        (poll_interval, lead),
        (Duration::from_millis(1), Duration::from_millis(5))
    );
    let mut driver = NdiDriver::connect(config).unwrap();
    // The first frames teach the driver the interval.
    for _ in 0..5 {
        driver.next_frame().unwrap();
    }
    let before = driver.stats();
    let frames = 20;
    let mut half_widths: Vec<i64> = (0..frames)
        .map(|_| driver.next_frame().unwrap().available_half_width_ns)
        .collect();
    let stats = driver.stats();
    let polls_per_frame = (stats.polls - before.polls) as f64 / f64::from(frames);
    assert!(
        polls_per_frame < 15.0,
        "{polls_per_frame} polls per frame; {stats:?}"
    );
    assert!(stats.early_frames <= 2, "{stats:?}");
    half_widths.sort_unstable();
    let median = Duration::from_nanos(half_widths[half_widths.len() / 2] as u64);
    assert!(
        median <= poll_interval,
        "median bracket half-width {median:?}: {half_widths:?}"
    );
    drop(driver);
    rig.shut_down();
}

#[test]
fn a_silent_tracker_is_a_timeout_not_a_hang() {
    // Nobody serves the terminal: INIT, the break and the RESET wait all time out.
    let pty = Pty::open().unwrap();
    let path = pty.slave_path().to_str().unwrap().to_owned();
    let started = Instant::now();
    let result = NdiDriver::connect(impatient(&path));
    let elapsed = started.elapsed();
    assert!(
        matches!(result, Err(DriverError::Timeout { .. })),
        "{result:?}"
    );
    assert!(elapsed < Duration::from_secs(3), "took {elapsed:?}");
}

#[test]
fn a_tracker_that_dies_mid_stream_is_noticed() {
    let rig = serve(camera());
    let mut driver = NdiDriver::connect(config(&rig.path)).unwrap();
    driver.next_frame().unwrap();
    let _ = rig.shut_down(); // closes the master side: the device is gone
    let started = Instant::now();
    let result = driver.next_frame();
    assert!(
        matches!(
            result,
            Err(DriverError::Io { .. } | DriverError::Timeout { .. })
        ),
        "{result:?}"
    );
    assert!(started.elapsed() < Duration::from_secs(1));
}

#[test]
fn a_frozen_frame_counter_is_a_stall() {
    let rig = serve(|| {
        Some(SimFrame {
            frame: 42,
            readings: readings(42),
        })
    });
    let stall_timeout = Duration::from_millis(200);
    let mut driver = NdiDriver::connect(DriverConfig {
        stall_timeout,
        ..config(&rig.path)
    })
    .unwrap();
    assert_eq!(driver.next_frame().unwrap().reply.frame(), Some(42));
    let started = Instant::now();
    match driver.next_frame() {
        Err(DriverError::Stalled { last_frame, waited }) => {
            assert_eq!(last_frame, Some(42));
            assert!(waited > stall_timeout);
        }
        other => panic!("expected a stall, got {other:?}"),
    }
    assert!(
        started.elapsed() < stall_timeout * 10,
        "noticed, not waited on"
    );
    assert!(driver.stats().polls > 10);
    drop(driver);
    let (server, _) = rig.shut_down();
    assert_eq!(server.mode(), ServerMode::Setup);
}

#[test]
fn bx_options_without_frame_numbers_are_refused() {
    let result = NdiDriver::connect(DriverConfig {
        options: sabr_ndi::ReplyOptions::PASSIVE_STRAYS,
        ..config("/nonexistent")
    });
    assert!(matches!(result, Err(DriverError::Config(_))), "{result:?}");
}

/// Serves like [`Pty::serve`] but hands every BX reply to `tamper` first, with its number
/// (from 1) among the BX replies: it may change the reply's bytes, or empty it (no reply).
fn serve_tampered<S: sabr_ndi::FrameSource + Send + 'static>(
    source: S,
    mut tamper: impl FnMut(u64, &mut Vec<u8>) + Send + 'static,
) -> Rig<S> {
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
    use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
    use std::io::{Read, Write};
    use std::os::fd::AsFd;

    let pair = nix::pty::openpty(None, None).unwrap();
    let mut termios = tcgetattr(&pair.slave).unwrap();
    cfmakeraw(&mut termios);
    tcsetattr(&pair.slave, SetArg::TCSANOW, &termios).unwrap();
    let path = nix::unistd::ttyname(&pair.slave)
        .unwrap()
        .to_str()
        .unwrap()
        .to_owned();
    drop(pair.slave);
    let mut master = std::fs::File::from(pair.master);
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let thread = std::thread::spawn(move || {
        let mut server = NdiServer::new(4, source);
        let mut buf = [0u8; 1024];
        let mut bx_replies = 0u64;
        let mut stats = ServeStats::default();
        while !flag.load(Ordering::Relaxed) {
            let mut fds = [PollFd::new(master.as_fd(), PollFlags::POLLIN)];
            let ready = poll(&mut fds, PollTimeout::from(20u16)).unwrap_or(0);
            let readable = fds[0]
                .revents()
                .is_some_and(|r| r.contains(PollFlags::POLLIN));
            if ready == 0 || !readable {
                std::thread::sleep(Duration::from_millis(5));
                continue;
            }
            let Ok(n) = master.read(&mut buf) else {
                continue;
            };
            let mut reply = server.feed(&buf[..n]);
            if reply.starts_with(&[0xC4, 0xA5]) {
                bx_replies += 1;
                tamper(bx_replies, &mut reply);
            }
            if master.write_all(&reply).is_ok() {
                stats.bytes_out += reply.len() as u64;
            }
        }
        (server, stats)
    });
    Rig { path, stop, thread }
}

#[test]
fn corrupted_replies_on_the_wire_are_counted_and_tracking_goes_on() {
    let corrupted = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let counter = corrupted.clone();
    // Flips one byte of every fourth BX reply, inside the body: the body CRC catches it.
    let rig = serve_tampered(camera(), move |bx, reply| {
        if bx.is_multiple_of(4) {
            let last = reply.len() - 3;
            reply[last] ^= 0x40;
            counter.fetch_add(1, Ordering::Relaxed);
        }
    });
    let mut driver = NdiDriver::connect(config(&rig.path)).unwrap();
    let (mut frames, mut rejected) = (0u64, 0u64);
    while frames < 20 {
        match driver.next_frame() {
            Ok(stamped) => {
                let frame = stamped.reply.frame().unwrap();
                let front = stamped.reply.handle(2).unwrap().transform.unwrap();
                assert_eq!(front.t[0], 0.5 * frame as f32, "frame {frame}: data intact");
                frames += 1;
            }
            Err(DriverError::Reply { command, error }) => {
                assert_eq!(command, "BX:0001");
                assert!(
                    matches!(error, sabr_ndi::ReplyError::BadCrc { .. }),
                    "{error}"
                );
                rejected += 1;
            }
            Err(other) => panic!("{other}"),
        }
    }
    let stats = driver.stats();
    drop(driver);
    rig.shut_down();
    let corrupted = corrupted.load(Ordering::Relaxed);
    assert_eq!(rejected, corrupted, "every corrupted reply was rejected");
    assert_eq!(stats.framing.bad_replies, rejected, "and counted");
    assert!(
        rejected >= stats.polls / 4 - 1 && rejected > 0,
        "{rejected} of {} polls",
        stats.polls
    );
}

#[test]
fn an_unanswered_poll_is_sent_again_and_tracking_goes_on() {
    // The 5th and 9th BX replies are lost on the line.
    let rig = serve_tampered(camera(), |bx, reply| {
        if bx == 5 || bx == 9 {
            reply.clear();
        }
    });
    let mut driver = NdiDriver::connect(impatient(&rig.path)).unwrap();
    let mut last = None;
    for _ in 0..15 {
        let frame = driver.next_frame().unwrap().reply.frame();
        assert!(frame > last, "{frame:?} after {last:?}");
        last = frame;
    }
    let stats = driver.stats();
    drop(driver);
    rig.shut_down();
    assert_eq!(stats.timeouts, 2, "{stats:?}");
    assert_eq!(stats.retried_polls, 2, "{stats:?}");
}

#[test]
fn a_tracker_that_goes_silent_is_a_timeout_after_the_retries() {
    // Every BX reply from the 5th on is lost.
    let rig = serve_tampered(camera(), |bx, reply| {
        if bx >= 5 {
            reply.clear();
        }
    });
    let config = impatient(&rig.path);
    let mut driver = NdiDriver::connect(config.clone()).unwrap();
    let mut result = driver.next_frame().map(|_| ());
    while result.is_ok() {
        result = driver.next_frame().map(|_| ());
    }
    assert!(
        matches!(result, Err(DriverError::Timeout { .. })),
        "{result:?}"
    );
    let stats = driver.stats();
    drop(driver);
    rig.shut_down();
    assert_eq!(stats.retried_polls, u64::from(config.poll_retries));
    assert_eq!(stats.timeouts, u64::from(config.poll_retries) + 1);
}
