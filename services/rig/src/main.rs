//! `sabr-rig`: the simulated hardware of the SABR graph, driven in real time on the host's
//! `CLOCK_MONOTONIC` (robot time 0 = the rig's start, "power-up").
//!
//! - Motors: [`MotorSetpoint`]s in on `sabr/motion/setpoints`, each motor following its
//!   setpoint through a rate-limited first-order servo ([`servo`]) into the true robot of a
//!   `sabr-sim` session (seeded, with injected effects; [`sim_rig`]).
//! - Counters: the quadrature counter register ([`CounterLatch`]) published at
//!   `--counter-rate-hz` on `sabr/rig/counters`, for `sabr-encoders` to sample.
//! - Tracker: an NDI Combined API device on a pseudo-terminal, reachable at the device path
//!   `--pty-link` ([`tracker_port`]); each frame is served once its simulated arrival time
//!   has passed. The truth of every frame goes out as [`RigTruth`] on `sabr/rig/truth`.
//! - `--autoplay`: without a motion node, the rig plays the session plan itself and announces
//!   each finished phase as a [`PhaseMark`] on `sabr/rig/phases` ([`autoplay`]).
//!
//! Readiness is announced once the tracker is served and its first frame has arrived.

mod autoplay;
mod commands;
mod servo;
mod sim_rig;
mod tracker_port;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{bail, Context};
use sabr_msgs::{
    services, CounterLatch, FixedString, MotionStatus, MotorSetpoint, PhaseMark, RigTruth,
};
use sabr_node::{monotonic_ns, Exit, NodeRuntime, Publisher, StatusTimer, Subscriber};
use sabr_sim::{Session, SimConfig, SimEffect};

use autoplay::{Autoplay, StartGate};
use commands::{tip_phase_running, SetpointQueue, TipSphere};
use sim_rig::{Capture, SimRig};
use tracker_port::{sim_frame, SharedFrames, TrackerPort};

/// How long after the plan's end autoplay announces the graph done: the last frames still
/// have to arrive (latency) and pass through the graph.
const FINISH_TAIL_NS: i64 = 1_000_000_000;
/// Longest wait for the first tracker frame to arrive before readiness.
const FIRST_FRAME_TIMEOUT: Duration = Duration::from_secs(5);

/// Command line of the simulated rig.
#[derive(Debug, clap::Parser)]
#[command(name = "sabr-rig", about)]
struct Args {
    /// Seed of the true robot, the plan and the sensor noise (as `sabr sim record --seed`).
    #[arg(long, value_name = "N", default_value_t = 1)]
    seed: u64,
    /// Effect injected into the true robot or tracker (repeatable), same syntax as
    /// `sabr sim record --effect`: `ripple:joint=J,harmonic=H,amplitude=RAD[,phase=RAD]`,
    /// `backlash:joint=J,width=RAD`, `link:link=NAME,delta=MM`, `compliance:joint=J,gain=RAD`,
    /// `tilt:joint=J,axis=1|2,angle=RAD`, `latency:ms=MS`,
    /// `thermal:joint=J,amplitude=RAD[,tau_s=S]`, `thermal:link=NAME,delta=MM[,tau_s=S]`,
    /// `sag:mm=MM`, `clockdrift:ppm=PPM`.
    #[arg(long = "effect", value_name = "SPEC", value_parser = parse_effect)]
    effects: Vec<SimEffect>,
    /// Multiplies the phase durations of the session plan (1 ≈ 5 minutes).
    #[arg(long, value_name = "F", default_value_t = 1.0)]
    duration_scale: f64,
    /// Device path of the tracker: a symlink to the pseudo-terminal, created at start and
    /// removed at exit [default: $SABR_RUN_DIR/polaris-tty].
    #[arg(long, value_name = "PATH")]
    pty_link: Option<PathBuf>,
    /// Rate at which the counter register is latched and published, Hz.
    #[arg(long, value_name = "HZ", default_value_t = 2000.0)]
    counter_rate_hz: f64,
    /// Time constant of the motor position servos, ms.
    #[arg(long, value_name = "MS", default_value_t = 5.0)]
    servo_tau_ms: f64,
    /// Top speed of the motors, rad/s of the motor shaft.
    #[arg(long, value_name = "RAD_PER_S", default_value_t = 50.0)]
    servo_max_speed: f64,
    /// Play the session plan (homing, excitation, tip, validation) instead of following
    /// motor setpoints, announcing phases on `sabr/rig/phases`.
    #[arg(long)]
    autoplay: bool,
    /// Start the plan only once this node announced readiness (repeatable).
    #[arg(long, value_name = "NODE", requires = "autoplay")]
    autoplay_after: Vec<String>,
    /// Start the plan this long after the nodes of `--autoplay-after` are ready, s.
    #[arg(long, value_name = "S", default_value_t = 0.0, requires = "autoplay")]
    autoplay_delay_s: f64,
    /// Announce the graph's job done 1 s after the plan ends (the rig then holds the last pose
    /// until it is stopped).
    #[arg(long, requires = "autoplay")]
    finish_when_done: bool,
    /// When the tip sphere is on the needle.
    #[arg(long, value_enum, default_value_t = TipSphere::Auto)]
    tip_sphere: TipSphere,
}

