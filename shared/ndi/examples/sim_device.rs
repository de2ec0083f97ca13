//! Serves a simulated Polaris (4 tools, 20 Hz, frame counter +3 per frame) on a pseudo-terminal
//! and prints the terminal's path, for trying a driver by hand:
//!
//! `cargo run -p sabr-ndi --example sim_device [seconds]`, then
//! `cargo run -p sabr-tracker -- --port /dev/pts/N --frames 20`.

use sabr_ndi::{NdiServer, Pty, SimFrame, SimReading, Transform};
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seconds: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(60);
    let start = Instant::now();
    let source = move || {
        let index = (start.elapsed().as_millis() / 50) as u32;
        let x = (index as f32 * 0.1).sin() * 20.0;
        let pose = |dx: f32| {
            SimReading::Pose(Transform {
                q: [1.0, 0.0, 0.0, 0.0],
                t: [x + dx, 0.0, -1500.0],
                rms: 0.2,
            })
        };
        let tip = SimReading::Point {
            position: [x, -90.0, -1420.0],
            rms: 0.15,
        };
        Some(SimFrame {
            frame: 3 * index,
            readings: vec![pose(-80.0), pose(0.0), pose(20.0), tip],
        })
    };
    let mut pty = Pty::open()?;
    println!("{}", pty.slave_path().display());
    std::io::stdout().flush()?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    std::thread::spawn(move || {
        std::thread::sleep(Duration::from_secs(seconds));
        flag.store(true, Ordering::Relaxed);
    });
    let mut server = NdiServer::new(4, source);
    let stats = pty.serve(&mut server, &stop)?;
    eprintln!("served {stats:?}, device {:?}", server.stats());
    Ok(())
}
