//! [`IkClient`]: one request at a time to the IK server, with a timeout.

use sabr_msgs::{services, IkRequest, IkResponse};
use sabr_node::iceoryx2::port::notifier::Notifier;
use sabr_node::iceoryx2::prelude::ipc;
use sabr_node::{Client, NodeError, NodeRuntime};
use std::time::{Duration, Instant};

/// Why a request got no response.
#[derive(Debug, thiserror::Error)]
pub enum IkClientError {
    /// An iceoryx2 operation failed.
    #[error(transparent)]
    Port(#[from] NodeError),
    /// No IK server is connected to the service.
    #[error("no IK server is running on {}", services::IK_SOLVE)]
    NoServer,
    /// The server disconnected before it answered.
    #[error("the IK server went away before answering request {id}")]
    ServerGone {
        /// The request's id.
        id: u64,
    },
    /// No answer within the timeout.
    #[error("the IK server did not answer request {id} within {timeout:?}")]
    Timeout {
        /// The request's id.
        id: u64,
        /// The timeout.
        timeout: Duration,
    },
}

/// A client of the IK server (`sabr-ik`) on [`services::IK_SOLVE`].
///
/// ```no_run
/// use sabr_ik::IkClient;
/// use sabr_msgs::IkRequest;
/// use std::time::Duration;
///
/// let rt = sabr_node::NodeRuntime::start("planner")?;
/// let mut ik = IkClient::new(&rt)?;
/// let request = IkRequest {
///     tip_mm: [0.0, -90.0, 180.0],
///     direction: [0.0, 0.0, 1.0],
///     near_joints_rad: sabr_model::HOME_JOINTS,
///     ..IkRequest::default()
/// };
/// let response = ik.solve(request, Duration::from_millis(100))?;
/// println!("{:?}: {:?} {}", response.status, response.joints_rad, response.error);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct IkClient {
    client: Client<IkRequest, IkResponse>,
    wake_server: Notifier<ipc::Service>,
    next_id: u64,
}

impl IkClient {
    /// Opens the IK service (creating it if no server runs yet) and a notifier that wakes
    /// the server.
    pub fn new(rt: &NodeRuntime) -> Result<Self, NodeError> {
        Ok(Self {
            client: rt.client::<IkRequest, IkResponse>(services::IK_SOLVE)?,
            wake_server: rt.notifier(services::IK_SOLVE)?,
            next_id: 1,
        })
    }

    /// Sends `request` (its `id` is replaced by the client's next id), wakes the server and
    /// waits up to `timeout` for the response. The response's status may still be an error
    /// (unreachable or invalid target, no parameters).
    pub fn solve(
        &mut self,
        mut request: IkRequest,
        timeout: Duration,
    ) -> Result<IkResponse, IkClientError> {
        let start = Instant::now();
        request.id = self.next_id;
        self.next_id += 1;
        let pending = self
            .client
            .send_copy(request)
            .map_err(|e| port_error("send a request", e))?;
        if pending.number_of_server_connections() == 0 {
            return Err(IkClientError::NoServer);
        }
        self.wake_server
            .notify()
            .map_err(|e| port_error("wake the server", e))?;
        let receive = || -> Result<Option<IkResponse>, IkClientError> {
            let response = pending
                .receive()
                .map_err(|e| port_error("receive a response", e))?;
            Ok(response.map(|response| *response.payload()))
        };
        // Poll, yielding the CPU between polls: on a busy host the server may need this
        // core to answer (a pure spin made the p99 ten times longer on a loaded host).
        loop {
            if let Some(response) = receive()? {
                return Ok(response);
            }
            // The server drops the request right after answering: look once more.
            if !pending.is_connected() {
                return receive()?.ok_or(IkClientError::ServerGone { id: request.id });
            }
            if start.elapsed() >= timeout {
                return Err(IkClientError::Timeout {
                    id: request.id,
                    timeout,
                });
            }
            std::thread::yield_now();
        }
    }
}

fn port_error(operation: &'static str, error: impl std::fmt::Debug) -> NodeError {
    NodeError::Port {
        service: services::IK_SOLVE.to_owned(),
        operation,
        reason: format!("{error:?}"),
    }
}