fn parse_effect(spec: &str) -> Result<SimEffect, sabr_sim::EffectSpecError> {
    spec.parse()
}

fn main() -> ExitCode {
    sabr_node::service_main("rig", run)
}

fn run(args: &Args, rt: &mut NodeRuntime) -> anyhow::Result<Exit> {
    if !(args.counter_rate_hz.is_finite() && (1000.0..=20_000.0).contains(&args.counter_rate_hz)) {
        bail!(
            "--counter-rate-hz {}: must be between 1000 and 20000",
            args.counter_rate_hz
        );
    }
    if !(args.autoplay_delay_s.is_finite() && args.autoplay_delay_s >= 0.0) {
        bail!("--autoplay-delay-s {}: must be ≥ 0", args.autoplay_delay_s);
    }
    let link = sabr_node::in_run_dir(args.pty_link.as_deref(), "polaris-tty", "--pty-link")?;
    let mut config = SimConfig::new(args.seed);
    config.duration_scale = args.duration_scale;
    config.effects = args.effects.clone();
    let session = Session::new(&config).context("cannot build the simulated session")?;
    let sim = SimRig::new(&session, args.servo_tau_ms * 1e-3, args.servo_max_speed)
        .map_err(anyhow::Error::msg)
        .context("--servo-tau-ms / --servo-max-speed")?;

    let mode = if args.autoplay {
        let gate = StartGate::new(
            rt.domain(),
            &args.autoplay_after,
            Duration::from_secs_f64(args.autoplay_delay_s),
        )?;
        Mode::Autoplay(Box::new(Autoplay::new(session.plan().clone())), gate)
    } else {
        Mode::Setpoints(SetpointQueue::default())
    };
    let frames = SharedFrames::default();
    let port = TrackerPort::start(&link, frames.clone())?;
    tracing::info!(
        device = %link.display(),
        pty = %port.slave_path().display(),
        "NDI tracker served"
    );
    let mut live = Live {
        ports: Ports::open(rt)?,
        sim,
        origin_ns: monotonic_ns(),
        mode,
        tip: args.tip_sphere,
        tip_from_motion: false,
        frames,
        counts: Counters::default(),
        status: StatusTimer::new(),
        plan_over_logged: false,
    };
    tracing::info!(
        seed = args.seed,
        effects = args.effects.len(),
        autoplay = args.autoplay,
        "simulated rig powered up"
    );

    let period = Duration::from_secs_f64(1.0 / args.counter_rate_hz);
    // Readiness only once the tracker has a frame to give: no empty frame 0 for the driver.
    let warm_up_end = monotonic_ns() + FIRST_FRAME_TIMEOUT.as_nanos() as i64;
    loop {
        let now = monotonic_ns();
        live.tick(now)?;
        if live.first_frame_arrived(now) {
            break;
        }
        if now > warm_up_end {
            bail!("no tracker frame arrived within {FIRST_FRAME_TIMEOUT:?} of power-up");
        }
        if !rt.sleep(period) {
            port.finish()?;
            return Ok(Exit::Signal);
        }
    }
    rt.ready();
    let finish_when_done = args.finish_when_done;
    let mut done_announced = false;
    // After announcing the job done the rig goes on (holding the last pose, serving counters
    // and tracker) until the launcher stops the graph, so the others stop in order.
    let exit = loop {
        let exit = rt.run_loop(period, |ctx| {
            let over = live.tick(monotonic_ns())?;
            if !port.is_serving() {
                bail!("the tracker's pseudo-terminal is no longer served");
            }
            if over && finish_when_done && !done_announced {
                done_announced = true;
                ctx.finish_graph();
            }
            Ok::<_, anyhow::Error>(())
        });
        match exit {
            Ok(Exit::Done) => tracing::info!("job done announced; running until stopped"),
            other => break other,
        }
    };
    let stats = port.finish();
    tracing::info!(
        robot_s = live.sim.time_ns() as f64 * 1e-9,
        latches = live.counts.latches,
        frames = live.counts.frames,
        dropped_frames = live.counts.dropped_frames,
        ignored_setpoints = live.counts.ignored_setpoints,
        refused_setpoints = live.counts.refused_setpoints,
        "rig stopped"
    );
    let stats = stats?;
    tracing::info!(
        bytes_in = stats.bytes_in,
        bytes_out = stats.bytes_out,
        dropped_replies = stats.dropped_replies,
        "tracker port closed"
    );
    exit
}

