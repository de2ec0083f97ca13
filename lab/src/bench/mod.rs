//! `sabr bench`: the latency of the transports the graph is built on (iceoryx2 with busy
//! polling and with blocking wake-up, Unix-domain sockets; separate processes, the graph's own
//! message sizes), compute costs (FK, IK, `sim record`, calibration), and the live-graph hops
//! (the sensing graph with the IK server, and the rig following setpoints, each launched in a
//! domain of its own) as ratios to those baselines, with the CPU use of every process. Prints
//! p50/p90/p99/p99.9/max and writes one `.hgrm` per measurement, `bench.csv` and
//! `idle-cpu.csv` to the output directory, the graphs' launch files and logs to
//! `<out>/graphs/`.

mod compute;
mod cpu;
mod doorbell;
mod futex;
mod graph;
mod hops;
mod iox;
mod machine;
mod output;
pub mod payload;
mod pingpong;
pub mod pong;
mod sensing;
mod setpoints;
mod stats;
mod timer;
mod uds;

use anyhow::bail;
use cpu::CpuShare;
use payload::{Payload, Transport};
use sabr_launcher::placement::Placement;
use sabr_launcher::progress::Progress;
use sabr_launcher::steal::CpuTimes;
use sabr_launcher::wake_latency::WakeLatencyBound;
use sabr_node::{errln, out, outln, Domain};
use stats::{format_ns, Measurement};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

/// Arguments of `sabr bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Output directory (must be absent or empty) [default: runs/bench-<unix time>].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Round trips per ping-pong baseline (a paced one: as many as fit 5 s, 1 s with --quick,
    /// from 20 to N/10); also sets the kinematics batches (N/100), the live graph's IK requests
    /// (N/2) and motor setpoints (N/10) [default: 20000, with --quick 1000].
    #[arg(long, value_name = "N")]
    samples: Option<u64>,
    /// A quick check, not figures to quote: fewer samples, short idle windows, a simulated
    /// session of 1/10 the default length, 5 s of the sensing graph instead of 60 s.
    #[arg(long)]
    quick: bool,
    /// Parts to run (comma-separated) [default: all].
    #[arg(long, value_enum, value_delimiter = ',', value_name = "PART")]
    only: Vec<Part>,
    /// Directory of the node executables of the live graphs [default: the directory of this
    /// executable].
    #[arg(long, value_name = "DIR")]
    bin_dir: Option<PathBuf>,
}

/// A part of the bench.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Part {
    /// Ping-pong baselines between two processes.
    Baselines,
    /// FK and IK per solve, `sim record` and calibration time.
    Compute,
    /// Hops of the live graphs, as ratios to the baselines, and their CPU use.
    Hops,
}

/// How much a run measures.
struct Settings {
    parts: Vec<Part>,
    ping_pong: pingpong::Plan,
    /// Longest a paced ping-pong runs (its round trips are then fewer than the others').
    paced_window: Duration,
    kinematics_batches: u64,
    session_scale: f64,
    sensing: sensing::Plan,
    setpoints: setpoints::Plan,
    bin_dir: PathBuf,
    /// The spinner naming what is being measured (on a terminal only).
    progress: Progress,
}

/// The transports whose back-to-back ping-pongs of one payload run together, taking turns
/// slice by slice (see [`pingpong::run`]): those placed as the shipped graph places the hop
/// and sleeping while they wait (a busy-polling pong would take the CPU from the others;
/// `futex-cross` is placed differently).
const TOGETHER: [Transport; 4] = [
    Transport::IoxEvent,
    Transport::Uds,
    Transport::Doorbell,
    Transport::Futex,
];

/// Slices each ping-pong's recorded round trips are split into (see [`pingpong::Plan`]).
const ROUNDS: u64 = 10;

/// The transports also measured paced at each hop's rate, together: the floor, the graph's
/// transport and the Unix socket it is judged against.
const PACED_TRANSPORTS: [Transport; 3] = [Transport::Uds, Transport::Doorbell, Transport::Futex];

