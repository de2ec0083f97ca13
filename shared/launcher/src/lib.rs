//! `sabr launch FILE`: runs a process graph described by a TOML launch file.
//!
//! Starts the nodes in dependency order, each once its dependencies announced readiness on
//! `sabr/graph/lifecycle`; supervises them (restart policy, required nodes, optional heartbeat
//! watchdog); stops in reverse order on Ctrl-C/SIGTERM, `--duration`, a node announcing the job
//! done, or a required node ending; then removes the domain's iceoryx2 leftovers. Each node's
//! stdout and stderr go to `runs/<id>/logs/<node>.log`. See [`spec`] for the file format.
//!
//! A library: the `sabr` command, the performance lab (`sabr-lab`) and the integration tests
//! use it.

mod build;
mod out_dir;
pub mod placement;
pub mod progress;
mod run_dir;
pub mod spec;
pub mod steal;
mod supervisor;
pub mod wake_latency;

pub use build::build_graph_executables;
pub use out_dir::create_out_dir;
pub use run_dir::RunDir;
pub use supervisor::{describe, StopReason};

use anyhow::Context;
use sabr_node::{console, errln, Domain};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;
use steal::CpuTimes;
use supervisor::Supervisor;
use wake_latency::WakeLatencyBound;

/// Arguments of `sabr launch`.
#[derive(Debug, Clone, clap::Args)]
pub struct LaunchArgs {
    /// Launch file (TOML), e.g. launch/graphs/sim-sensing.toml.
    pub file: PathBuf,
    /// Directory under which the run directory `<id>/` (logs, recordings) is created.
    #[arg(long, default_value = "runs")]
    pub run_dir: PathBuf,
    /// iceoryx2 domain isolating this graph [default: env SABR_DOMAIN, else "sabr"].
    #[arg(long)]
    pub domain: Option<String>,
    /// Stop the graph (successfully) after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Directory of the node executables [default: the directory of this executable; a cargo
    /// build of this workspace builds the ones the launch file names first].
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// Only validate the launch file and print the start order.
    #[arg(long)]
    pub check: bool,
    /// Run the nodes without the launch file's placement (`cpus`, `sched`,
    /// `cpu_wake_latency_us`): for a machine where real-time scheduling or the CPU latency
    /// bound is not allowed. The graph works the same, with less predictable latency.
    #[arg(long)]
    pub unplaced: bool,
}

/// Prints what `sabr launch --check` shows: the graph's start order with each node's placement
/// and loop phase, and the CPU wake-up latency bound (through [`console`]: a closed standard
/// output, `| head`, ends the listing quietly).
fn print_start_order(args: &LaunchArgs, graph: &spec::GraphSpec) {
    use std::fmt::Write as _;
    let mut text = format!("{}: valid; start order:\n", args.file.display());
    if let Some((latency_us, _)) = graph.cpu_wake_latency {
        let polled = match wake_latency::polls_idle_cpus_itself(latency_us) {
            true => "; this kernel has no cpuidle driver: the launcher polls idle CPUs itself",
            false => "",
        };
        let _ = writeln!(
            text,
            "  (CPU wake-up latency held at ≤ {latency_us} µs while it runs{polled})"
        );
    }
    for node in &graph.nodes {
        let placement = if node.placement.is_default() {
            String::new()
        } else {
            format!(", {}", node.placement)
        };
        let phase = node
            .loop_phase_us
            .map_or(String::new(), |phase| format!(", phase_us = {phase}"));
        let _ = writeln!(
            text,
            "  {} ({}{placement}{phase})",
            node.name,
            node.exec.display()
        );
    }
    console::write_str(&text);
}

/// The directory of the node executables: `dir` when given, else the directory of the running
/// `sabr` executable (cargo builds them side by side).
pub fn bin_dir_or_beside_sabr(dir: Option<&Path>) -> anyhow::Result<PathBuf> {
    match dir {
        Some(dir) => Ok(dir.to_path_buf()),
        None => std::env::current_exe()
            .context("cannot locate the sabr executable")?
            .parent()
            .map(PathBuf::from)
            .context("the sabr executable has no directory"),
    }
}

/// Runs `sabr launch`: success (0) when the graph was stopped on request, by `--duration` or
/// because a node announced the job done; failure (1) when a required node ended or could not
/// be started; an error for a bad launch file or arguments.
pub fn run(args: &LaunchArgs) -> anyhow::Result<ExitCode> {
    let bin_dir = bin_dir_or_beside_sabr(args.bin_dir.as_deref())?;
    if args.bin_dir.is_none() && !args.check {
        build_graph_executables(&args.file, &bin_dir)?;
    }
    let mut graph = spec::load(&args.file, &bin_dir)?;
    if args.unplaced {
        graph.remove_placement();
    }
    spec::check_placements(&graph).map_err(|error| {
        anyhow::anyhow!("{error}\n(or add --unplaced to run the graph without its placement)")
    })?;
    if args.check {
        print_start_order(args, &graph);
        return Ok(ExitCode::SUCCESS);
    }
    let duration = match args.duration {
        Some(s) if s.is_finite() && s > 0.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--duration must be a positive number of seconds, got {s}"),
        None => None,
    };
    let domain = match &args.domain {
        Some(name) => Domain::new(name)?,
        None => Domain::from_env()?,
    };
    let run = RunDir::create(&args.run_dir)?;
    let wake_latency = graph
        .cpu_wake_latency
        .map(|(latency_us, line)| {
            WakeLatencyBound::hold(latency_us).map_err(|reason| spec::LaunchFileError {
                file: graph.file.clone(),
                line,
                column: 1,
                reason,
            })
        })
        .transpose()?;
    errln!(
        "sabr launch: {} — {} nodes, domain {domain}, run directory {}",
        args.file.display(),
        graph.nodes.len(),
        run.path().display()
    );
    if let Some(bound) = &wake_latency {
        errln!(
            "sabr launch: CPU wake-up latency held at ≤ {} µs while the graph runs",
            bound.latency_us
        );
        if !bound.polled_cpus().is_empty() {
            errln!(
                "sabr launch: this kernel has no cpuidle driver to obey it: polling idle CPUs \
                 {:?} from the launcher (SCHED_IDLE threads)",
                bound.polled_cpus()
            );
        }
    }
    let cpu_at_start = CpuTimes::now().ok();
    let mut supervisor = Supervisor::new(&graph, &run, domain.clone(), duration)?;
    let reason = supervisor.run();
    supervisor.say(format_args!("stopping the graph: {reason}"));
    supervisor.stop_all();
    let stolen = cpu_at_start.zip(CpuTimes::now().ok());
    if let Some(share) = stolen.and_then(|(start, end)| end.steal_share_since(&start)) {
        if share >= steal::NOTABLE_STEAL {
            errln!(
                "sabr launch: the hypervisor took {:.0} % of the CPUs' time while the graph ran \
                 (steal): late wake-ups and skipped samples in the logs are the host's",
                share * 100.0
            );
        }
    }
    drop(wake_latency);
    let left = sabr_node::release_domain(&domain);
    if !left.is_empty() {
        errln!("sabr launch: iceoryx2 files of domain {domain} left behind: {left:?}");
    }
    errln!(
        "sabr launch: {} — logs in {}",
        if reason.is_success() {
            "finished"
        } else {
            "FAILED"
        },
        run.path().join("logs").display()
    );
    Ok(if reason.is_success() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
