//! The measuring side of a ping-pong baseline: spawns `sabr-pong` (beside this executable) as
//! a separate process, times round trips, then watches the waiting pong's CPU use.

use super::cpu::{measure_cpu_share, CpuShare};
use super::doorbell::DoorbellEnd;
use super::futex::FutexEnd;
use super::graph::placed;
use super::iox::{IoxEnd, Wait};
use super::payload::{baseline_name, paced_name, Payload, Transport};
use super::stats::Measurement;
use super::uds::{SocketFile, UdsEnd};
use anyhow::{bail, Context};
use sabr_launcher::placement::Placement;
use sabr_node::msgs::{
    EncoderSample, IkRequest, IkResponse, MatchedSample, MotorSetpoint, TrackerFrame,
};
use sabr_node::{Domain, Message};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Longest wait of the pong for the next message before it gives up (the measuring process
/// hung or died); longer than any idle window.
pub const PEER_TIMEOUT: Duration = Duration::from_secs(60);

/// Longest round trip before the measuring side gives up (the pong hung or died); the worst
/// seen on a heavily loaded 2-core machine was below 0.1 s.
const ROUND_TRIP_TIMEOUT: Duration = Duration::from_secs(5);

/// Longest wait for the pong process to start up (and to exit at the end).
const STARTUP_TIMEOUT: Duration = Duration::from_secs(20);

/// How many round trips one ping-pong runs, and how long the idle pong is watched.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// Round trips run first and not recorded (caches, page faults, connection set-up).
    pub warmup: u64,
    /// Round trips recorded.
    pub samples: u64,
    /// Window over which the pong's CPU use is measured while it waits for a message.
    pub idle_window: Duration,
    /// Pause after each recorded round trip: zero back to back (caches and wake-up paths
    /// hot), else the period at which the live graph sends the payload, so the round trip
    /// runs as cold as the hop it stands for. A paced row is named by [`paced_name`].
    pub pause: Duration,
}

impl Plan {
    /// Messages the pong answers: warm-up, samples and the final one that releases it.
    pub fn pong_count(&self) -> u64 {
        self.warmup + self.samples + 1
    }
}

/// What one ping-pong measured.
pub struct PingPong {
    /// Round-trip times (ns), named `<transport>/<payload>`.
    pub round_trips: Measurement,
    /// CPU use of the pong process while it waited for a message that did not come.
    pub pong_idle: CpuShare,
}

/// The two iceoryx2 service names of a ping-pong: (ping, pong).
pub fn service_names(transport: Transport, payload: Payload) -> (String, String) {
    let base = format!("sabr-bench/{}", baseline_name(transport, payload));
    (format!("{base}/ping"), format!("{base}/pong"))
}

/// Where the two processes of a ping-pong run: the measuring side (a thread of the bench)
/// and the pong process.
#[derive(Debug, Clone, Default)]
pub struct Pinning {
    /// Placement of the measuring thread.
    pub ping: Placement,
    /// Placement of the pong process.
    pub pong: Placement,
}

/// Runs one ping-pong of `payload` over `transport` against a freshly spawned pong process,
/// the two placed as `pinning` says (the measuring side on a thread of its own).
/// iceoryx2 services live in `domain`; the Unix socket is created in `socket_dir`.
pub fn run(
    transport: Transport,
    payload: Payload,
    plan: &Plan,
    pinning: &Pinning,
    domain: &Domain,
    socket_dir: &Path,
) -> anyhow::Result<PingPong> {
    placed(&pinning.ping, || {
        run_here(transport, payload, plan, &pinning.pong, domain, socket_dir)
    })
}

