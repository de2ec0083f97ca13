//! The NDI Combined API (Polaris) serial protocol, both sides of the wire.
//!
//! - [`crc`]: CRC-16/ARC, the checksum of every command and reply.
//! - [`command`]: host commands (`INIT:`, `COMM:`, `PHSR:`, `BX:`, ...) encoded with their CRC, and
//!   decoded again on the device side.
//! - [`framing`]: splitting a byte stream into replies (ASCII replies ending in CRC + CR, binary
//!   `C4 A5` BX replies), checking CRCs, resynchronising after garbage; [`ReplyReader`] over any
//!   [`std::io::Read`].
//! - [`reply`], [`bx`], [`tx`], [`text`]: typed replies — one [`TrackingReply`] for both BX and TX,
//!   port-handle lists (PHSR), device errors (`ERRORxx`), `OKAY`.
//! - [`server`]: the device side, an [`NdiServer`] state machine for the simulated rig, fed by a
//!   [`FrameSource`]; [`pty`]: a pseudo-terminal to serve it on.
//! - [`driver`]: the host side, [`NdiDriver`], over a real serial port (or the rig's PTY);
//!   [`availability`]: when a polled frame became available at the device; [`pacing`]: when to
//!   start polling for the next frame.
//!
//! Units: positions in millimetres in the tracker frame `S`, quaternions (q0, qx, qy, qz) unitless.
//! Every malformed input is a typed error, never a panic.

pub mod availability;
pub mod bx;
pub mod command;
pub mod crc;
pub mod driver;
pub mod error;
pub mod framing;
pub mod pacing;
pub mod pty;
pub mod reply;
pub mod server;
pub mod text;
pub mod tx;

pub use availability::{Availability, AvailabilityEstimator};
pub use command::{
    Baud, CommSettings, Command, CommandError, DataBits, Parity, PhsrFilter, StopBits,
    TrackingPriority,
};
pub use crc::crc16;
pub use driver::{CommandWarning, DriverConfig, DriverError, DriverStats, NdiDriver, Stamped};
pub use error::{DeviceError, EncodeError, ReplyError};
pub use framing::{decode_reply, FramerStats, RawReply, ReadError, ReplyFramer, ReplyReader};
pub use pacing::PollPacer;
pub use pty::{Pty, PtyError, ServeStats};
pub use reply::{
    ActiveMarker, HandleReading, HandleStatus, MarkerPosition, ReplyOptions, ToolInfo,
    TrackingReply, Transform,
};
pub use server::{
    FrameSource, MeasurementVolume, NdiServer, ServerMode, ServerStats, SimFrame, SimReading,
};
pub use text::{Acknowledgement, PortHandleStatus};
