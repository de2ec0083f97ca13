//! Round trip of the IK server process and its idle CPU, in a private domain:
//!
//! ```text
//! cargo bench -p sabr-ik-service --bench round_trip [-- --requests 20000]
//! ```
//!
//! Prints the in-process solve time, the request → response round trip through `sabr-ik`
//! (back to back, and paced at 1 kHz so the server sleeps between requests), and the server's
//! CPU use while idle. Goals: round trip p99 ≤ 50 µs, idle ≤ 5 % of a core.

use hdrhistogram::Histogram;
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_ik::{IkClient, IkSolver, ParameterSet};
use sabr_model::{forward, RobotParams, HOME_JOINTS};
use sabr_msgs::{IkRequest, IkStatus};
use sabr_node::{Domain, GraphObserver, NodeRuntime};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const GOAL_P99_NS: u64 = 50_000;
const GOAL_IDLE_CORES: f64 = 0.05;

/// Reachable requests around the home pose (FK of joints within ±0.1 rad of home).
fn requests(params: &RobotParams) -> Vec<IkRequest> {
    let geometry = params.effective_geometry();
    (0..64)
        .map(|k| {
            let q: [f64; 5] = std::array::from_fn(|i| {
                HOME_JOINTS[i] + 0.1 * ((k * 7 + i * 13) as f64 * 0.37).sin()
            });
            let pose = forward(&geometry, &q).expect("FK near home");
            IkRequest {
                id: 0,
                tip_mm: pose.tip.coords.into(),
                direction: pose.direction.into_inner().into(),
                near_joints_rad: HOME_JOINTS,
            }
        })
        .collect()
}

fn summary(name: &str, histogram: &Histogram<u64>) {
    println!(
        "{name:<28} n={:<6} p50={:>6.1} µs  p90={:>6.1} µs  p99={:>6.1} µs  p99.9={:>6.1} µs  max={:>7.1} µs",
        histogram.len(),
        histogram.value_at_quantile(0.5) as f64 * 1e-3,
        histogram.value_at_quantile(0.9) as f64 * 1e-3,
        histogram.value_at_quantile(0.99) as f64 * 1e-3,
        histogram.value_at_quantile(0.999) as f64 * 1e-3,
        histogram.max() as f64 * 1e-3,
    );
}

/// CPU time of process `pid`'s main thread so far (ns, from the scheduler's statistics).
fn cpu_ns(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/schedstat")).expect("/proc schedstat");
    stat.split_whitespace()
        .next()
        .and_then(|ns| ns.parse().ok())
        .expect("schedstat format")
}

fn main() -> anyhow::Result<()> {
    let mut count = 20_000usize;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--requests" {
            count = args.next().and_then(|v| v.parse().ok()).unwrap_or(count);
        }
    }
    let mut params = RobotParams::nominal();
    params.joints.offset = Some(HOME_JOINTS);
    let requests = requests(&params);

    // In-process solve time, for reference.
    let solver = IkSolver::with_parameters(ParameterSet::new(
        params.clone(),
        0,
        std::path::Path::new("params.toml"),
    ));
    let mut solve = Histogram::<u64>::new(3)?;
    for k in 0..count {
        let start = Instant::now();
        let response = solver.solve(&requests[k % requests.len()]);
        solve.record(start.elapsed().as_nanos() as u64)?;
        assert_eq!(response.status, IkStatus::Ok);
    }

    let domain = Domain::new(&format!("bench-ik-{}", std::process::id()))?;
    let dir = tempfile::tempdir()?;
    let file = dir.path().join("params.toml");
    std::fs::write(&file, params.to_toml_string())?;
    let observer = GraphObserver::new(&domain)?;
    let mut server = Command::new(env!("CARGO_BIN_EXE_sabr-ik"))
        .arg("--params")
        .arg(&file)
        .env("SABR_DOMAIN", domain.as_str())
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .spawn()?;
    let mut ready = false;
    let start = Instant::now();
    while !ready && start.elapsed() < Duration::from_secs(10) {
        observer.poll(|m| ready |= m.state == sabr_msgs::LifecycleState::Ready)?;
        std::thread::sleep(Duration::from_millis(5));
    }
    anyhow::ensure!(ready, "sabr-ik did not get ready");

    let rt = NodeRuntime::with_domain("ik-bench", domain.clone())?;
    let mut client = IkClient::new(&rt)?;
    let timeout = Duration::from_millis(100);
    for request in requests.iter().cycle().take(1_000) {
        client.solve(*request, timeout)?;
    }
    let mut back_to_back = Histogram::<u64>::new(3)?;
    for request in requests.iter().cycle().take(count) {
        let start = Instant::now();
        let response = client.solve(*request, timeout)?;
        back_to_back.record(start.elapsed().as_nanos() as u64)?;
        assert_eq!(response.status, IkStatus::Ok);
    }
    let mut paced = Histogram::<u64>::new(3)?;
    let paced_count = (count / 4).max(1);
    let mut next = Instant::now();
    for request in requests.iter().cycle().take(paced_count) {
        next += Duration::from_millis(1);
        while Instant::now() < next {
            std::thread::sleep(next - Instant::now());
        }
        let start = Instant::now();
        let response = client.solve(*request, timeout)?;
        paced.record(start.elapsed().as_nanos() as u64)?;
        assert_eq!(response.status, IkStatus::Ok);
    }

    // Idle CPU of the server over 3 s without requests.
    let (before, start) = (cpu_ns(server.id()), Instant::now());
    std::thread::sleep(Duration::from_secs(3));
    let idle_cores = (cpu_ns(server.id()) - before) as f64 * 1e-9 / start.elapsed().as_secs_f64();

    kill(Pid::from_raw(server.id() as i32), Signal::SIGINT)?;
    let status = server.wait()?;
    drop((client, rt, observer));
    let left = sabr_node::release_domain(&domain);

    summary("ik solve (in process)", &solve);
    summary("ik round trip back-to-back", &back_to_back);
    summary("ik round trip paced 1 kHz", &paced);
    let p99 = paced
        .value_at_quantile(0.99)
        .max(back_to_back.value_at_quantile(0.99));
    println!(
        "goal round trip p99 ≤ {} µs: {}",
        GOAL_P99_NS / 1_000,
        if p99 <= GOAL_P99_NS { "met" } else { "MISSED" }
    );
    println!(
        "ik server idle CPU: {:.3} % of a core (goal ≤ {:.0} %): {}",
        idle_cores * 100.0,
        GOAL_IDLE_CORES * 100.0,
        if idle_cores <= GOAL_IDLE_CORES {
            "met"
        } else {
            "MISSED"
        }
    );
    anyhow::ensure!(status.success(), "sabr-ik exited with {status}");
    anyhow::ensure!(left.is_empty(), "left behind: {left:?}");
    Ok(())
}
