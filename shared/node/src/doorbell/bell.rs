//! The doorbell of a process ([`Bell`]), the event ids of its inbound ports ([`Inbox`]) and
//! the producer side that rings consumers' doorbells ([`Ringer`]).

use super::Doorbell;
use crate::NodeError;
use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::{EventId, PortName, ServiceName};
use iceoryx2::service::port_factory::event;
use sabr_msgs::services;
use std::cell::{Cell, RefCell};
use std::rc::Rc;
use std::time::{Duration, Instant};

/// Highest event id of a doorbell: at most 15 inbound ports per process (id 0 is unused; the
/// busiest service, the calibrator, has 7). Every wake-up drains iceoryx2's counting bit set
/// with one atomic swap per id up to this one, in shared memory the producers write: on a
/// 2-vCPU guest a doorbell round trip took 5.4 µs (p50) with 64 ids, 4.9 µs with 16.
const EVENT_ID_MAX: usize = 15;
// The ids that rang and the free ones are bit masks of one `u64`.
const _: () = assert!(EVENT_ID_MAX < 64);
/// Producers that may ring one doorbell at once (one notifier per producer port).
const MAX_RINGERS: usize = 64;
/// Nodes that may hold one doorbell's service open.
const MAX_NODES: usize = 64;
/// Prefix of the port name that carries an inbound port's event id.
const PORT_NAME_PREFIX: &str = "doorbell-";

/// The doorbell service of the node with `id`.
fn doorbell_service(id: &UniqueNodeId) -> Result<ServiceName, NodeError> {
    let name = format!("{}/{id}", services::GRAPH_DOORBELLS);
    ServiceName::new(&name).map_err(|e| NodeError::port(&name, "parse service name", e))
}

/// The event id an inbound port carries in its name, if it is a doorbell port.
fn event_id_of(port: &PortName) -> Option<EventId> {
    let id: usize = port.as_str().strip_prefix(PORT_NAME_PREFIX)?.parse().ok()?;
    (1..=EVENT_ID_MAX).contains(&id).then(|| EventId::new(id))
}

/// Why a wait on the doorbell ended early.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Interrupted;

/// The one inbound doorbell of a process: an event listener on its own service, and which
/// event ids rang and were not looked at yet.
pub struct Bell {
    listener: Listener<Doorbell>,
    _service: event::PortFactory<Doorbell>,
    /// Bit `i`: event id `i` rang and no one took it yet.
    pending: Cell<u64>,
    /// Bit `i`: event id `i` belongs to no inbound port.
    free: Cell<u64>,
    name: String,
}

impl Bell {
    /// Creates the doorbell of `node` (its service must not exist yet).
    pub(crate) fn open(node: &Node<Doorbell>) -> Result<Rc<Self>, NodeError> {
        let service_name = doorbell_service(node.id())?;
        let name = service_name.to_string();
        let service = node
            .service_builder(&service_name)
            .event()
            .max_listeners(1)
            .max_notifiers(MAX_RINGERS)
            .max_nodes(MAX_NODES)
            .event_id_max_value(EVENT_ID_MAX)
            .create()
            .map_err(|e| NodeError::port(&name, "create the doorbell", e))?;
        let listener = service
            .listener_builder()
            .create()
            .map_err(|e| NodeError::port(&name, "listen on the doorbell", e))?;
        Ok(Rc::new(Self {
            listener,
            _service: service,
            pending: Cell::new(0),
            // Ids 1 to EVENT_ID_MAX.
            free: Cell::new((u64::MAX >> (63 - EVENT_ID_MAX)) & !1),
            name,
        }))
    }

    /// An event id for a new inbound port.
    pub(crate) fn allocate(self: &Rc<Self>) -> Result<Inbox, NodeError> {
        let free = self.free.get();
        if free == 0 {
            return Err(NodeError::Port {
                service: self.name.clone(),
                operation: "allocate an event id",
                reason: format!("all {EVENT_ID_MAX} event ids of the doorbell are in use"),
            });
        }
        let id = free.trailing_zeros() as usize;
        self.free.set(free & !(1 << id));
        self.pending.set(self.pending.get() & !(1 << id));
        let port_name = format!("{PORT_NAME_PREFIX}{id}");
        let port_name =
            PortName::new(&port_name).map_err(|e| NodeError::port(&self.name, "name a port", e))?;
        Ok(Inbox {
            bell: Rc::clone(self),
            id,
            port_name,
        })
    }

