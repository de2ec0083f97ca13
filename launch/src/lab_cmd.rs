//! `sabr bench` and `sabr soak`: hand over to the performance lab, the `sabr-lab` executable
//! beside `sabr` (its own crate, so the lab's code stays out of this command).

use anyhow::{bail, Context};
use std::ffi::OsString;
use std::os::unix::process::CommandExt;
use std::process::{Command, ExitCode};

/// Arguments passed to `sabr-lab <command>` unchanged.
#[derive(Debug, clap::Args)]
pub struct LabArgs {
    /// The lab command's arguments (see `sabr bench --help`, `sabr soak --help`).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, num_args = 0..)]
    args: Vec<OsString>,
}

/// Replaces this process with `sabr-lab <command> <args>`; returns only if that fails.
pub fn run(command: &str, args: &LabArgs) -> anyhow::Result<ExitCode> {
    let sabr = std::env::current_exe().context("cannot locate the sabr executable")?;
    let lab = sabr.with_file_name("sabr-lab");
    if !lab.is_file() {
        bail!(
            "{} not found: build it with `cargo build --release --workspace --bins`",
            lab.display()
        );
    }
    let error = Command::new(&lab).arg(command).args(&args.args).exec();
    Err(error).with_context(|| format!("cannot run {} {command}", lab.display()))
}
