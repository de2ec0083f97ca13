//! The IK server of the SABR graph and its client.
//!
//! - [`IkSolver`]: answers an [`IkRequest`] (needle tip and direction in `Bb`, mm) with the
//!   joints (rad) and motor counts of the loaded [`ParameterSet`], using the same library calls
//!   as `sabr ik` (`sabr_model::realtime::RealtimeGeometry::inverse`, then
//!   `RobotParams::counts_from_joints` at rest).
//!   NaN, infinite, degenerate and unreachable targets get an error status and a reason, never
//!   a guess.
//! - [`server::serve`]: the event-driven server loop of the `sabr-ik` process on
//!   [`services::IK_SOLVE`]; it reloads the parameters when the calibrator announces a new set
//!   on [`services::CALIBRATOR_PARAMETERS`] and keeps the previous set when the new file is
//!   corrupt.
//! - [`IkClient`]: sends a request, rings the server's doorbell and sleeps on its own until
//!   the answer rings it back (the graph's doorbell transport, `sabr_node::Doorbell`).
//!
//! [`IkRequest`]: sabr_msgs::IkRequest
//! [`services::IK_SOLVE`]: sabr_msgs::services::IK_SOLVE
//! [`services::CALIBRATOR_PARAMETERS`]: sabr_msgs::services::CALIBRATOR_PARAMETERS

mod client;
mod parameter_set;
pub mod server;
mod solver;

pub use client::{IkClient, IkClientError};
pub use parameter_set::ParameterSet;
pub use solver::{IkSolver, ReloadOutcome};