    /// Sleeps until the doorbell rings or `timeout` passes, then records the ids that rang;
    /// does not sleep if an id of `wanted` (bit `i`: id `i`) is pending already. `Err` on a
    /// signal.
    pub(crate) fn wait_for(&self, wanted: u64, timeout: Duration) -> Result<(), Interrupted> {
        let result = if self.pending.get() & wanted != 0 || timeout.is_zero() {
            self.listener
                .try_wait(|activation| self.record(activation.id))
        } else {
            self.listener
                .timed_wait(|activation| self.record(activation.id), timeout)
        };
        match result {
            Ok(_) => Ok(()),
            Err(_) => Err(Interrupted),
        }
    }

    fn record(&self, id: EventId) {
        if id.as_value() <= EVENT_ID_MAX {
            self.pending.set(self.pending.get() | (1 << id.as_value()));
        }
    }

    /// True if an id of `mask` rang and was not taken yet.
    pub(crate) fn any_pending(&self, mask: u64) -> bool {
        self.pending.get() & mask != 0
    }

    /// True (and forgotten) if an id of `mask` rang since it was last taken.
    fn take(&self, mask: u64) -> bool {
        let pending = self.pending.get();
        self.pending.set(pending & !mask);
        pending & mask != 0
    }

    fn release(&self, id: usize) {
        self.free.set(self.free.get() | (1 << id));
        self.pending.set(self.pending.get() & !(1 << id));
    }
}

/// The event id of one inbound port on its process's doorbell; released when dropped.
pub struct Inbox {
    bell: Rc<Bell>,
    id: usize,
    port_name: PortName,
}

impl Inbox {
    /// The iceoryx2 port name that tells producers the id (`doorbell-<id>`).
    pub(crate) fn port_name(&self) -> &PortName {
        &self.port_name
    }

    /// This port's id as a bit mask of the doorbell's ids.
    pub(crate) fn mask(&self) -> u64 {
        1 << self.id
    }

    /// True (and forgotten) if this port's id rang.
    pub(crate) fn take(&self) -> bool {
        self.bell.take(self.mask())
    }

    /// Sleeps on the doorbell up to `timeout` unless this port's id rang already; true if it
    /// rang (other ids stay pending for their ports).
    pub(crate) fn wait(&self, timeout: Duration) -> Result<bool, Interrupted> {
        self.bell.wait_for(self.mask(), timeout)?;
        Ok(self.take())
    }
}

impl Drop for Inbox {
    fn drop(&mut self) {
        self.bell.release(self.id);
    }
}

/// How long a producer rings the consumer ports it read last before it reads them again
/// although their number did not change (a consumer that restarted between two sends). The
/// read copies iceoryx2's port list to the heap: the one allocation a send of ours adds to
/// iceoryx2's own, at most once per this period.
pub const CONSUMERS_REFRESH: Duration = Duration::from_millis(20);

/// One consumer port a producer may ring: its node, its event id, and its port id (a server
/// answers one client of several).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Consumer {
    node: UniqueNodeId,
    id: EventId,
    port: u128,
}

/// The highest real-time priority (`SCHED_FIFO`/`SCHED_RR`, 1–99; 0 at the normal policy)
/// among the threads of the process that owns `node`, from `/proc/<pid>/task/*/stat` (the
/// thread that waits on the doorbell may be the only one placed, as the bench's is); `None`
/// if none can be read (the process ended, or the id names no process of this host).
fn realtime_priority(node: &UniqueNodeId) -> Option<u8> {
    let pid = node.pid::<Doorbell>().ok()?;
    let tasks = std::fs::read_dir(format!("/proc/{}/task", pid.value())).ok()?;
    tasks
        .filter_map(|task| std::fs::read_to_string(task.ok()?.path().join("stat")).ok())
        .filter_map(|stat| rt_priority_of_stat(&stat))
        .max()
}

