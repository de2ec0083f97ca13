//! `sabr sim record`: simulate a calibration session on the simulated rig and write the
//! recording (format v1) to DIR and the truth (true parameters, effects, true validation
//! poses, tracker frame timing) to DIR/truth/.

use sabr_node::outln;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context};
use sabr_sim::{record_session, truth_dir, write_session, SimConfig, SimEffect};

/// Arguments of `sabr sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    #[command(subcommand)]
    command: SimCommand,
}

#[derive(Debug, clap::Subcommand)]
enum SimCommand {
    /// Record a simulated session (homing, excitation, tip phase, validation poses).
    Record(RecordArgs),
}

/// Arguments of `sabr sim record`.
#[derive(Debug, clap::Args)]
struct RecordArgs {
    /// Output directory: must be absent or empty. The truth goes to DIR/truth/.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Seed of the true robot, the plan and the sensor noise (same seed → same bytes).
    #[arg(long, value_name = "N")]
    seed: u64,
    /// Effect injected into the true robot or tracker (repeatable), joints 1..5:
    /// `ripple:joint=J,harmonic=H,amplitude=RAD[,phase=RAD]`, `backlash:joint=J,width=RAD`,
    /// `link:link=l_f|l_fe|l_b|l_be|d_offset,delta=MM`, `compliance:joint=J,gain=RAD`,
    /// `tilt:joint=J,axis=1|2,angle=RAD` (joint-axis tilt); outside the model's effect
    /// library: `latency:ms=MS` (extra tracker latency), `thermal:joint=J,amplitude=RAD[,tau_s=S]`
    /// (joint drift), `thermal:link=NAME,delta=MM[,tau_s=S]` (link-length drift),
    /// `sag:mm=MM` (needle sag under gravity), `clockdrift:ppm=PPM` (tracker clock rate).
    #[arg(long = "effect", value_name = "SPEC", value_parser = parse_effect)]
    effects: Vec<SimEffect>,
    /// Multiplies the phase durations (1 ≈ 5 minutes of robot time).
    #[arg(long, value_name = "F", default_value_t = 1.0)]
    duration_scale: f64,
}

fn parse_effect(spec: &str) -> Result<SimEffect, sabr_sim::EffectSpecError> {
    spec.parse()
}

/// Runs `sabr sim ...`.
pub fn run(args: &SimArgs) -> anyhow::Result<ExitCode> {
    match &args.command {
        SimCommand::Record(record) => run_record(record),
    }
}

fn run_record(args: &RecordArgs) -> anyhow::Result<ExitCode> {
    if args.out.exists() {
        let mut entries = std::fs::read_dir(&args.out)
            .with_context(|| format!("cannot read the output directory {}", args.out.display()))?;
        if entries.next().is_some() {
            bail!(
                "{} is not empty: choose a new output directory (nothing is overwritten)",
                args.out.display()
            );
        }
    }
    let started = Instant::now();
    let mut config = SimConfig::new(args.seed);
    config.duration_scale = args.duration_scale;
    config.effects = args.effects.clone();
    let (recording, truth) = record_session(&config)?;
    write_session(&args.out, &recording, &truth)?;

    let span_s = match (recording.encoders.first(), recording.encoders.last()) {
        (Some(first), Some(last)) => (last.t_ns - first.t_ns) as f64 * 1e-9,
        _ => 0.0,
    };
    let dropped = truth
        .frames
        .iter()
        .filter(|f| f.arrival_ns.is_none())
        .count();
    outln!(
        "recorded {span_s:.1} s of robot time: {} encoder samples, {} tracker frames ({} dropped), \
         {} validation poses, {} effect(s) → {} (truth in {}) in {:.2} s",
        recording.encoders.len(),
        truth.frames.len(),
        dropped,
        truth.validation.len(),
        truth.effects.len(),
        args.out.display(),
        truth_dir(&args.out).display(),
        started.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}
