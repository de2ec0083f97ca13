//! `sabr`: the launcher and the user commands of the SABR biopsy-robot project.

use clap::{Parser, Subcommand};

mod calibrate_cmd;
mod evaluate_cmd;
mod export_cmd;
mod import_cmd;
mod kinematics_cmd;
mod lab_cmd;
mod sim_cmd;

use sabr_launcher as launcher;

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
    /// Launch a process graph from a TOML launch file and supervise it until it stops.
    Launch(launcher::LaunchArgs),
    /// Latency and compute benchmarks: ping-pong baselines, FK/IK, sim record, calibrate
    /// (runs `sabr-lab bench`; `sabr bench --help` for its options).
    #[command(disable_help_flag = true)]
    Bench(lab_cmd::LabArgs),
    /// Calibrate the robot from a recording: params.toml, report.json, report.html.
    Calibrate(calibrate_cmd::CalibrateArgs),
    /// Error of calibrated serial-arm parameters on another poses-v1 recording.
    Evaluate(evaluate_cmd::EvaluateArgs),
    /// Import measured data as a recording: `sabr import ipa` (UR10 laser-tracker series → poses v1).
    Import(import_cmd::ImportArgs),
    /// Soak: run the sensing graph for minutes; lost encoder samples, rates, memory, CPU
    /// (runs `sabr-lab soak`; `sabr soak --help` for its options).
    #[command(disable_help_flag = true)]
    Soak(lab_cmd::LabArgs),
    /// Export a recording for other tools: `sabr export mcap` (Foxglove).
    Export(export_cmd::ExportArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fk(args) => kinematics_cmd::run_fk(&args),
        Command::Ik(args) => kinematics_cmd::run_ik(&args),
        Command::Sim(args) => sim_cmd::run(&args),
        Command::Launch(args) => launcher::run(&args),
        Command::Bench(args) => lab_cmd::run("bench", &args),
        Command::Calibrate(args) => calibrate_cmd::run(&args),
        Command::Evaluate(args) => evaluate_cmd::run(&args),
        Command::Import(args) => import_cmd::run(&args),
        Command::Soak(args) => lab_cmd::run("soak", &args),
        Command::Export(args) => export_cmd::run(&args),
    };
    sabr_node::console::exit_status("sabr", result)
}