/// Field 40 (`rt_priority`) of a `/proc/<pid>/stat` line. The fields are counted after the
/// command name, which is in parentheses and may itself hold spaces and parentheses.
fn rt_priority_of_stat(stat: &str) -> Option<u8> {
    let after_name = &stat[stat.rfind(')')? + 1..];
    // `after_name` starts with field 3 (the state).
    after_name.split_whitespace().nth(40 - 3)?.parse().ok()
}

/// The doorbell of one consumer node as a producer rings it: its notifier, and the node's
/// real-time priority, read from `/proc` the first time the ringing order needs it and kept
/// for as long as the notifier (a node's placement is set before it starts).
struct ConsumerBell {
    notifier: Notifier<Doorbell>,
    priority: Cell<Option<u8>>,
}

impl ConsumerBell {
    /// The real-time priority of `node`, this bell's node (0 if it cannot be read: rung as
    /// one at the normal policy).
    fn priority(&self, node: &UniqueNodeId) -> u8 {
        if let Some(priority) = self.priority.get() {
            return priority;
        }
        let priority = realtime_priority(node).unwrap_or(0);
        self.priority.set(Some(priority));
        priority
    }
}

/// When the consumer ports were last read, and how many the service listed then.
#[derive(Debug, Clone, Copy)]
struct LastRead {
    listed: usize,
    at: Instant,
}

/// The producer side of one port: rings the doorbells of the consumer ports of its service.
///
/// The consumer ports are read from the service's dynamic config when their number changes,
/// when a ring finds no one listening on a consumer's doorbell (its node ended; a replacement
/// may be listed already), and at least every [`CONSUMERS_REFRESH`] otherwise: reading them
/// copies the whole port list out of shared memory into two heap buffers, the largest cost
/// of a ring had it been done on every send. Unless their number changed, they are read
/// after the ports read last were rung (then only the new ones are rung): a producer sending
/// less often than the refresh period (the tracker at 20 Hz) would otherwise read them
/// before every ring, cold, while its consumers wait. So ports that appear (a restarted node)
/// are rung from the next read on, ports that went away (iceoryx2 removes dead nodes' ports)
/// are not rung after it, and a port whose doorbell could not be opened yet is tried again on
/// the next ring; a notifier per consumer node is opened when its first port appears and
/// closed when its last one goes. The ports are rung in descending real-time priority of
/// their processes (their highest thread's), read from `/proc` once per consumer node
/// ([`in_ringing_order`]).
pub struct Ringer {
    node: Rc<Node<Doorbell>>,
    service: String,
    /// The consumers read last, in ringing order, and the doorbell of each one's node.
    consumers: RefCell<Vec<(Consumer, Rc<ConsumerBell>)>>,
    /// Scratch list of the consumers now in the dynamic config.
    current: RefCell<Vec<Consumer>>,
    /// `None` until the first read, and after a read that left a consumer out.
    last_read: Cell<Option<LastRead>>,
}

impl Ringer {
    /// A ringer for a port of `service` (its name for errors) created by `node`.
    pub(crate) fn new(node: &Rc<Node<Doorbell>>, service: &str) -> Self {
        Self {
            node: Rc::clone(node),
            service: service.to_owned(),
            consumers: RefCell::new(Vec::new()),
            current: RefCell::new(Vec::new()),
            last_read: Cell::new(None),
        }
    }

