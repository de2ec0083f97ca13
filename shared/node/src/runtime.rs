//! [`NodeRuntime`]: the iceoryx2 node of one process, its lifecycle and its main loops.

use crate::events::service_name;
use crate::message::Message;
use crate::ports::{Publisher, Subscriber};
use crate::signals::{termination_requested, wait_on_node};
use crate::transport::{Transport, Waitable};
use crate::Doorbell;
use crate::{monotonic_ns, Domain, NodeError};
use iceoryx2::node::Node;
use iceoryx2::prelude::{NodeBuilder, NodeName};
use sabr_msgs::{services, Lifecycle, LifecycleState, NodeLabel};
use std::path::PathBuf;
use std::rc::Rc;
use std::time::{Duration, Instant};

/// Environment variable holding the node's name in the launch file (set by the launcher).
pub const NODE_NAME_ENV: &str = "SABR_NODE_NAME";
/// Environment variable holding the run directory `runs/<id>` (set by the launcher).
pub const RUN_DIR_ENV: &str = "SABR_RUN_DIR";
/// Environment variable holding the phase of the node's periodic loop in µs (set by the
/// launcher from the node's `phase_us`): [`NodeRuntime::run_loop`] then keeps its deadlines
/// that long after each multiple of its period on `CLOCK_MONOTONIC`.
pub const LOOP_PHASE_ENV: &str = "SABR_LOOP_PHASE_US";
/// Largest loop phase accepted, µs (one second, the longest period a node loops at).
pub const MAX_LOOP_PHASE_US: u32 = 999_999;
/// How often a running node repeats its `Ready` lifecycle announcement (its heartbeat).
pub const HEARTBEAT_PERIOD: Duration = Duration::from_millis(100);
/// Publisher capacity of the lifecycle service: one per node process plus spares for restarts.
const LIFECYCLE_MAX_PUBLISHERS: usize = 64;
/// Subscriber capacity of the lifecycle service (the launcher and a few watchers).
const LIFECYCLE_MAX_SUBSCRIBERS: usize = 8;
/// Buffer of a lifecycle subscriber: several seconds of heartbeats of a whole graph.
pub(crate) const LIFECYCLE_BUFFER: usize = 256;

/// The run directory given by the launcher ([`RUN_DIR_ENV`]), where recorder and calibrator
/// write; `None` when the process was started by hand without it.
pub fn run_dir() -> Option<PathBuf> {
    std::env::var_os(RUN_DIR_ENV).map(PathBuf::from)
}

/// A loop phase as [`LOOP_PHASE_ENV`] gives it: whole µs, 0..=[`MAX_LOOP_PHASE_US`].
pub fn parse_loop_phase(value: &str) -> Result<Duration, NodeError> {
    let invalid = |reason| NodeError::InvalidLoopPhase {
        value: value.to_owned(),
        reason,
    };
    let us: u32 = value
        .trim()
        .parse()
        .map_err(|_| invalid("not a whole number of µs"))?;
    if us > MAX_LOOP_PHASE_US {
        return Err(invalid("must be below one second (999999 µs at most)"));
    }
    Ok(Duration::from_micros(u64::from(us)))
}

/// Why a main loop returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    /// SIGINT or SIGTERM arrived (the launcher's stop request, or Ctrl-C).
    Signal,
    /// The loop body called [`LoopCtx::stop`].
    Stopped,
    /// The loop body called [`LoopCtx::finish_graph`]: the graph's job is done.
    Done,
}

/// What the loop body sees on each call, and how it ends the loop.
#[derive(Debug)]
pub struct LoopCtx {
    tick: u64,
    now: Instant,
    woke_on_data: bool,
    /// In [`NodeRuntime::run_on_data`]: the address of each input's wake-up, in input order.
    inputs: Vec<usize>,
    /// Bit `i`: input `i` rang for this call (every bit on an idle call).
    rang: u64,
    missed: u64,
    exit: Option<Exit>,
}

impl LoopCtx {
    fn new() -> Self {
        Self {
            tick: 0,
            now: Instant::now(),
            woke_on_data: false,
            inputs: Vec::new(),
            rang: u64::MAX,
            missed: 0,
            exit: None,
        }
    }

    /// Number of body calls before this one.
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// When this call started.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// In [`NodeRuntime::run_on_data`]: true if an input woke the loop, false on an idle timeout.
    pub fn woke_on_data(&self) -> bool {
        self.woke_on_data
    }

