//! The sensing graph under measurement — `sabr-rig --autoplay` (session seed
//! [`SESSION_SEED`]), encoders, tracker, sync, recorder — with the IK server beside it, watched
//! by a node of the bench in the same domain (subscribed before the graph starts):
//!
//! - [`ENCODER_TO_SUBSCRIBER`]: an `EncoderSample`'s receipt by the bench minus its `t_ns`
//!   (stamped by `encoders` right before publishing). The sync wakes on the same samples the
//!   same way but does not say when it consumed one, so this is the encoder → consumer hop as
//!   a second subscriber sees it.
//! - [`TRACKER_FRAME_TO_MATCHED`]: a `MatchedSample`'s receipt by the bench minus its frame's
//!   `arrival_t_ns` (stamped by `tracker` on arrival): tracker → sync → bench. Beside it, in
//!   a window of its own after that one, [`TRACKER_FRAME_TO_SUBSCRIBER`]: the `TrackerFrame`'s
//!   own receipt by the bench minus the same stamp (tracker → bench), which splits the chain
//!   into the tracker's part and the sync's (measured apart because the bench, listening
//!   above the graph's priority, would otherwise run between the tracker and the sync). The
//!   stamps the matched sample carries split the chain in four, `chain/*`: the tracker's work
//!   ([`CHAIN_TRACKER_WORK`]), the hop to the sync ([`CHAIN_TRACKER_TO_SYNC`]), the sync's
//!   work ([`CHAIN_SYNC_WORK`]), the hop on ([`CHAIN_SYNC_TO_SUBSCRIBER`]); and [`CHAIN_WORK`],
//!   the two works of a frame added.
//! - [`MATCHING_ERROR`]: |`MatchedSample.exposure_t_ns` − `RigTruth.exposure_t_ns`| of the
//!   same frame number, the sync given the simulated tracker's latency; and
//!   [`MATCHING_ERROR_ABOUT_MEAN`], the same about its mean (the constant part a calibrated
//!   latency absorbs, e.g. the tracker driver's polling delay, which the simulated latency
//!   does not include).
//! - [`IK_ROUND_TRIP`]: `IkClient::solve` from the bench to `sabr-ik` as the motion node
//!   calls it while it plans a line: bursts of
//!   [`IK_REQUESTS_PER_SETPOINT_PERIOD`](sabr_node::msgs::IK_REQUESTS_PER_SETPOINT_PERIOD)
//!   requests back to back, one burst per setpoint period, targets near home; last, with the
//!   bench's subscriptions dropped and its thread placed like the motion node (an IK client
//!   and nothing else, where the graph's client runs). Beside it [`IK_SERVER_SOLVE`], the solve
//!   time the server reports in each response, [`IK_TRANSPORT`], each round trip minus its
//!   request's solve time, and [`IK_ROUND_TRIP_FIRST`], the first round trip of each burst.
//! - CPU use of every process of the graph over a window while the bench only listens.

use super::compute::{self, Target, SESSION_SEED};
use super::cpu::measure_cpu_shares;
use super::graph::{self, GraphMeasured, LiveGraph, SENSING_LAUNCH_FILE, SHIPPED_LAUNCH_FILE};
use super::hops::{
    Outcome, CHAIN_SYNC_TO_SUBSCRIBER, CHAIN_SYNC_WORK, CHAIN_TRACKER_TO_SYNC, CHAIN_TRACKER_WORK,
    CHAIN_WORK, ENCODER_TO_SUBSCRIBER, IK_ROUND_TRIP, IK_ROUND_TRIP_FIRST, IK_SERVER_SOLVE,
    IK_TRANSPORT, MATCHING_ERROR, MATCHING_ERROR_MEAN_LIMIT_NS, TRACKER_FRAME_TO_MATCHED,
};
use super::payload::{Payload, IK_PERIOD};
use super::stats::{self, format_ns, Measurement};
use super::timer;
use anyhow::{bail, Context};
use sabr_ik::IkClient;
use sabr_launcher::placement::Placement;
use sabr_model::HOME_JOINTS;
use sabr_node::msgs::{
    services, EncoderSample, IkRequest, IkStatus, MatchedSample, RigTruth, TrackerFrame,
};
use sabr_node::{delay_to_phase, monotonic_ns, Domain, Exit, NodeRuntime, Subscriber, Waitable};
use sabr_sim::{Session, SimConfig};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

/// Nodes of the sensing graph, in the launch file's order.
const NODES: [&str; 6] = ["rig", "encoders", "tracker", "sync", "recorder", "ik"];

/// Longest wait for the sync's first matched sample once every node is ready (its frame
/// clock must lock first).
const LOCK_TIMEOUT: Duration = Duration::from_secs(30);

/// Longest wait for one IK response.
const IK_TIMEOUT: Duration = Duration::from_millis(200);

/// Longest sleep of the listening loop without data.
const IDLE: Duration = Duration::from_millis(10);

/// How often the listening loops check that the graph still runs.
const CHECK_PERIOD: Duration = Duration::from_millis(500);

/// |matching error − its mean| (ns): the matching error with an ideally calibrated tracker
/// latency, its constant part removed using the truth (a real calibration estimates that part
/// with an error of its own).
pub const MATCHING_ERROR_ABOUT_MEAN: &str = "hop/matching-error-about-mean";

