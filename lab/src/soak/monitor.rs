//! The soak's own view of the running graph: a node in the graph's domain that counts encoder
//! samples, tracker frames and matched samples by sequence number, follows the nodes'
//! lifecycle announcements to learn their process ids, and reads their memory and CPU time.

use super::processes::{Reading, Tracked};
use super::streams::SeqCheck;
use sabr_node::msgs::{services, EncoderSample, LifecycleState, MatchedSample, TrackerFrame};
use sabr_node::{errln, Domain, GraphObserver, NodeError, NodeRuntime, Subscriber};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// Name of the soak's node in the graph's domain.
const MONITOR_NODE: &str = "soak-monitor";
/// Sequence gaps printed as they happen; later ones are only counted.
const GAPS_PRINTED: u64 = 20;

/// What arrived on the graph's streams.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Streams {
    /// `EncoderSample`s from `encoders`.
    pub encoders: SeqCheck,
    /// `TrackerFrame`s from `tracker`.
    pub tracker: SeqCheck,
    /// `MatchedSample`s from `sync`.
    pub matched: SeqCheck,
}

/// What the monitor gathered, once it has left the domain.
#[derive(Debug, Clone)]
pub struct Gathered {
    /// Stream counts.
    pub streams: Streams,
    /// Every process seen: the launcher and each node process (a restarted node twice).
    pub processes: Vec<Tracked>,
    /// Longest time between two reads of the encoder stream by the monitor itself: beyond the
    /// subscriber buffer (256 samples ≈ 256 ms at 1 kHz) a gap may be the monitor's own loss.
    pub max_read_gap: Duration,
}

/// The soak's node in the graph's domain.
pub struct Monitor {
    rt: NodeRuntime,
    observer: GraphObserver,
    encoders: Subscriber<EncoderSample>,
    frames: Subscriber<TrackerFrame>,
    matched: Subscriber<MatchedSample>,
    streams: Streams,
    processes: Vec<Tracked>,
    ready: BTreeMap<String, u32>,
    last_read: Option<Instant>,
    max_read_gap: Duration,
}

impl Monitor {
    /// Joins `domain` and subscribes before the graph starts, so no sample is missed.
    pub fn new(domain: &Domain) -> Result<Self, NodeError> {
        let rt = NodeRuntime::with_domain(MONITOR_NODE, domain.clone())?;
        let observer = GraphObserver::new(domain)?;
        Ok(Self {
            encoders: rt.subscriber(services::ENCODER_SAMPLES)?,
            frames: rt.subscriber(services::TRACKER_FRAMES)?,
            matched: rt.subscriber(services::SYNC_MATCHED)?,
            rt,
            observer,
            streams: Streams::default(),
            processes: Vec::new(),
            ready: BTreeMap::new(),
            last_read: None,
            max_read_gap: Duration::ZERO,
        })
    }

    /// Watches a process that does not announce itself (the launcher).
    pub fn track(&mut self, label: &str, pid: u32) {
        self.processes.push(Tracked::new(label, pid));
    }

    /// Waits up to `wait` for an encoder sample, then takes everything that arrived.
    pub fn read_streams(&mut self, wait: Duration) -> Result<(), NodeError> {
        let now = Instant::now();
        if let Some(last) = self.last_read {
            self.max_read_gap = self.max_read_gap.max(now - last);
        }
        self.last_read = Some(now);
        let streams = &mut self.streams;
        let mut encoder = |sample: EncoderSample| {
            let missing = streams.encoders.push(sample.seq, sample.t_ns);
            if missing > 0 && streams.encoders.gaps <= GAPS_PRINTED {
                errln!(
                    "sabr soak: {missing} encoder sample(s) lost before seq {}",
                    sample.seq
                );
            }
        };
        if let Some(sample) = self.encoders.recv_timeout(wait)? {
            encoder(sample);
        }
        self.encoders.drain(&mut encoder)?;
        self.frames.drain(|frame| {
            streams.tracker.push(frame.seq, frame.arrival_t_ns);
        })?;
        self.matched.drain(|sample| {
            streams.matched.push(sample.seq, sample.arrival_t_ns);
        })?;
        Ok(())
    }

    /// Reads the lifecycle announcements: new node processes are tracked, readiness noted.
    pub fn poll_lifecycle(&mut self) -> Result<(), NodeError> {
        let own = std::process::id();
        let mut messages = Vec::new();
        self.observer.poll(|m| messages.push(m))?;
        for message in messages.into_iter().filter(|m| m.pid != own) {
            let node = message.node.as_str();
            let known = self
                .processes
                .iter()
                .any(|p| p.pid == message.pid && p.label == node);
            if !known {
                self.processes.push(Tracked::new(node, message.pid));
            }
            if message.state == LifecycleState::Ready {
                self.ready.insert(node.to_owned(), message.pid);
            }
        }
        Ok(())
    }

    /// True once every node of `nodes` announced readiness.
    pub fn all_ready<'a>(&self, mut nodes: impl Iterator<Item = &'a str>) -> bool {
        nodes.all(|node| self.ready.contains_key(node))
    }

    /// Starts the measurement window of the streams.
    pub fn start_window(&mut self) {
        self.streams.encoders.start_window();
        self.streams.tracker.start_window();
        self.streams.matched.start_window();
    }

    /// Reads every live process now; returns the readings taken.
    pub fn read_processes(&mut self, t_s: f64) -> Vec<(String, u32, Reading)> {
        self.processes
            .iter_mut()
            .filter_map(|p| p.read(t_s).map(|r| (p.label.clone(), p.pid, r)))
            .collect()
    }

    /// The stream counts so far.
    pub fn streams(&self) -> &Streams {
        &self.streams
    }

    /// Total resident memory of the live processes at their last reading, KiB.
    pub fn total_rss_kib(&self) -> u64 {
        self.processes
            .iter()
            .filter(|p| !p.gone)
            .filter_map(|p| p.readings.last())
            .map(|r| r.proc.rss_kib)
            .sum()
    }

    /// False once SIGINT or SIGTERM arrived.
    pub fn keep_running(&mut self) -> bool {
        self.rt.keep_running()
    }

    /// Leaves the domain (so the launcher can remove it when it stops) and hands over what
    /// was gathered.
    pub fn finish(self) -> Gathered {
        Gathered {
            streams: self.streams,
            processes: self.processes,
            max_read_gap: self.max_read_gap,
        }
    }
}
