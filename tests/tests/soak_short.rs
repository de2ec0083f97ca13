//! A short `sabr soak` of the real sensing graph, for CI: no encoder sample lost (sequence
//! numbers), the streams at full rate, and memory growth bounded once warmed up. The
//! 10-minute soak is the command `sabr soak` itself (see its `--help`).
//!
//! Needs the `sabr` and service binaries next to the test executable: `cargo build
//! --workspace --bins` (CI: `cargo build --release --workspace --bins` first).

use sabr_integration_tests::bin;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// Measurement window of the short soak, s.
const WINDOW_S: f64 = 15.0;
/// Start of the window excluded from the memory figures, s.
const WARM_UP_S: f64 = 5.0;
/// Largest RSS growth of any process from the end of the warm-up to the end, KiB.
const MAX_GROWTH_KIB: u64 = 2048;

/// Rows of a CSV file written by `sabr soak` (plain numbers and names, no quoting), by header.
fn csv(file: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(file)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", file.display()));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header line").split(',').collect();
    lines
        .map(|line| {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields.len(), header.len(), "{}: {line}", file.display());
            header
                .iter()
                .zip(fields)
                .map(|(h, f)| ((*h).to_owned(), f.to_owned()))
                .collect()
        })
        .collect()
}

fn number(row: &BTreeMap<String, String>, column: &str) -> f64 {
    row[column]
        .parse()
        .unwrap_or_else(|e| panic!("{column} = {:?}: {e}", row[column]))
}

#[test]
fn a_short_soak_loses_no_encoder_sample_and_memory_stays_bounded() {
    let _alone = sabr_integration_tests::run_alone();
    let out = tempfile::tempdir().unwrap();
    let graph = Path::new(env!("CARGO_MANIFEST_DIR")).join("../launch/graphs/sim-sensing.toml");
    let domain = format!("it-soak-{}", std::process::id());
    let output = Command::new(bin("sabr"))
        .arg("soak")
        .args(["--seconds", &WINDOW_S.to_string()])
        .args(["--warm-up-s", &WARM_UP_S.to_string()])
        // Memory slope over a 10 s fit: only a gross leak shows; the bound below is the test.
        .args(["--max-rss-slope", "4096"])
        .args(["--domain", &domain])
        .arg("--graph")
        .arg(&graph)
        .arg("--out")
        .arg(out.path())
        .output()
        .expect("run sabr soak");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    let launcher = std::fs::read_to_string(out.path().join("launcher.log")).unwrap_or_default();
    eprintln!("{stdout}");
    assert!(
        output.status.success(),
        "sabr soak failed ({}):\n{stdout}\n{stderr}\nlauncher:\n{launcher}",
        output.status
    );

    let streams = csv(&out.path().join("streams.csv"));
    let last = streams.last().expect("stream rows");
    assert_eq!(number(last, "encoder_lost"), 0.0, "{stdout}");
    assert_eq!(number(last, "encoder_restarts"), 0.0, "{stdout}");
    let samples = number(last, "encoder_samples");
    assert!(
        samples >= 0.9 * 1000.0 * WINDOW_S,
        "{samples} encoder samples\n{stdout}"
    );
    let frames = number(last, "tracker_frames");
    assert!(
        frames >= 0.9 * 20.0 * WINDOW_S,
        "{frames} tracker frames\n{stdout}"
    );

    // Memory: every process's RSS once warmed up against its largest later value.
    let readings = csv(&out.path().join("soak.csv"));
    let end_s = readings
        .iter()
        .map(|r| number(r, "t_s"))
        .fold(0.0, f64::max);
    let warm_s = end_s - (WINDOW_S - WARM_UP_S);
    let mut per_process: BTreeMap<String, (Option<u64>, u64)> = BTreeMap::new();
    for row in &readings {
        let key = format!("{} pid {}", row["process"], row["pid"]);
        let (t_s, rss) = (number(row, "t_s"), number(row, "rss_kib") as u64);
        if t_s >= warm_s {
            let entry = per_process.entry(key).or_insert((None, 0));
            entry.0.get_or_insert(rss);
            entry.1 = entry.1.max(rss);
        }
    }
    let processes: Vec<&str> = readings.iter().map(|r| r["process"].as_str()).collect();
    for node in ["launcher", "rig", "encoders", "tracker", "sync", "recorder"] {
        assert!(
            processes.contains(&node),
            "{node} never read: {processes:?}"
        );
    }
    for (process, (warm, max)) in per_process {
        let growth = max.saturating_sub(warm.unwrap_or(max));
        assert!(
            growth <= MAX_GROWTH_KIB,
            "{process}: RSS grew {growth} KiB after the warm-up\n{stdout}"
        );
    }
}
