//! [`IkClient`]: one request at a time to the IK server, with a timeout.

use sabr_msgs::{services, IkRequest, IkResponse};
use sabr_node::{DoorbellClient, NodeError, NodeRuntime};
use std::time::Duration;

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
    client: DoorbellClient<IkRequest, IkResponse>,
    next_id: u64,
}

impl IkClient {
    /// Opens the IK service (creating it if no server runs yet).
    pub fn new(rt: &NodeRuntime) -> Result<Self, NodeError> {
        Ok(Self {
            client: rt.client::<IkRequest, IkResponse>(services::IK_SOLVE)?,
            next_id: 1,
        })
    }

    /// Sends `request` (its `id` is replaced by the client's next id), rings the server's
    /// doorbell and sleeps on this process's doorbell up to `timeout` for the response. The
    /// response's status may still be an error (unreachable or invalid target, no parameters).
    pub fn solve(
        &mut self,
        mut request: IkRequest,
        timeout: Duration,
    ) -> Result<IkResponse, IkClientError> {
        request.id = self.next_id;
        self.next_id += 1;
        let pending = self.client.send(request)?.ok_or(IkClientError::NoServer)?;
        match self.client.receive(&pending, timeout)? {
            Some(response) => Ok(response),
            None if !pending.is_connected() => Err(IkClientError::ServerGone { id: request.id }),
            None => Err(IkClientError::Timeout {
                id: request.id,
                timeout,
            }),
        }
    }
}
