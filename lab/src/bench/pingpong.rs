//! The measuring side of a ping-pong baseline: spawns `sabr-pong` (beside this executable) as
//! a separate process, times round trips (several ping-pongs taking turns), then watches the
//! waiting pong's CPU use.

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

/// How many round trips one ping-pong runs, in how many rounds, and how long the idle pong
/// is watched.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// Round trips run first and not recorded (caches, page faults, connection set-up).
    pub warmup: u64,
    /// Round trips recorded.
    pub samples: u64,
    /// Slices the recorded round trips are split into (0 counts as 1). Ping-pongs run
    /// together take turns slice by slice (see [`run`]), so a change of the machine's speed
    /// during the run falls on all of them alike; each slice starts with `warmup / rounds`
    /// unrecorded round trips (the other ping-pongs' slices ran in between).
    pub rounds: u64,
    /// Window over which the pong's CPU use is measured while it waits for a message;
    /// `None`: not measured.
    pub idle_window: Option<Duration>,
    /// Pause before each burst of round trips: zero back to back (caches and wake-up paths
    /// hot), else the period at which the live graph sends the payload, so the round trips run
    /// as cold as the hop they stand for. A paced row is named by [`paced_name`].
    pub pause: Duration,
    /// Round trips back to back after each pause (0 counts as 1): as many as the live graph
    /// sends in one period ([`Payload::live_burst`]).
    pub burst: u64,
}

impl Plan {
    /// The name of the row of `transport` and `payload` this plan measures:
    /// `<transport>/<payload>` back to back, [`paced_name`] paced.
    pub fn row_name(&self, transport: Transport, payload: Payload) -> String {
        if self.pause.is_zero() {
            baseline_name(transport, payload)
        } else {
            paced_name(transport, payload)
        }
    }

    /// Whether the round trip `index` (from 0) of a run waits for the pause first: the first
    /// of every burst.
    fn pauses_before(&self, index: u64) -> bool {
        index.is_multiple_of(self.burst.max(1))
    }

    /// Slices, at least one.
    fn slices(&self) -> u64 {
        self.rounds.max(1)
    }

    /// Unrecorded round trips at the start of each slice.
    fn slice_warmup(&self) -> u64 {
        self.warmup / self.slices()
    }

    /// Recorded round trips of slice `round` (the samples spread as evenly as they go).
    fn slice_samples(&self, round: u64) -> u64 {
        let slices = self.slices();
        self.samples / slices + u64::from(round < self.samples % slices)
    }

    /// Messages the pong answers: warm-up, each slice's warm-up and samples, and the final
    /// one that releases it.
    pub fn pong_count(&self) -> u64 {
        self.warmup + self.slices() * self.slice_warmup() + self.samples + 1
    }
}

