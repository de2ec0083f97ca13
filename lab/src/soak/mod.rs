//! `sabr soak`: runs the sensing graph at full rate for minutes and checks that it loses no
//! encoder sample and that no process grows.
//!
//! The graph runs as a child `sabr launch` in a domain of its own. A monitor node in that
//! domain subscribes to the encoder samples, tracker frames and matched samples before the
//! graph starts and checks their sequence numbers; it learns the node processes from their
//! lifecycle announcements and reads every process's resident memory (`VmRSS`) and CPU time
//! (`utime + stime`) once a second. The measurement window starts once every node is ready.
//! At the end it prints per process the start/end/peak RSS, the least-squares RSS slope after
//! the warm-up and the CPU use, the stream counts and rates, and PASS/FAIL against the goals;
//! `soak.csv`, `streams.csv` and `summary.txt` go to the output directory. Exit status 1 on
//! FAIL.

mod launcher_child;
mod monitor;
mod processes;
mod report;
mod streams;

use anyhow::{bail, Context};
use launcher_child::LauncherChild;
use monitor::Monitor;
use report::{Goals, Outcome, SoakCsv};
use sabr_launcher::describe;
use sabr_launcher::progress::Progress;
use sabr_launcher::spec;
use sabr_node::{out, outln, Domain};
use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Arguments of `sabr soak`.
#[derive(Debug, Clone, clap::Args)]
pub struct SoakArgs {
    /// Length of the measurement window, minutes (after every node is ready).
    #[arg(long, value_name = "M", default_value_t = 10.0)]
    minutes: f64,
    /// Length of the measurement window in seconds, instead of --minutes.
    #[arg(long, value_name = "S", conflicts_with = "minutes")]
    seconds: Option<f64>,
    /// Output directory for soak.csv, streams.csv, summary.txt, the launcher's output and the
    /// graph's run directory; must be absent or empty [default: runs/soak-<unix time>].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Launch file of the graph.
    #[arg(
        long,
        value_name = "FILE",
        default_value = "launch/graphs/sim-sensing.toml"
    )]
    graph: PathBuf,
    /// Start of the window excluded from the memory slope, s [default: a quarter of the
    /// window, at most 60].
    #[arg(long, value_name = "S")]
    warm_up_s: Option<f64>,
    /// Memory goal: largest RSS slope of any process after the warm-up, KiB per minute
    /// (64 KiB/min ≈ one byte kept per encoder sample).
    #[arg(long, value_name = "KIB_PER_MIN", default_value_t = 64.0)]
    max_rss_slope: f64,
    /// Nominal encoder sample rate, Hz.
    #[arg(long, value_name = "HZ", default_value_t = 1000.0)]
    encoder_hz: f64,
    /// Nominal tracker frame rate, Hz.
    #[arg(long, value_name = "HZ", default_value_t = 20.0)]
    tracker_hz: f64,
    /// Rate goal: fraction of the nominal rates each stream must reach.
    #[arg(long, value_name = "F", default_value_t = 0.95)]
    min_rate_fraction: f64,
    /// Longest wait for every node to announce readiness, s.
    #[arg(long, value_name = "S", default_value_t = 60.0)]
    ready_timeout_s: f64,
    /// iceoryx2 domain of the graph [default: soak-<pid>].
    #[arg(long)]
    domain: Option<String>,
    /// Directory of the node executables [default: the directory of this executable].
    #[arg(long, value_name = "DIR")]
    bin_dir: Option<PathBuf>,
}

/// The validated plan of a soak.
struct Plan {
    window: Duration,
    warm_up: Duration,
    ready_timeout: Duration,
    goals: Goals,
}

