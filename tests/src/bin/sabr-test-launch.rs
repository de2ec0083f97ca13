//! `sabr launch` as a binary of the test package, so `cargo test -p sabr-integration-tests`
//! builds it next to `sabr-test-node` (same code as `sabr launch`: `sabr_launcher::run`).

use clap::Parser;
use std::process::ExitCode;

/// Launch a process graph (identical to `sabr launch`).
#[derive(Debug, Parser)]
#[command(name = "sabr-test-launch")]
struct Cli {
    #[command(flatten)]
    args: sabr_launcher::LaunchArgs,
}

fn main() -> ExitCode {
    let result = sabr_launcher::run(&Cli::parse().args);
    sabr_node::console::exit_status("sabr", result)
}
