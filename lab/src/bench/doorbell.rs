//! One side of a ping-pong on the graph's own transport: `sabr_node` ports on the futex
//! doorbell (each side a `NodeRuntime` whose one doorbell the peer's publisher rings).

use anyhow::{bail, Context};
use sabr_node::{Domain, Message, NodeRuntime, Publisher, Subscriber};
use std::time::Instant;

/// One side of a doorbell ping-pong: sends `Out` on `outbound`, receives `In` on `inbound`.
pub struct DoorbellEnd<Out: Message, In: Message> {
    // Ports before the runtime that made them: fields drop in order.
    publisher: Publisher<Out>,
    subscriber: Subscriber<In>,
    _rt: NodeRuntime,
}

impl<Out: Message, In: Message> DoorbellEnd<Out, In> {
    /// Starts a node `name` in `domain` with its subscriber, then its publisher (a peer that
    /// sees this side's subscriber may send).
    pub fn open(
        domain: &Domain,
        name: &str,
        outbound: &str,
        inbound: &str,
    ) -> anyhow::Result<Self> {
        let rt = NodeRuntime::with_domain(name, domain.clone())
            .with_context(|| format!("cannot start node {name} in domain {domain}"))?;
        let subscriber = rt.subscriber::<In>(inbound)?;
        let publisher = rt.publisher::<Out>(outbound)?;
        Ok(Self {
            publisher,
            subscriber,
            _rt: rt,
        })
    }

    /// True once the peer subscribed to what this side sends.
    pub fn peer_ready(&self) -> bool {
        self.publisher.subscribers() > 0
    }

    /// Publishes `value` and rings the peer's doorbell.
    pub fn send(&self, value: Out) -> anyhow::Result<()> {
        Ok(self.publisher.send(value)?)
    }

    /// Sleeps on this process's doorbell until the peer's message arrives or `deadline`
    /// passes (an error: the peer hung or died).
    pub fn receive(&self, deadline: Instant) -> anyhow::Result<In> {
        let left = deadline.saturating_duration_since(Instant::now());
        match self.subscriber.recv_timeout(left)? {
            Some(value) => Ok(value),
            None => bail!(
                "no message on {} before the deadline",
                self.subscriber.service()
            ),
        }
    }
}