impl Plan {
    fn new(args: &SoakArgs) -> anyhow::Result<Self> {
        let window_s = args.seconds.unwrap_or(args.minutes * 60.0);
        let positive = |value: f64, name: &str| {
            if value.is_finite() && value > 0.0 {
                Ok(value)
            } else {
                bail!("{name} must be a positive number, got {value}")
            }
        };
        let window_s = positive(window_s, "--minutes/--seconds")?;
        let warm_up_s = args.warm_up_s.unwrap_or((window_s / 4.0).min(60.0));
        if !(warm_up_s.is_finite() && (0.0..window_s).contains(&warm_up_s)) {
            bail!("--warm-up-s must be ≥ 0 and shorter than the window ({window_s} s), got {warm_up_s}");
        }
        if !(args.min_rate_fraction.is_finite() && (0.0..=1.0).contains(&args.min_rate_fraction)) {
            bail!(
                "--min-rate-fraction must be between 0 and 1, got {}",
                args.min_rate_fraction
            );
        }
        Ok(Self {
            window: Duration::from_secs_f64(window_s),
            warm_up: Duration::from_secs_f64(warm_up_s),
            ready_timeout: Duration::from_secs_f64(positive(
                args.ready_timeout_s,
                "--ready-timeout-s",
            )?),
            goals: Goals {
                max_rss_slope_kib_per_min: positive(args.max_rss_slope, "--max-rss-slope")?,
                encoder_hz: positive(args.encoder_hz, "--encoder-hz")?,
                tracker_hz: positive(args.tracker_hz, "--tracker-hz")?,
                min_rate_fraction: args.min_rate_fraction,
            },
        })
    }
}

/// Where the live phase of a soak ended.
struct Live {
    t0: Instant,
    window_start: Option<Instant>,
    end: Instant,
    early_end: Option<String>,
}

