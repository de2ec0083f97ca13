//! Graph messages: node lifecycle and heartbeat.

use crate::FixedString;
use iceoryx2::prelude::ZeroCopySend;

/// A node name as carried in messages (at most 32 bytes).
pub type NodeLabel = FixedString<32>;

/// Where a node is in its life.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, ZeroCopySend)]
pub enum LifecycleState {
    /// Process started, setting up its ports.
    #[default]
    Starting,
    /// Set up and working; repeated periodically as the heartbeat.
    Ready,
    /// Leaving after a stop request.
    Stopping,
    /// The node finished the graph's job: the launcher stops the graph with success.
    Done,
}

/// Lifecycle announcement and heartbeat of a node, on [`crate::services::GRAPH_LIFECYCLE`].
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.Lifecycle.v1")]
pub struct Lifecycle {
    /// Name of the node in the launch file.
    pub node: NodeLabel,
    /// Process id of the node.
    pub pid: u32,
    /// The node's state.
    pub state: LifecycleState,
    /// Sequence number, +1 per announcement of this process.
    pub seq: u64,
    /// Host `CLOCK_MONOTONIC` time of the announcement, ns.
    pub t_ns: i64,
}