impl Settings {
    /// The ping-pong plan of `burst` round trips after each `pause`: as many round trips as
    /// fit the paced window (at least 20, at most a tenth of the back-to-back ones); the
    /// pong's idle CPU is not measured (the back-to-back rows measure it).
    fn paced_plan(&self, pause: Duration, burst: u64) -> pingpong::Plan {
        let fit = (self.paced_window.as_nanos() / pause.as_nanos().max(1)) as u64 * burst;
        pingpong::Plan {
            warmup: 10,
            samples: fit.clamp(20, (self.ping_pong.samples / 10).max(20)),
            rounds: ROUNDS,
            idle_window: None,
            pause,
            burst,
        }
    }

    fn new(args: &BenchArgs) -> anyhow::Result<Self> {
        let samples = args
            .samples
            .unwrap_or(if args.quick { 1_000 } else { 20_000 });
        if samples == 0 {
            bail!("--samples must be at least 1");
        }
        let parts = if args.only.is_empty() {
            vec![Part::Baselines, Part::Compute, Part::Hops]
        } else {
            args.only.clone()
        };
        let bin_dir = sabr_launcher::bin_dir_or_beside_sabr(args.bin_dir.as_deref())?;
        let graph_cpu_window = Duration::from_secs(if args.quick { 1 } else { 5 });
        let ready_timeout = Duration::from_secs(60);
        Ok(Self {
            parts,
            ping_pong: pingpong::Plan {
                warmup: (samples / 10).max(10),
                samples,
                rounds: ROUNDS,
                idle_window: Some(Duration::from_millis(if args.quick { 300 } else { 2_000 })),
                pause: Duration::ZERO,
                burst: 1,
            },
            paced_window: Duration::from_secs(if args.quick { 1 } else { 5 }),
            kinematics_batches: (samples / compute::SOLVES_PER_BATCH).max(10),
            session_scale: if args.quick { 0.1 } else { 1.0 },
            sensing: sensing::Plan {
                ready_timeout,
                cpu_window: graph_cpu_window,
                window: Duration::from_secs(if args.quick { 5 } else { 60 }),
                ik_requests: (samples / 2).max(10),
            },
            setpoints: setpoints::Plan {
                ready_timeout,
                cpu_window: graph_cpu_window,
                setpoints: (samples / 10).max(10),
            },
            bin_dir,
            progress: Progress::spinner(),
        })
    }

    fn runs(&self, part: Part) -> bool {
        self.parts.contains(&part)
    }

    /// Prints `measuring <what> ...` and shows it beside the spinner.
    fn measuring(&self, what: impl std::fmt::Display) {
        self.progress.line(format_args!("measuring {what} ..."));
        self.progress.set_message(format_args!("measuring {what}"));
    }
}

/// Everything a run measured or could not measure.
#[derive(Default)]
struct Results {
    measurements: Vec<Measurement>,
    idle: Vec<(String, CpuShare)>,
    unavailable: Vec<String>,
    notes: Vec<String>,
}

impl Results {
    /// Keeps `measured`, or prints and keeps `<name>: not available: <reason>`.
    fn add(&mut self, name: &str, measured: anyhow::Result<Vec<Measurement>>) {
        match measured {
            Ok(measurements) => self.measurements.extend(measurements),
            Err(error) => self.not_available(name, &error),
        }
    }

    /// Keeps what a live graph measured, or prints and keeps why it could not be.
    fn add_graph(&mut self, name: &str, measured: anyhow::Result<graph::GraphMeasured>) {
        match measured {
            Ok(graph) => {
                self.measurements.extend(graph.measurements);
                self.idle.extend(graph.idle);
                self.notes.extend(graph.notes);
            }
            Err(error) => self.not_available(name, &error),
        }
    }

    fn not_available(&mut self, name: &str, error: &anyhow::Error) {
        let line = format!("{name}: not available: {error:#}");
        errln!("{line}");
        self.unavailable.push(line);
    }
}