    /// In [`NodeRuntime::run_on_data`]: true if `input` rang since the previous call, so it
    /// has data to read; also true on an idle call (every input is then worth a look: data
    /// that came without a ring, e.g. a subscriber's history, is read within one idle
    /// period) and for a port that is not an input of the loop. A body that reads only the
    /// inputs that rang leaves the others' shared memory untouched, which on a busy core
    /// means fewer cold cache lines between a wake-up and the answer.
    pub fn woken_by<S: Transport>(&self, input: &dyn Waitable<S>) -> bool {
        let address = wake_address(input);
        match self.inputs.iter().position(|&a| a == address) {
            Some(index) if index < 64 => self.rang & (1 << index) != 0,
            _ => true,
        }
    }

    /// In [`NodeRuntime::run_loop`]: periods skipped so far because the body overran.
    pub fn missed_periods(&self) -> u64 {
        self.missed
    }

    /// Leave the loop after this call.
    pub fn stop(&mut self) {
        self.exit = Some(Exit::Stopped);
    }

    /// Announce that the graph's job is done (the launcher then stops the graph with success)
    /// and leave the loop after this call.
    pub fn finish_graph(&mut self) {
        self.exit = Some(Exit::Done);
    }
}

/// The runtime of one SABR process: iceoryx2 node in the graph's domain, typed ports,
/// lifecycle announcements (readiness, heartbeat, stopping, done) and signal-aware loops, on
/// transport `S` (the graph's futex [`Doorbell`] by default, or stock iceoryx2 events with
/// `ipc::Service`: every process of a domain uses the same).
///
/// ```no_run
/// use sabr_node::NodeRuntime;
/// use sabr_msgs::{services, EncoderSample};
/// use std::time::Duration;
///
/// fn main() -> Result<(), sabr_node::NodeError> {
///     let mut rt = NodeRuntime::start("encoders")?;
///     let out = rt.publisher::<EncoderSample>(services::ENCODER_SAMPLES)?;
///     let mut seq = 0;
///     rt.run_loop(Duration::from_millis(1), |_ctx| {
///         seq += 1;
///         out.send(EncoderSample { seq, t_ns: sabr_node::monotonic_ns(), counts: [0; 5] })
///     })?;
///     Ok(())
/// }
/// ```
pub struct NodeRuntime<S: Transport = Doorbell> {
    // Ports before the node they were made by: fields drop in order.
    lifecycle: iceoryx2::port::publisher::Publisher<S, Lifecycle, ()>,
    inbound: S::Inbound,
    node: Rc<Node<S>>,
    name: String,
    label: NodeLabel,
    domain: Domain,
    lifecycle_seq: u64,
    state: LifecycleState,
    last_heartbeat: Instant,
    loop_phase: Option<Duration>,
}

impl NodeRuntime<Doorbell> {
    /// Starts the runtime of a service process on the graph's transport ([`Doorbell`]):
    /// logging to stderr, the node name from [`NODE_NAME_ENV`] (else `default_name`), the
    /// domain from [`crate::DOMAIN_ENV`], stale resources of dead nodes removed, SIGINT/SIGTERM
    /// caught, `Starting` announced.
    pub fn start(default_name: &str) -> Result<Self, NodeError> {
        Self::start_on(default_name)
    }

    /// Like [`NodeRuntime::start`] with an explicit name and domain, ignoring the environment
    /// (and leaving logging set-up to the caller).
    pub fn with_domain(name: &str, domain: Domain) -> Result<Self, NodeError> {
        Self::in_domain(name, domain)
    }
}

impl<S: Transport> NodeRuntime<S> {
    /// [`NodeRuntime::start`] on transport `S`.
    pub fn start_on(default_name: &str) -> Result<Self, NodeError> {
        crate::init_tracing();
        let name = std::env::var(NODE_NAME_ENV).unwrap_or_else(|_| default_name.to_owned());
        let loop_phase = match std::env::var(LOOP_PHASE_ENV) {
            Ok(value) => Some(parse_loop_phase(&value)?),
            Err(_) => None,
        };
        let mut runtime = Self::in_domain(&name, Domain::from_env()?)?;
        runtime.set_loop_phase(loop_phase);
        Ok(runtime)
    }

