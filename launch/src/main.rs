//! `sabr`: the launcher and the user commands of the SABR biopsy-robot project.

use clap::{Parser, Subcommand};

mod kinematics_cmd;
mod sim_cmd;

/// Command-line interface of the SABR robot software.
#[derive(Debug, Parser)]
#[command(name = "sabr", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Forward kinematics: joints or counts CSV → tip and needle direction CSV.
    Fk(kinematics_cmd::FkArgs),
    /// Inverse kinematics: targets CSV → joints (and counts) CSV.
    Ik(kinematics_cmd::IkArgs),
    /// Simulated rig: `sabr sim record` writes a simulated session and its truth.
    Sim(sim_cmd::SimArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fk(args) => kinematics_cmd::run_fk(&args),
        Command::Ik(args) => kinematics_cmd::run_ik(&args),
        Command::Sim(args) => sim_cmd::run(&args),
    };
    match result {
        Ok(code) => code,
        Err(error) => {
            eprintln!("sabr: {error:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