/// A `TrackerFrame`'s receipt by the bench minus its `arrival_t_ns` (ns): the tracker's part
/// of [`TRACKER_FRAME_TO_MATCHED`] (reply parsing, publishing, the wake-up of a subscriber).
pub const TRACKER_FRAME_TO_SUBSCRIBER: &str = "hop/tracker-frame-to-subscriber";

/// The window of [`TRACKER_FRAME_TO_SUBSCRIBER`] is the main window divided by this.
const FRAMES_WINDOW_DIVISOR: u32 = 3;

/// Truths kept for frames not matched yet (over three minutes at 20 Hz).
const TRUTHS_KEPT: usize = 4096;

/// What the sensing part measures and how long it waits.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// Longest wait for every node's readiness.
    pub ready_timeout: Duration,
    /// Window of the CPU use of each process.
    pub cpu_window: Duration,
    /// Window over which the sensing hops are recorded.
    pub window: Duration,
    /// IK requests recorded (after a tenth as many unrecorded).
    pub ik_requests: u64,
}

impl Plan {
    /// IK requests sent first and not recorded.
    fn ik_warmup(&self) -> u64 {
        (self.ik_requests / 10).max(10)
    }

    /// Longest the graph may need to run; the launcher stops it by itself after that.
    pub fn backstop(&self) -> Duration {
        self.ready_timeout
            + LOCK_TIMEOUT
            + self.cpu_window
            + self.window
            + IK_PERIOD
                * (self.ik_requests + self.ik_warmup()).div_ceil(Payload::Ik.live_burst()) as u32
            + Duration::from_secs(120)
    }
}

/// Runs the sensing graph in `domain` from a launch file written to `dir` (node executables
/// in `bin_dir`) and measures its hops, matching error and CPU use.
pub fn run(
    plan: &Plan,
    dir: &Path,
    bin_dir: &Path,
    domain: Domain,
) -> anyhow::Result<GraphMeasured> {
    let session = Session::new(&SimConfig::new(SESSION_SEED))
        .context("cannot build the simulated session")?;
    let tracker = session.tracker_truth();
    let latency_ms = tracker.base_latency_ms + tracker.extra_latency_ms;
    let params = &session.robot_truth().params;
    let targets = compute::targets(&params.effective_geometry())?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let params_file = dir.join("ik-params.toml");
    std::fs::write(&params_file, params.to_toml_string())
        .with_context(|| format!("cannot write {}", params_file.display()))?;

    let mut probe = Probe::open(&domain)?;
    let mut graph = LiveGraph::start(
        "sensing",
        SENSING_LAUNCH_FILE,
        dir,
        bin_dir,
        domain,
        plan.backstop(),
    )?;
    graph.wait_ready(&NODES, plan.ready_timeout)?;
    let mut hops = SensingHops::default();
    probe.wait_for_matched(&mut graph, &mut hops)?;

    let processes = graph.processes();
    let pids: Vec<u32> = processes.iter().map(|(_, pid)| *pid).collect();
    let shares = measure_cpu_shares(&pids, plan.cpu_window)?;
    graph.check_running()?;
    let idle = processes
        .iter()
        .zip(shares)
        .map(|((node, _), share)| (cpu_label(node), share))
        .collect();

    probe.discard_pending(&mut hops)?;
    probe.listen(&mut graph, &mut hops, plan.window)?;
    probe.listen_to_frames(&mut graph, &mut hops, plan.window / FRAMES_WINDOW_DIVISOR)?;
    let client = graph::placement_of(SHIPPED_LAUNCH_FILE, "motion", bin_dir)?;
    let phase = graph::loop_phase_of(SHIPPED_LAUNCH_FILE, "motion", bin_dir)?;
    let client = IkClientPlace {
        placement: client,
        phase: phase.map(|us| Duration::from_micros(u64::from(us))),
    };
    let (ik, ik_note) = probe.ik_round_trips(&mut graph, &targets, plan, &client)?;
    graph.stop()?;

    let mut notes = hops.notes(latency_ms);
    notes.push(ik_note);
    let mut measurements = hops.into_measurements()?;
    measurements.extend(ik.into_measurements());
    Ok(GraphMeasured {
        measurements,
        idle,
        notes,
    })
}

/// The label of a sensing-graph process in the CPU table.
fn cpu_label(node: &str) -> String {
    match node {
        "rig" => "sensing/rig-autoplay".to_owned(),
        other => format!("sensing/{other}"),
    }
}

/// The bench's node in the sensing graph's domain.
struct Probe {
    rt: NodeRuntime,
    encoders: Subscriber<EncoderSample>,
    matched: Subscriber<MatchedSample>,
    truth: Subscriber<RigTruth>,
}

impl Probe {
    fn open(domain: &Domain) -> anyhow::Result<Self> {
        let rt = NodeRuntime::with_domain("bench", domain.clone())?;
        Ok(Self {
            encoders: rt.subscriber(services::ENCODER_SAMPLES)?,
            matched: rt.subscriber(services::SYNC_MATCHED)?,
            truth: rt.subscriber(services::RIG_TRUTH)?,
            rt,
        })
    }

