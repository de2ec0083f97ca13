//! `sabr-sync`: matches tracker frames to encoder samples and publishes matched samples.
//!
//! Subscribes to `sabr/encoders/samples`, `sabr/tracker/frames` and
//! `sabr/calibrator/parameters`; publishes `sabr/sync/matched`. See the library
//! documentation for the method. A ring of the frames without a frame is the tracker's
//! pre-wake before a poll: the sync passes it on to its own subscribers and matches the frame
//! due in advance (`Matcher::warm`), so that the frame itself is matched from the cache.

use anyhow::{bail, Context};
use sabr_msgs::{
    services, EncoderSample, MatchedSample, ParameterSetAnnouncement, TrackerFrame, ENCODER_RATE_HZ,
};
use sabr_node::{monotonic_ns, Exit, NodeRuntime, StallWatch, StatusTimer, STATUS_PERIOD};
use sabr_sync::clock::{ClockConfig, ClockEstimate};
use sabr_sync::encoder_buffer::Pushed;
use sabr_sync::latency::{self, LatencySetting, ParameterSet};
use sabr_sync::matcher::{MatchStats, Matcher, MatcherConfig, Unmatched};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Command line of the sync process.
#[derive(Debug, clap::Parser)]
#[command(name = "sabr-sync", about)]
struct Args {
    /// Tracker latency, ms: the frame clock line (a robust fit of each frame's availability
    /// stamp against its frame counter) minus the exposure time. Replaced by the calibrated latency of a parameter
    /// set (`--params`, or announced on sabr/calibrator/parameters) when it has one.
    #[arg(long, value_name = "MS")]
    latency_ms: Option<f64>,
    /// A robot.toml or calibrated params.toml to start with: counts per revolution for the
    /// encoder angles, and its calibrated latency if it has one [default: the nominal model].
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
    /// Encoder history kept for matching, s.
    #[arg(long, value_name = "S", default_value_t = 3.0)]
    buffer_s: f64,
    /// Most tracker frames in the clock fit window.
    #[arg(long, value_name = "N", default_value_t = 1200)]
    window_frames: usize,
    /// Publish only once the clock line's predicted uncertainty is at most this, µs (once
    /// locked, until it exceeds 1.25 times this).
    #[arg(long, value_name = "US", default_value_t = 200.0)]
    max_clock_uncertainty_us: f64,
    /// Largest gap between the two encoder samples interpolated between, ms.
    #[arg(long, value_name = "MS", default_value_t = 5.0)]
    max_span_ms: f64,
    /// Longest a frame waits for the encoder sample after its exposure, ms.
    #[arg(long, value_name = "MS", default_value_t = 100.0)]
    match_timeout_ms: f64,
    /// Warn when the encoder or tracker stream is silent this long, ms.
    #[arg(long, value_name = "MS", default_value_t = 500.0)]
    stall_ms: f64,
}

/// Index of the encoder stream in [`Watch::streams`].
const ENCODER_STREAM: usize = 0;
/// Index of the tracker stream in [`Watch::streams`].
const TRACKER_STREAM: usize = 1;
/// Longest sleep of the loop without data (retries waiting frames, checks deadlines).
const IDLE: Duration = Duration::from_millis(10);

fn main() -> std::process::ExitCode {
    sabr_node::service_main("sync", run)
}

fn positive_ms(name: &str, ms: f64) -> anyhow::Result<i64> {
    if !(ms.is_finite() && ms > 0.0) {
        bail!("--{name} must be a positive number of milliseconds, got {ms}");
    }
    Ok((ms * 1e6).round() as i64)
}

fn matcher_config(args: &Args) -> anyhow::Result<MatcherConfig> {
    if !(args.buffer_s.is_finite() && args.buffer_s >= 2.0) {
        bail!("--buffer-s must be at least 2 s, got {}", args.buffer_s);
    }
    if args.window_frames < 20 {
        bail!(
            "--window-frames must be at least 20, got {}",
            args.window_frames
        );
    }
    if !(args.max_clock_uncertainty_us.is_finite() && args.max_clock_uncertainty_us > 0.0) {
        bail!(
            "--max-clock-uncertainty-us must be positive, got {}",
            args.max_clock_uncertainty_us
        );
    }
    Ok(MatcherConfig {
        clock: ClockConfig {
            window: args.window_frames,
            ..ClockConfig::default()
        },
        buffer_samples: (args.buffer_s * ENCODER_RATE_HZ).ceil() as usize,
        max_span_ns: positive_ms("max-span-ms", args.max_span_ms)?,
        match_timeout_ns: positive_ms("match-timeout-ms", args.match_timeout_ms)?,
        max_uncertainty_ns: args.max_clock_uncertainty_us * 1e3,
    })
}

