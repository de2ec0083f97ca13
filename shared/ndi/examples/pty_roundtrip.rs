//! Measures the driver against the simulated device on a pseudo-terminal: BX round-trip time,
//! how late a new frame is stamped after the device has it, and parser throughput.
//!
//! `cargo run --release -p sabr-ndi --example pty_roundtrip [polls]`

use sabr_ndi::bx::{encode_bx, parse_bx_frame};
use sabr_ndi::tx::{encode_tx, parse_tx};
use sabr_ndi::{
    decode_reply, DriverConfig, HandleReading, HandleStatus, NdiDriver, NdiServer, Pty,
    ReplyOptions, SimFrame, SimReading, TrackingReply, Transform,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const FRAME_PERIOD: Duration = Duration::from_millis(50); // 20 Hz, like the Vicra

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn report(name: &str, mut samples: Vec<Duration>) {
    samples.sort();
    println!(
        "{name}: n={} p50={:?} p99={:?} max={:?}",
        samples.len(),
        percentile(&samples, 0.5),
        percentile(&samples, 0.99),
        samples[samples.len() - 1]
    );
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let polls: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(2000);
    let start = Instant::now();
    // When each frame became available on the device (to measure the stamping lag).
    let published: Arc<Mutex<Vec<Instant>>> = Arc::default();
    let log = published.clone();
    let source = move || {
        let index = (start.elapsed().as_nanos() / FRAME_PERIOD.as_nanos()) as u32;
        let mut log = log.lock().ok()?;
        while log.len() <= index as usize {
            let n = log.len() as u32;
            log.push(start + FRAME_PERIOD * n);
        }
        let pose = SimReading::Pose(Transform {
            q: [1.0, 0.0, 0.0, 0.0],
            t: [index as f32, 0.0, -1500.0],
            rms: 0.2,
        });
        Some(SimFrame {
            frame: 3 * index,
            readings: vec![pose; 4],
        })
    };
    let mut pty = Pty::open()?;
    let path = pty
        .slave_path()
        .to_str()
        .ok_or("PTY path is not UTF-8")?
        .to_owned();
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let server = std::thread::spawn(move || {
        let mut server = NdiServer::new(4, source);
        pty.serve(&mut server, &flag)
    });

    let mut driver = NdiDriver::connect(DriverConfig::new(&path))?;
    let mut round_trips = Vec::with_capacity(polls);
    for _ in 0..polls {
        let sent = Instant::now();
        let stamped = driver.poll()?;
        round_trips.push(stamped.arrival - sent);
    }
    report("BX:0001 round trip, 4 handles, PTY", round_trips);

    // The first new frame may have been waiting since before the loop: not a lag.
    driver.next_frame()?;
    let mut lags = Vec::new();
    for _ in 0..60 {
        let stamped = driver.next_frame()?;
        let index = stamped.reply.frame().unwrap_or(0) / 3;
        let available = published.lock().map_err(|_| "poisoned")?[index as usize];
        lags.push(stamped.arrival.saturating_duration_since(available));
    }
    report(
        "new frame stamped after the device had it (poll interval 1 ms)",
        lags,
    );
    println!("driver stats: {:?}", driver.stats());
    driver.stop()?;
    stop.store(true, Ordering::Relaxed);
    server.join().map_err(|_| "server thread panicked")??;

    // Parser throughput on a 4-handle reply.
    let reading = HandleReading {
        transform: Some(Transform {
            q: [0.5, 0.5, 0.5, 0.5],
            t: [12.34, -56.78, -1500.0],
            rms: 0.2,
        }),
        port_status: Some(0x31),
        frame: Some(1234),
        ..HandleReading::bare(1, HandleStatus::Valid)
    };
    let reply = TrackingReply {
        options: ReplyOptions::TRANSFORMS,
        handles: (1..=4)
            .map(|h| HandleReading {
                handle: h,
                ..reading.clone()
            })
            .collect(),
        stray_markers: None,
        system_status: 0,
    };
    let bx = encode_bx(&reply)?;
    let tx = encode_tx(&reply)?;
    let n = 200_000;
    let t = Instant::now();
    for _ in 0..n {
        std::hint::black_box(parse_bx_frame(
            std::hint::black_box(&bx),
            ReplyOptions::TRANSFORMS,
        )?);
    }
    println!(
        "parse BX frame ({} bytes): {:?} each",
        bx.len(),
        t.elapsed() / n
    );
    let t = Instant::now();
    for _ in 0..n {
        let text = decode_reply(std::hint::black_box(&tx))?.into_text()?;
        std::hint::black_box(parse_tx(&text, ReplyOptions::TRANSFORMS)?);
    }
    println!(
        "decode + parse TX reply ({} bytes): {:?} each",
        tx.len(),
        t.elapsed() / n
    );
    Ok(())
}