    /// Waits for the sync's first matched sample (its clock locked), keeping the truths.
    fn wait_for_matched(
        &mut self,
        graph: &mut LiveGraph,
        hops: &mut SensingHops,
    ) -> anyhow::Result<()> {
        let started = Instant::now();
        loop {
            if self.matched.recv_timeout(CHECK_PERIOD)?.is_some() {
                return self.discard_pending(hops);
            }
            self.truth.drain(|rig_truth| hops.truth(&rig_truth))?;
            graph.check_running()?;
            if !self.rt.keep_running() {
                bail!("interrupted");
            }
            if started.elapsed() > LOCK_TIMEOUT {
                bail!(
                    "the sync published no matched sample within {LOCK_TIMEOUT:?} of the \
                     graph being ready (see its log under {})",
                    graph.runs_dir().display()
                );
            }
        }
    }

    /// Drops the encoder samples, tracker frames and matched samples waiting (they queued
    /// while the bench did not listen); truths are kept for the matched samples still to come.
    fn discard_pending(&mut self, hops: &mut SensingHops) -> anyhow::Result<()> {
        self.encoders.drain(|_| {})?;
        self.matched.drain(|_| {})?;
        self.truth.drain(|rig_truth| hops.truth(&rig_truth))?;
        Ok(())
    }

    /// Records the encoder hop, the tracker frame → matched sample hop and the matching
    /// error for `window`, woken by every message. The bench does not subscribe to the
    /// tracker frames meanwhile: a subscriber above the graph's priority would run between
    /// the tracker and the sync and lengthen the hop it measures.
    fn listen(
        &mut self,
        graph: &mut LiveGraph,
        hops: &mut SensingHops,
        window: Duration,
    ) -> anyhow::Result<()> {
        let Probe {
            rt,
            encoders,
            matched,
            truth,
        } = self;
        let mut received_encoders = Vec::new();
        let mut received_matched = Vec::new();
        let inputs: [&dyn Waitable; 3] = [&*encoders, &*matched, &*truth];
        listen_for(rt, graph, &inputs, window, || {
            encoders.drain(|sample| received_encoders.push((sample, monotonic_ns())))?;
            truth.drain(|rig_truth| hops.truth(&rig_truth))?;
            matched.drain(|sample| received_matched.push((sample, monotonic_ns())))?;
            for (sample, received_ns) in received_encoders.drain(..) {
                hops.encoder_sample(&sample, received_ns)?;
            }
            for (sample, received_ns) in received_matched.drain(..) {
                hops.matched_sample(&sample, received_ns)?;
            }
            Ok(())
        })
    }

    /// Records [`TRACKER_FRAME_TO_SUBSCRIBER`] for `window` with a subscriber to the tracker
    /// frames made for it (the other messages are dropped, truths kept).
    fn listen_to_frames(
        &mut self,
        graph: &mut LiveGraph,
        hops: &mut SensingHops,
        window: Duration,
    ) -> anyhow::Result<()> {
        let frames: Subscriber<TrackerFrame> = self.rt.subscriber(services::TRACKER_FRAMES)?;
        // Neither the publisher's history (a frame from before the subscription) nor the
        // first frame after it (the tracker then connects to the bench's doorbell, once) is
        // a hop.
        let subscribed_ns = monotonic_ns();
        let mut connected = false;
        let Probe {
            rt,
            encoders,
            matched,
            truth,
        } = self;
        let mut received = Vec::new();
        let inputs: [&dyn Waitable; 4] = [&frames, &*encoders, &*matched, &*truth];
        listen_for(rt, graph, &inputs, window, || {
            frames.drain(|frame| {
                if frame.arrival_t_ns < subscribed_ns {
                    return;
                }
                if connected {
                    received.push((frame, monotonic_ns()));
                }
                connected = true;
            })?;
            encoders.drain(|_| {})?;
            matched.drain(|_| {})?;
            truth.drain(|rig_truth| hops.truth(&rig_truth))?;
            for (frame, received_ns) in received.drain(..) {
                hops.tracker_frame(&frame, received_ns)?;
            }
            Ok(())
        })
    }