fn run(args: &Args, rt: &mut NodeRuntime) -> anyhow::Result<Exit> {
    let config = matcher_config(args)?;
    let stall = Duration::from_nanos(positive_ms("stall-ms", args.stall_ms)? as u64);
    let configured = args
        .latency_ms
        .map(latency::latency_ns)
        .transpose()
        .map_err(|reason| anyhow::anyhow!("--latency-ms: {reason}"))?;
    let mut setting = LatencySetting::new(configured);
    let initial = match &args.params {
        Some(path) => Some(latency::read_parameter_set(path).context("--params")?),
        None => None,
    };
    let counts_per_rev = initial.as_ref().map_or(
        sabr_model::RobotParams::nominal().joints.counts_per_rev,
        |set| set.params.joints.counts_per_rev,
    );
    if let Some(set) = &initial {
        setting.apply(set);
    }
    let mut matcher = Matcher::new(config, counts_per_rev);

    let encoders = rt.subscriber::<EncoderSample>(services::ENCODER_SAMPLES)?;
    // Frames that arrived before this point are the tracker publisher's history: they only
    // teach the clock (a restarted sync locks at once instead of after seconds of new frames).
    let started_ns = monotonic_ns();
    let frames = rt.subscriber_with_history::<TrackerFrame>(
        services::TRACKER_FRAMES,
        services::TRACKER_FRAMES_HISTORY,
    )?;
    let announcements =
        rt.subscriber::<ParameterSetAnnouncement>(services::CALIBRATOR_PARAMETERS)?;
    let matched = rt.publisher::<MatchedSample>(services::SYNC_MATCHED)?;
    match setting.current() {
        Some(latency) => tracing::info!(
            latency_ms = latency.ns as f64 * 1e-6,
            source = ?latency.source,
            "tracker latency"
        ),
        None => tracing::warn!(
            "no tracker latency (--latency-ms, or --params with a calibrated \
             `[calibration] latency_ms`): no frame is matched until a parameter set with \
             one is announced"
        ),
    }
    tracing::info!(
        ?counts_per_rev,
        window_frames = config.clock.window,
        max_clock_uncertainty_us = args.max_clock_uncertainty_us,
        "matching tracker frames to encoder samples"
    );

    let mut watch = Watch::new(stall);
    let mut history_frames = 0_usize;
    // Only the inputs that rang are read: on the real-time core, looking into a subscriber
    // that has nothing (the announcements, at most a few per session) costs cold cache lines
    // on every encoder sample.
    let exit = rt.run_on_data(&[&encoders, &frames, &announcements], IDLE, |ctx| {
        if ctx.woken_by(&announcements) {
            announcements.drain(|a| {
                if let Some(set) = load_announced(&a) {
                    matcher.set_counts_per_rev(set.params.joints.counts_per_rev);
                    if setting.apply(&set) {
                        if let Some(now) = setting.current() {
                            tracing::info!(
                                latency_ms = now.ns as f64 * 1e-6,
                                source = ?now.source,
                                version = a.version,
                                file = %set.path.display(),
                                "using the calibrated tracker latency"
                            );
                        }
                    }
                }
            })?;
        }
        if ctx.woken_by(&encoders) {
            encoders.drain(|sample| {
                watch.streams.feed(ENCODER_STREAM);
                match matcher.push_encoder(sample) {
                    Pushed::AfterGap { lost } => tracing::warn!(
                        lost,
                        seq = sample.seq,
                        "encoder samples lost (sequence gap)"
                    ),
                    Pushed::SequenceRestarted => {
                        tracing::warn!(seq = sample.seq, "encoder sequence restarted")
                    }
                    Pushed::NotAfter { newest_ns } => tracing::warn!(
                        t_ns = sample.t_ns,
                        newest_ns,
                        "encoder sample refused: its time stamp is not after the previous one"
                    ),
                    Pushed::InSequence => {}
                }
            })?;
            // A matched sample goes out at 20 Hz, from memory the core's other work evicts
            // in between; warmed on every encoder sample (1 kHz), its send runs from the cache.
            matched.warm();
        }
        if ctx.woken_by(&frames) {
            let now = monotonic_ns();
            let read = frames.drain(|frame| {
                if frame.arrival_t_ns < started_ns {
                    history_frames += 1;
                    matcher.learn_clock(frame);
                    return;
                }
                if history_frames > 0 {
                    tracing::info!(
                        frames = history_frames,
                        clock = ?matcher.last_clock(),
                        "clock warm-started from the tracker's frame history"
                    );
                    history_frames = 0;
                }
                watch.streams.feed(TRACKER_STREAM);
                let result = matcher.push_frame(frame, setting.current(), now);
                watch.frame_admitted(frame.frame_number, result, matcher.last_clock());
            })?;
            if read == 0 && ctx.woke_on_data() {
                // Rung without a frame: the tracker's pre-wake before a BX poll. Passed on,
                // so that the matched sample's subscribers wake from the cache too, and the
                // frame due is matched in advance, so that its matching runs from the cache.
                matched.prewake()?;
                std::hint::black_box(matcher.warm(setting.current()));
            }
        }
        let mut send = Ok(());
        matcher.poll(monotonic_ns(), |result| match result {
            Ok(mut sample) => {
                if send.is_ok() {
                    sample.sent_t_ns = monotonic_ns();
                    send = matched.send(sample);
                }
            }
            Err((frame_number, reason)) => watch.frame_dropped(frame_number, reason),
        });
        send?;
        watch.check(&matcher.stats());
        Ok::<_, anyhow::Error>(())
    })?;
    let stats = matcher.stats();
    tracing::info!(?stats, "sync stopped");
    Ok(exit)
}

