//! Benchmark: reading a 300 s, 1 kHz `encoders.csv` (300,000 rows) must take under 1 s in
//! release. Writes such a file with realistic counts (slow sinusoidal joint motion of tens of
//! thousands of counts, 1 ms ± jitter sample spacing), then times streaming it with
//! `EncoderReader` and reading the whole recording with `Recording::read`.
//!
//! Run: `cargo bench -p sabr-recording --bench read_encoders` (prints the figures).

use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

use sabr_recording::{EncoderReader, EncoderRow, Recording, RecordingWriter};

/// 300 s at 1 kHz.
const ROWS: usize = 300_000;
/// Timed repetitions of each measurement.
const REPETITIONS: usize = 7;

fn main() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let recording = dir.path().join("recording");
    let write_time = write_recording(&recording);
    let path = recording.join("encoders.csv");
    let bytes = std::fs::metadata(&path).expect("encoders.csv").len();
    println!(
        "encoders.csv: {ROWS} rows, {:.1} MB; written in {:.3} s",
        bytes as f64 / 1e6,
        write_time.as_secs_f64()
    );

    let stream = median_time(|| {
        let mut sum = 0i64;
        for row in EncoderReader::open(&path).expect("open") {
            let row = row.expect("valid row");
            sum = sum.wrapping_add(row.counts[2]);
        }
        black_box(sum);
    });
    report("EncoderReader (streaming)", stream, bytes);

    let whole = median_time(|| {
        let read = Recording::read(&recording).expect("valid recording");
        assert_eq!(read.encoders.len(), ROWS);
        black_box(read);
    });
    report("Recording::read (whole recording)", whole, bytes);
    let verdict = if stream.max(whole) < Duration::from_secs(1) {
        "PASS"
    } else {
        "FAIL"
    };
    println!("goal: < 1 s for 300,000 rows: {verdict}");
}

/// Writes a recording whose `encoders.csv` holds `ROWS` realistic samples; returns the time.
fn write_recording(dir: &Path) -> Duration {
    let start = Instant::now();
    let mut writer = RecordingWriter::create(dir, "format = 1\n").expect("create");
    let mut t_ns: i64 = 1_734_000_123_456_789;
    for i in 0..ROWS {
        let seconds = i as f64 * 1e-3;
        let mut counts = [0i64; 5];
        for (joint, count) in counts.iter_mut().enumerate() {
            let amplitude = 12_000.0 + 4_000.0 * joint as f64;
            let frequency = 0.05 + 0.013 * joint as f64;
            let phase = (std::f64::consts::TAU * frequency * seconds).sin();
            *count = (amplitude * phase).round() as i64 - 35_000;
        }
        t_ns += 1_000_000 + (i as i64 * 7919 % 20_001) - 10_000;
        writer
            .write_encoder(&EncoderRow { t_ns, counts })
            .expect("write");
    }
    writer.finish().expect("finish");
    start.elapsed()
}

/// The median wall time of `REPETITIONS` runs of `run`, after one warm-up run.
fn median_time(mut run: impl FnMut()) -> Duration {
    run();
    let mut times: Vec<Duration> = (0..REPETITIONS)
        .map(|_| {
            let start = Instant::now();
            run();
            start.elapsed()
        })
        .collect();
    times.sort();
    times[REPETITIONS / 2]
}

fn report(what: &str, time: Duration, bytes: u64) {
    let seconds = time.as_secs_f64();
    println!(
        "{what}: median {:.1} ms over {REPETITIONS} runs ({:.2} M rows/s, {:.0} MB/s)",
        seconds * 1e3,
        ROWS as f64 / seconds / 1e6,
        bytes as f64 / seconds / 1e6
    );
}