    /// Times IK requests to the graph's server as the motion node makes them, in bursts of
    /// [`Payload::live_burst`] back to back, one burst per [`IK_PERIOD`] (at the motion node's
    /// loop phase on `CLOCK_MONOTONIC`, where the launch file gives one): after dropping the
    /// bench's subscriptions (the bench is then an IK client and nothing else; a sample rung
    /// into its doorbell would wake it while it waits for a response), and from the calling
    /// thread placed as `client` (the motion node's place; the bench listened above the graph
    /// before). Also returns the note on the placement.
    fn ik_round_trips(
        self,
        graph: &mut LiveGraph,
        targets: &[Target],
        plan: &Plan,
        client: &IkClientPlace,
    ) -> anyhow::Result<(IkRoundTrips, String)> {
        let Probe {
            mut rt,
            encoders,
            matched,
            truth,
        } = self;
        drop((encoders, matched, truth));
        let IkClientPlace {
            placement: client,
            phase,
        } = client;
        let note = match client.probe() {
            Ok(()) => {
                let prepared = client.prepare().map_err(anyhow::Error::msg)?;
                prepared
                    .apply()
                    .with_context(|| format!("cannot place the bench's IK client: {client}"))?;
                let phase = phase.map_or(String::new(), |phase| {
                    format!(
                        ", its bursts {} µs into each millisecond",
                        phase.as_micros()
                    )
                });
                format!("the bench's IK client ran at {client}{phase}, as the motion node does")
            }
            Err(reason) => {
                format!("the bench's IK client kept the listening thread's placement ({reason})")
            }
        };
        let mut client = IkClient::new(&rt)?;
        let mut round_trips = IkRoundTrips::default();
        let warmup = plan.ik_warmup();
        let burst = Payload::Ik.live_burst();
        // The bursts' grid: the motion node's phase, or wherever the first burst starts.
        let period_ns = stats::duration_ns(IK_PERIOD) as i64;
        let phase_ns = phase.map_or_else(monotonic_ns, |phase| stats::duration_ns(phase) as i64);
        for (index, target) in (0..warmup + plan.ik_requests).zip(targets.iter().cycle()) {
            let first = index.is_multiple_of(burst);
            if first {
                let now = monotonic_ns();
                timer::sleep_until(now + delay_to_phase(now, period_ns, phase_ns))?;
            }
            let request = IkRequest {
                id: 0,
                tip_mm: [target.tip.x, target.tip.y, target.tip.z],
                direction: [target.direction.x, target.direction.y, target.direction.z],
                near_joints_rad: HOME_JOINTS,
            };
            let started = Instant::now();
            let response = client
                .solve(request, IK_TIMEOUT)
                .with_context(|| format!("IK request {index}"))?;
            let elapsed = started.elapsed();
            if response.status != IkStatus::Ok {
                bail!(
                    "IK request {index} near home was refused: {:?}: {}",
                    response.status,
                    response.error
                );
            }
            if index >= warmup {
                round_trips.record(elapsed, response.solve_ns, first)?;
            }
            if index % 1000 == 999 {
                graph.check_running()?;
                if !rt.keep_running() {
                    bail!("interrupted");
                }
            }
        }
        Ok((round_trips, note))
    }
}

/// Where the bench's IK client runs: the motion node's placement, and its loop phase.
struct IkClientPlace {
    placement: Placement,
    phase: Option<Duration>,
}

/// The IK round trips, their parts, and the first of each burst.
struct IkRoundTrips {
    round_trip: Measurement,
    server_solve: Measurement,
    transport: Measurement,
    first_of_burst: Measurement,
}

impl Default for IkRoundTrips {
    fn default() -> Self {
        Self {
            round_trip: Measurement::new(IK_ROUND_TRIP, "ns"),
            server_solve: Measurement::new(IK_SERVER_SOLVE, "ns"),
            transport: Measurement::new(IK_TRANSPORT, "ns"),
            first_of_burst: Measurement::new(IK_ROUND_TRIP_FIRST, "ns"),
        }
    }
}

impl IkRoundTrips {
    /// Records a round trip of `elapsed` whose response reports `solve_ns`, also as the first
    /// of its burst if `first`; a solve longer than its round trip is an error (the server's
    /// report cannot be right).
    fn record(&mut self, elapsed: Duration, solve_ns: u64, first: bool) -> anyhow::Result<()> {
        let round_trip_ns = stats::duration_ns(elapsed);
        let Some(transport_ns) = round_trip_ns.checked_sub(solve_ns) else {
            bail!(
                "the IK server reported a solve of {} in a round trip of {}",
                format_ns(solve_ns),
                format_ns(round_trip_ns)
            );
        };
        self.round_trip.record(round_trip_ns)?;
        self.server_solve.record(solve_ns)?;
        self.transport.record(transport_ns)?;
        if first {
            self.first_of_burst.record(round_trip_ns)?;
        }
        Ok(())
    }

    fn into_measurements(self) -> [Measurement; 4] {
        [
            self.round_trip,
            self.server_solve,
            self.transport,
            self.first_of_burst,
        ]
    }
}

/// Calls `step` on every wake-up by `inputs` for `window`, checking every [`CHECK_PERIOD`]
/// that the graph still runs.
fn listen_for(
    rt: &mut NodeRuntime,
    graph: &mut LiveGraph,
    inputs: &[&dyn Waitable],
    window: Duration,
    mut step: impl FnMut() -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let started = Instant::now();
    let mut checked = started;
    let exit = rt.run_on_data(inputs, IDLE, |ctx| {
        step()?;
        if checked.elapsed() >= CHECK_PERIOD {
            checked = Instant::now();
            graph.check_running()?;
        }
        if started.elapsed() >= window {
            ctx.stop();
        }
        Ok::<_, anyhow::Error>(())
    })?;
    if exit == Exit::Signal {
        bail!("interrupted");
    }
    Ok(())
}

