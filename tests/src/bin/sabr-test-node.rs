//! A minimal service on `sabr-node`, used by the launcher tests and as the example of a node:
//! publishes a counter (`EncoderSample` with `seq` counting and `counts[0]` = its pid) on
//! `sabr/test/counter`, and can misbehave on request.

use clap::Parser;
use sabr_msgs::{services, EncoderSample};
use sabr_node::{monotonic_ns, Exit, NodeRuntime};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Test node of the launcher tests.
#[derive(Debug, Parser)]
struct Args {
    /// Publishing rate, Hz.
    #[arg(long, default_value_t = 100.0)]
    rate_hz: f64,
    /// Delay before announcing readiness, ms.
    #[arg(long, default_value_t = 0)]
    ready_delay_ms: u64,
    /// Leave on its own after this long, with `--exit-code`, ms.
    #[arg(long)]
    exit_after_ms: Option<u64>,
    /// Exit status when leaving on its own.
    #[arg(long, default_value_t = 0)]
    exit_code: u8,
    /// Announce the graph's job done after this long, ms.
    #[arg(long)]
    done_after_ms: Option<u64>,
    /// Hang (alive, but no heartbeat and no data) after this long, ms.
    #[arg(long)]
    hang_after_ms: Option<u64>,
    /// Ignore stop requests (SIGINT/SIGTERM): only SIGKILL ends it.
    #[arg(long)]
    ignore_stop: bool,
}

fn main() -> ExitCode {
    let result = run(&Args::parse()).map_err(anyhow::Error::from);
    sabr_node::console::exit_status("sabr-test-node", result)
}

fn run(args: &Args) -> Result<ExitCode, sabr_node::NodeError> {
    let mut rt = NodeRuntime::start("test-node")?;
    let counter = rt.publisher::<EncoderSample>(services::TEST_COUNTER)?;
    if !rt.sleep(Duration::from_millis(args.ready_delay_ms)) {
        return Ok(ExitCode::SUCCESS);
    }
    rt.ready();
    let started = Instant::now();
    let period = Duration::from_secs_f64(1.0 / args.rate_hz.max(0.1));
    let pid = i64::from(std::process::id());
    let mut seq = 0;
    let mut sample = move || {
        seq += 1;
        EncoderSample {
            seq,
            t_ns: monotonic_ns(),
            counts: [pid, 0, 0, 0, 0],
        }
    };
    if args.ignore_stop {
        loop {
            rt.sleep(period);
            counter.send(sample())?;
        }
    }
    let after =
        |ms: Option<u64>| ms.is_some_and(|ms| started.elapsed() >= Duration::from_millis(ms));
    let exit = rt.run_loop(period, |ctx| {
        counter.send(sample())?;
        if after(args.hang_after_ms) {
            std::thread::sleep(Duration::from_secs(3600));
        }
        if after(args.done_after_ms) {
            ctx.finish_graph();
        } else if after(args.exit_after_ms) {
            ctx.stop();
        }
        Ok::<_, sabr_node::NodeError>(())
    })?;
    Ok(match exit {
        Exit::Stopped => ExitCode::from(args.exit_code),
        Exit::Signal | Exit::Done => ExitCode::SUCCESS,
    })
}
