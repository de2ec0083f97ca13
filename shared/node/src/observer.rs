//! Watching the nodes of a domain from outside the graph (the launcher, tests).

use crate::runtime::{lifecycle_service, LIFECYCLE_BUFFER};
use crate::signals::wait_on_node;
use crate::Doorbell;
use crate::{Domain, NodeError, Transport};
use iceoryx2::node::Node;
use iceoryx2::prelude::NodeBuilder;
use sabr_msgs::{services, Lifecycle};
use std::time::Duration;

/// An iceoryx2 node that receives every node's lifecycle announcements of a domain and can
/// clean up after dead nodes. It does not announce itself. `S` is the graph's transport.
pub struct GraphObserver<S: Transport = Doorbell> {
    lifecycle: iceoryx2::port::subscriber::Subscriber<S, Lifecycle, ()>,
    node: Node<S>,
    domain: Domain,
}

impl GraphObserver<Doorbell> {
    /// Joins the graph of `domain` (on the graph's transport, [`Doorbell`]) (creating the lifecycle service) and removes stale resources of dead
    /// nodes. Catches SIGINT/SIGTERM: see [`GraphObserver::wait`].
    pub fn new(domain: &Domain) -> Result<Self, NodeError> {
        Self::join(domain)
    }
}

impl<S: Transport> GraphObserver<S> {
    /// [`GraphObserver::new`] in a graph on transport `S`.
    pub fn join(domain: &Domain) -> Result<Self, NodeError> {
        let node = NodeBuilder::new()
            .config(&domain.iceoryx_config())
            .create::<S>()
            .map_err(|e| NodeError::Node(e.to_string()))?;
        let lifecycle = lifecycle_service(&node)?
            .subscriber_builder()
            .buffer_size(LIFECYCLE_BUFFER)
            .create()
            .map_err(|e| NodeError::port(services::GRAPH_LIFECYCLE, "create subscriber", e))?;
        let observer = Self {
            node,
            lifecycle,
            domain: domain.clone(),
        };
        observer.cleanup_dead_nodes();
        Ok(observer)
    }

    /// Hands every lifecycle announcement received since the last call to `f`, oldest first.
    pub fn poll(&self, mut f: impl FnMut(Lifecycle)) -> Result<usize, NodeError> {
        let mut count = 0;
        loop {
            let sample = self
                .lifecycle
                .receive()
                .map_err(|e| NodeError::port(services::GRAPH_LIFECYCLE, "receive", e))?;
            match sample {
                Some(sample) => {
                    f(*sample.payload());
                    count += 1;
                }
                None => return Ok(count),
            }
        }
    }

    /// Sleeps up to `duration` (any signal may cut it short); `false` once SIGINT or SIGTERM
    /// has arrived.
    pub fn wait(&self, duration: Duration) -> bool {
        !wait_on_node(&self.node, duration)
    }

    /// Removes the iceoryx2 resources of nodes whose process died (e.g. by SIGKILL), waiting
    /// briefly for any other process doing the same; returns how many nodes were removed.
    pub fn cleanup_dead_nodes(&self) -> u64 {
        let state = self
            .node
            .blocking_cleanup_dead_nodes(Duration::from_millis(500));
        if state.failed_cleanups > 0 {
            tracing::warn!(
                failed = state.failed_cleanups,
                "could not remove the resources of some dead nodes"
            );
        }
        state.cleanups + crate::orphans::remove_orphaned_nodes::<S>(&self.domain) as u64
    }

    /// The underlying iceoryx2 node.
    pub fn node(&self) -> &Node<S> {
        &self.node
    }
}