/// The sensing hops, fed with the messages as the bench receives them.
struct SensingHops {
    encoder: Measurement,
    frame: Measurement,
    matched: Measurement,
    /// [`CHAIN_TRACKER_WORK`], [`CHAIN_TRACKER_TO_SYNC`], [`CHAIN_SYNC_WORK`],
    /// [`CHAIN_SYNC_TO_SUBSCRIBER`], [`CHAIN_WORK`].
    chain: [Measurement; 5],
    matching_error: Measurement,
    /// True exposure time (ns) by frame number, of frames not matched yet.
    truths: BTreeMap<u32, i64>,
    /// Matched samples whose frame had no truth.
    without_truth: u64,
    /// Signed matching errors sync − truth (ns), in arrival order.
    signed_errors: Vec<i64>,
    last_encoder_seq: Option<u64>,
    /// Encoder samples the bench itself missed (sequence gaps).
    encoder_missed: u64,
}

impl Default for SensingHops {
    fn default() -> Self {
        Self {
            encoder: Measurement::new(ENCODER_TO_SUBSCRIBER, "ns"),
            frame: Measurement::new(TRACKER_FRAME_TO_SUBSCRIBER, "ns"),
            matched: Measurement::new(TRACKER_FRAME_TO_MATCHED, "ns"),
            chain: [
                CHAIN_TRACKER_WORK,
                CHAIN_TRACKER_TO_SYNC,
                CHAIN_SYNC_WORK,
                CHAIN_SYNC_TO_SUBSCRIBER,
                CHAIN_WORK,
            ]
            .map(|name| Measurement::new(name, "ns")),
            matching_error: Measurement::new(MATCHING_ERROR, "ns"),
            truths: BTreeMap::new(),
            without_truth: 0,
            signed_errors: Vec::new(),
            last_encoder_seq: None,
            encoder_missed: 0,
        }
    }
}

impl SensingHops {
    /// An encoder sample received at `received_ns`.
    fn encoder_sample(&mut self, sample: &EncoderSample, received_ns: i64) -> anyhow::Result<()> {
        if let Some(last) = self.last_encoder_seq {
            self.encoder_missed += sample.seq.saturating_sub(last + 1);
        }
        self.last_encoder_seq = Some(sample.seq);
        let latency = elapsed_ns(sample.t_ns, received_ns)
            .with_context(|| format!("encoder sample {}", sample.seq))?;
        self.encoder.record(latency)
    }

    /// The rig's truth of a frame.
    fn truth(&mut self, truth: &RigTruth) {
        self.truths.insert(truth.frame_number, truth.exposure_t_ns);
        while self.truths.len() > TRUTHS_KEPT {
            self.truths.pop_first();
        }
    }

    /// A tracker frame received at `received_ns`.
    fn tracker_frame(&mut self, frame: &TrackerFrame, received_ns: i64) -> anyhow::Result<()> {
        let latency = elapsed_ns(frame.arrival_t_ns, received_ns)
            .with_context(|| format!("tracker frame {}", frame.frame_number))?;
        self.frame.record(latency)
    }

    /// A matched sample received at `received_ns`.
    fn matched_sample(&mut self, sample: &MatchedSample, received_ns: i64) -> anyhow::Result<()> {
        let context = || format!("matched sample of frame {}", sample.frame_number);
        let latency = elapsed_ns(sample.arrival_t_ns, received_ns).with_context(context)?;
        self.matched.record(latency)?;
        self.chain_parts(sample, received_ns)
            .with_context(context)?;
        match self.truths.remove(&sample.frame_number) {
            Some(true_exposure_ns) => {
                let error = sample.exposure_t_ns - true_exposure_ns;
                self.signed_errors.push(error);
                self.matching_error.record(error.unsigned_abs())
            }
            None => {
                self.without_truth += 1;
                Ok(())
            }
        }
    }

    /// The parts of the chain from the stamps of a matched sample received at `received_ns`.
    fn chain_parts(&mut self, sample: &MatchedSample, received_ns: i64) -> anyhow::Result<()> {
        if sample.frame_sent_t_ns == 0 || sample.sent_t_ns == 0 {
            bail!(
                "it carries no send stamp (frame_sent_t_ns {}, sent_t_ns {}): tracker and \
                 sync must be of this build",
                sample.frame_sent_t_ns,
                sample.sent_t_ns
            );
        }
        let stamps = [
            sample.arrival_t_ns,
            sample.frame_sent_t_ns,
            sample.frame_received_t_ns,
            sample.sent_t_ns,
            received_ns,
        ];
        let mut parts = [0; 4];
        for (part, pair) in parts.iter_mut().zip(stamps.windows(2)) {
            *part = elapsed_ns(pair[0], pair[1])?;
        }
        let [tracker_work, _, sync_work, _] = parts;
        for (measurement, value) in self.chain.iter_mut().zip(parts) {
            measurement.record(value)?;
        }
        self.chain[4].record(tracker_work + sync_work)
    }

    /// Mean signed matching error sync − truth (ns); `None` before any.
    fn mean_error_ns(&self) -> Option<f64> {
        let count = self.signed_errors.len();
        (count > 0)
            .then(|| self.signed_errors.iter().map(|&e| e as f64).sum::<f64>() / count as f64)
    }

