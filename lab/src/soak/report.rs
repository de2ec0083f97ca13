//! The soak's verdict against its goals, the table it prints, and the CSV files it writes.

use super::monitor::{Gathered, Streams};
use super::processes::{Figures, Reading};
use super::streams::SeqCheck;
use anyhow::Context;
use std::fmt::Write as _;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Per-process readings, one row per process and second: `t_s,process,pid,rss_kib,cpu_s`.
pub const PROCESS_CSV: &str = "soak.csv";
/// Stream counts, one row per second: cumulative counts of every stream.
pub const STREAMS_CSV: &str = "streams.csv";
/// The printed table and verdict.
pub const SUMMARY_TXT: &str = "summary.txt";

/// The goals a soak is judged against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goals {
    /// Largest memory slope of any process after the warm-up, KiB per minute.
    pub max_rss_slope_kib_per_min: f64,
    /// Nominal encoder sample rate, Hz.
    pub encoder_hz: f64,
    /// Nominal tracker frame rate, Hz.
    pub tracker_hz: f64,
    /// Fraction of a nominal rate a stream must reach in the window.
    pub min_rate_fraction: f64,
}

/// Everything the soak observed, ready to be judged.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The launch file.
    pub graph: PathBuf,
    /// The measurement window (from all nodes ready to the end), s.
    pub window_s: f64,
    /// Warm-up at the start of the window excluded from the memory slope, s.
    pub warm_up_s: f64,
    /// What the monitor gathered.
    pub gathered: Gathered,
    /// Per-process figures over the window.
    pub figures: Vec<Figures>,
    /// Why the soak ended before its time, if it did.
    pub early_end: Option<String>,
    /// How the launcher ended, e.g. "exit code 0".
    pub launcher_exit: String,
    /// True if the launcher exited with success.
    pub launcher_ok: bool,
    /// Processes of the graph still alive after the launcher exited.
    pub survivors: Vec<u32>,
    /// iceoryx2 files of the domain left after everything stopped.
    pub leftover_files: Vec<PathBuf>,
}

/// One goal and whether it was met.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// The goal.
    pub goal: String,
    /// Met or not.
    pub passed: bool,
    /// The measured figure.
    pub detail: String,
}

/// Judges `outcome` against `goals`.
pub fn checks(outcome: &Outcome, goals: &Goals) -> Vec<Check> {
    let streams = &outcome.gathered.streams;
    let enc = &streams.encoders;
    let mut checks = vec![Check {
        goal: "0 lost encoder samples (sequence numbers)".to_owned(),
        passed: enc.received > 0 && enc.lost == 0 && enc.restarts == 0,
        detail: format!(
            "{} lost in {} gap(s), {} sequence restart(s), {} received",
            enc.lost, enc.gaps, enc.restarts, enc.received
        ),
    }];
    let worst = outcome
        .figures
        .iter()
        .map(|f| (f, f.rss_slope_kib_per_min.unwrap_or(f64::INFINITY)))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    checks.push(Check {
        goal: format!(
            "memory flat: RSS slope ≤ {} KiB/min per process after a {:.0} s warm-up",
            goals.max_rss_slope_kib_per_min, outcome.warm_up_s
        ),
        passed: worst.is_some_and(|(_, slope)| slope <= goals.max_rss_slope_kib_per_min),
        detail: match worst {
            Some((f, slope)) if slope.is_finite() => {
                format!("largest {slope:+.1} KiB/min ({} pid {})", f.label, f.pid)
            }
            Some((f, _)) => format!(
                "{} pid {}: too few readings after the warm-up ({})",
                f.label, f.pid, f.slope_readings
            ),
            None => "no process was read".to_owned(),
        },
    });
    for (name, check, nominal) in [
        ("encoder", enc, goals.encoder_hz),
        ("tracker", &streams.tracker, goals.tracker_hz),
    ] {
        let rate = rate_hz(check, outcome.window_s);
        checks.push(Check {
            goal: format!(
                "{name} rate ≥ {:.0}% of {nominal} Hz",
                goals.min_rate_fraction * 100.0
            ),
            passed: rate >= goals.min_rate_fraction * nominal,
            detail: format!(
                "{rate:.2} Hz, longest interval {:.1} ms",
                check.window_max_interval_ns as f64 * 1e-6
            ),
        });
    }
    let restarted = restarted_nodes(&outcome.gathered);
    checks.push(Check {
        goal: "the graph ran the whole time without a restart".to_owned(),
        passed: outcome.early_end.is_none() && restarted.is_empty(),
        detail: match (&outcome.early_end, restarted.is_empty()) {
            (Some(why), _) => why.clone(),
            (None, false) => format!("restarted: {}", restarted.join(", ")),
            (None, true) => format!("{:.1} s", outcome.window_s),
        },
    });
    checks.push(Check {
        goal: "clean stop: launcher success, no process or shared memory left".to_owned(),
        passed: outcome.launcher_ok
            && outcome.survivors.is_empty()
            && outcome.leftover_files.is_empty(),
        detail: format!(
            "launcher {}, {} process(es) left, {} iceoryx2 file(s) left",
            outcome.launcher_exit,
            outcome.survivors.len(),
            outcome.leftover_files.len()
        ),
    });
    checks
}

