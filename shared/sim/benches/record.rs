//! Benchmark: time to simulate and write a default session (about 5 minutes of robot time).
//! `cargo bench -p sabr-sim --bench record` prints the wall time of each run and the median.

use std::time::Instant;

use sabr_sim::{record_session, write_session, SimConfig};

const RUNS: u64 = 5;

fn main() {
    let root = std::env::temp_dir().join(format!("sabr-sim-bench-{}", std::process::id()));
    let mut simulate = Vec::new();
    let mut total = Vec::new();
    for run in 0..RUNS {
        let config = SimConfig::new(run);
        let started = Instant::now();
        let (recording, truth) = record_session(&config).expect("simulation");
        let simulated = started.elapsed().as_secs_f64();
        write_session(&root.join(run.to_string()), &recording, &truth).expect("write");
        let written = started.elapsed().as_secs_f64();
        let robot_s =
            (recording.encoders.last().unwrap().t_ns - recording.encoders[0].t_ns) as f64 * 1e-9;
        println!(
            "run {run}: {robot_s:.1} s robot time, {} encoder rows, {} tracker rows: simulate \
             {simulated:.3} s, simulate + write {written:.3} s",
            recording.encoders.len(),
            recording.tracker.len()
        );
        simulate.push(simulated);
        total.push(written);
    }
    std::fs::remove_dir_all(&root).expect("clean up");
    let median = |values: &mut Vec<f64>| {
        values.sort_by(f64::total_cmp);
        values[values.len() / 2]
    };
    println!(
        "default session: simulate median {:.3} s, simulate + write median {:.3} s (goal ≤ 10 s)",
        median(&mut simulate),
        median(&mut total)
    );
}