    /// What the figures do not show: the bias of the matching error, frames without truth,
    /// samples the bench missed.
    fn notes(&self, latency_ms: f64) -> Vec<String> {
        let matched = self.matching_error.summary().count;
        let mut notes = vec![format!(
            "sensing graph: {} encoder samples, {} matched samples ({} compared with the rig's \
             truth); sync latency {latency_ms:.4} ms (the session's true one); mean signed \
             matching error (sync − truth) {}",
            self.encoder.summary().count,
            self.matched.summary().count,
            matched,
            self.mean_error_ns().map_or("-".to_owned(), |mean| format!(
                "{} (goal |mean| ≤ {}: {})",
                signed_ns(mean),
                format_ns(MATCHING_ERROR_MEAN_LIMIT_NS as u64),
                Outcome::of(mean.abs() <= MATCHING_ERROR_MEAN_LIMIT_NS)
            ))
        )];
        if self.without_truth > 0 {
            notes.push(format!(
                "warning: {} matched samples had no rig truth with their frame number",
                self.without_truth
            ));
        }
        if self.encoder_missed > 0 {
            notes.push(format!(
                "warning: the bench missed {} encoder samples (sequence gaps): it fell behind",
                self.encoder_missed
            ));
        }
        notes
    }

    /// The hops, [`TRACKER_FRAME_TO_SUBSCRIBER`], and [`MATCHING_ERROR_ABOUT_MEAN`]: |error −
    /// mean error|, what is left once a calibrated latency absorbs the constant part.
    fn into_measurements(self) -> anyhow::Result<Vec<Measurement>> {
        let mut about_mean = Measurement::new(MATCHING_ERROR_ABOUT_MEAN, "ns");
        if let Some(mean) = self.mean_error_ns() {
            for &error in &self.signed_errors {
                about_mean.record((error as f64 - mean).abs().round() as u64)?;
            }
        }
        let mut measurements = vec![self.encoder, self.frame, self.matched];
        measurements.extend(self.chain);
        measurements.extend([self.matching_error, about_mean]);
        Ok(measurements)
    }
}

/// `to_ns − from_ns` of two `CLOCK_MONOTONIC` stamps; an error if negative.
fn elapsed_ns(from_ns: i64, to_ns: i64) -> anyhow::Result<u64> {
    u64::try_from(to_ns - from_ns).map_err(|_| {
        anyhow::anyhow!(
            "received at {to_ns} ns, before its time stamp {from_ns} ns: the processes do not \
             share CLOCK_MONOTONIC"
        )
    })
}