/// Samples per second of a stream in the window.
fn rate_hz(check: &SeqCheck, window_s: f64) -> f64 {
    if window_s > 0.0 {
        check.window_received as f64 / window_s
    } else {
        0.0
    }
}

/// Nodes seen with more than one process id.
fn restarted_nodes(gathered: &Gathered) -> Vec<String> {
    let mut labels: Vec<&str> = gathered
        .processes
        .iter()
        .map(|p| p.label.as_str())
        .collect();
    labels.sort_unstable();
    let mut restarted: Vec<String> = labels
        .windows(2)
        .filter(|w| w[0] == w[1])
        .map(|w| w[0].to_owned())
        .collect();
    restarted.dedup();
    restarted
}

/// The table of processes, the stream figures and the verdict, as printed.
pub fn summary_text(outcome: &Outcome, checks: &[Check]) -> String {
    let mut text = String::new();
    let _ = writeln!(
        text,
        "sabr soak: {} for {:.1} s (memory slope after a {:.0} s warm-up)\n",
        outcome.graph.display(),
        outcome.window_s,
        outcome.warm_up_s
    );
    let _ = writeln!(
        text,
        "{:<12} {:>8} {:>14} {:>12} {:>12} {:>14} {:>8}",
        "process", "pid", "RSS start KiB", "RSS end KiB", "RSS max KiB", "slope KiB/min", "CPU %"
    );
    for f in &outcome.figures {
        let slope = f
            .rss_slope_kib_per_min
            .map_or("-".to_owned(), |s| format!("{s:+.1}"));
        let cpu = f.cpu_percent.map_or("-".to_owned(), |c| format!("{c:.1}"));
        let _ = writeln!(
            text,
            "{:<12} {:>8} {:>14} {:>12} {:>12} {:>14} {:>8}",
            f.label, f.pid, f.rss_start_kib, f.rss_end_kib, f.rss_max_kib, slope, cpu
        );
    }
    let s = &outcome.gathered.streams;
    let _ = writeln!(text);
    for (name, check) in [
        ("encoder samples", &s.encoders),
        ("tracker frames", &s.tracker),
        ("matched samples", &s.matched),
    ] {
        let _ = writeln!(
            text,
            "{name:<16} {:>9} received ({:>9} in the window, {:8.2} Hz), lost {}, sequence restarts {}, first seq {}",
            check.received,
            check.window_received,
            rate_hz(check, outcome.window_s),
            check.lost,
            check.restarts,
            check.first_seq.map_or("-".to_owned(), |s| s.to_string())
        );
    }
    let gap = outcome.gathered.max_read_gap;
    let _ = writeln!(
        text,
        "monitor: longest pause between reads {:.1} ms{}",
        gap.as_secs_f64() * 1e3,
        if gap > Duration::from_millis(200) {
            " (over 200 ms: a gap may be the monitor's own buffer overflow)"
        } else {
            ""
        }
    );
    let _ = writeln!(text, "\ngoals:");
    for check in checks {
        let _ = writeln!(
            text,
            "  [{}] {} — {}",
            if check.passed { "PASS" } else { "FAIL" },
            check.goal,
            check.detail
        );
    }
    let passed = checks.iter().all(|c| c.passed);
    let _ = writeln!(text, "\n{}", if passed { "PASS" } else { "FAIL" });
    text
}

/// The CSV files written while the soak runs, flushed every second.
pub struct SoakCsv {
    processes: csv::Writer<File>,
    streams: csv::Writer<File>,
}

impl SoakCsv {
    /// Creates [`PROCESS_CSV`] and [`STREAMS_CSV`] in `dir` with their headers.
    pub fn create(dir: &Path) -> anyhow::Result<Self> {
        let open = |name: &str| {
            let path = dir.join(name);
            csv::Writer::from_path(&path)
                .with_context(|| format!("cannot create {}", path.display()))
        };
        let mut processes = open(PROCESS_CSV)?;
        processes.write_record(["t_s", "process", "pid", "rss_kib", "cpu_s"])?;
        let mut streams = open(STREAMS_CSV)?;
        streams.write_record([
            "t_s",
            "encoder_samples",
            "encoder_lost",
            "encoder_restarts",
            "tracker_frames",
            "tracker_lost",
            "tracker_restarts",
            "matched_samples",
            "matched_lost",
        ])?;
        Ok(Self { processes, streams })
    }