/// What one ping-pong measured.
pub struct PingPong {
    /// Round-trip times (ns), named `<transport>/<payload>`.
    pub round_trips: Measurement,
    /// CPU use of the pong process while it waited for a message that did not come (if the
    /// plan has an idle window).
    pub pong_idle: Option<CpuShare>,
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

/// Runs the ping-pongs of `rows` (transport, payload) together, each against a freshly
/// spawned pong process, all placed as `pinning` says (the measuring side on a thread of its
/// own): every pong is started and warmed up, then the rows take turns for `plan.rounds`
/// slices (the order rotating each round), then each pong's idle CPU is measured and the
/// pong released. Returns one result per row, in the order of `rows`; a row that fails
/// leaves the others running. iceoryx2 services live in `domain`; Unix sockets are created
/// in `socket_dir`.
pub fn run(
    rows: &[(Transport, Payload)],
    plan: &Plan,
    pinning: &Pinning,
    domain: &Domain,
    socket_dir: &Path,
) -> Vec<anyhow::Result<PingPong>> {
    let placed_run = placed(&pinning.ping, || {
        Ok(run_here(rows, plan, &pinning.pong, domain, socket_dir))
    });
    match placed_run {
        Ok(results) => results,
        Err(error) => rows
            .iter()
            .map(|_| Err(anyhow::anyhow!("{error:#}")))
            .collect(),
    }
}

/// [`run`] on the calling thread.
fn run_here(
    rows: &[(Transport, Payload)],
    plan: &Plan,
    pong: &Placement,
    domain: &Domain,
    socket_dir: &Path,
) -> Vec<anyhow::Result<PingPong>> {
    let mut sessions: Vec<anyhow::Result<Session>> = rows
        .iter()
        .map(|&(transport, payload)| {
            let peer = Peer {
                transport,
                payload,
                plan,
                placement: pong,
            };
            let mut session = start(&peer, domain, socket_dir)?;
            session.run(plan.warmup, false)?;
            Ok(session)
        })
        .collect();
    for (round, index) in turns(plan.slices(), sessions.len()) {
        let slot = &mut sessions[index];
        if let Ok(session) = slot {
            let slice = session
                .run(plan.slice_warmup(), false)
                .and_then(|()| session.run(plan.slice_samples(round), true));
            if let Err(error) = slice {
                *slot = Err(error);
            }
        }
    }
    sessions
        .into_iter()
        .map(|session| session.and_then(Session::finish))
        .collect()
}

/// The order in which `sessions` ping-pongs take their slices over `rounds` rounds:
/// (round, session index), every session once per round, the first one rotating.
fn turns(rounds: u64, sessions: usize) -> impl Iterator<Item = (u64, usize)> {
    (0..rounds.max(1)).flat_map(move |round| {
        (0..sessions).map(move |turn| (round, (turn + round as usize) % sessions))
    })
}

/// Starts the pong of `peer` and opens the measuring side.
fn start<'a>(peer: &Peer<'a>, domain: &Domain, socket_dir: &Path) -> anyhow::Result<Session<'a>> {
    match peer.transport {
        Transport::IoxPoll | Transport::IoxEvent => match peer.payload {
            Payload::EncoderSample => start_iox::<EncoderSample, EncoderSample>(peer, domain),
            Payload::TrackerFrame => start_iox::<TrackerFrame, MatchedSample>(peer, domain),
            Payload::Ik => start_iox::<IkRequest, IkResponse>(peer, domain),
            Payload::MotorSetpoint => start_iox::<MotorSetpoint, MotorSetpoint>(peer, domain),
        },
        Transport::Doorbell => match peer.payload {
            Payload::EncoderSample => start_doorbell::<EncoderSample, EncoderSample>(peer, domain),
            Payload::TrackerFrame => start_doorbell::<TrackerFrame, MatchedSample>(peer, domain),
            Payload::Ik => start_doorbell::<IkRequest, IkResponse>(peer, domain),
            Payload::MotorSetpoint => start_doorbell::<MotorSetpoint, MotorSetpoint>(peer, domain),
        },
        Transport::Futex | Transport::FutexCross => start_futex(peer, domain),
        Transport::Uds => start_uds(peer, socket_dir),
    }
}

/// The pong process a ping-pong starts: what it runs and where.
struct Peer<'a> {
    transport: Transport,
    payload: Payload,
    plan: &'a Plan,
    placement: &'a Placement,
}

impl<'a> Peer<'a> {
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

    /// The session of the started pong, whose round trip (given its deadline) is
    /// `round_trip`.
    fn session(
        &self,
        process: PongProcess,
        round_trip: impl FnMut(Instant) -> anyhow::Result<()> + 'a,
    ) -> Session<'a> {
        let name = self.plan.row_name(self.transport, self.payload);
        Session {
            round_trips: Measurement::new(name.clone(), "ns"),
            name,
            plan: self.plan,
            process,
            round_trip: Box::new(round_trip),
        }
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

fn start_iox<'a, Req: Message + Default, Resp: Message>(
    peer: &Peer<'a>,
    domain: &Domain,
) -> anyhow::Result<Session<'a>> {
    let (ping, pong) = service_names(peer.transport, peer.payload);
    let end = IoxEnd::<Req, Resp>::open(domain, &ping, &pong, wait_mode(peer.transport)?)?;
    let mut process = peer.spawn(&["--domain", domain.as_str()])?;
    await_peer(&mut process, || end.peer_ready())?;
    Ok(peer.session(process, move |deadline| {
        end.send(Req::default())?;
        end.receive(deadline).map(drop)
    }))
}

fn start_doorbell<'a, Req: Message + Default, Resp: Message>(
    peer: &Peer<'a>,
    domain: &Domain,
) -> anyhow::Result<Session<'a>> {
    let (ping, pong) = service_names(peer.transport, peer.payload);
    let end = DoorbellEnd::<Req, Resp>::open(domain, "bench-ping", &ping, &pong)?;
    let mut process = peer.spawn(&["--domain", domain.as_str()])?;
    await_peer(&mut process, || end.peer_ready())?;
    Ok(peer.session(process, move |deadline| {
        end.send(Req::default())?;
        end.receive(deadline).map(drop)
    }))
}

fn start_futex<'a>(peer: &Peer<'a>, domain: &Domain) -> anyhow::Result<Session<'a>> {
    let name = futex_segment(domain, peer.transport, peer.payload);
    let mut end = FutexEnd::create(&name)?;
    let process = peer.spawn(&["--domain", domain.as_str()])?;
    Ok(peer.session(process, move |deadline| {
        end.send()?;
        end.receive(end.sent(), deadline)
    }))
}