/// A signed nanosecond value for people: `+12.3 µs`, `-850 ns`.
fn signed_ns(value: f64) -> String {
    let sign = if value < 0.0 { "-" } else { "+" };
    format!("{sign}{}", format_ns(value.abs().round() as u64))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth(frame_number: u32, exposure_t_ns: i64) -> RigTruth {
        RigTruth {
            frame_number,
            exposure_t_ns,
            ..RigTruth::default()
        }
    }

    /// A matched sample whose frame arrived at `arrival_t_ns`, was sent by the tracker 100 ns
    /// later, received by the sync 300 ns later and matched and sent 600 ns later.
    fn matched(frame_number: u32, exposure_t_ns: i64, arrival_t_ns: i64) -> MatchedSample {
        MatchedSample {
            frame_number,
            exposure_t_ns,
            arrival_t_ns,
            frame_sent_t_ns: arrival_t_ns + 100,
            frame_received_t_ns: arrival_t_ns + 300,
            sent_t_ns: arrival_t_ns + 600,
            ..MatchedSample::default()
        }
    }

    #[test]
    fn the_chain_splits_into_the_works_and_the_hops_of_its_stamps() {
        let mut hops = SensingHops::default();
        hops.matched_sample(&matched(3, 0, 10_000), 11_500).unwrap();
        let values: Vec<(&str, u64)> = hops
            .chain
            .iter()
            .map(|m| (m.name.as_str(), m.summary().max))
            .collect();
        assert_eq!(
            values,
            [
                (CHAIN_TRACKER_WORK, 100),
                (CHAIN_TRACKER_TO_SYNC, 200),
                (CHAIN_SYNC_WORK, 300),
                (CHAIN_SYNC_TO_SUBSCRIBER, 900),
                (CHAIN_WORK, 400),
            ]
        );
        let unstamped = MatchedSample {
            sent_t_ns: 0,
            ..matched(4, 0, 20_000)
        };
        let reordered = MatchedSample {
            frame_received_t_ns: 19_000,
            ..matched(5, 0, 20_000)
        };
        for (sample, expected) in [
            (
                unstamped,
                "matched sample of frame 4: it carries no send stamp",
            ),
            (
                reordered,
                "frame 5: received at 19000 ns, before its time stamp 20100 ns",
            ),
        ] {
            let error = hops.matched_sample(&sample, 21_000).unwrap_err();
            assert!(format!("{error:#}").contains(expected), "{error:#}");
        }
    }

    #[test]
    fn an_ik_round_trip_splits_into_the_servers_solve_and_the_transport() {
        let mut ik = IkRoundTrips::default();
        ik.record(Duration::from_nanos(11_000), 2_000, false)
            .unwrap();
        ik.record(Duration::from_nanos(9_000), 1_000, true).unwrap();
        let error = ik
            .record(Duration::from_nanos(3_000), 4_000, true)
            .unwrap_err()
            .to_string();
        assert!(error.contains("solve of 4.000 µs"), "{error}");
        let [round_trip, solve, transport, first] = ik.into_measurements();
        assert_eq!(
            (round_trip.name.as_str(), solve.name.as_str()),
            (IK_ROUND_TRIP, IK_SERVER_SOLVE)
        );
        assert_eq!(
            (transport.name.as_str(), first.name.as_str()),
            (IK_TRANSPORT, IK_ROUND_TRIP_FIRST)
        );
        for (measurement, count, max) in [
            (&round_trip, 2, 11_000),
            (&solve, 2, 2_000),
            (&transport, 2, 9_000),
            (&first, 1, 9_000),
        ] {
            let summary = measurement.summary();
            assert_eq!(
                summary.count, count,
                "{}: the refused one is not recorded",
                measurement.name
            );
            assert!(
                summary.max.abs_diff(max) <= max / 500,
                "{}: max {} ≠ {max}",
                measurement.name,
                summary.max
            );
        }
        // 9 000 − 1 000 and 11 000 − 2 000: the transport part of each round trip.
        assert!(
            transport.summary().p50.abs_diff(8_000) <= 16,
            "{:?}",
            transport.summary()
        );
    }

    #[test]
    fn matching_error_pairs_frames_by_number() {
        let mut hops = SensingHops::default();
        hops.truth(&truth(7, 1_000_000));
        hops.truth(&truth(9, 2_000_000));
        // Frame 9 estimated 300 µs late, frame 7 100 µs early; frame 8 has no truth.
        hops.matched_sample(&matched(9, 2_300_000, 2_040_000), 2_045_000)
            .unwrap();
        hops.matched_sample(&matched(7, 900_000, 1_040_000), 1_042_000)
            .unwrap();
        hops.matched_sample(&matched(8, 1_500_000, 1_540_000), 1_541_000)
            .unwrap();

        let error = hops.matching_error.summary();
        assert_eq!(error.count, 2);
        // Above 2048 ns the histogram keeps 3 significant digits.
        let min = hops.matching_error.histogram.min();
        assert!(min.abs_diff(100_000) < 100, "{min}");
        assert!(error.max.abs_diff(300_000) < 300, "{error:?}");
        assert_eq!(hops.without_truth, 1);
        assert_eq!(hops.signed_errors, [300_000, -100_000]);
        // Receipt − arrival: 5 µs, 2 µs, 1 µs.
        let latency = hops.matched.summary();
        assert_eq!(latency.count, 3);
        assert_eq!(hops.matched.histogram.min(), 1_000);
        assert!(latency.max.abs_diff(5_000) < 5, "{latency:?}");
        assert!(hops.truths.is_empty());

        let notes = hops.notes(39.6);
        assert!(notes[0].contains("+100.000 µs"), "{notes:?}");
        assert!(
            notes[1].contains("1 matched samples had no rig truth"),
            "{notes:?}"
        );
        // Both errors are 200 µs from their mean of +100 µs.
        let about_mean = hops.into_measurements().unwrap().pop().unwrap();
        assert_eq!(about_mean.name, MATCHING_ERROR_ABOUT_MEAN);
        let spread = about_mean.summary();
        assert_eq!(spread.count, 2);
        assert!(spread.p50.abs_diff(200_000) < 200 && spread.max.abs_diff(200_000) < 200);
    }

    #[test]
    fn encoder_hop_counts_the_samples_the_bench_missed() {
        let mut hops = SensingHops::default();
        for (seq, t_ns, received_ns) in [(1, 1_000, 1_700), (2, 2_000, 2_900), (5, 5_000, 5_800)] {
            let sample = EncoderSample {
                seq,
                t_ns,
                counts: [0; 5],
            };
            hops.encoder_sample(&sample, received_ns).unwrap();
        }
        let summary = hops.encoder.summary();
        assert_eq!((summary.count, summary.p50, summary.max), (3, 800, 900));
        assert_eq!(hops.encoder_missed, 2);
    }

    #[test]
    fn tracker_frames_are_timed_from_their_arrival_stamp() {
        let mut hops = SensingHops::default();
        for (frame_number, arrival_t_ns, received_ns) in
            [(4, 50_000, 50_120), (6, 100_000, 100_300)]
        {
            let frame = TrackerFrame {
                frame_number,
                arrival_t_ns,
                ..TrackerFrame::default()
            };
            hops.tracker_frame(&frame, received_ns).unwrap();
        }
        let summary = hops.frame.summary();
        assert_eq!((summary.count, summary.p50, summary.max), (2, 120, 300));
        let error = hops
            .tracker_frame(
                &TrackerFrame {
                    frame_number: 9,
                    arrival_t_ns: 10,
                    ..TrackerFrame::default()
                },
                5,
            )
            .unwrap_err();
        assert!(
            format!("{error:#}").contains("tracker frame 9"),
            "{error:#}"
        );
    }

    #[test]
    fn a_receipt_before_the_stamp_is_an_error() {
        let mut hops = SensingHops::default();
        let sample = EncoderSample {
            seq: 3,
            t_ns: 10_000,
            counts: [0; 5],
        };
        let error = hops.encoder_sample(&sample, 9_000).unwrap_err();
        let text = format!("{error:#}");
        assert!(text.contains("encoder sample 3"), "{text}");
        assert!(text.contains("before its time stamp"), "{text}");
    }

    #[test]
    fn launch_file_runs_the_chain_and_the_ik_server_with_the_sessions_true_latency() {
        let bin_dir = graph::stand_in_bin_dir();
        let graph = sabr_launcher::spec::parse(
            Path::new("bench-sensing.toml"),
            SENSING_LAUNCH_FILE,
            bin_dir.path(),
        )
        .unwrap();
        let names: Vec<&str> = graph.nodes.iter().map(|n| n.name.as_str()).collect();
        assert_eq!(names, NODES);
        let args = |name: &str| {
            let node = graph.nodes.iter().find(|n| n.name == name).unwrap();
            assert_eq!(node.restart, sabr_launcher::spec::RestartPolicy::Never);
            node.args.clone()
        };
        assert_eq!(
            args("rig"),
            ["--autoplay", "--seed", &SESSION_SEED.to_string()]
        );
        assert_eq!(args("ik"), ["--params", "ik-params.toml"]);
        let sync = args("sync");
        assert_eq!(sync[0], "--latency-ms");
        let configured: f64 = sync[1].parse().unwrap();
        let session = Session::new(&SimConfig::new(SESSION_SEED)).unwrap();
        let tracker = session.tracker_truth();
        let truth = tracker.base_latency_ms + tracker.extra_latency_ms;
        assert!(
            (configured - truth).abs() < 1e-3,
            "launch file {configured} ms, session truth {truth} ms"
        );
    }

    #[test]
    fn the_bench_places_every_node_as_the_shipped_graphs_do() {
        let bin_dir = graph::stand_in_bin_dir();
        let parse = |name: &str, text: &str| {
            sabr_launcher::spec::parse(Path::new(name), text, bin_dir.path()).unwrap()
        };
        let shipped = parse("sim-calibration.toml", SHIPPED_LAUNCH_FILE);
        for (name, text) in [
            ("bench-sensing.toml", SENSING_LAUNCH_FILE),
            ("bench-setpoints.toml", graph::SETPOINTS_LAUNCH_FILE),
        ] {
            let graph = parse(name, text);
            assert_eq!(
                graph.cpu_wake_latency.map(|(bound, _)| bound),
                shipped.cpu_wake_latency.map(|(bound, _)| bound),
                "{name}: CPU wake-up latency bound"
            );
            for node in graph.nodes {
                let same = shipped.nodes.iter().find(|n| n.name == node.name).unwrap();
                assert_eq!(node.placement, same.placement, "{name}: {}", node.name);
                assert_eq!(
                    node.loop_phase_us, same.loop_phase_us,
                    "{name}: {} loop phase",
                    node.name
                );
                assert!(
                    node.placement.cpus.is_some(),
                    "{name}: {} is placed",
                    node.name
                );
            }
        }
    }

    /// The shipped graphs' loop phases keep the motion node's bursts of IK requests clear of
    /// every other timer on its core: the rig's two ticks a millisecond, the encoders' tick,
    /// and the kernel's scheduler tick just after each whole millisecond (at any HZ up to
    /// 1000), each with the time it takes to run.
    #[test]
    fn the_motion_nodes_bursts_fall_where_no_other_timer_does() {
        const TICK_RUN_US: u32 = 60;
        const BURST_US: u32 = 150;
        let bin_dir = graph::stand_in_bin_dir();
        let shipped =
            sabr_launcher::spec::parse(Path::new("shipped"), SHIPPED_LAUNCH_FILE, bin_dir.path())
                .unwrap();
        let node = |name: &str| shipped.nodes.iter().find(|n| n.name == name).unwrap();
        let phase = |name: &str| node(name).loop_phase_us.unwrap_or_else(|| panic!("{name}"));
        let motion = phase("motion");
        // Deadlines within each millisecond (µs): the rig ticks at 2 kHz; the scheduler
        // tick also comes at the start of the next millisecond.
        let rig = phase("rig") % 500;
        let others = [0, rig, rig + 500, phase("encoders"), 1_000];
        assert_eq!(node("motion").placement.cpus, node("rig").placement.cpus);
        assert_eq!(
            node("motion").placement.cpus,
            node("encoders").placement.cpus
        );
        for other in others {
            assert!(
                motion >= other + TICK_RUN_US || motion + BURST_US <= other,
                "motion's bursts at {motion}–{} µs meet a timer at {other} µs",
                motion + BURST_US
            );
        }
        // The encoders read the rig's latch after the rig made it.
        assert!(
            phase("encoders") >= rig + TICK_RUN_US,
            "encoders before the rig's latch"
        );
    }

    #[test]
    fn old_truths_are_forgotten() {
        let mut hops = SensingHops::default();
        for frame in 0..(TRUTHS_KEPT as u32 + 10) {
            hops.truth(&truth(frame, i64::from(frame)));
        }
        assert_eq!(hops.truths.len(), TRUTHS_KEPT);
        assert_eq!(hops.truths.first_key_value(), Some((&10, &10)));
    }
}
