//! The IK server process (`sabr-ik`): reachable targets answered exactly like `sabr ik`
//! (the same `sabr_model::inverse` and counts), NaN / infinite / zero / unreachable targets
//! answered with errors, and parameter reloads on announcements, a corrupt file keeping the
//! previous set in service.
//!
//! Needs the workspace binaries: `cargo build --workspace --bins` first.

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use sabr_integration_tests::{bin, test_domain};
use sabr_msgs::{
    services, FixedString, IkRequest, IkResponse, IkStatus, LifecycleState,
    ParameterSetAnnouncement,
};
use sabr_node::{Domain, DoorbellClient, GraphObserver, NodeRuntime};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The home joints of docs/robot-model.md §3, the `near` that `sabr ik` uses.
const HOME_JOINTS: [f64; 5] = [-2.368404, -0.777628, 0.0, -2.685073, -0.601543];
const LONG: Duration = Duration::from_secs(15);

/// A calibrated parameter file (docs/robot-model.md §7 plus joint offsets) with needle length `l_n`.
fn params_toml(l_n: f64) -> String {
    format!(
        r#"format = 1
[geometry]
l_f = 50.0
l_fe = 20.0
l_b = 50.0
l_be = 20.0
d_offset = 20.0
l_n = {l_n}
front_base_translation = [0.3, -0.2, 100.4]
front_base_rotation = [0.004, -0.003, 0.0]
[joints]
counts_per_rev = [2000, 2000, 4000, 2000, 2000]
gear_ratio = [0.1, 0.101, 0.05, 0.099, 0.1]
home_stops = [-2.2, -0.9, -0.2, -2.55, -0.75]
joint_offset = [-2.31, -0.72, 0.04, -2.66, -0.58]
[markers]
base_to_robot_translation = [80.0, -40.0, 50.0]
base_to_robot_rotation = [0.0, 0.0, 0.0]
front_mount_translation = [0.0, 0.0, 15.0]
front_mount_rotation = [0.0, 0.0, 0.0]
back_mount_translation = [0.0, 0.0, -15.0]
back_mount_rotation = [0.0, 0.0, 0.0]
[tracker]
rate_hz = 20.0
"#
    )
}

/// Reachable targets (tip mm, direction) from docs/robot-model.md §3's test vectors.
const TARGETS: [[f64; 6]; 4] = [
    [0.0, -90.0, 180.0, 0.0, 0.0, 1.0],
    [0.6994, -102.5676, 172.3905, 0.006198, -0.106914, 0.994249],
    [6.8652, -61.6116, 193.763, 0.060675, 0.198498, 0.978221],
    [17.6674, -89.0828, 167.8082, 0.030056, -0.006635, 0.999526],
];

/// `sabr ik` on `targets`: each row `Ok(q1..q5, c1..c5)` or `Err(reason)`.
fn sabr_ik(dir: &Path, params: &Path, targets: &[[f64; 6]]) -> Vec<Result<Vec<f64>, String>> {
    let csv = dir.join("targets.csv");
    let mut text = String::from("x,y,z,ux,uy,uz\n");
    for t in targets {
        let row: Vec<String> = t.iter().map(f64::to_string).collect();
        text += &(row.join(",") + "\n");
    }
    std::fs::write(&csv, text).unwrap();
    let output = Command::new(bin("sabr"))
        .args(["ik", "--params"])
        .arg(params)
        .arg("--targets")
        .arg(&csv)
        .output()
        .expect("run sabr ik");
    let stdout = String::from_utf8(output.stdout).unwrap();
    let mut lines = stdout.lines();
    assert_eq!(
        lines.next(),
        Some("q1,q2,q3,q4,q5,c1,c2,c3,c4,c5"),
        "{stdout}"
    );
    lines
        .map(|line| match line.strip_prefix("error,") {
            Some(reason) => Err(reason.to_owned()),
            None => Ok(line.split(',').map(|v| v.parse().unwrap()).collect()),
        })
        .collect()
}

