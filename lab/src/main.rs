//! `sabr-lab`: the performance lab (`bench`, `soak`); `sabr bench` and `sabr soak` run it.

use clap::{Parser, Subcommand};
use sabr_lab::{bench, soak};
use std::process::ExitCode;

/// The performance lab of the SABR graph.
#[derive(Debug, Parser)]
#[command(name = "sabr-lab", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Latency and compute benchmarks: ping-pong baselines, FK/IK, sim record, calibrate,
    /// live-graph hops.
    Bench(bench::BenchArgs),
    /// Soak: run the sensing graph for minutes; lost encoder samples, rates, memory, CPU.
    Soak(soak::SoakArgs),
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Bench(args) => bench::run(&args),
        Command::Soak(args) => soak::run(&args),
    };
    sabr_node::console::exit_status("sabr-lab", result)
}
