//! One side of an iceoryx2 ping-pong: publishes one message type and receives another, either
//! spinning on `receive()` or sleeping in an event listener woken by the peer's notifier.

use anyhow::{bail, Context};
use sabr_node::iceoryx2::node::Node;
use sabr_node::iceoryx2::port::listener::Listener;
use sabr_node::iceoryx2::port::notifier::Notifier;
use sabr_node::iceoryx2::port::publisher::Publisher;
use sabr_node::iceoryx2::port::subscriber::Subscriber;
use sabr_node::iceoryx2::prelude::{ipc, NodeBuilder, PortFactory, ServiceName};
use sabr_node::iceoryx2::service::port_factory::{event, publish_subscribe};
use sabr_node::{Domain, Message};
use std::time::Instant;

/// Spins between deadline checks while busy polling (a clock read per spin would dominate).
const SPINS_PER_CLOCK_READ: u32 = 1024;

/// How a side waits for the peer's message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wait {
    /// Spin on `receive()`.
    BusyPoll,
    /// Sleep in the listener until the peer's notifier fires.
    Event,
}

/// The event ports that pair a publish-subscribe service in [`Wait::Event`] mode.
struct Wakeup {
    notifier: Notifier<ipc::Service>,
    listener: Listener<ipc::Service>,
    inbound: event::PortFactory<ipc::Service>,
}

/// One side of a ping-pong: sends `Out` on `outbound`, receives `In` on `inbound` (service
/// names in the domain), so the peer uses the same two names swapped.
pub struct IoxEnd<Out: Message, In: Message> {
    // Ports before the node: fields drop in order and ports must go first.
    publisher: Publisher<ipc::Service, Out, ()>,
    subscriber: Subscriber<ipc::Service, In, ()>,
    wakeup: Option<Wakeup>,
    inbound: publish_subscribe::PortFactory<ipc::Service, In, ()>,
    _node: Node<ipc::Service>,
}

impl<Out: Message, In: Message> IoxEnd<Out, In> {
    /// Creates the node and ports in `domain`. The receiving ports are created before the
    /// sending ones, so a peer that sees this side's publisher (and notifier) may send.
    pub fn open(
        domain: &Domain,
        outbound: &str,
        inbound: &str,
        wait: Wait,
    ) -> anyhow::Result<Self> {
        let node = NodeBuilder::new()
            .config(&domain.iceoryx_config())
            .create::<ipc::Service>()
            .with_context(|| format!("cannot create an iceoryx2 node in domain {domain}"))?;
        let outbound_name = service_name(outbound)?;
        let inbound_name = service_name(inbound)?;
        let port_error = |what: &str, service: &str| format!("service {service}: cannot {what}");

        let inbound_service = node
            .service_builder(&inbound_name)
            .publish_subscribe::<In>()
            .open_or_create()
            .with_context(|| port_error("open", inbound))?;
        let subscriber = inbound_service
            .subscriber_builder()
            .create()
            .with_context(|| port_error("create a subscriber", inbound))?;
        let listening = match wait {
            Wait::BusyPoll => None,
            Wait::Event => {
                let events = node
                    .service_builder(&inbound_name)
                    .event()
                    .open_or_create()
                    .with_context(|| port_error("open the event service", inbound))?;
                let listener = events
                    .listener_builder()
                    .create()
                    .with_context(|| port_error("create a listener", inbound))?;
                Some((events, listener))
            }
        };
        let publisher = node
            .service_builder(&outbound_name)
            .publish_subscribe::<Out>()
            .open_or_create()
            .with_context(|| port_error("open", outbound))?
            .publisher_builder()
            .create()
            .with_context(|| port_error("create a publisher", outbound))?;
        let wakeup = match listening {
            None => None,
            Some((inbound_events, listener)) => {
                let notifier = node
                    .service_builder(&outbound_name)
                    .event()
                    .open_or_create()
                    .with_context(|| port_error("open the event service", outbound))?
                    .notifier_builder()
                    .create()
                    .with_context(|| port_error("create a notifier", outbound))?;
                Some(Wakeup {
                    notifier,
                    listener,
                    inbound: inbound_events,
                })
            }
        };
        Ok(Self {
            publisher,
            subscriber,
            wakeup,
            inbound: inbound_service,
            _node: node,
        })
    }

    /// True once the peer's sending ports exist (it created its receiving ports before them).
    pub fn peer_ready(&self) -> bool {
        let publishing = self.inbound.dynamic_config().number_of_publishers() > 0;
        let notifying = self
            .wakeup
            .as_ref()
            .is_none_or(|w| w.inbound.dynamic_config().number_of_notifiers() > 0);
        publishing && notifying
    }

    /// Publishes `value` and, in event mode, wakes the peer.
    pub fn send(&self, value: Out) -> anyhow::Result<()> {
        self.publisher
            .send_copy(value)
            .map_err(|e| anyhow::anyhow!("iceoryx2 send failed: {e:?}"))?;
        if let Some(wakeup) = &self.wakeup {
            wakeup
                .notifier
                .notify()
                .map_err(|e| anyhow::anyhow!("iceoryx2 notify failed: {e:?}"))?;
        }
        Ok(())
    }

    /// The next message from the peer; an error if none arrives before `deadline`.
    pub fn receive(&self, deadline: Instant) -> anyhow::Result<In> {
        let mut spins = 0u32;
        loop {
            if let Some(sample) = self
                .subscriber
                .receive()
                .map_err(|e| anyhow::anyhow!("iceoryx2 receive failed: {e:?}"))?
            {
                return Ok(*sample.payload());
            }
            match &self.wakeup {
                None => {
                    spins += 1;
                    if spins.is_multiple_of(SPINS_PER_CLOCK_READ) && Instant::now() >= deadline {
                        bail!("no message from the peer in time");
                    }
                    std::hint::spin_loop();
                }
                Some(wakeup) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        bail!("no message from the peer in time");
                    }
                    wakeup
                        .listener
                        .timed_wait(|_| {}, left)
                        .map_err(|e| anyhow::anyhow!("iceoryx2 listener wait failed: {e:?}"))?;
                }
            }
        }
    }
}

fn service_name(name: &str) -> anyhow::Result<ServiceName> {
    ServiceName::new(name).map_err(|e| anyhow::anyhow!("invalid service name {name:?}: {e:?}"))
}