/// Runs `sabr soak`: success if every goal is met, failure (1) otherwise.
pub fn run(args: &SoakArgs) -> anyhow::Result<ExitCode> {
    let plan = Plan::new(args)?;
    let bin_dir = sabr_launcher::bin_dir_or_beside_sabr(args.bin_dir.as_deref())?;
    if args.bin_dir.is_none() {
        sabr_launcher::build_graph_executables(&args.graph, &bin_dir)?;
    }
    let graph = spec::load(&args.graph, &bin_dir)?;
    let domain = Domain::new(
        &args
            .domain
            .clone()
            .unwrap_or_else(|| format!("soak-{}", std::process::id())),
    )?;
    let stale = sabr_node::domain_files(&domain);
    if !stale.is_empty() {
        bail!("domain {domain} is in use (iceoryx2 files {stale:?}); choose another with --domain");
    }
    let out = sabr_launcher::create_out_dir(args.out.clone(), "soak")?;
    let ticks_per_second = crate::procfs::ticks_per_second()?;
    outln!(
        "sabr soak: {} — {} nodes, domain {domain}, window {:.0} s, output {}",
        args.graph.display(),
        graph.nodes.len(),
        plan.window.as_secs_f64(),
        out.display()
    );

    let mut monitor = Monitor::new(&domain)?;
    // A backstop: the launcher stops by itself if this process dies without stopping it.
    let backstop = plan.ready_timeout + plan.window + Duration::from_secs(120);
    let launch_args: Vec<OsString> = vec![
        args.graph.clone().into(),
        "--run-dir".into(),
        out.join("runs").into(),
        "--domain".into(),
        domain.as_str().into(),
        "--duration".into(),
        format!("{}", backstop.as_secs_f64()).into(),
        "--bin-dir".into(),
        bin_dir.clone().into(),
    ];
    let mut launcher = LauncherChild::spawn(&bin_dir, &launch_args, &out.join("launcher.log"))?;
    monitor.track("launcher", launcher.pid());
    let mut csv = SoakCsv::create(&out)?;
    let nodes: Vec<String> = graph.nodes.iter().map(|n| n.name.clone()).collect();

    let live = watch(
        &mut monitor,
        &mut launcher,
        &mut csv,
        &plan,
        &nodes,
        ticks_per_second,
    )?;

    let gathered = monitor.finish();
    let status = launcher.stop(launcher_child::STOP_TIMEOUT);
    let survivors: Vec<u32> = gathered
        .processes
        .iter()
        .map(|p| p.pid)
        .filter(|&pid| process_alive(pid))
        .collect();
    let leftover_files = sabr_node::release_domain(&domain);
    let window_start_s = live
        .window_start
        .map_or(f64::INFINITY, |w| (w - live.t0).as_secs_f64());
    let warm_up_end_s = window_start_s + plan.warm_up.as_secs_f64();
    let figures = gathered
        .processes
        .iter()
        .filter_map(|p| processes::figures(p, window_start_s, warm_up_end_s, ticks_per_second))
        .collect();
    let outcome = Outcome {
        graph: args.graph.clone(),
        window_s: live
            .window_start
            .map_or(0.0, |w| (live.end - w).as_secs_f64()),
        warm_up_s: plan.warm_up.as_secs_f64(),
        gathered,
        figures,
        early_end: live.early_end,
        launcher_exit: status.map_or("did not stop (killed)".to_owned(), describe),
        launcher_ok: status.is_some_and(|s| s.success()),
        survivors,
        leftover_files,
    };
    let checks = report::checks(&outcome, &plan.goals);
    let text = report::summary_text(&outcome, &checks);
    out!("{text}");
    let summary = out.join(report::SUMMARY_TXT);
    std::fs::write(&summary, &text)
        .with_context(|| format!("cannot write {}", summary.display()))?;
    outln!(
        "wrote {}, {} and {} to {}",
        report::PROCESS_CSV,
        report::STREAMS_CSV,
        report::SUMMARY_TXT,
        out.display()
    );
    Ok(if checks.iter().all(|c| c.passed) {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// Watches the graph until the window is over, the graph ends, or a stop is requested.
fn watch(
    monitor: &mut Monitor,
    launcher: &mut LauncherChild,
    csv: &mut SoakCsv,
    plan: &Plan,
    nodes: &[String],
    ticks_per_second: u64,
) -> anyhow::Result<Live> {
    const READ_PERIOD: Duration = Duration::from_secs(1);
    const PROGRESS_PERIOD: Duration = Duration::from_secs(10);
    let t0 = Instant::now();
    let mut next_read = t0;
    let mut next_progress = t0 + PROGRESS_PERIOD;
    let mut window_start: Option<Instant> = None;
    let progress = Progress::bar(plan.window.as_secs(), "s measured");
    progress.set_message("starting the graph");
    let early_end = loop {
        monitor.read_streams(Duration::from_millis(5))?;
        monitor.poll_lifecycle()?;
        let now = Instant::now();
        let window_over = window_start.is_some_and(|w| now >= w + plan.window);
        if now >= next_read || window_over {
            let t_s = (now - t0).as_secs_f64();
            let readings = monitor.read_processes(t_s);
            csv.write(t_s, &readings, monitor.streams(), ticks_per_second)?;
            while next_read <= now {
                next_read += READ_PERIOD;
            }
        }
        if now >= next_progress {
            next_progress += PROGRESS_PERIOD;
            let s = monitor.streams();
            progress.line(format_args!(
                "[{:6.0} s] encoder samples {} (lost {}), tracker frames {}, matched {}, RSS of all {:.1} MiB{}",
                (now - t0).as_secs_f64(),
                s.encoders.received,
                s.encoders.lost,
                s.tracker.received,
                s.matched.received,
                monitor.total_rss_kib() as f64 / 1024.0,
                if window_start.is_none() { " (starting)" } else { "" }
            ));
            progress.set_message(format_args!("{} encoder samples lost", s.encoders.lost));
        }
        if let Some(start) = window_start {
            progress.set_position((now - start).as_secs());
        }
        if window_over {
            break None;
        }
        if window_start.is_none() {
            if monitor.all_ready(nodes.iter().map(String::as_str)) {
                progress.line(format_args!(
                    "sabr soak: all nodes ready after {:.1} s; measuring",
                    (now - t0).as_secs_f64()
                ));
                progress.set_message("measuring");
                window_start = Some(now);
                monitor.start_window();
            } else if now - t0 > plan.ready_timeout {
                break Some(format!(
                    "not every node was ready within {:.0} s",
                    plan.ready_timeout.as_secs_f64()
                ));
            }
        }
        if let Some(status) = launcher.exited() {
            break Some(format!(
                "the graph stopped early: launcher {}",
                describe(status)
            ));
        }
        if !monitor.keep_running() {
            break Some("interrupted".to_owned());
        }
    };
    progress.finish();
    Ok(Live {
        t0,
        window_start,
        end: Instant::now(),
        early_end,
    })
}

/// True if a process with this pid exists.
fn process_alive(pid: u32) -> bool {
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), None).is_ok()
}
