//! `sabr-ik`: the IK server process. Answers `IkRequest`s on `sabr/ik/solve` with joints and
//! motor counts under the parameter set in service, and reloads the parameters when the
//! calibrator announces a new set.

use anyhow::Context;
use clap::Parser;
use sabr_ik::{server, IkSolver, ParameterSet};
use sabr_node::{Exit, NodeRuntime};
use std::path::PathBuf;
use std::process::ExitCode;

/// The IK server of the SABR graph (request-response on `sabr/ik/solve`).
#[derive(Debug, Parser)]
#[command(name = "sabr-ik", version)]
struct Args {
    /// Parameter file served until the calibrator announces a new set (version 0): a
    /// calibrated params.toml, or a robot.toml (it has no joint offsets, so requests get
    /// `NoParameters` until a calibrated set arrives). Without it, no set is in service until
    /// the first announcement.
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
}

fn main() -> ExitCode {
    sabr_node::service_main("ik", run)
}

fn run(args: &Args, rt: &mut NodeRuntime) -> anyhow::Result<Exit> {
    let mut solver = match &args.params {
        Some(path) => {
            let set = ParameterSet::load(path, 0).context("--params")?;
            if set.params.joints.offset.is_none() {
                tracing::warn!(path = %path.display(),
                    "the parameter file has no joint offsets: requests get NoParameters until a calibrated set is announced");
            }
            tracing::info!(path = %path.display(), "parameter set v0 in service");
            IkSolver::with_parameters(set)
        }
        None => {
            tracing::warn!("no --params: requests get NoParameters until a set is announced");
            IkSolver::new()
        }
    };
    let (exit, counts) = server::serve(rt, &mut solver)?;
    tracing::info!(
        solved = counts.solved,
        refused = counts.refused,
        send_failures = counts.send_failures,
        "IK server stopped"
    );
    Ok(exit)
}