/// The shared-memory segment of a futex ping-pong (unique per domain, transport and payload).
pub fn futex_segment(domain: &Domain, transport: Transport, payload: Payload) -> String {
    format!("{domain}-{}-{}", transport.name(), payload.name())
}

fn start_uds<'a>(peer: &Peer<'a>, socket_dir: &Path) -> anyhow::Result<Session<'a>> {
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
    Ok(peer.session(process, move |_| {
        // The socket file lives as long as the session.
        let _bound = &socket;
        end.send()?;
        end.receive()
    }))
}

/// A started ping-pong: its pong process, the measuring side's round trip (given its
/// deadline), and the round trips recorded so far.
struct Session<'a> {
    name: String,
    plan: &'a Plan,
    process: PongProcess,
    round_trip: Box<dyn FnMut(Instant) -> anyhow::Result<()> + 'a>,
    round_trips: Measurement,
}

impl Session<'_> {
    /// Runs `count` round trips in bursts of the plan's, each burst after the plan's pause,
    /// recording them if `record`.
    fn run(&mut self, count: u64, record: bool) -> anyhow::Result<()> {
        let name = &self.name;
        for index in 0..count {
            if self.plan.pauses_before(index) {
                std::thread::sleep(self.plan.pause);
            }
            let start = Instant::now();
            (self.round_trip)(start + ROUND_TRIP_TIMEOUT).with_context(|| {
                let what = if record {
                    "round trip"
                } else {
                    "warm-up round trip"
                };
                format!("{name}: {what} {index}")
            })?;
            if record {
                self.round_trips.record_duration(start.elapsed())?;
            }
        }
        Ok(())
    }

    /// Measures the pong's idle CPU use if the plan asks, then releases the pong and checks
    /// it exited well.
    fn finish(mut self) -> anyhow::Result<PingPong> {
        let name = &self.name;
        let pong_idle = self
            .plan
            .idle_window
            .map(|window| measure_cpu_share(self.process.pid(), window))
            .transpose()
            .with_context(|| format!("{name}: idle CPU of the pong process"))?;
        (self.round_trip)(Instant::now() + ROUND_TRIP_TIMEOUT)
            .with_context(|| format!("{name}: last round trip"))?;
        self.process.finish()?;
        Ok(PingPong {
            round_trips: self.round_trips,
            pong_idle,
        })
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(warmup: u64, samples: u64, rounds: u64) -> Plan {
        Plan {
            warmup,
            samples,
            rounds,
            idle_window: None,
            pause: Duration::ZERO,
            burst: 1,
        }
    }

    #[test]
    fn slices_hold_every_sample_and_the_pong_answers_every_round_trip() {
        for (warmup, samples, rounds) in [(2000, 20_000, 10), (10, 23, 10), (10, 7, 10), (5, 30, 1)]
        {
            let plan = plan(warmup, samples, rounds);
            let slices: Vec<u64> = (0..rounds).map(|round| plan.slice_samples(round)).collect();
            assert_eq!(slices.iter().sum::<u64>(), samples, "{plan:?}");
            let (min, max) = (slices.iter().min().unwrap(), slices.iter().max().unwrap());
            assert!(max - min <= 1, "uneven slices {slices:?}");
            let round_trips = warmup + rounds * plan.slice_warmup() + samples + 1;
            assert_eq!(plan.pong_count(), round_trips, "{plan:?}");
        }
        assert_eq!(plan(2000, 20_000, 10).slice_warmup(), 200);
    }

    #[test]
    fn a_burst_of_round_trips_follows_each_pause() {
        let paused = |burst: u64| -> Vec<u64> {
            let plan = Plan {
                burst,
                ..plan(0, 25, 1)
            };
            (0..25).filter(|&index| plan.pauses_before(index)).collect()
        };
        assert_eq!(paused(10), [0, 10, 20]);
        assert_eq!(paused(1), (0..25).collect::<Vec<_>>());
        assert_eq!(paused(0), paused(1), "0 counts as 1");
    }

    #[test]
    fn every_session_takes_one_slice_per_round_and_the_first_turn_rotates() {
        let order: Vec<(u64, usize)> = turns(3, 4).collect();
        assert_eq!(order.len(), 12);
        for round in 0..3 {
            let mut sessions: Vec<usize> = order
                .iter()
                .filter(|(r, _)| *r == round)
                .map(|(_, index)| *index)
                .collect();
            assert_eq!(
                sessions[0], round as usize,
                "round {round} starts with another"
            );
            sessions.sort_unstable();
            assert_eq!(sessions, [0, 1, 2, 3], "round {round}");
        }
        assert_eq!(turns(0, 2).count(), 2, "at least one round");
        assert_eq!(turns(5, 0).count(), 0);
    }
}
