//! The common process runtime of every SABR service.
//!
//! - [`NodeRuntime`]: the iceoryx2 node of the process in the graph's [`Domain`] (env
//!   `SABR_DOMAIN`, one explicit iceoryx2 config for every process), stale-node cleanup at start,
//!   SIGINT/SIGTERM handling, readiness and heartbeat on `sabr/graph/lifecycle`, typed
//!   [`Publisher`]/[`Subscriber`] ports, and the main loops [`NodeRuntime::run_loop`] (fixed
//!   rate) and [`NodeRuntime::run_on_data`] (wake on data, with an idle deadline).
//! - [`Deadline`]: notices a stalled or dead peer while waiting.
//! - [`GraphObserver`]: watches the lifecycle of all nodes of a domain (used by the launcher).
//! - [`monotonic_ns`]: the clock of every `t_ns`.
//! - [`console`]: standard output and error that never panic (`out!`, `outln!`, `errln!`), for
//!   the services and the command-line tools alike.
//!
//! A consumer that wakes on data and notices a stalled producer:
//!
//! ```no_run
//! use sabr_msgs::{services, EncoderSample, TrackerFrame};
//! use sabr_node::{Deadline, NodeRuntime};
//! use std::time::Duration;
//!
//! fn main() -> Result<(), sabr_node::NodeError> {
//!     let mut rt = NodeRuntime::start("sync")?;
//!     let encoders = rt.subscriber::<EncoderSample>(services::ENCODER_SAMPLES)?;
//!     let frames = rt.subscriber::<TrackerFrame>(services::TRACKER_FRAMES)?;
//!     let mut encoder_deadline = Deadline::new(Duration::from_millis(20));
//!     rt.run_on_data(&[&encoders, &frames], Duration::from_millis(10), |_ctx| {
//!         encoders.drain(|_sample| encoder_deadline.feed())?;
//!         frames.drain(|_frame| { /* match and publish */ })?;
//!         if encoder_deadline.expired() {
//!             tracing::warn!(silence = ?encoder_deadline.silence(), "encoder stream stalled");
//!         }
//!         Ok::<_, sabr_node::NodeError>(())
//!     })?;
//!     Ok(())
//! }
//! ```

pub mod console;
mod deadline;
mod domain;
pub mod doorbell;
mod doorbell_rpc;
mod events;
mod files;
mod message;
mod observer;
mod orphans;
mod ports;
mod runtime;
mod service;
mod signals;
mod time;
mod transport;

pub use deadline::Deadline;
pub use domain::{Domain, DEFAULT_DOMAIN, DOMAIN_ENV, MAX_DOMAIN_LEN};
pub use doorbell::Doorbell;
pub use doorbell_rpc::{Answered, DoorbellClient, DoorbellServer, Pending};
pub use files::{domain_files, release_domain};
pub use message::Message;
pub use observer::GraphObserver;
pub use ports::{Publisher, Subscriber};
pub use runtime::{
    parse_loop_phase, run_dir, validate_node_name, Exit, LoopCtx, NodeRuntime, HEARTBEAT_PERIOD,
    LOOP_PHASE_ENV, MAX_LOOP_PHASE_US, NODE_NAME_ENV, RUN_DIR_ENV,
};
pub use service::{in_run_dir, service_main, StallWatch, StatusTimer, STATUS_PERIOD};
pub use signals::termination_requested;
pub use time::{delay_to_phase, monotonic_ns};
pub use transport::{Transport, Waitable};

/// The iceoryx2 crate this runtime is built on, for direct use of what the helpers lack.
pub use iceoryx2;
/// The message types and service names.
pub use sabr_msgs as msgs;

/// Errors of the node runtime; each names what failed and why.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The domain name is not usable.
    #[error("invalid domain {value:?} (env SABR_DOMAIN): {reason}")]
    InvalidDomain {
        /// The rejected value.
        value: String,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// The node name is not usable.
    #[error("invalid node name {name:?}: {reason}")]
    InvalidName {
        /// The rejected name.
        name: String,
        /// Why it was rejected.
        reason: String,
    },
    /// The loop phase given by the launcher is not usable.
    #[error("invalid loop phase {value:?} (env SABR_LOOP_PHASE_US): {reason}")]
    InvalidLoopPhase {
        /// The rejected value.
        value: String,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// The iceoryx2 node could not be created.
    #[error("cannot create the iceoryx2 node: {0}")]
    Node(String),
    /// An operation on a service or port failed.
    #[error("service {service:?}: {operation} failed: {reason}")]
    Port {
        /// The service name.
        service: String,
        /// What was attempted.
        operation: &'static str,
        /// The iceoryx2 error.
        reason: String,
    },
}

impl NodeError {
    pub(crate) fn port(
        service: &str,
        operation: &'static str,
        error: impl std::fmt::Debug,
    ) -> Self {
        NodeError::Port {
            service: service.to_owned(),
            operation,
            reason: format!("{error:?}"),
        }
    }
}

/// Sets up logging to stderr (level from `RUST_LOG`, default `info`; no colours unless stderr
/// is a terminal) and iceoryx2's own log level (warnings). The launcher sends each node's
/// stderr to `runs/<id>/logs/<node>.log`. Calling it again does nothing.
pub fn init_tracing() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    // An error only means a subscriber is already installed.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
}
