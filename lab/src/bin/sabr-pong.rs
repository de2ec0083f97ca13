//! `sabr-pong`: the echo side of one ping-pong baseline of `sabr bench`; answers `--count`
//! messages over `--transport` and exits.

use clap::Parser;
use sabr_lab::bench::pong::{self, PongArgs};
use std::process::ExitCode;

fn main() -> ExitCode {
    match pong::run(&PongArgs::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("sabr-pong: {error:#}");
            ExitCode::FAILURE
        }
    }
}
