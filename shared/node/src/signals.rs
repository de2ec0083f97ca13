//! Whether this process was asked to stop (SIGINT or SIGTERM), as one answer every reader
//! shares.
//!
//! iceoryx2's signal handler keeps only the last signal, and reading it resets it: its node
//! and waitset waits read it on entry and report a `TerminationRequest`, after which the flag
//! says nothing. A request that arrived while a node was busy between waits would thus be
//! seen once, by whichever wait came next, and lost to every later reader. Here the first
//! reader to see it records it for the life of the process, and every wait that reports it
//! records it too.

use iceoryx2::node::{Node, NodeWaitFailure};
use iceoryx2::service::Service;
use iceoryx2_bb_posix::signal::SignalHandler;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Set once a stop request was seen; never cleared (a process does not un-ask to stop).
static TERMINATION_SEEN: AtomicBool = AtomicBool::new(false);

/// True once SIGINT or SIGTERM has arrived in this process (what
/// [`crate::NodeRuntime::keep_running`] looks at), for code that has no runtime at hand,
/// e.g. to tell a device lost in a stop from a failure. Reads a flag; no system call.
pub fn termination_requested() -> bool {
    if !TERMINATION_SEEN.load(Ordering::Relaxed) && SignalHandler::termination_requested() {
        note_termination_request();
    }
    TERMINATION_SEEN.load(Ordering::Relaxed)
}

/// Records a stop request that an iceoryx2 wait reported (having reset its own flag).
pub(crate) fn note_termination_request() {
    TERMINATION_SEEN.store(true, Ordering::Relaxed);
}

/// Sleeps on `node` for up to `duration` (any signal may cut the sleep short); returns
/// whether a stop was requested.
pub(crate) fn wait_on_node<S: Service>(node: &Node<S>, duration: Duration) -> bool {
    if let Err(NodeWaitFailure::TerminationRequest) = node.wait(duration) {
        note_termination_request();
    }
    termination_requested()
}
