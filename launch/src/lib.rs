//! Library side of the `sabr` command: the launcher, shared by `main.rs` and the
//! integration tests.

pub mod launcher;
pub mod progress;