/// What moves the motors.
enum Mode {
    /// The session plan, started once the gate opens.
    Autoplay(Box<Autoplay>, StartGate),
    /// `motion`'s setpoints.
    Setpoints(SetpointQueue),
}

/// The rig's iceoryx2 ports.
struct Ports {
    counters: Publisher<CounterLatch>,
    truth: Publisher<RigTruth>,
    phases: Publisher<PhaseMark>,
    setpoints: Subscriber<MotorSetpoint>,
    motion_status: Subscriber<MotionStatus>,
}

impl Ports {
    fn open(rt: &NodeRuntime) -> Result<Self, sabr_node::NodeError> {
        Ok(Ports {
            counters: rt.publisher(services::RIG_COUNTERS)?,
            truth: rt.publisher(services::RIG_TRUTH)?,
            phases: rt.publisher(services::RIG_PHASES)?,
            setpoints: rt.subscriber(services::MOTION_SETPOINTS)?,
            motion_status: rt.subscriber(services::MOTION_STATUS)?,
        })
    }
}

/// Counters of what the rig did (also the sequence numbers of its messages).
#[derive(Debug, Default)]
struct Counters {
    latches: u64,
    frames: u64,
    dropped_frames: u64,
    phases: u64,
    ignored_setpoints: u64,
    refused_setpoints: u64,
    first_arrival_ns: Option<i64>,
}

/// The running rig.
struct Live {
    ports: Ports,
    sim: SimRig,
    /// Host time of power-up (robot time 0), ns.
    origin_ns: i64,
    mode: Mode,
    tip: TipSphere,
    tip_from_motion: bool,
    frames: SharedFrames,
    counts: Counters,
    status: StatusTimer,
    plan_over_logged: bool,
}

impl Live {
    /// Advances the rig to host time `now`, publishing counters, truth and phases; true once
    /// an autoplayed plan is over (plus the tail).
    fn tick(&mut self, now: i64) -> anyhow::Result<bool> {
        let t = now - self.origin_ns;
        self.read_commands()?;
        let target = match &mut self.mode {
            Mode::Autoplay(autoplay, gate) => {
                if autoplay.start_ns().is_none() && gate.is_open()? {
                    autoplay.start(t);
                    tracing::info!(robot_s = t as f64 * 1e-9, "autoplay: session plan started");
                }
                self.sim.counts_for_joints(&autoplay.joints_at(t))
            }
            Mode::Setpoints(queue) => queue
                .current_at(now)
                .unwrap_or_else(|| self.sim.true_counts()),
        };
        let (mode, tip, from_motion) = (&self.mode, self.tip, self.tip_from_motion);
        let tip_attached = |t_ns: i64| match (tip, mode) {
            (TipSphere::Always, _) => true,
            (TipSphere::Never, _) => false,
            (TipSphere::Auto, Mode::Autoplay(autoplay, _)) => autoplay.tip_attached(t_ns),
            (TipSphere::Auto, Mode::Setpoints(_)) => from_motion,
        };
        let captures = self.sim.advance(t, &target, tip_attached)?;
        for capture in captures {
            self.publish_frame(capture)?;
        }
        self.counts.latches += 1;
        self.ports.counters.send(CounterLatch {
            seq: self.counts.latches,
            latch_t_ns: now,
            counts: self.sim.counts(),
        })?;
        self.log_status(t);
        self.autoplay_progress(t)
    }