    /// [`NodeRuntime::with_domain`] on transport `S`.
    pub fn in_domain(name: &str, domain: Domain) -> Result<Self, NodeError> {
        let label = validate_node_name(name)?;
        let node_name = NodeName::new(name).map_err(|e| NodeError::InvalidName {
            name: name.to_owned(),
            reason: format!("{e:?}"),
        })?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&domain.iceoryx_config())
            .create::<S>()
            .map_err(|e| NodeError::Node(e.to_string()))?;
        // Creation already removed dead nodes; a second pass waits for any other process that
        // was cleaning up at the same moment.
        let cleanup = node.blocking_cleanup_dead_nodes(Duration::from_millis(500));
        let orphans = crate::orphans::remove_orphaned_nodes::<S>(&domain);
        if cleanup.cleanups > 0 || cleanup.failed_cleanups > 0 || orphans > 0 {
            tracing::info!(
                removed = cleanup.cleanups,
                failed = cleanup.failed_cleanups,
                half_removed = orphans,
                "removed stale iceoryx2 resources of dead nodes"
            );
        }
        // Installs iceoryx2's SIGINT/SIGTERM handler now rather than at the first wait, so a stop
        // request during set-up is seen instead of killing the process (and kept for the loops).
        wait_on_node(&node, Duration::ZERO);
        let lifecycle = lifecycle_service(&node)?
            .publisher_builder()
            .create()
            .map_err(|e| NodeError::port(services::GRAPH_LIFECYCLE, "create publisher", e))?;
        let inbound = S::open_inbound(&node)?;
        let mut runtime = Self {
            inbound,
            node: Rc::new(node),
            name: name.to_owned(),
            label,
            domain,
            lifecycle,
            lifecycle_seq: 0,
            state: LifecycleState::Starting,
            last_heartbeat: Instant::now(),
            loop_phase: None,
        };
        runtime.announce(LifecycleState::Starting);
        tracing::info!(node = name, domain = %runtime.domain, pid = std::process::id(), "starting");
        Ok(runtime)
    }

    /// The node's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The domain the node lives in.
    pub fn domain(&self) -> &Domain {
        &self.domain
    }

    /// The underlying iceoryx2 node, for anything the helpers below do not cover.
    pub fn node(&self) -> &Node<S> {
        &self.node
    }

    pub(crate) fn shared_node(&self) -> &Rc<Node<S>> {
        &self.node
    }

    pub(crate) fn inbound(&self) -> &S::Inbound {
        &self.inbound
    }

    /// A publisher of `T` on a publish-subscribe service (see `sabr_msgs::services`).
    pub fn publisher<T: Message>(&self, service: &str) -> Result<Publisher<T, S>, NodeError> {
        let factory = self
            .node
            .service_builder(&service_name(service)?)
            .publish_subscribe::<T>()
            .history_size(services::history_size(service))
            .open_or_create()
            .map_err(|e| NodeError::port(service, "open service", e))?;
        let port = factory
            .publisher_builder()
            .create()
            .map_err(|e| NodeError::port(service, "create publisher", e))?;
        let wake = S::wake(&self.node, service)?;
        Ok(Publisher::new(port, wake, factory, service))
    }

    /// A subscriber of `T` on a publish-subscribe service, woken by its publishers. On
    /// connecting it receives the publishers' latest sample, if any.
    pub fn subscriber<T: Message>(&self, service: &str) -> Result<Subscriber<T, S>, NodeError> {
        self.subscriber_with_history(service, 1)
    }

    /// A subscriber that, on connecting, first receives up to `history` of the samples each
    /// publisher sent before (oldest first; at most `services::history_size(service)`), so
    /// a restarted node can rebuild state from what it missed.
    pub fn subscriber_with_history<T: Message>(
        &self,
        service: &str,
        history: usize,
    ) -> Result<Subscriber<T, S>, NodeError> {
        let inbox = S::inbox(&self.node, &self.inbound, service)?;
        let factory = self
            .node
            .service_builder(&service_name(service)?)
            .publish_subscribe::<T>()
            .history_size(services::history_size(service))
            .open_or_create()
            .map_err(|e| NodeError::port(service, "open service", e))?;
        let mut builder = factory
            .subscriber_builder()
            .history_request(history.min(services::history_size(service)));
        if let Some(name) = S::port_name(&inbox) {
            builder = builder.name(name);
        }
        let port = builder
            .create()
            .map_err(|e| NodeError::port(service, "create subscriber", e))?;
        Ok(Subscriber::new(port, inbox, service))
    }

    /// Announces readiness to the launcher: call once the ports are set up. The loops call it
    /// on entry if it was not called before.
    pub fn ready(&mut self) {
        if self.state == LifecycleState::Starting {
            self.announce(LifecycleState::Ready);
            tracing::info!(node = %self.name, "ready");
        }
    }

    /// Announces that the graph's job is done; the launcher then stops the graph with success.
    pub fn finish_graph(&mut self) {
        self.announce(LifecycleState::Done);
        tracing::info!(node = %self.name, "announced the graph's job done");
    }

    /// False once a stop was requested (SIGINT/SIGTERM). Also sends the heartbeat when due:
    /// a hand-written loop calls this every iteration.
    pub fn keep_running(&mut self) -> bool {
        // The flag iceoryx2's signal handler sets, read without a system call (a wake-up of
        // the doorbell transport costs only a few).
        let stop = termination_requested();
        self.heartbeat_if_due();
        !stop
    }

    /// Sleeps up to `duration`, returning early with `false` on a stop request; sends the
    /// heartbeat when due. A sleep cut short by a signal that requests no stop (a SIGCONT
    /// after a SIGSTOP, say) goes on until `duration` is over.
    pub fn sleep(&mut self, duration: Duration) -> bool {
        let until = Instant::now() + duration;
        let mut stop = termination_requested();
        while !stop {
            stop = wait_on_node(&self.node, until.saturating_duration_since(Instant::now()));
            if Instant::now() >= until {
                break;
            }
        }
        self.heartbeat_if_due();
        !stop
    }

    /// Sets the phase of [`NodeRuntime::run_loop`]'s deadlines (see [`LOOP_PHASE_ENV`]);
    /// `None` starts the schedule at the loop's first call instead.
    pub fn set_loop_phase(&mut self, phase: Option<Duration>) {
        self.loop_phase = phase;
    }

    /// Calls `body` every `period` (drift-free schedule; when the body overruns, missed
    /// periods are skipped, not bunched) until a signal arrives or the body stops the loop.
    /// With a loop phase (see [`NodeRuntime::set_loop_phase`]) the calls fall that long
    /// after each multiple of `period` on `CLOCK_MONOTONIC` (the phase taken modulo the
    /// period), so periodic nodes sharing a core wake at the times the launch file gives them
    /// rather than wherever their start left them. A zero period calls it back to back: a
    /// body paced by a device it waits for.
    pub fn run_loop<E>(
        &mut self,
        period: Duration,
        mut body: impl FnMut(&mut LoopCtx) -> Result<(), E>,
    ) -> Result<Exit, E> {
        self.ready();
        let mut ctx = LoopCtx::new();
        let mut next = Instant::now();
        if let Some(phase) = self.loop_phase.filter(|_| !period.is_zero()) {
            let delay = crate::delay_to_phase(
                monotonic_ns(),
                i64::try_from(period.as_nanos()).unwrap_or(i64::MAX),
                i64::try_from(phase.as_nanos()).unwrap_or(0),
            );
            next += Duration::from_nanos(delay.unsigned_abs());
        }
        loop {
            let now = Instant::now();
            if next > now && !self.sleep(next - now) {
                return Ok(self.leave(Exit::Signal));
            }
            if !self.keep_running() {
                return Ok(self.leave(Exit::Signal));
            }
            ctx.now = Instant::now();
            body(&mut ctx)?;
            ctx.tick += 1;
            if let Some(exit) = ctx.exit {
                return Ok(self.leave(exit));
            }
            next += period;
            let behind = Instant::now().saturating_duration_since(next);
            if period.is_zero() {
                next = Instant::now();
            } else if behind >= period {
                let skipped = (behind.as_nanos() / period.as_nanos().max(1)) as u32;
                ctx.missed += u64::from(skipped);
                next += period * skipped;
            }
        }
    }

    /// Does nothing but stay in the graph (ready, heartbeat) until a signal arrives: a node
    /// whose job ended but which must not leave, e.g. holding the robot's last setpoint.
    pub fn idle(&mut self) -> Exit {
        let idle = self.run_loop(HEARTBEAT_PERIOD, |_ctx| {
            Ok::<_, std::convert::Infallible>(())
        });
        match idle {
            Ok(exit) => exit,
            Err(never) => match never {},
        }
    }

    /// Calls `body` whenever data arrives on any of `inputs`, and after `idle` without data,
    /// until a signal arrives or the body stops the loop. Blocks in between (no spinning); the
    /// idle call is where a node notices a stalled or dead peer (see [`crate::Deadline`]).
    pub fn run_on_data<E>(
        &mut self,
        inputs: &[&dyn Waitable<S>],
        idle: Duration,
        body: impl FnMut(&mut LoopCtx) -> Result<(), E>,
    ) -> Result<Exit, E> {
        self.ready();
        let inbound = self.inbound.clone();
        let looped = S::with_waiter(&inbound, inputs, |wait| {
            self.on_data_loop(wait, inputs, idle, body)
        });
        match looped {
            Ok(result) => result,
            Err(error) => {
                tracing::error!(%error, "cannot wait on the inputs; leaving the loop");
                Ok(self.leave(Exit::Signal))
            }
        }
    }

    /// The loop of [`NodeRuntime::run_on_data`], waiting with `wait` (up to a timeout).
    fn on_data_loop<E>(
        &mut self,
        wait: &mut dyn FnMut(Duration) -> crate::transport::sealed::Waited,
        inputs: &[&dyn Waitable<S>],
        idle: Duration,
        mut body: impl FnMut(&mut LoopCtx) -> Result<(), E>,
    ) -> Result<Exit, E> {
        let mut ctx = LoopCtx::new();
        ctx.inputs = inputs.iter().map(|input| wake_address(*input)).collect();
        let mut last_body = Instant::now();
        loop {
            let until_idle = idle.saturating_sub(last_body.elapsed());
            let until_heartbeat = HEARTBEAT_PERIOD.saturating_sub(self.last_heartbeat.elapsed());
            // A wait cut short by a signal returns like a timeout: whether the signal requests
            // a stop (SIGINT, SIGTERM) or not (a SIGCONT after a SIGSTOP) is the flag's to say.
            let waited = wait(until_idle.min(until_heartbeat));
            if !self.keep_running() {
                return Ok(self.leave(Exit::Signal));
            }
            let mut rang = 0_u64;
            if waited.data {
                for (index, input) in inputs.iter().enumerate() {
                    // (Inputs beyond the 64th count as rung on every call.)
                    if input.take_ring() && index < 64 {
                        rang |= 1 << index;
                    }
                }
            }
            if waited.data || last_body.elapsed() >= idle {
                ctx.now = Instant::now();
                ctx.woke_on_data = waited.data;
                ctx.rang = if waited.data { rang } else { u64::MAX };
                body(&mut ctx)?;
                ctx.tick += 1;
                last_body = Instant::now();
                if let Some(exit) = ctx.exit {
                    return Ok(self.leave(exit));
                }
            }
        }
    }

    fn leave(&mut self, exit: Exit) -> Exit {
        match exit {
            Exit::Done => self.finish_graph(),
            Exit::Signal => tracing::info!(node = %self.name, "stop requested"),
            Exit::Stopped => {}
        }
        exit
    }

    fn heartbeat_if_due(&mut self) {
        if self.state == LifecycleState::Ready && self.last_heartbeat.elapsed() >= HEARTBEAT_PERIOD
        {
            self.announce(LifecycleState::Ready);
        }
    }

    fn announce(&mut self, state: LifecycleState) {
        self.state = state;
        self.lifecycle_seq += 1;
        self.last_heartbeat = Instant::now();
        let message = Lifecycle {
            node: self.label,
            pid: std::process::id(),
            state,
            seq: self.lifecycle_seq,
            t_ns: monotonic_ns(),
        };
        if let Err(error) = self.lifecycle.send_copy(message) {
            tracing::warn!(?error, ?state, "cannot publish the lifecycle state");
        }
    }
}

