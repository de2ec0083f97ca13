//! `sabr bench` end to end: the baselines with a tiny sample count, run by the built binary
//! (which spawns its own pong processes), and the files it writes.

use std::path::Path;
use std::process::{Command, Output};

const SAMPLES: u64 = 30;
const TRANSPORTS: [&str; 6] = [
    "iox2-poll",
    "iox2-event",
    "uds",
    "doorbell",
    "futex",
    "futex-cross",
];
const PAYLOADS: [&str; 4] = ["encoder-sample", "tracker-frame", "ik", "motor-setpoint"];
/// Transports also measured paced at the live graph's rate of each payload that has one.
const PACED_TRANSPORTS: [&str; 3] = ["uds", "doorbell", "futex"];
const PACED_PAYLOADS: [&str; 3] = ["encoder-sample", "tracker-frame", "ik"];
/// Round trips of a paced row here: the floor, since a tenth of `SAMPLES` is fewer.
const PACED_SAMPLES: u64 = 20;
/// The host's timer at the encoders' place: one wake-up a millisecond for the paced window
/// (1 s with `--quick`).
const TIMER_ROW: &str = "timer/encoders-tick";
const TIMER_TICKS: u64 = 1_000;

fn sabr_bench(args: &[&str]) -> (Output, u32) {
    let child = Command::new(env!("CARGO_BIN_EXE_sabr-lab"))
        .arg("bench")
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    (child.wait_with_output().unwrap(), pid)
}

fn csv_rows(path: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .map(|line| line.split(',').map(str::to_owned).collect())
        .collect()
}

#[test]
fn quick_baselines_measure_every_transport_and_payload() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let samples = SAMPLES.to_string();
    let (output, pid) = sabr_bench(&[
        "--quick",
        "--samples",
        &samples,
        "--only",
        "baselines",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stdout}\n{stderr}");
    assert!(!stdout.contains("not available"), "{stdout}");
    // Whether the machine lets it hold the graphs' wake-up latency bound or not, the output
    // says under which the round trips ran.
    assert!(
        stdout.contains("the ping-pong baselines ran with the CPUs' wake-up latency held")
            || stdout.contains("the ping-pong baselines ran without the wake-up latency bound"),
        "{stdout}"
    );
    // It says how much CPU time the hypervisor took meanwhile (this machine has /proc/stat).
    assert!(
        stdout
            .lines()
            .any(|line| line.starts_with("the hypervisor took ")
                && line.ends_with("% of the CPUs' time during the bench (steal)")),
        "{stdout}"
    );
    for payload in PAYLOADS {
        let judged = stdout.lines().any(|line| {
            line.trim_start()
                .starts_with(&format!("doorbell/{payload} "))
                && line.contains("p50 ")
                && line.contains("p99 ")
                && line.contains("< uds")
        });
        assert!(
            judged,
            "doorbell/{payload} not judged against uds:\n{stdout}"
        );
    }

    let rows = csv_rows(&out.join("bench.csv"));
    assert_eq!(
        rows[0],
        ["name", "unit", "count", "p50", "p90", "p99", "p999", "max"]
    );
    let mut expected_names = Vec::new();
    for transport in TRANSPORTS {
        for payload in PAYLOADS {
            expected_names.push(format!("{transport}/{payload}"));
        }
    }
    let back_to_back = expected_names.len();
    for transport in PACED_TRANSPORTS {
        for payload in PACED_PAYLOADS {
            expected_names.push(format!("{transport}-paced/{payload}"));
        }
    }
    let paced = expected_names.len();
    expected_names.push(TIMER_ROW.to_owned());
    let names: Vec<&str> = rows[1..].iter().map(|r| r[0].as_str()).collect();
    assert_eq!(names, expected_names);
    for (index, row) in rows[1..].iter().enumerate() {
        let count = if index < back_to_back {
            SAMPLES
        } else if index < paced {
            PACED_SAMPLES
        } else {
            TIMER_TICKS
        };
        assert_eq!(row[1], "ns", "{row:?}");
        assert_eq!(row[2], count.to_string(), "{row:?}");
        let values: Vec<u64> = row[3..].iter().map(|v| v.parse().unwrap()).collect();
        assert!(values[0] > 0, "a p50 of 0 ns: {row:?}");
        assert!(
            values.windows(2).all(|w| w[0] <= w[1]),
            "percentiles not monotone: {row:?}"
        );
        let hgrm = out.join(format!("{}.hgrm", row[0].replace('/', "_")));
        let text = std::fs::read_to_string(&hgrm).unwrap();
        assert!(
            text.contains(&format!("Total count    = {count:>12}]")),
            "{text}"
        );
    }

    // The pong's idle CPU use is measured on the back-to-back rows.
    let idle = csv_rows(&out.join("idle-cpu.csv"));
    assert_eq!(idle.len(), 1 + back_to_back);
    for row in &idle[1..] {
        let cores: f64 = row[2].parse().unwrap();
        assert!((0.0..=2.5).contains(&cores), "{row:?}");
    }

    // The run's iceoryx2 domain is gone: no shared memory or service files left.
    let domain = sabr_node::Domain::new(&format!("sabr-bench-{pid}")).unwrap();
    let left = sabr_node::domain_files(&domain);
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn refuses_zero_samples_and_a_non_empty_output_directory() {
    let dir = tempfile::tempdir().unwrap();
    let (output, _) = sabr_bench(&["--samples", "0", "--out", dir.path().to_str().unwrap()]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("--samples must be at least 1"));

    std::fs::write(dir.path().join("keep.txt"), "x").unwrap();
    let (output, _) = sabr_bench(&["--only", "compute", "--out", dir.path().to_str().unwrap()]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("is not empty"), "{stderr}");
}