/// Runs `sabr bench`.
pub fn run(args: &BenchArgs) -> anyhow::Result<ExitCode> {
    let settings = Settings::new(args)?;
    let out = sabr_launcher::create_out_dir(args.out.clone(), "bench")?;
    let machine = machine::describe();
    outln!("sabr bench on {machine}; output in {}", out.display());
    let cpu_at_start = CpuTimes::now();
    let mut results = Results::default();
    if settings.runs(Part::Baselines) {
        run_baselines(&settings, &mut results)?;
    }
    if settings.runs(Part::Compute) {
        run_compute(&settings, &out, &mut results);
    }
    if settings.runs(Part::Hops) {
        run_hops(&settings, &out, &mut results);
    }
    settings.progress.finish();
    let hop_rows = hops::ratio_rows(&results.measurements, "failed: see the error above");

    output::write_hgrm_files(&out, &results.measurements)?;
    output::write_csv(&out.join(output::CSV_FILE), &results.measurements)?;
    output::write_idle_csv(&out.join(output::IDLE_CSV_FILE), &results.idle)?;

    outln!();
    out!("{}", output::percentile_table(&results.measurements));
    if settings.runs(Part::Baselines) {
        outln!("\npayloads (request → response):");
        for payload in Payload::ALL {
            outln!("  {}", payload.describe());
        }
    }
    let transport_checks = hops::transport_checks(&results.measurements);
    if !transport_checks.is_empty() {
        outln!("\nthe doorbell against Unix sockets (same payload, same placement):");
        out!("{}", hops::transport_table(&transport_checks));
    }
    if !results.idle.is_empty() {
        out!("\n{}", output::idle_table(&results.idle));
    }
    for note in &results.notes {
        outln!("{note}");
    }
    if settings.runs(Part::Hops) {
        outln!(
            "\nlive-graph hops (p50 as a ratio to the same payload's futex round-trip p50, p99 \
             to its Unix-socket round-trip p99, p50 to the futex round trip paced at the hop's \
             rate):"
        );
        out!("{}", hops::ratio_table(&hop_rows));
        let floor_checks = hops::floor_checks(&results.measurements);
        if !floor_checks.is_empty() {
            outln!(
                "\nthe floor at the graph's rates: the bare futex round trip paced as the graph \
                 sends each payload, both processes cold, judged by the goals of that \
                 payload's hop (a goal it misses is out of reach of a transport whose path \
                 goes cold between messages; a hop whose path stays warm can go below it):"
            );
            out!("{}", hops::floor_table(&floor_checks));
        }
        let budgets = hops::work_budgets(&results.measurements);
        if !budgets.is_empty() {
            outln!(
                "\nwhat each hop's p50 goal ({}× futex p50) leaves for the hop's own work once \
                 its one-way legs are paid at the hot doorbell's price (the doorbell round trip \
                 of its payload, back to back, halved per leg; a hop's legs are never faster \
                 than that, so work that takes longer puts the goal out of reach):",
                hops::FUTEX_P50_FACTOR
            );
            out!("{}", hops::budget_table(&budgets));
        }
    }
    for line in &results.unavailable {
        outln!("{line}");
    }
    outln!(
        "\nload average at the end: {} (1, 5, 15 min)",
        machine::load_average()
    );
    outln!("{}", steal_line(cpu_at_start, CpuTimes::now()));
    outln!(
        "\nwrote {} .hgrm files (values in µs), {} and {} to {}",
        results.measurements.len(),
        output::CSV_FILE,
        output::IDLE_CSV_FILE,
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// How much CPU time the hypervisor took during the bench: on a busy host a vCPU waits
/// for tens of ms now and then, which shows in every tail percentile.
fn steal_line(start: anyhow::Result<CpuTimes>, end: anyhow::Result<CpuTimes>) -> String {
    match start.and_then(|start| Ok((start, end?))) {
        Ok((start, end)) => match end.steal_share_since(&start) {
            Some(share) => format!(
                "the hypervisor took {:.1} % of the CPUs' time during the bench (steal)",
                share * 100.0
            ),
            None => "CPU steal during the bench: no clock tick elapsed".to_owned(),
        },
        Err(error) => format!("CPU steal during the bench: unknown ({error:#})"),
    }
}

/// Every transport × payload ping-pong in an iceoryx2 domain of its own, released afterwards,
/// each placed as [`pinning`] says; per payload, the [`TOGETHER`] ones run together and so do
/// the [`PACED_TRANSPORTS`] ones, taking turns in [`ROUNDS`] slices.
fn run_baselines(settings: &Settings, results: &mut Results) -> anyhow::Result<()> {
    let domain = Domain::new(&format!("sabr-bench-{}", std::process::id()))?;
    // The round trips run under the CPU wake-up latency bound the shipped graphs hold while
    // they run, so that a hop and its baselines are measured on equally awake CPUs.
    let _bound = match graph::wake_latency_of(graph::SENSING_LAUNCH_FILE, &settings.bin_dir)? {
        Some(latency_us) => match WakeLatencyBound::hold(latency_us) {
            Ok(bound) => {
                let polled = match bound.polled_cpus() {
                    [] => String::new(),
                    cpus => format!(
                        " (this kernel has no cpuidle driver to obey it: CPUs {cpus:?} were \
                         polled by SCHED_IDLE threads, in the baselines and by the launcher in \
                         the graphs; their time is left out of the CPU figures)"
                    ),
                };
                results.notes.push(format!(
                    "the ping-pong baselines ran with the CPUs' wake-up latency held at ≤ \
                     {latency_us} µs, as the shipped graphs hold it{polled}"
                ));
                Some(bound)
            }
            Err(reason) => {
                results.notes.push(format!(
                    "the ping-pong baselines ran without the wake-up latency bound of the \
                     shipped graphs ({reason}): cross-core and idle wake-ups cost more than in \
                     the graph"
                ));
                None
            }
        },
        None => None,
    };
    let socket_dir = std::env::temp_dir();
    let mut measured = BTreeMap::new();
    let mut run_group = |transports: &[Transport], payload: Payload, plan: &pingpong::Plan| {
        let rows: Vec<(Transport, Payload)> = transports.iter().map(|&t| (t, payload)).collect();
        let names: Vec<String> = transports
            .iter()
            .map(|&t| plan.row_name(t, payload))
            .collect();
        settings.measuring(names.join(", "));
        let results = match pinning(transports[0], payload, &settings.bin_dir) {
            Ok(pinning) => pingpong::run(&rows, plan, &pinning, &domain, &socket_dir),
            Err(error) => rows
                .iter()
                .map(|_| Err(anyhow::anyhow!("{error:#}")))
                .collect(),
        };
        measured.extend(names.into_iter().zip(results));
    };
    for payload in Payload::ALL {
        run_group(&[Transport::IoxPoll], payload, &settings.ping_pong);
        run_group(&TOGETHER, payload, &settings.ping_pong);
        run_group(&[Transport::FutexCross], payload, &settings.ping_pong);
        if let Some(pause) = payload.live_period() {
            let plan = settings.paced_plan(pause, payload.live_burst());
            run_group(&PACED_TRANSPORTS, payload, &plan);
        }
    }
    let paced = PACED_TRANSPORTS.iter().flat_map(|&transport| {
        Payload::ALL
            .into_iter()
            .filter(|payload| payload.live_period().is_some())
            .map(move |payload| payload::paced_name(transport, payload))
    });
    let back_to_back = Transport::ALL.iter().flat_map(|&transport| {
        Payload::ALL
            .into_iter()
            .map(move |payload| payload::baseline_name(transport, payload))
    });
    for name in back_to_back.chain(paced) {
        let Some(ping_pong) = measured.remove(&name) else {
            continue;
        };
        let ping_pong = ping_pong.map(|ping_pong| {
            results
                .idle
                .extend(ping_pong.pong_idle.map(|idle| (name.clone(), idle)));
            vec![ping_pong.round_trips]
        });
        results.add(&name, ping_pong);
    }
    measure_timer(settings, results);
    let left = sabr_node::release_domain(&domain);
    if !left.is_empty() {
        results.notes.push(format!(
            "warning: iceoryx2 files of domain {domain} left behind: {left:?}"
        ));
    }
    Ok(())
}

/// [`timer::TIMER_LATENESS`] at the encoders' rate and place, for as long as a paced
/// baseline runs (under the wake-up latency bound the caller holds).
fn measure_timer(settings: &Settings, results: &mut Results) {
    settings.measuring(timer::TIMER_LATENESS);
    let period = Duration::from_secs_f64(1.0 / sabr_node::msgs::ENCODER_RATE_HZ);
    let ticks = (settings.paced_window.as_nanos() / period.as_nanos().max(1)) as u64;
    let measured = graph::placement_of(graph::SHIPPED_LAUNCH_FILE, "encoders", &settings.bin_dir)
        .and_then(|place| graph::placed(&place, || timer::lateness(ticks, period)));
    results.add(timer::TIMER_LATENESS, measured.map(|m| vec![m]));
}

/// The two nodes of the live-graph hop a payload stands for (producer, consumer), placed as
/// the shipped main job places them.
fn hop_nodes(payload: Payload) -> (&'static str, &'static str) {
    match payload {
        Payload::EncoderSample => ("encoders", "sync"),
        Payload::TrackerFrame => ("tracker", "sync"),
        Payload::Ik => ("motion", "ik"),
        Payload::MotorSetpoint => ("motion", "rig"),
    }
}

/// Where a ping-pong runs: busy polling wherever the system puts it (spinning on a shared core
/// would only measure the time slice), `futex-cross` with the two processes on CPUs 0 and 1,
/// every other transport as the shipped graph places the hop of that payload.
fn pinning(
    transport: Transport,
    payload: Payload,
    bin_dir: &Path,
) -> anyhow::Result<pingpong::Pinning> {
    let on = |cpu: usize| Placement {
        cpus: Some(vec![cpu]),
        sched: None,
    };
    match transport {
        Transport::IoxPoll => Ok(pingpong::Pinning::default()),
        Transport::FutexCross => {
            if sabr_launcher::placement::online_cpus() < 2 {
                bail!("futex-cross needs two CPUs");
            }
            Ok(pingpong::Pinning {
                ping: on(0),
                pong: on(1),
            })
        }
        _ => {
            let (producer, consumer) = hop_nodes(payload);
            Ok(pingpong::Pinning {
                ping: graph::placement_of(graph::SHIPPED_LAUNCH_FILE, producer, bin_dir)?,
                pong: graph::placement_of(graph::SHIPPED_LAUNCH_FILE, consumer, bin_dir)?,
            })
        }
    }
}

/// The live graphs one after the other, each in an iceoryx2 domain of its own; their launch
/// files and logs go to `<out>/graphs/`.
fn run_hops(settings: &Settings, out: &Path, results: &mut Results) {
    let dir = out.join("graphs");
    let pid = std::process::id();
    // Runs one graph in its own fresh domain, then releases the domain whatever happened
    // (the bench's and the graph's nodes are gone by then).
    let mut in_domain =
        |graph: &str, run: &dyn Fn(Domain) -> anyhow::Result<graph::GraphMeasured>| {
            let measured =
                graph::fresh_domain(&format!("sabr-bench-{pid}-{graph}")).and_then(|domain| {
                    let measured = run(domain.clone());
                    let left = sabr_node::release_domain(&domain);
                    if !left.is_empty() {
                        results.notes.push(format!(
                            "warning: iceoryx2 files of domain {domain} left behind: {left:?}"
                        ));
                    }
                    measured
                });
            results.add_graph(&format!("{graph} graph"), measured);
        };
    // The bench listens on the sync's CPUs (a second subscriber of the same streams, and the
    // IK client beside the server) and sends setpoints from the rig's, at a real-time
    // priority where allowed (see `graph::probe_placement`).
    settings.measuring("the sensing graph: hops, matching error, IK round trips, CPU");
    in_domain("sensing", &|domain| {
        let place = graph::placement_of(graph::SENSING_LAUNCH_FILE, "sync", &settings.bin_dir)?;
        let (place, note) = graph::probe_placement(place);
        let mut measured = graph::placed(&place, || {
            sensing::run(&settings.sensing, &dir, &settings.bin_dir, domain)
        })?;
        measured.notes.push(note);
        Ok(measured)
    });
    settings.measuring("the setpoint graph: setpoint → rig, CPU");
    in_domain("setpoints", &|domain| {
        let place = graph::placement_of(graph::SETPOINTS_LAUNCH_FILE, "rig", &settings.bin_dir)?;
        let (place, _) = graph::probe_placement(place);
        graph::placed(&place, || {
            setpoints::run(&settings.setpoints, &dir, &settings.bin_dir, domain)
        })
    });
}

/// Kinematics per solve, then `sim record` and calibration of that recording in `out/work`
/// (removed afterwards).
fn run_compute(settings: &Settings, out: &Path, results: &mut Results) {
    settings.measuring("compute/fk, compute/ik and their glam versions");
    let kinematics = compute::kinematics(settings.kinematics_batches);
    if let Ok(costs) = &kinematics {
        let ik_median = costs.ik_glam.summary().p50;
        results.notes.push(format!(
            "\nFK: {:.0} solves/s, IK: {:.0} solves/s; glam FK: {:.0} solves/s, glam IK: {:.0} \
             solves/s (median of {} batches of {}); one IK solve of the server (glam) {} \
             (goal ≤ {}: {})",
            compute::solves_per_second(&costs.fk),
            compute::solves_per_second(&costs.ik),
            compute::solves_per_second(&costs.fk_glam),
            compute::solves_per_second(&costs.ik_glam),
            settings.kinematics_batches,
            compute::SOLVES_PER_BATCH,
            format_ns(ik_median),
            format_ns(hops::IK_SOLVE_LIMIT_NS),
            hops::Outcome::of(ik_median <= hops::IK_SOLVE_LIMIT_NS)
        ));
    }
    results.add(
        "compute/fk, compute/ik, compute/fk-glam, compute/ik-glam",
        kinematics.map(compute::KinematicsCosts::into_rows),
    );

    let work = out.join("work");
    let session = work.join("session");
    settings.measuring("compute/sim-record");
    let recorded = compute::sim_record(&session, settings.session_scale);
    let recorded_ok = recorded.is_ok();
    results.add(
        &format!("compute/sim-record-x{}", settings.session_scale),
        recorded.map(|m| vec![m]),
    );
    let calibrate_name = format!("compute/calibrate-x{}", settings.session_scale);
    if recorded_ok {
        settings.measuring(&calibrate_name);
        let calibrated = compute::calibration(&session, &work.join("calibration"), &calibrate_name);
        results.add(&calibrate_name, calibrated.map(|m| vec![m]));
    } else {
        results.add(
            &calibrate_name,
            Err(anyhow::anyhow!("no recording (sim record failed)")),
        );
    }
    if let Err(error) = std::fs::remove_dir_all(&work) {
        if work.exists() {
            results.notes.push(format!(
                "warning: cannot remove {}: {error}",
                work.display()
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn baselines_are_placed_as_the_shipped_graph_places_each_hop() {
        let bin_dir = graph::stand_in_bin_dir();
        let shipped = |node: &str| {
            graph::placement_of(graph::SHIPPED_LAUNCH_FILE, node, bin_dir.path()).unwrap()
        };
        let priority = |placement: &Placement| placement.sched.map_or(0, |s| s.priority());
        for payload in Payload::ALL {
            let (producer, consumer) = hop_nodes(payload);
            let placed = pinning(Transport::Doorbell, payload, bin_dir.path()).unwrap();
            assert_eq!(placed.ping, shipped(producer), "{}", payload.name());
            assert_eq!(placed.pong, shipped(consumer), "{}", payload.name());
        }
        // The consumers of the event-driven hops outrank their producers on the shared core,
        // so a ring runs the consumer at once and its answer needs no wake-up.
        for payload in [Payload::EncoderSample, Payload::TrackerFrame, Payload::Ik] {
            let placed = pinning(Transport::Doorbell, payload, bin_dir.path()).unwrap();
            assert_eq!(placed.ping.cpus, placed.pong.cpus, "{}", payload.name());
            assert!(
                priority(&placed.pong) > priority(&placed.ping),
                "{}: {} is not above {}",
                payload.name(),
                placed.pong,
                placed.ping
            );
        }
        // The IK client outranks the other producers on its core, so a tick of theirs that
        // falls inside a burst of IK requests waits for the burst's end.
        let motion = shipped("motion");
        for node in ["encoders", "tracker"] {
            let other = shipped(node);
            assert_eq!(other.cpus, motion.cpus, "{node}");
            assert!(
                priority(&motion) > priority(&other),
                "motion ({motion}) is not above {node} ({other})"
            );
        }
    }
}
