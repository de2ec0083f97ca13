//! `sabr-tracker`: drives an NDI tracker (a real Polaris, or the rig's pseudo-terminal) with
//! the `sabr_ndi` driver and publishes every new frame, stamped on arrival with the host's
//! `CLOCK_MONOTONIC`, as a [`TrackerFrame`] on `sabr/tracker/frames`. Before every BX poll it
//! warms its send and pre-wakes the frames' subscribers, so that the frame's way to them runs
//! from the cache (`sabr_node::Publisher::prewake`).
//!
//! A corrupt or refused reply is logged, counted and skipped; an unanswered poll is logged and
//! sent again (twice, by the driver's default). A tracker that stops answering (time-outs in a
//! row, serial I/O error) or whose frame counter stands still is dead: the node says so and
//! leaves with failure, for the launcher to restart it. On a stop request it leaves
//! tracking mode (TSTOP) before exiting.

mod convert;

use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use sabr_msgs::{services, Tool, TrackerFrame};
use sabr_ndi::{Baud, DriverConfig, DriverError, NdiDriver};
use sabr_node::{monotonic_ns, Exit, NodeRuntime, Publisher};

use convert::{tracker_frame, HandleMap};

/// Bad replies logged one by one before only every 100th is.
const BAD_REPLIES_LOGGED: u64 = 10;

/// Command line of the tracker process.
#[derive(Debug, clap::Parser)]
#[command(name = "sabr-tracker", about)]
struct Args {
    /// Serial device of the tracker (e.g. /dev/ttyUSB0, or the rig's device path)
    /// [default: $SABR_RUN_DIR/polaris-tty, where `sabr-rig` puts it].
    #[arg(long)]
    port: Option<String>,
    /// Serial speed to switch to after INIT, bit/s (9600 keeps the power-up speed).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Stop after this many frames (0: run until stopped or an error).
    #[arg(long, default_value_t = 0)]
    frames: u64,
    /// Port handles (hexadecimal) of the base, front, back and tip tools.
    #[arg(long, value_name = "B,F,K,T", default_value = "01,02,03,04")]
    handles: HandleMap,
}

fn main() -> ExitCode {
    sabr_node::service_main("tracker", run)
}

fn run(args: &Args, rt: &mut NodeRuntime) -> anyhow::Result<Exit> {
    let port = sabr_node::in_run_dir(args.port.as_deref().map(Path::new), "polaris-tty", "--port")?;
    let port = port.to_string_lossy().into_owned();
    let baud = Baud::from_bits_per_second(args.baud).with_context(|| {
        format!(
            "--baud {}: not a speed the NDI COMM command offers",
            args.baud
        )
    })?;
    let out = rt.publisher::<TrackerFrame>(services::TRACKER_FRAMES)?;
    let config = DriverConfig {
        baud,
        ..DriverConfig::new(&port)
    };
    let mut driver =
        NdiDriver::connect(config).with_context(|| format!("starting the tracker on {port}"))?;
    log_start(&driver, &args.handles);

    let mut tracking = Tracking::default();
    // Ready only once the device gives frames.
    while tracking.published == 0 {
        if !rt.keep_running() {
            return Ok(Exit::Signal);
        }
        tracking.step(&mut driver, &out, &args.handles)?;
    }
    // Paced by the device: `next_frame` returns when the next frame is there.
    let exit = rt.run_loop(Duration::ZERO, |ctx| {
        if args.frames != 0 && tracking.published >= args.frames {
            ctx.stop();
            return Ok(());
        }
        tracking.step(&mut driver, &out, &args.handles)
    });
    let exit = match exit {
        Err(_) if sabr_node::termination_requested() => {
            // Stopping anyway (e.g. the whole graph at once): the device went first.
            tracing::info!(?tracking, "stop requested; tracker gone");
            return Ok(Exit::Signal);
        }
        exit => exit?,
    };
    let stats = driver.stats();
    driver.stop().context("stopping the tracker (TSTOP)")?;
    tracing::info!(?tracking, ?stats, "tracking stopped");
    Ok(exit)
}

/// Frames published and bad replies skipped so far.
#[derive(Debug, Default)]
struct Tracking {
    published: u64,
    bad_replies: u64,
}

impl Tracking {
    /// Waits for the next frame and publishes it; a bad reply is counted and skipped, a dead
    /// tracker is an error.
    fn step(
        &mut self,
        driver: &mut NdiDriver,
        out: &Publisher<TrackerFrame>,
        handles: &HandleMap,
    ) -> anyhow::Result<()> {
        let retried_before = driver.stats().retried_polls;
        // The frame comes with one of the polls, 50 ms after the last one. Before each poll
        // the send is warmed and the subscribers pre-woken: the send runs from the cache, not
        // from memory the core's other work evicted, and so do the subscribers' wake-ups.
        let mut prewoken = Ok(());
        let next = driver.next_frame_with(|| {
            out.warm();
            if prewoken.is_ok() {
                prewoken = out.prewake();
            }
        });
        let retried = driver.stats().retried_polls - retried_before;
        if retried > 0 {
            tracing::warn!(
                retried,
                total = driver.stats().retried_polls,
                "the tracker left BX polls unanswered; sent them again"
            );
        }
        match next {
            Ok(stamped) => {
                self.published += 1;
                let mut frame = tracker_frame(self.published, &stamped, handles);
                frame.sent_t_ns = monotonic_ns();
                out.send(frame)?;
            }
            Err(error @ (DriverError::Reply { .. } | DriverError::Device { .. })) => {
                self.bad_replies += 1;
                let bad_replies = self.bad_replies;
                if bad_replies <= BAD_REPLIES_LOGGED || bad_replies.is_multiple_of(100) {
                    tracing::warn!(bad_replies, "skipping a bad tracker reply: {error}");
                }
            }
            Err(error) => {
                tracing::info!(tracking = ?self, stats = ?driver.stats(), "tracker lost");
                return Err(error).context("the tracker is dead");
            }
        }
        // (After the frame is out: a failed ring would fail its send too.)
        prewoken.context("pre-waking the frames' subscribers")?;
        Ok(())
    }
}

fn log_start(driver: &NdiDriver, map: &HandleMap) {
    let enabled: Vec<u8> = driver.handles().iter().map(|h| h.handle).collect();
    tracing::info!(
        device = driver.version().lines().next().unwrap_or("device"),
        handles = ?enabled,
        "tracking"
    );
    for tool in Tool::ALL {
        if !enabled.contains(&map.handle(tool)) {
            tracing::warn!(
                tool = tool.name(),
                handle = map.handle(tool),
                "the tool's port handle is not enabled: reported as disabled"
            );
        }
    }
}