impl<S: Transport> Drop for NodeRuntime<S> {
    fn drop(&mut self) {
        self.announce(LifecycleState::Stopping);
        tracing::info!(node = %self.name, "stopped");
    }
}

/// The address of an input's wake-up (its listener or doorbell id), which identifies the input
/// while the loop borrows it.
fn wake_address<S: Transport>(input: &dyn Waitable<S>) -> usize {
    input.wake_listener() as *const S::Inbox as usize
}

/// The lifecycle service with its fixed capacities (every process opens it identically).
pub(crate) fn lifecycle_service<S: Transport>(
    node: &Node<S>,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<S, Lifecycle, ()>,
    NodeError,
> {
    node.service_builder(&service_name(services::GRAPH_LIFECYCLE)?)
        .publish_subscribe::<Lifecycle>()
        .max_publishers(LIFECYCLE_MAX_PUBLISHERS)
        .max_subscribers(LIFECYCLE_MAX_SUBSCRIBERS)
        .subscriber_max_buffer_size(LIFECYCLE_BUFFER)
        .history_size(0)
        .open_or_create()
        .map_err(|e| NodeError::port(services::GRAPH_LIFECYCLE, "open service", e))
}

/// Checks a node name: 1..=32 bytes of ASCII letters, digits, `-` or `_` (it names log files).
pub fn validate_node_name(name: &str) -> Result<NodeLabel, NodeError> {
    let invalid = |reason: &str| NodeError::InvalidName {
        name: name.to_owned(),
        reason: reason.to_owned(),
    };
    if name.is_empty() {
        return Err(invalid("it is empty"));
    }
    if !name
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
    {
        return Err(invalid(
            "only ASCII letters, digits, '-' and '_' are allowed",
        ));
    }
    NodeLabel::new(name).map_err(|e| invalid(&e.to_string()))
}
