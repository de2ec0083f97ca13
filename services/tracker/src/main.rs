//! `sabr-tracker`: drives an NDI tracker (a real Polaris, or the rig's pseudo-terminal) with
//! the `sabr_ndi` driver and publishes every new frame, stamped on arrival with the host's
//! `CLOCK_MONOTONIC`, as a [`TrackerFrame`] on `sabr/tracker/frames`.
//!
//! A corrupt or refused reply is logged, counted and skipped. A tracker that stops answering
//! (time-out, serial I/O error) or whose frame counter stands still is dead: the node says so
//! and leaves with failure, for the launcher to restart it. On a stop request it leaves
//! tracking mode (TSTOP) before exiting.

mod convert;

use std::process::ExitCode;

use anyhow::Context;
use clap::Parser;
use sabr_msgs::{services, Tool, TrackerFrame};
use sabr_ndi::{Baud, DriverConfig, DriverError, NdiDriver};
use sabr_node::NodeRuntime;

use convert::{tracker_frame, HandleMap};

/// Bad replies logged one by one before only every 100th is.
const BAD_REPLIES_LOGGED: u64 = 10;

/// Command line of the tracker process.
#[derive(Debug, Parser)]
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
    sabr_node::init_tracing();
    match run(&Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            tracing::error!("{error:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> anyhow::Result<()> {
    let port = match (&args.port, sabr_node::run_dir()) {
        (Some(port), _) => port.clone(),
        (None, Some(run_dir)) => run_dir.join("polaris-tty").to_string_lossy().into_owned(),
        (None, None) => anyhow::bail!("no --port given and SABR_RUN_DIR is unset"),
    };
    let baud = Baud::from_bits_per_second(args.baud).with_context(|| {
        format!(
            "--baud {}: not a speed the NDI COMM command offers",
            args.baud
        )
    })?;
    let mut rt = NodeRuntime::start("tracker")?;
    let out = rt.publisher::<TrackerFrame>(services::TRACKER_FRAMES)?;
    let config = DriverConfig {
        baud,
        ..DriverConfig::new(&port)
    };
    let mut driver =
        NdiDriver::connect(config).with_context(|| format!("starting the tracker on {port}"))?;
    log_start(&driver, &args.handles);

    let mut published = 0u64;
    let mut bad_replies = 0u64;
    while args.frames == 0 || published < args.frames {
        if !rt.keep_running() {
            break;
        }
        match driver.next_frame() {
            Ok(stamped) => {
                published += 1;
                out.send(tracker_frame(published, &stamped, &args.handles))?;
                if published == 1 {
                    rt.ready();
                }
            }
            Err(error @ (DriverError::Reply { .. } | DriverError::Device { .. })) => {
                bad_replies += 1;
                if bad_replies <= BAD_REPLIES_LOGGED || bad_replies.is_multiple_of(100) {
                    tracing::warn!(bad_replies, "skipping a bad tracker reply: {error}");
                }
            }
            Err(error) if !rt.keep_running() => {
                // Stopping anyway (e.g. the whole graph at once): the device went first.
                tracing::info!(
                    published,
                    bad_replies,
                    "stop requested; tracker gone: {error}"
                );
                return Ok(());
            }
            Err(error) => {
                tracing::info!(published, bad_replies, stats = ?driver.stats(), "tracker lost");
                return Err(error).context("the tracker is dead");
            }
        }
    }
    let stats = driver.stats();
    driver.stop().context("stopping the tracker (TSTOP)")?;
    tracing::info!(published, bad_replies, ?stats, "tracking stopped");
    Ok(())
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