    fn read_commands(&mut self) -> anyhow::Result<()> {
        let counts = &mut self.counts;
        match &mut self.mode {
            Mode::Setpoints(queue) => {
                self.ports.setpoints.drain(|setpoint| {
                    if let Err(error) = queue.push(setpoint) {
                        counts.refused_setpoints += 1;
                        tracing::error!("{error}");
                    }
                })?;
            }
            Mode::Autoplay(..) => {
                let ignored = self.ports.setpoints.drain(|_| {})? as u64;
                if ignored > 0 && counts.ignored_setpoints == 0 {
                    tracing::warn!("motor setpoints arrive while autoplaying the plan: ignored");
                }
                counts.ignored_setpoints += ignored;
            }
        }
        if let Some(status) = self.ports.motion_status.latest()? {
            self.tip_from_motion = tip_phase_running(&status);
        }
        Ok(())
    }

    fn publish_frame(&mut self, capture: Capture) -> anyhow::Result<()> {
        let exposure = capture.frame.exposure;
        self.counts.frames += 1;
        self.ports.truth.send(RigTruth {
            seq: self.counts.frames,
            frame_number: exposure.frame,
            exposure_t_ns: self.origin_ns + exposure.exposure_ns,
            joints_rad: capture.joints,
            counts: capture.counts,
            tip_mm: capture.tip_mm,
            direction: capture.direction,
        })?;
        match capture.frame.arrival_ns {
            Some(arrival) => {
                let arrival = self.origin_ns + arrival;
                self.counts.first_arrival_ns.get_or_insert(arrival);
                self.frames.lock().push(arrival, sim_frame(&capture.frame));
            }
            None => self.counts.dropped_frames += 1,
        }
        Ok(())
    }

    fn first_frame_arrived(&self, now: i64) -> bool {
        self.counts.first_arrival_ns.is_some_and(|t| t <= now)
    }

    /// Announces finished phases; true once the plan is over (plus the tail).
    fn autoplay_progress(&mut self, t: i64) -> anyhow::Result<bool> {
        let Mode::Autoplay(autoplay, _) = &mut self.mode else {
            return Ok(false);
        };
        for phase in autoplay.finished_phases(t) {
            self.counts.phases += 1;
            let mark = PhaseMark {
                seq: self.counts.phases,
                t_start_ns: self.origin_ns + phase.start_ns,
                t_end_ns: self.origin_ns + phase.end_ns,
                phase: FixedString::new(phase.name)
                    .with_context(|| format!("phase name {:?}", phase.name))?,
            };
            self.ports.phases.send(mark)?;
            tracing::info!(
                phase = phase.name,
                duration_s = (phase.end_ns - phase.start_ns) as f64 * 1e-9,
                "autoplay: phase finished"
            );
        }
        let over = autoplay
            .end_ns()
            .is_some_and(|end| t >= end + FINISH_TAIL_NS);
        if over && !self.plan_over_logged {
            self.plan_over_logged = true;
            tracing::info!("autoplay: session plan over; holding the last pose");
        }
        Ok(over)
    }

    fn log_status(&mut self, t: i64) {
        if self.status.due() {
            tracing::info!(
                robot_s = (t as f64 * 1e-9).round(),
                counts = ?self.sim.counts(),
                frames = self.counts.frames,
                dropped_frames = self.counts.dropped_frames,
                "rig status"
            );
        }
    }
}
