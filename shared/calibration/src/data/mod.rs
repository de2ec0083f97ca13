//! Data layer: a recording of the biopsy robot turned into observations.
//!
//! - [`frames`]: tracker rows → tools in the robot base `Bb`, relative to the base marker;
//! - [`clock`]: the tracker's exposure clock (the robust line the latency is defined
//!   against; the live synchroniser `sabr-sync` fits the same line);
//! - [`encoders`], [`motion`]: the encoder stream at any host time and each joint's direction
//!   of motion from its count history;
//! - [`phases`], [`span`]: the session plan's phases and the span of the session;
//! - [`session`]: the synchronised session and its [`session::Observation`]s at a latency;
//! - [`latency`]: the model-free latency estimate that starts the fits.
//!
//! Nothing here knows a model's parameters: the layers above predict what these
//! observations measured.

pub mod clock;
pub mod encoders;
pub mod frames;
pub mod latency;
pub mod motion;
pub mod phases;
pub mod session;
pub mod span;