/// A hand-made client, as a benchmark would build it: `NodeRuntime::client` on the graph's
/// doorbell transport (sending rings the server; the answer rings this process back).
struct TestClient {
    client: DoorbellClient<IkRequest, IkResponse>,
    next_id: u64,
}

impl TestClient {
    fn new(rt: &NodeRuntime) -> Self {
        Self {
            client: rt
                .client::<IkRequest, IkResponse>(services::IK_SOLVE)
                .unwrap(),
            next_id: 1,
        }
    }

    fn solve(&mut self, target: [f64; 6]) -> IkResponse {
        self.next_id += 1;
        let request = IkRequest {
            id: self.next_id,
            tip_mm: [target[0], target[1], target[2]],
            direction: [target[3], target[4], target[5]],
            near_joints_rad: HOME_JOINTS,
        };
        let sent = Instant::now();
        let pending = self
            .client
            .send(request)
            .unwrap()
            .expect("server connected");
        let response = self
            .client
            .receive(&pending, Duration::from_secs(5))
            .unwrap()
            .expect("an answer within 5 s");
        let round_trip = sent.elapsed();
        assert_eq!(response.id, request.id);
        // The server's own time is part of the round trip, and a solution takes some.
        assert!(
            Duration::from_nanos(response.solve_ns) < round_trip,
            "solve {} ns in a round trip of {round_trip:?}",
            response.solve_ns
        );
        if response.status == IkStatus::Ok {
            assert!(response.solve_ns > 0, "a solution reported no solve time");
        }
        response
    }
}

/// The `sabr-ik` process; stopped with SIGINT on drop.
struct IkServer {
    child: Child,
    log: PathBuf,
}

