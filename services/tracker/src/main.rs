//! `sabr-tracker`: drives an NDI tracker (a real Polaris, or the rig's pseudo-terminal) with the
//! `sabr_ndi` driver. For now it prints one line per new frame on stdout; publishing on the graph
//! comes with the graph runtime.

use anyhow::Context;
use clap::Parser;
use sabr_ndi::{Baud, DriverConfig, HandleStatus, NdiDriver};

/// Command line of the tracker process.
#[derive(Debug, Parser)]
#[command(name = "sabr-tracker", about)]
struct Args {
    /// Serial device of the tracker (e.g. /dev/ttyUSB0, or the PTY path the rig prints).
    #[arg(long)]
    port: String,
    /// Serial speed to switch to after INIT, bit/s (9600 keeps the power-up speed).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Stop after this many frames (0: run until an error).
    #[arg(long, default_value_t = 0)]
    frames: u64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let baud = Baud::from_bits_per_second(args.baud).with_context(|| {
        format!(
            "--baud {}: not a speed the NDI COMM command offers",
            args.baud
        )
    })?;
    let config = DriverConfig {
        baud,
        ..DriverConfig::new(&args.port)
    };
    let mut driver = NdiDriver::connect(config)
        .with_context(|| format!("starting the tracker on {}", args.port))?;
    let handles: Vec<String> = driver
        .handles()
        .iter()
        .map(|h| format!("{:02X}", h.handle))
        .collect();
    eprintln!(
        "sabr-tracker: {} tracking, port handles {}",
        driver.version().lines().next().unwrap_or("device"),
        handles.join(" ")
    );
    let mut count = 0u64;
    while args.frames == 0 || count < args.frames {
        let stamped = driver.next_frame().context("reading the tracker")?;
        let tools: Vec<String> = stamped
            .reply
            .handles
            .iter()
            .map(|h| match (h.status, h.transform) {
                (HandleStatus::Valid, Some(t)) => {
                    format!("{:02X}:{:.2},{:.2},{:.2}", h.handle, t.t[0], t.t[1], t.t[2])
                }
                (status, _) => format!("{:02X}:{}", h.handle, status.name()),
            })
            .collect();
        let frame = stamped.reply.frame().unwrap_or_default();
        println!("{} {frame} {}", stamped.arrival_ns, tools.join(" "));
        count += 1;
    }
    driver.stop().context("stopping the tracker")?;
    Ok(())
}