/// [`run`] on the calling thread.
fn run_here(
    transport: Transport,
    payload: Payload,
    plan: &Plan,
    pong: &Placement,
    domain: &Domain,
    socket_dir: &Path,
) -> anyhow::Result<PingPong> {
    let peer = Peer {
        transport,
        payload,
        plan,
        placement: pong,
    };
    match transport {
        Transport::IoxPoll | Transport::IoxEvent => match payload {
            Payload::EncoderSample => run_iox::<EncoderSample, EncoderSample>(&peer, domain),
            Payload::TrackerFrame => run_iox::<TrackerFrame, MatchedSample>(&peer, domain),
            Payload::Ik => run_iox::<IkRequest, IkResponse>(&peer, domain),
            Payload::MotorSetpoint => run_iox::<MotorSetpoint, MotorSetpoint>(&peer, domain),
        },
        Transport::Doorbell => match payload {
            Payload::EncoderSample => run_doorbell::<EncoderSample, EncoderSample>(&peer, domain),
            Payload::TrackerFrame => run_doorbell::<TrackerFrame, MatchedSample>(&peer, domain),
            Payload::Ik => run_doorbell::<IkRequest, IkResponse>(&peer, domain),
            Payload::MotorSetpoint => run_doorbell::<MotorSetpoint, MotorSetpoint>(&peer, domain),
        },
        Transport::Futex | Transport::FutexCross => run_futex(&peer, domain),
        Transport::Uds => run_uds(&peer, socket_dir),
    }
}

/// The pong process a ping-pong starts: what it runs and where.
struct Peer<'a> {
    transport: Transport,
    payload: Payload,
    plan: &'a Plan,
    placement: &'a Placement,
}

impl Peer<'_> {
    /// Starts the pong with `extra` arguments and places it.
    fn spawn(&self, extra: &[&str]) -> anyhow::Result<PongProcess> {
        let process = PongProcess::spawn(self.transport, self.payload, self.plan, extra)?;
        self.placement
            .prepare()
            .map_err(anyhow::Error::msg)?
            .apply_to(process.pid())
            .with_context(|| format!("cannot place the pong process: {}", self.placement))?;
        Ok(process)
    }

    /// Runs the plan against the started pong (see [`measure`]).
    fn measure(
        &self,
        process: PongProcess,
        round_trip: impl FnMut(Instant) -> anyhow::Result<()>,
    ) -> anyhow::Result<PingPong> {
        measure(self.transport, self.payload, self.plan, process, round_trip)
    }
}

/// The iceoryx2 wait mode of a transport.
pub fn wait_mode(transport: Transport) -> anyhow::Result<Wait> {
    match transport {
        Transport::IoxPoll => Ok(Wait::BusyPoll),
        Transport::IoxEvent => Ok(Wait::Event),
        other => bail!("the {} transport is not stock iceoryx2", other.name()),
    }
}