    /// Rings the consumer ports of the service (all of them, or only the port with id `only`),
    /// `listed` being how many consumer ports the service's dynamic config counts now (a
    /// cheap read). `list` visits the ports (node id, port name, port id; ports without a
    /// doorbell id are skipped) when they are to be read (see [`Ringer`]): before ringing when
    /// they changed (their number differs from the last read, `only` is none of the ports
    /// read last, or nothing was read yet), else after ringing the ports read last, when
    /// their refresh is due or a doorbell had no listener, and then only the ports that are
    /// new are rung. A refresh thus never delays the consumers already known. Returns how
    /// many ports were rung.
    pub(crate) fn ring(
        &self,
        listed: usize,
        only: Option<u128>,
        list: impl FnOnce(&mut dyn FnMut(UniqueNodeId, &PortName, u128)),
    ) -> Result<usize, NodeError> {
        let now = Instant::now();
        let mut consumers = self.consumers.borrow_mut();
        let unknown = only.is_some_and(|port| consumers.iter().all(|(c, _)| c.port != port));
        let last_read = match self.last_read.get() {
            Some(last) if !unknown && last.listed == listed => last,
            _ => {
                self.read(&mut consumers, listed, now, list);
                return Ok(self.notify(&consumers, only, &[])?.0);
            }
        };
        let (rung, unheard) = self.notify(&consumers, only, &[])?;
        let stale = now.duration_since(last_read.at) >= CONSUMERS_REFRESH;
        if !(stale || unheard) {
            return Ok(rung);
        }
        // Due for a refresh, or a doorbell had no listener (its node ended; a replacement
        // may already be listed with the same number of ports): read them again and ring
        // the ones not rung above.
        let Some(previous) = self.read(&mut consumers, listed, now, list) else {
            return Ok(rung);
        };
        Ok(rung + self.notify(&consumers, only, &previous)?.0)
    }

    /// Rings `consumers` (all of them, or only the port with id `only`) except those in
    /// `rung_already`; returns how many and whether any doorbell rung had no listener.
    fn notify(
        &self,
        consumers: &[(Consumer, Rc<ConsumerBell>)],
        only: Option<u128>,
        rung_already: &[(Consumer, Rc<ConsumerBell>)],
    ) -> Result<(usize, bool), NodeError> {
        let mut rung = 0;
        let mut unheard = false;
        for (consumer, bell) in consumers.iter().filter(|(c, _)| {
            only.is_none_or(|port| c.port == port) && rung_already.iter().all(|(r, _)| r != c)
        }) {
            let listeners = bell
                .notifier
                .notify_with_custom_event_id(consumer.id)
                .map_err(|e| NodeError::port(&self.service, "ring a doorbell", e))?;
            unheard |= listeners == 0;
            rung += 1;
        }
        Ok((rung, unheard))
    }

    /// Reads the consumer ports `list` visits into `consumers`, connecting to new ones, and
    /// notes the read (at `now`, with `listed` ports counted) unless a consumer was left out.
    /// Returns the list it replaced if the ports changed.
    fn read(
        &self,
        consumers: &mut Vec<(Consumer, Rc<ConsumerBell>)>,
        listed: usize,
        now: Instant,
        list: impl FnOnce(&mut dyn FnMut(UniqueNodeId, &PortName, u128)),
    ) -> Option<Vec<(Consumer, Rc<ConsumerBell>)>> {
        let mut current = self.current.borrow_mut();
        current.clear();
        list(&mut |node, port_name, port| {
            if let Some(id) = event_id_of(port_name) {
                current.push(Consumer { node, id, port });
            }
        });
        // (`consumers` is in ringing order, `current` in the dynamic config's.)
        let unchanged = consumers.len() == current.len()
            && current
                .iter()
                .all(|n| consumers.iter().any(|(c, _)| c == n));
        let replaced = (!unchanged).then(|| {
            let connected = self.connect(consumers, &current);
            std::mem::replace(consumers, connected)
        });
        let complete = consumers.len() == current.len();
        self.last_read
            .set(complete.then_some(LastRead { listed, at: now }));
        replaced
    }

    /// Notifiers for `current`, reusing those of `previous` by node, in ringing order; a
    /// consumer whose doorbell cannot be opened (yet) is left out and tried again on the next
    /// ring.
    fn connect(
        &self,
        previous: &[(Consumer, Rc<ConsumerBell>)],
        current: &[Consumer],
    ) -> Vec<(Consumer, Rc<ConsumerBell>)> {
        let mut connected: Vec<(Consumer, Rc<ConsumerBell>)> = Vec::with_capacity(current.len());
        for consumer in current {
            let known = connected
                .iter()
                .chain(previous.iter())
                .find(|(c, _)| c.node == consumer.node)
                .map(|(_, bell)| Rc::clone(bell));
            let bell = match known {
                Some(bell) => bell,
                None => match self.open(&consumer.node) {
                    Ok(notifier) => Rc::new(ConsumerBell {
                        notifier,
                        priority: Cell::new(None),
                    }),
                    Err(error) => {
                        tracing::debug!(%error, service = %self.service, "doorbell not reachable yet");
                        continue;
                    }
                },
            };
            connected.push((*consumer, bell));
        }
        // A node's priority is read once, the first time its bell is ordered among others.
        in_ringing_order(&mut connected, |(consumer, bell)| {
            bell.priority(&consumer.node)
        });
        connected
    }