/// Reads an announced parameter file; a bad one is reported and ignored (the previous
/// parameters stay in service).
fn load_announced(announcement: &ParameterSetAnnouncement) -> Option<ParameterSet> {
    let path = Path::new(announcement.path.as_str());
    match latency::read_parameter_set(path) {
        Ok(set) => {
            tracing::info!(
                version = announcement.version,
                file = %path.display(),
                calibrated_latency_ms = set.latency_ns.map(|ns| ns as f64 * 1e-6),
                "parameter set announced"
            );
            Some(set)
        }
        Err(error) => {
            tracing::error!(
                version = announcement.version,
                "announced parameter set rejected, keeping the previous one: {error}"
            );
            None
        }
    }
}

/// Stream deadlines, first-occurrence warnings and the periodic status line.
struct Watch {
    streams: StallWatch<2>,
    locked: bool,
    clock: Option<ClockEstimate>,
    warned_drop: bool,
    warned_no_latency: bool,
    status: StatusTimer,
    last_stats: MatchStats,
}

impl Watch {
    fn new(stall: Duration) -> Self {
        Self {
            streams: StallWatch::new(["encoder", "tracker"], stall),
            locked: false,
            clock: None,
            warned_drop: false,
            warned_no_latency: false,
            status: StatusTimer::new(),
            last_stats: MatchStats::default(),
        }
    }

    fn frame_admitted(
        &mut self,
        frame_number: u32,
        result: Result<(), Unmatched>,
        clock: Option<ClockEstimate>,
    ) {
        self.clock = clock.or(self.clock);
        match result {
            Ok(()) if !self.locked => {
                self.locked = true;
                tracing::info!(
                    frame_number,
                    frames = clock.map(|c| c.frames),
                    spread_us = clock.map(|c| (c.spread_ns * 1e-3).round()),
                    uncertainty_us = clock.map(|c| (c.uncertainty_ns * 1e-3).round()),
                    "frame clock locked: publishing matched samples"
                );
            }
            Ok(()) => {}
            Err(Unmatched::Learning {
                restart: Some(restart),
                ..
            }) => {
                self.locked = false;
                tracing::warn!(frame_number, "frame clock fit starts over: {restart}");
            }
            Err(Unmatched::NoLatency) if !self.warned_no_latency => {
                self.warned_no_latency = true;
                tracing::warn!(
                    frame_number,
                    "no tracker latency known: frames are not matched (counted in the status \
                     line)"
                )
            }
            Err(reason) => tracing::debug!(frame_number, ?reason, "frame not matched"),
        }
    }

    fn frame_dropped(&mut self, frame_number: u32, reason: Unmatched) {
        if self.warned_drop {
            tracing::debug!(frame_number, ?reason, "frame not matched");
        } else {
            self.warned_drop = true;
            tracing::warn!(
                frame_number,
                ?reason,
                "frame not matched (further ones are counted in the status line)"
            );
        }
    }

    fn check(&mut self, stats: &MatchStats) {
        self.streams.check();
        if self.status.due() {
            let last = self.last_stats;
            tracing::info!(
                frames = stats.frames - last.frames,
                matched = stats.matched - last.matched,
                converging = stats.converging - last.converging,
                no_latency = stats.no_latency - last.no_latency,
                timed_out = stats.timed_out - last.timed_out,
                gaps = stats.gaps - last.gaps,
                too_old = stats.too_old - last.too_old,
                encoder_lost = stats.encoder_lost - last.encoder_lost,
                clock_frames = self.clock.map(|c| c.frames),
                clock_spread_us = self.clock.map(|c| (c.spread_ns * 1e-3).round()),
                clock_uncertainty_us = self.clock.map(|c| (c.uncertainty_ns * 1e-3).round()),
                clock_period_ns = self.clock.map(|c| c.period_ns.round()),
                "status (last {} s)",
                STATUS_PERIOD.as_secs()
            );
            self.last_stats = *stats;
        }
    }
}