impl IkServer {
    fn start(domain: &Domain, params: &Path, log: PathBuf) -> Self {
        let observer = GraphObserver::new(domain).unwrap();
        let child = Command::new(bin("sabr-ik"))
            .arg("--params")
            .arg(params)
            .env("SABR_DOMAIN", domain.as_str())
            .env("SABR_NODE_NAME", "ik")
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .expect("start sabr-ik");
        let start = Instant::now();
        let mut ready = false;
        while !ready {
            assert!(start.elapsed() < LONG, "sabr-ik not ready");
            observer
                .poll(|m| ready |= m.node.as_str() == "ik" && m.state == LifecycleState::Ready)
                .unwrap();
            std::thread::sleep(Duration::from_millis(5));
        }
        Self { child, log }
    }

    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    fn stop(mut self) -> std::process::ExitStatus {
        kill(Pid::from_raw(self.child.id() as i32), Signal::SIGINT).unwrap();
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            assert!(start.elapsed() < LONG, "sabr-ik does not stop");
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for IkServer {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn assert_matches_sabr_ik(response: &IkResponse, expected: &Result<Vec<f64>, String>) {
    let expected = expected.as_ref().expect("sabr ik solves it");
    assert_eq!(response.status, IkStatus::Ok, "{}", response.error);
    assert!(response.error.is_empty());
    assert_eq!(&response.joints_rad[..], &expected[..5], "joints");
    assert_eq!(&response.counts[..], &expected[5..], "counts");
}

#[test]
fn ik_server_answers_like_sabr_ik_and_refuses_bad_targets() {
    let _alone = sabr_integration_tests::run_alone();
    let domain = test_domain("ik-answers");
    let dir = tempfile::tempdir().unwrap();
    let params = dir.path().join("params.toml");
    std::fs::write(&params, params_toml(181.0)).unwrap();
    let server = IkServer::start(&domain, &params, dir.path().join("ik.log"));
    let rt = NodeRuntime::with_domain("ik-test", domain.clone()).unwrap();
    let mut client = TestClient::new(&rt);

    let expected = sabr_ik(dir.path(), &params, &TARGETS);
    for (target, expected) in TARGETS.iter().zip(&expected) {
        let response = client.solve(*target);
        assert_eq!(response.parameter_version, 0);
        assert_matches_sabr_ik(&response, expected);
    }

    let nan = f64::NAN;
    let inf = f64::INFINITY;
    let bad = [
        ([nan, -90.0, 180.0, 0.0, 0.0, 1.0], IkStatus::InvalidInput),
        ([0.0, inf, 180.0, 0.0, 0.0, 1.0], IkStatus::InvalidInput),
        ([0.0, -90.0, 180.0, 0.0, -inf, 1.0], IkStatus::InvalidInput),
        ([0.0, -90.0, 180.0, 0.0, 0.0, 0.0], IkStatus::InvalidInput),
        ([0.0, -90.0, 600.0, 0.0, 0.0, 1.0], IkStatus::Unreachable),
        ([300.0, -90.0, 180.0, 0.0, 0.0, 1.0], IkStatus::Unreachable),
    ];
    for (target, status) in bad {
        let response = client.solve(target);
        assert_eq!(response.status, status, "{target:?}: {}", response.error);
        assert!(!response.error.is_empty(), "a reason is given");
        assert_eq!(response.joints_rad, [0.0; 5], "no guess");
    }
    // `sabr ik` refuses the finite unreachable ones too.
    let unreachable: Vec<[f64; 6]> = bad[4..].iter().map(|(t, _)| *t).collect();
    for row in sabr_ik(dir.path(), &params, &unreachable) {
        assert!(row.unwrap_err().contains("unreachable"));
    }

    assert!(server.stop().success());
    drop((client, rt));
    let left = sabr_node::release_domain(&domain);
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn ik_server_reloads_announced_parameters_and_keeps_them_when_a_file_is_corrupt() {
    let _alone = sabr_integration_tests::run_alone();
    let domain = test_domain("ik-reload");
    let dir = tempfile::tempdir().unwrap();
    let first = dir.path().join("params.toml");
    std::fs::write(&first, params_toml(181.0)).unwrap();
    let server = IkServer::start(&domain, &first, dir.path().join("ik.log"));
    let rt = NodeRuntime::with_domain("ik-test", domain.clone()).unwrap();
    let mut client = TestClient::new(&rt);
    let announcements = rt
        .publisher::<ParameterSetAnnouncement>(services::CALIBRATOR_PARAMETERS)
        .unwrap();
    let announce = |version: u64, path: &Path| {
        announcements
            .send(ParameterSetAnnouncement {
                version,
                t_ns: sabr_node::monotonic_ns(),
                path: FixedString::new(path.to_str().unwrap()).unwrap(),
            })
            .unwrap();
    };
    let target = TARGETS[1];
    let before = client.solve(target);
    assert_eq!((before.status, before.parameter_version), (IkStatus::Ok, 0));

    // A corrupt file is rejected with a logged error; version 0 stays in service.
    let corrupt = dir.path().join("corrupt.toml");
    std::fs::write(&corrupt, "format = 1\n[geometry]\nl_f = \"fifty\"\n").unwrap();
    announce(1, &corrupt);
    let start = Instant::now();
    while !server
        .log()
        .contains("rejected the announced parameter set")
    {
        assert!(
            start.elapsed() < LONG,
            "no rejection logged:\n{}",
            server.log()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(server.log().contains("corrupt.toml"), "{}", server.log());
    let after_corrupt = client.solve(target);
    assert_eq!(
        after_corrupt,
        IkResponse {
            id: after_corrupt.id,
            solve_ns: after_corrupt.solve_ns,
            ..before
        }
    );

    // A valid new set is in service once announced, and answers like `sabr ik` on it.
    let second = dir.path().join("params-v2.toml");
    std::fs::write(&second, params_toml(183.5)).unwrap();
    announce(2, &second);
    let start = Instant::now();
    let reloaded = loop {
        let response = client.solve(target);
        if response.parameter_version == 2 {
            break response;
        }
        assert!(start.elapsed() < LONG, "set 2 never in service");
        std::thread::sleep(Duration::from_millis(5));
    };
    assert_ne!(reloaded.joints_rad, before.joints_rad);
    assert_matches_sabr_ik(&reloaded, &sabr_ik(dir.path(), &second, &[target])[0]);

    assert!(server.stop().success());
    drop((client, announcements, rt));
    let left = sabr_node::release_domain(&domain);
    assert!(left.is_empty(), "left behind: {left:?}");
}
