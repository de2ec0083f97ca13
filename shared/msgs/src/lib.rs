//! Fixed-layout sample types exchanged over iceoryx2 shared memory, and the one list of
//! service names of the SABR process graph.
//!
//! Every message is `#[repr(C)]`, `Copy`, and derives [`ZeroCopySend`] with a stable type name
//! (`sabr.<Type>.v<N>`) so that processes built separately agree on the layout; changing a layout
//! means bumping the version in the type name. Times `t_ns` are host `CLOCK_MONOTONIC` in
//! nanoseconds (the same clock as the recording format), lengths are millimetres and angles
//! radians, as in `docs/robot-model.md`.

// The `ZeroCopySend` derive expands to an `unsafe impl`; the derive checks `repr(C)` and that
// every field is itself `ZeroCopySend`, which is the whole safety contract.
#![allow(unsafe_code)]

mod fixed_string;
mod graph;
mod motion;
mod sensing;
pub mod services;

pub use fixed_string::{FixedString, FixedStringError};
pub use graph::{Lifecycle, LifecycleState, NodeLabel};
pub use motion::{
    IkRequest, IkResponse, IkStatus, MotionState, MotionStatus, MotorSetpoint,
    ParameterSetAnnouncement, PhaseMark, IK_REQUESTS_PER_SETPOINT_PERIOD, SETPOINT_PERIOD_NS,
};
pub use sensing::{
    CounterLatch, EncoderSample, LatencySource, MatchQuality, MatchedSample, RigTruth, Tool,
    ToolSample, ToolStatus, TrackerFrame, ENCODER_RATE_HZ, JOINTS, TOOLS,
};

/// Re-export of the derive and trait every message implements, for services that define
/// private test messages of their own.
pub use iceoryx2::prelude::ZeroCopySend;
