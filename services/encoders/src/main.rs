//! `sabr-encoders`: samples the rig's quadrature counter register (`sabr/rig/counters`) at
//! 1 kHz on a drift-free schedule of absolute deadlines, stamps each reading with the host's
//! `CLOCK_MONOTONIC` and publishes it as an [`EncoderSample`] with a sequence number on
//! `sabr/encoders/samples`.
//!
//! A register that stops updating is a stalled or dead rig: its counts are not published as
//! fresh. The node logs it, publishes nothing while it lasts, and leaves with failure (its
//! lifecycle going to `Stopping`) if it lasts `--rig-timeout-ms`.

mod sampler;

use std::process::ExitCode;
use std::time::Duration;

use anyhow::bail;
use sabr_msgs::{services, CounterLatch, EncoderSample, ENCODER_RATE_HZ};
use sabr_node::{monotonic_ns, Deadline, Exit, NodeRuntime, StatusTimer};

use sampler::{Reading, Sampler};

/// Longest single wait for the first latch before checking for a stop request.
const WAIT_SLICE: Duration = Duration::from_millis(100);

/// Command line of the encoder sampler.
#[derive(Debug, clap::Parser)]
#[command(name = "sabr-encoders", about)]
struct Args {
    /// Sampling rate, Hz.
    #[arg(long, value_name = "HZ", default_value_t = ENCODER_RATE_HZ)]
    rate_hz: f64,
    /// A register latch older than this is stale and not published, ms.
    #[arg(long, value_name = "MS", default_value_t = 10.0)]
    stale_ms: f64,
    /// Leave with failure when no latch arrives, or the register stays stale, this long, ms.
    #[arg(long, value_name = "MS", default_value_t = 2000)]
    rig_timeout_ms: u64,
}

fn main() -> ExitCode {
    sabr_node::service_main("encoders", run)
}

fn run(args: &Args, rt: &mut NodeRuntime) -> anyhow::Result<Exit> {
    if !(args.rate_hz.is_finite() && (1.0..=10_000.0).contains(&args.rate_hz)) {
        bail!("--rate-hz {}: must be between 1 and 10000", args.rate_hz);
    }
    if !(args.stale_ms.is_finite() && args.stale_ms > 0.0) {
        bail!("--stale-ms {}: must be a positive number", args.stale_ms);
    }
    let rig_timeout = Duration::from_millis(args.rig_timeout_ms);
    let rig_timeout_ns = rig_timeout.as_nanos() as i64;
    let register = rt.subscriber::<CounterLatch>(services::RIG_COUNTERS)?;
    let out = rt.publisher::<EncoderSample>(services::ENCODER_SAMPLES)?;
    let mut sampler = Sampler::new((args.stale_ms * 1e6) as i64);

    // Ready only once the rig's register is there.
    let first = Deadline::new(rig_timeout);
    loop {
        if let Some(latch) = register.recv_timeout(first.remaining().min(WAIT_SLICE))? {
            sampler.latch(latch);
            break;
        }
        if !rt.keep_running() {
            return Ok(Exit::Signal);
        }
        if first.expired() {
            bail!(
                "no counter latch from the rig on {} within {rig_timeout:?}",
                services::RIG_COUNTERS
            );
        }
    }

    let period = Duration::from_secs_f64(1.0 / args.rate_hz);
    let mut stats = Stats::default();
    let mut status = StatusTimer::new();
    let exit = rt.run_loop(period, |ctx| {
        register.drain(|latch| sampler.latch(latch))?;
        let now = monotonic_ns();
        match sampler.read(now) {
            Reading::Sample(sample) => {
                out.send(sample)?;
                stats.sample(sampler.age_ns(now).unwrap_or(0), now);
                if let Some(since) = stats.stale_since.take() {
                    tracing::info!(
                        after_ms = (now - since) as f64 * 1e-6,
                        stale_instants = stats.stale_instants,
                        "counter register fresh again"
                    );
                }
            }
            Reading::Stale { age_ns, latch_seq } => {
                stats.stale_instants += 1;
                if stats.stale_since.is_none() {
                    stats.stale_since = Some(now);
                    tracing::warn!(
                        latch_seq,
                        age_ms = age_ns as f64 * 1e-6,
                        "the rig's counter register is stale (rig stalled or dead): not sampling"
                    );
                }
                if age_ns > rig_timeout_ns {
                    bail!(
                        "the rig's counter register has not changed for {:.0} ms (latch {latch_seq}): \
                         the rig is dead",
                        age_ns as f64 * 1e-6
                    );
                }
            }
            Reading::NoData => bail!("the counter register lost its first latch"),
        }
        stats.missed_periods = ctx.missed_periods();
        if status.due() {
            stats.log();
        }
        Ok::<_, anyhow::Error>(())
    })?;
    stats.log();
    Ok(exit)
}

/// What the sampler did since the last status line.
#[derive(Debug, Default)]
struct Stats {
    samples: u64,
    max_age_ns: i64,
    stale_instants: u64,
    stale_since: Option<i64>,
    last_sample_ns: Option<i64>,
    max_gap_ns: i64,
    /// Loop periods missed since start, as counted by the run loop.
    missed_periods: u64,
}

impl Stats {
    /// A sample published at `now` from a latch `age_ns` old.
    fn sample(&mut self, age_ns: i64, now: i64) {
        self.samples += 1;
        self.max_age_ns = self.max_age_ns.max(age_ns);
        if let Some(last) = self.last_sample_ns.replace(now) {
            self.max_gap_ns = self.max_gap_ns.max(now - last);
        }
    }

    fn log(&mut self) {
        tracing::info!(
            samples = self.samples,
            missed_periods = self.missed_periods,
            stale_instants = self.stale_instants,
            max_register_age_us = self.max_age_ns / 1000,
            max_gap_us = self.max_gap_ns / 1000,
            "encoder sampling"
        );
        self.max_age_ns = 0;
        self.max_gap_ns = 0;
    }
}