    fn open(&self, node: &UniqueNodeId) -> Result<Notifier<Doorbell>, NodeError> {
        let service_name = doorbell_service(node)?;
        let name = service_name.to_string();
        self.node
            .service_builder(&service_name)
            .event()
            .open()
            .map_err(|e| NodeError::port(&name, "open a consumer's doorbell", e))?
            .notifier_builder()
            .create()
            .map_err(|e| NodeError::port(&name, "create a notifier", e))
    }
}

/// Sorts `consumers` into ringing order: the highest real-time priority of their nodes first
/// (`priority_of`, asked for one entry of each node, and not at all when there is only one
/// node), ties in the order given. On one core, a ring makes a consumer above the producer
/// run at once, before the producer rings the next one: so the consumer that must run first
/// is rung first, whichever subscribed first (a restarted node's ports are listed last).
fn in_ringing_order<T>(
    consumers: &mut [(Consumer, T)],
    mut priority_of: impl FnMut(&(Consumer, T)) -> u8,
) {
    let Some((first, _)) = consumers.first() else {
        return;
    };
    if consumers.iter().all(|(c, _)| c.node == first.node) {
        // One node: nothing to order, nothing to look up.
        return;
    }
    let mut priorities: Vec<(UniqueNodeId, u8)> = Vec::new();
    for entry in consumers.iter() {
        if priorities.iter().all(|(node, _)| *node != entry.0.node) {
            priorities.push((entry.0.node, priority_of(entry)));
        }
    }
    let priority = |consumer: &Consumer| {
        priorities
            .iter()
            .find(|(node, _)| *node == consumer.node)
            .map_or(0, |(_, priority)| *priority)
    };
    consumers.sort_by_key(|(consumer, _)| std::cmp::Reverse(priority(consumer)));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::Domain;
    use crate::files::release_domain;
    use iceoryx2::prelude::NodeBuilder;

    #[test]
    fn port_names_carry_event_ids_in_range() {
        let name = |text: &str| PortName::new(text).unwrap();
        assert_eq!(event_id_of(&name("doorbell-1")), Some(EventId::new(1)));
        assert_eq!(event_id_of(&name("doorbell-15")), Some(EventId::new(15)));
        for other in ["doorbell-0", "doorbell-16", "doorbell-x", "publisher", ""] {
            assert_eq!(event_id_of(&name(other)), None, "{other:?}");
        }
    }

    #[test]
    fn the_rt_priority_is_read_after_the_command_name() {
        // Fields 3 to 39, then rt_priority (42) and the policy (1, SCHED_FIFO); the command
        // name holds a space and a parenthesis.
        let tail: Vec<String> = (3..40).map(|field| field.to_string()).collect();
        let stat = format!("4242 (sabr (sync) x) {} 42 1 0 0", tail.join(" "));
        assert_eq!(rt_priority_of_stat(&stat), Some(42));
        assert_eq!(rt_priority_of_stat("4242 (sabr-sync) S 1 2"), None);
        assert_eq!(rt_priority_of_stat("no name"), None);
    }

    #[test]
    fn consumers_are_rung_by_descending_priority_of_their_nodes_ties_as_listed() {
        let domain = Domain::new(&format!("d-ring-priority-{}", std::process::id())).unwrap();
        {
            let nodes: Vec<Node<Doorbell>> = (0..3)
                .map(|_| {
                    NodeBuilder::new()
                        .config(&domain.iceoryx_config())
                        .create::<Doorbell>()
                        .unwrap()
                })
                .collect();
            let (normal, sync, probe) = (*nodes[0].id(), *nodes[1].id(), *nodes[2].id());
            let port = |node, port| {
                (
                    Consumer {
                        node,
                        id: EventId::new(1),
                        port,
                    },
                    (),
                )
            };
            // As the dynamic config lists them: the normal-policy node subscribed first.
            let mut consumers = [
                port(normal, 1),
                port(sync, 2),
                port(probe, 3),
                port(sync, 4),
            ];
            let mut asked = Vec::new();
            in_ringing_order(&mut consumers, |(consumer, _)| {
                asked.push(consumer.node);
                match consumer.node {
                    n if n == sync => 42,
                    n if n == probe => 50,
                    _ => 0,
                }
            });
            let order: Vec<u128> = consumers.iter().map(|(c, _)| c.port).collect();
            assert_eq!(order, [3, 2, 4, 1]);
            assert_eq!(asked, [normal, sync, probe], "one look per node");
            // The ports of one node are not looked up.
            let mut one_node = [port(sync, 2), port(sync, 4)];
            in_ringing_order(&mut one_node, |_| panic!("looked up"));
            assert_eq!(one_node.map(|(c, _)| c.port), [2, 4]);

            // A node of this process: its priority is the highest of this process's threads
            // (this test's thread among them).
            let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap();
            let this_thread = rt_priority_of_stat(&stat);
            assert!(this_thread.is_some(), "{stat}");
            let found = realtime_priority(&normal);
            assert!(
                found.is_some() && found >= this_thread,
                "{found:?} < {this_thread:?}"
            );
        }
        let left = release_domain(&domain);
        assert!(left.is_empty(), "left behind: {left:?}");
    }

    #[test]
    fn known_consumers_are_rung_before_a_due_refresh_reads_the_ports() {
        let domain = Domain::new(&format!("d-ring-order-{}", std::process::id())).unwrap();
        {
            let node = || {
                let node = NodeBuilder::new()
                    .config(&domain.iceoryx_config())
                    .create::<Doorbell>()
                    .unwrap();
                Rc::new(node)
            };
            let (producer, consumer) = (node(), node());
            let bell = Bell::open(&consumer).unwrap();
            let (first, second) = (bell.allocate().unwrap(), bell.allocate().unwrap());
            let ringer = Ringer::new(&producer, "sabr/test/ring-order");
            // Whether the port rang before the ports were read (taking the ring).
            let rang = |inbox: &Inbox| inbox.wait(Duration::ZERO).unwrap();
            let rung_at_read = Cell::new(None);
            let list_one = |visit: &mut dyn FnMut(UniqueNodeId, &PortName, u128)| {
                rung_at_read.set(Some(rang(&first)));
                visit(*consumer.id(), first.port_name(), 1);
            };

            // The first ring reads the ports before ringing.
            assert_eq!(ringer.ring(1, None, list_one).unwrap(), 1);
            assert_eq!(rung_at_read.take(), Some(false));
            assert!(rang(&first));
            // Within the refresh period the ports are not read again.
            assert_eq!(ringer.ring(1, None, |_| panic!("read")).unwrap(), 1);
            assert!(rang(&first));
            // A due refresh reads them after ringing the known port.
            std::thread::sleep(CONSUMERS_REFRESH);
            assert_eq!(ringer.ring(1, None, list_one).unwrap(), 1);
            assert_eq!(rung_at_read.take(), Some(true));

            // A port that replaced the known one (the count unchanged) is rung after the read.
            std::thread::sleep(CONSUMERS_REFRESH);
            let list_second = |visit: &mut dyn FnMut(UniqueNodeId, &PortName, u128)| {
                visit(*consumer.id(), second.port_name(), 2);
            };
            assert_eq!(ringer.ring(1, None, list_second).unwrap(), 2);
            assert!(rang(&first) && rang(&second));
            // A changed count reads the ports before ringing any.
            let list_both = |visit: &mut dyn FnMut(UniqueNodeId, &PortName, u128)| {
                rung_at_read.set(Some(rang(&first) || rang(&second)));
                visit(*consumer.id(), first.port_name(), 1);
                visit(*consumer.id(), second.port_name(), 2);
            };
            assert_eq!(ringer.ring(2, None, list_both).unwrap(), 2);
            assert_eq!(rung_at_read.take(), Some(false));
        }
        let left = release_domain(&domain);
        assert!(left.is_empty(), "left behind: {left:?}");
    }
}
