//! The performance lab of the SABR graph: `sabr bench` (transport baselines, compute costs,
//! live-graph hops, CPU use) and `sabr soak` (minutes of the sensing graph: losses, memory),
//! kept out of the `sabr` command. The `sabr-lab` executable runs them (`sabr bench` and
//! `sabr soak` hand over to it); `sabr-pong` is the echo side of the ping-pong baselines.

pub mod bench;
mod procfs;
pub mod soak;
