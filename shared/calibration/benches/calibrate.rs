//! Benchmark of `sabr calibrate` on a default simulated recording (5 minutes of robot
//! time): wall time and peak resident memory (VmHWM) of reading, calibrating and writing
//! the outputs, each run in a fresh child process so that the memory figure is the
//! calibration's alone; plus the accuracy against the simulator's truth.
//!
//! `cargo bench -p sabr-calibration --bench calibrate [-- SEED [RUNS]]`

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use sabr_calibration::{calibrate, write_outputs, CalibrationOptions};
use sabr_model::{forward, JointMotion, RobotParams};
use sabr_recording::Recording;
use sabr_sim::{record_session, write_session, SimConfig};

const CHILD_FLAG: &str = "--child-calibrate";
/// Goal for the median wall time of `sabr calibrate` on a default session (s).
const WALL_GOAL_S: f64 = 2.0;
/// Goal for the peak resident memory (MB).
const MEMORY_GOAL_MB: f64 = 500.0;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    if args.first().map(String::as_str) == Some(CHILD_FLAG) {
        return child(Path::new(&args[1]), Path::new(&args[2]));
    }
    let seed: u64 = args.first().map_or(Ok(1), |s| s.parse())?;
    let runs: usize = args.get(1).map_or(Ok(3), |s| s.parse())?;
    let work = tempfile::tempdir()?;
    let recording_dir = work.path().join("recording");
    let (recording, truth) = record_session(&SimConfig::new(seed))?;
    write_session(&recording_dir, &recording, &truth)?;
    let mut walls = Vec::new();
    let mut peaks = Vec::new();
    for run in 0..runs {
        let out = work.path().join(format!("out{run}"));
        let output = Command::new(std::env::current_exe()?)
            .args([
                CHILD_FLAG,
                &recording_dir.display().to_string(),
                &out.display().to_string(),
            ])
            .output()?;
        anyhow::ensure!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let text = String::from_utf8(output.stdout)?;
        let mut fields = text.split_whitespace();
        walls.push(fields.next().unwrap_or_default().parse::<f64>()?);
        peaks.push(fields.next().unwrap_or_default().parse::<f64>()?);
    }
    walls.sort_by(f64::total_cmp);
    let params = RobotParams::from_toml_str(&std::fs::read_to_string(
        work.path().join("out0/params.toml"),
    )?)?;
    let errors: Vec<f64> = truth
        .validation
        .iter()
        .map(|hold| -> anyhow::Result<f64> {
            let q = params.joints_from_counts(&hold.counts, &JointMotion::default())?;
            Ok((forward(&params.effective_geometry(), &q)?.tip - hold.tip).norm())
        })
        .collect::<anyhow::Result<_>>()?;
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let (median, peak_mb) = (
        walls[walls.len() / 2],
        peaks.iter().copied().fold(0.0, f64::max) / 1024.0,
    );
    let verdict = if median <= WALL_GOAL_S && peak_mb <= MEMORY_GOAL_MB {
        "goals met"
    } else {
        "GOALS MISSED"
    };
    println!(
        "calibrate (seed {seed}, default session, {} tracker rows, {} encoder samples): wall \
         min {:.2} s, median {:.2} s, max {:.2} s over {runs} runs; peak RSS (VmHWM) max {:.0} MB \
         (goals: median ≤ {WALL_GOAL_S} s, ≤ {MEMORY_GOAL_MB} MB: {verdict}); truth tip error \
         RMS {rms:.4} mm",
        recording.tracker.len(),
        recording.encoders.len(),
        walls[0],
        median,
        walls[walls.len() - 1],
        peak_mb
    );
    Ok(())
}

/// Reads, calibrates and writes like `sabr calibrate`; prints wall seconds and VmHWM (kB).
fn child(recording_dir: &Path, out: &Path) -> anyhow::Result<()> {
    let started = Instant::now();
    let recording = Recording::read(recording_dir)?;
    let calibration = calibrate(&recording, &CalibrationOptions::default())?;
    write_outputs(&calibration, out)?;
    let wall = started.elapsed().as_secs_f64();
    let status = std::fs::read_to_string("/proc/self/status")?;
    let peak_kb: f64 = status
        .lines()
        .find_map(|line| line.strip_prefix("VmHWM:"))
        .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
        .ok_or_else(|| anyhow::anyhow!("no VmHWM in /proc/self/status"))?;
    println!("{wall} {peak_kb}");
    Ok(())
}