/// Waits until `ready` says the pong opened its side, or fails if it exited or took too long.
fn await_peer(process: &mut PongProcess, ready: impl Fn() -> bool) -> anyhow::Result<()> {
    let started = Instant::now();
    while !ready() {
        process.check_running()?;
        if started.elapsed() > STARTUP_TIMEOUT {
            bail!("the pong process did not open its side in {STARTUP_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    Ok(())
}

fn run_iox<Req: Message + Default, Resp: Message>(
    peer: &Peer,
    domain: &Domain,
) -> anyhow::Result<PingPong> {
    let (ping, pong) = service_names(peer.transport, peer.payload);
    let end = IoxEnd::<Req, Resp>::open(domain, &ping, &pong, wait_mode(peer.transport)?)?;
    let mut process = peer.spawn(&["--domain", domain.as_str()])?;
    await_peer(&mut process, || end.peer_ready())?;
    peer.measure(process, |deadline| {
        end.send(Req::default())?;
        end.receive(deadline).map(drop)
    })
}

fn run_doorbell<Req: Message + Default, Resp: Message>(
    peer: &Peer,
    domain: &Domain,
) -> anyhow::Result<PingPong> {
    let (ping, pong) = service_names(peer.transport, peer.payload);
    let end = DoorbellEnd::<Req, Resp>::open(domain, "bench-ping", &ping, &pong)?;
    let mut process = peer.spawn(&["--domain", domain.as_str()])?;
    await_peer(&mut process, || end.peer_ready())?;
    peer.measure(process, |deadline| {
        end.send(Req::default())?;
        end.receive(deadline).map(drop)
    })
}

fn run_futex(peer: &Peer, domain: &Domain) -> anyhow::Result<PingPong> {
    let name = futex_segment(domain, peer.transport, peer.payload);
    let mut end = FutexEnd::create(&name)?;
    let process = peer.spawn(&["--domain", domain.as_str()])?;
    peer.measure(process, |deadline| {
        end.send()?;
        end.receive(end.sent(), deadline)
    })
}

/// The shared-memory segment of a futex ping-pong (unique per domain, transport and payload).
pub fn futex_segment(domain: &Domain, transport: Transport, payload: Payload) -> String {
    format!("{domain}-{}-{}", transport.name(), payload.name())
}

fn run_uds(peer: &Peer, socket_dir: &Path) -> anyhow::Result<PingPong> {
    let path = socket_dir.join(format!(
        "sabr-bench-{}-{}.sock",
        std::process::id(),
        peer.payload.name()
    ));
    let socket = SocketFile::bind(&path)?;
    let socket_arg = socket.path().to_string_lossy().into_owned();
    let mut process = peer.spawn(&["--socket", &socket_arg])?;
    let stream = socket.accept(STARTUP_TIMEOUT, || process.check_running())?;
    let mut end = UdsEnd::new(
        stream,
        peer.payload.request_bytes(),
        peer.payload.response_bytes(),
        ROUND_TRIP_TIMEOUT,
    )?;
    peer.measure(process, |_| {
        end.send()?;
        end.receive()
    })
}

/// Runs the plan's round trips with `round_trip` (given its deadline), records the timed
/// ones, measures the pong's idle CPU use, then releases the pong and checks it exited well.
fn measure(
    transport: Transport,
    payload: Payload,
    plan: &Plan,
    peer: PongProcess,
    mut round_trip: impl FnMut(Instant) -> anyhow::Result<()>,
) -> anyhow::Result<PingPong> {
    let name = if plan.pause.is_zero() {
        baseline_name(transport, payload)
    } else {
        paced_name(transport, payload)
    };
    for _ in 0..plan.warmup {
        round_trip(Instant::now() + ROUND_TRIP_TIMEOUT)
            .with_context(|| format!("{name}: warm-up"))?;
    }
    let mut round_trips = Measurement::new(name.clone(), "ns");
    for index in 0..plan.samples {
        let start = Instant::now();
        round_trip(start + ROUND_TRIP_TIMEOUT)
            .with_context(|| format!("{name}: round trip {index}"))?;
        round_trips.record_duration(start.elapsed())?;
        std::thread::sleep(plan.pause);
    }
    let pong_idle = measure_cpu_share(peer.pid(), plan.idle_window)
        .with_context(|| format!("{name}: idle CPU of the pong process"))?;
    round_trip(Instant::now() + ROUND_TRIP_TIMEOUT)
        .with_context(|| format!("{name}: last round trip"))?;
    peer.finish()?;
    Ok(PingPong {
        round_trips,
        pong_idle,
    })
}

/// The `sabr-pong` executable beside the running one (cargo builds them side by side).
fn pong_executable() -> anyhow::Result<std::path::PathBuf> {
    let exe = std::env::current_exe().context("cannot locate the running executable")?;
    let pong = exe.with_file_name("sabr-pong");
    if !pong.is_file() {
        bail!(
            "{} not found: build it with `cargo build --release -p sabr-lab`",
            pong.display()
        );
    }
    Ok(pong)
}

/// A spawned pong process; killed if still running when dropped (on an error path).
struct PongProcess {
    child: Child,
}

impl PongProcess {
    fn spawn(
        transport: Transport,
        payload: Payload,
        plan: &Plan,
        extra: &[&str],
    ) -> anyhow::Result<Self> {
        let exe = pong_executable()?;
        let child = Command::new(&exe)
            .args(["--transport", transport.name()])
            .args(["--payload", payload.name()])
            .args(["--count", &plan.pong_count().to_string()])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot start {}", exe.display()))?;
        Ok(Self { child })
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    /// An error if the pong already exited.
    fn check_running(&mut self) -> anyhow::Result<()> {
        match self
            .child
            .try_wait()
            .context("cannot query the pong process")?
        {
            None => Ok(()),
            Some(status) => bail!("the pong process exited early ({status})"),
        }
    }

    /// Waits for the pong to exit after its last message; an error unless it succeeded.
    fn finish(mut self) -> anyhow::Result<()> {
        let started = Instant::now();
        loop {
            if let Some(status) = self
                .child
                .try_wait()
                .context("cannot query the pong process")?
            {
                if status.success() {
                    return Ok(());
                }
                bail!("the pong process failed ({status})");
            }
            if started.elapsed() > STARTUP_TIMEOUT {
                bail!("the pong process did not exit in {STARTUP_TIMEOUT:?}");
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

impl Drop for PongProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            // Best effort on an error path: the process is ours and may be stuck.
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}
