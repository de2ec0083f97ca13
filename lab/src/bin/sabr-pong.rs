//! `sabr-pong`: the echo side of one ping-pong baseline of `sabr bench`; answers `--count`
//! messages over `--transport` and exits.

use clap::Parser;
use sabr_lab::bench::pong::{self, PongArgs};
use std::process::ExitCode;

fn main() -> ExitCode {
    let result = pong::run(&PongArgs::parse()).map(|()| ExitCode::SUCCESS);
    sabr_node::console::exit_status("sabr-pong", result)
}