    /// Appends one second's readings and stream counts and flushes both files.
    pub fn write(
        &mut self,
        t_s: f64,
        readings: &[(String, u32, Reading)],
        streams: &Streams,
        ticks_per_second: u64,
    ) -> anyhow::Result<()> {
        for (label, pid, reading) in readings {
            self.processes.write_record([
                format!("{t_s:.3}"),
                label.clone(),
                pid.to_string(),
                reading.proc.rss_kib.to_string(),
                format!(
                    "{:.2}",
                    reading.proc.cpu_ticks as f64 / ticks_per_second as f64
                ),
            ])?;
        }
        self.streams.write_record([
            format!("{t_s:.3}"),
            streams.encoders.received.to_string(),
            streams.encoders.lost.to_string(),
            streams.encoders.restarts.to_string(),
            streams.tracker.received.to_string(),
            streams.tracker.lost.to_string(),
            streams.tracker.restarts.to_string(),
            streams.matched.received.to_string(),
            streams.matched.lost.to_string(),
        ])?;
        self.processes.flush()?;
        self.streams.flush()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::soak::processes::Tracked;

    fn figures(label: &str, pid: u32, slope: Option<f64>) -> Figures {
        Figures {
            label: label.to_owned(),
            pid,
            rss_start_kib: 1_000,
            rss_end_kib: 1_000,
            rss_max_kib: 1_000,
            rss_slope_kib_per_min: slope,
            slope_readings: 10,
            cpu_percent: Some(1.0),
        }
    }

    fn healthy() -> Outcome {
        let mut streams = Streams::default();
        streams.encoders.start_window();
        streams.tracker.start_window();
        for seq in 1..=10_000 {
            streams.encoders.push(seq, seq as i64 * 1_000_000);
        }
        for seq in 1..=200 {
            streams.tracker.push(seq, seq as i64 * 50_000_000);
        }
        Outcome {
            graph: PathBuf::from("g.toml"),
            window_s: 10.0,
            warm_up_s: 2.0,
            gathered: Gathered {
                streams,
                processes: vec![Tracked::new("rig", 1), Tracked::new("encoders", 2)],
                max_read_gap: Duration::from_millis(6),
            },
            figures: vec![
                figures("rig", 1, Some(3.0)),
                figures("encoders", 2, Some(-1.0)),
            ],
            early_end: None,
            launcher_exit: "exit code 0".to_owned(),
            launcher_ok: true,
            survivors: vec![],
            leftover_files: vec![],
        }
    }

    const GOALS: Goals = Goals {
        max_rss_slope_kib_per_min: 64.0,
        encoder_hz: 1000.0,
        tracker_hz: 20.0,
        min_rate_fraction: 0.95,
    };

    fn failed(outcome: &Outcome) -> Vec<String> {
        checks(outcome, &GOALS)
            .into_iter()
            .filter(|c| !c.passed)
            .map(|c| c.goal)
            .collect()
    }

    #[test]
    fn a_healthy_soak_passes() {
        let outcome = healthy();
        assert_eq!(failed(&outcome), Vec::<String>::new());
        let text = summary_text(&outcome, &checks(&outcome, &GOALS));
        assert!(text.trim_end().ends_with("PASS"), "{text}");
        assert!(text.contains("1000.00 Hz"), "{text}");
    }

    #[test]
    fn each_fault_fails_its_goal() {
        let mut lost = healthy();
        lost.gathered.streams.encoders.push(10_005, 0);
        assert_eq!(failed(&lost), ["0 lost encoder samples (sequence numbers)"]);

        let mut leak = healthy();
        leak.figures[1].rss_slope_kib_per_min = Some(100.0);
        let failures = failed(&leak);
        assert_eq!(failures.len(), 1);
        assert!(failures[0].starts_with("memory flat"), "{failures:?}");
        let text = summary_text(&leak, &checks(&leak, &GOALS));
        assert!(text.contains("+100.0 KiB/min (encoders pid 2)"), "{text}");
        assert!(text.trim_end().ends_with("FAIL"), "{text}");

        let mut unfitted = healthy();
        unfitted.figures[0].rss_slope_kib_per_min = None;
        assert_eq!(failed(&unfitted).len(), 1);

        let mut slow = healthy();
        slow.window_s = 20.0;
        assert_eq!(failed(&slow).len(), 2, "{:?}", failed(&slow));

        let mut restarted = healthy();
        restarted.gathered.processes.push(Tracked::new("rig", 3));
        assert_eq!(
            failed(&restarted),
            ["the graph ran the whole time without a restart"]
        );

        let mut dirty = healthy();
        dirty.leftover_files.push(PathBuf::from("/dev/shm/x"));
        assert_eq!(failed(&dirty).len(), 1);
    }
}
