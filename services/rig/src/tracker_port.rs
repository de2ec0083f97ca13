//! The rig's tracker as a serial device: the NDI Combined API served on a pseudo-terminal in
//! its own thread, reachable through a fixed device path (a symlink to the PTY slave, like
//! `/dev/ttyUSB0` on real hardware).
//!
//! Captured frames wait in a [`FrameQueue`] until their simulated arrival time has passed:
//! a BX poll only ever sees frames the host could have received by then (latency realism).

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;

use anyhow::{bail, Context};
use sabr_msgs::Tool as MsgTool;
use sabr_ndi::{FrameSource, NdiServer, Pty, ServeStats, SimFrame, SimReading, Transform};
use sabr_recording::{Tool, ToolReading};

/// Number of tools (port handles 1..=4: base, front, back, tip).
const TOOL_COUNT: u8 = sabr_msgs::TOOLS as u8;

/// The index of a tool in a frame (and its port handle minus one), as in `sabr_msgs::Tool`.
fn tool_index(tool: Tool) -> usize {
    let tool = match tool {
        Tool::Base => MsgTool::Base,
        Tool::Front => MsgTool::Front,
        Tool::Back => MsgTool::Back,
        Tool::Tip => MsgTool::Tip,
    };
    tool as usize
}

/// The device's view of an emulated frame: readings in port-handle order, in `S` (mm).
pub fn sim_frame(frame: &sabr_sim::TrackerFrame) -> SimFrame {
    let mut readings = vec![SimReading::Missing; usize::from(TOOL_COUNT)];
    for (tool, reading) in &frame.readings {
        readings[tool_index(*tool)] = match *reading {
            ToolReading::Missing => SimReading::Missing,
            ToolReading::Pose {
                quaternion,
                position,
                rms,
            } => SimReading::Pose(Transform {
                q: quaternion.map(|v| v as f32),
                t: position.map(|v| v as f32),
                rms: rms as f32,
            }),
            ToolReading::Point { position, rms } => SimReading::Point {
                position: position.map(|v| v as f32),
                rms: rms as f32,
            },
        };
    }
    SimFrame {
        frame: frame.exposure.frame,
        readings,
    }
}

/// Frames captured but not yet arrived at the host, and the newest one that has.
#[derive(Debug, Default)]
pub struct FrameQueue {
    pending: VecDeque<(i64, SimFrame)>,
    latest: Option<SimFrame>,
}

impl FrameQueue {
    /// Queues a frame that reaches the host at `arrival_ns` (host `CLOCK_MONOTONIC`). Frames
    /// are queued in arrival order.
    pub fn push(&mut self, arrival_ns: i64, frame: SimFrame) {
        self.pending.push_back((arrival_ns, frame));
    }

    /// The newest frame whose arrival time is at or before `now_ns`.
    pub fn latest_at(&mut self, now_ns: i64) -> Option<SimFrame> {
        while self
            .pending
            .front()
            .is_some_and(|(arrival, _)| *arrival <= now_ns)
        {
            self.latest = self.pending.pop_front().map(|(_, frame)| frame);
        }
        self.latest.clone()
    }
}

/// A [`FrameQueue`] shared between the rig's loop (producer) and the PTY thread (consumer).
#[derive(Debug, Clone, Default)]
pub struct SharedFrames(Arc<Mutex<FrameQueue>>);

impl SharedFrames {
    /// The queue, locked (a panic elsewhere cannot leave it inconsistent: it is plain data).
    pub fn lock(&self) -> MutexGuard<'_, FrameQueue> {
        self.0
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl FrameSource for SharedFrames {
    fn latest_frame(&mut self) -> Option<SimFrame> {
        self.lock().latest_at(sabr_node::monotonic_ns())
    }
}

/// The simulated tracker served on a pseudo-terminal, and the device path pointing at it.
#[derive(Debug)]
pub struct TrackerPort {
    link: PathBuf,
    slave: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<ServeStats, sabr_ndi::PtyError>>>,
}

impl TrackerPort {
    /// Opens a PTY, starts serving a 4-tool NDI device fed by `frames` on it, and makes `link`
    /// a symlink to its slave (replacing a stale symlink; any other file there is an error).
    pub fn start(link: &Path, frames: SharedFrames) -> anyhow::Result<Self> {
        let mut pty = Pty::open().context("cannot open the tracker's pseudo-terminal")?;
        let slave = pty.slave_path().to_path_buf();
        replace_symlink(link, &slave)?;
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("ndi-pty".into())
            .spawn(move || {
                let mut server = NdiServer::new(TOOL_COUNT, frames);
                pty.serve(&mut server, &stop_flag)
            })
            .context("cannot start the tracker thread")?;
        Ok(TrackerPort {
            link: link.to_path_buf(),
            slave,
            stop,
            thread: Some(thread),
        })
    }

    /// The PTY slave the device path points at.
    pub fn slave_path(&self) -> &Path {
        &self.slave
    }

    /// False once the serving thread has ended (it only ends on an error or [`Self::finish`]).
    pub fn is_serving(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stops serving, removes the device path and returns what the server did.
    pub fn finish(mut self) -> anyhow::Result<ServeStats> {
        self.stop.store(true, Ordering::Relaxed);
        let result = match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result.context("serving the tracker's pseudo-terminal failed"),
            Some(Err(_)) => Err(anyhow::anyhow!("the tracker thread panicked")),
            None => Ok(ServeStats::default()),
        };
        self.remove_link();
        result
    }

    fn remove_link(&self) {
        // Only our own link: a newer rig may have replaced it.
        if std::fs::read_link(&self.link).is_ok_and(|target| target == self.slave) {
            if let Err(error) = std::fs::remove_file(&self.link) {
                tracing::warn!(link = %self.link.display(), %error, "cannot remove the device path");
            }
        }
    }
}

impl Drop for TrackerPort {
    fn drop(&mut self) {
        if let Some(thread) = self.thread.take() {
            self.stop.store(true, Ordering::Relaxed);
            let _ = thread.join();
            self.remove_link();
        }
    }
}

/// Points `link` at `target` atomically (a temporary symlink renamed over it).
fn replace_symlink(link: &Path, target: &Path) -> anyhow::Result<()> {
    if let Ok(meta) = std::fs::symlink_metadata(link) {
        if !meta.file_type().is_symlink() {
            bail!(
                "--pty-link {}: exists and is not a symlink; refusing to replace it",
                link.display()
            );
        }
    }
    let mut temporary = link.as_os_str().to_owned();
    temporary.push(format!(".tmp-{}", std::process::id()));
    let temporary = PathBuf::from(temporary);
    let _ = std::fs::remove_file(&temporary);
    std::os::unix::fs::symlink(target, &temporary)
        .and_then(|()| std::fs::rename(&temporary, link))
        .with_context(|| {
            format!(
                "--pty-link {}: cannot create the symlink to {}",
                link.display(),
                target.display()
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_sim::Exposure;

    fn emulated(frame: u32) -> sabr_sim::TrackerFrame {
        sabr_sim::TrackerFrame {
            exposure: Exposure {
                frame,
                exposure_ns: 0,
            },
            arrival_ns: Some(1),
            // Deliberately not in handle order: the tool decides the handle.
            readings: [
                (
                    Tool::Tip,
                    ToolReading::Point {
                        position: [1.5, -2.0, -900.25],
                        rms: 0.0,
                    },
                ),
                (Tool::Back, ToolReading::Missing),
                (
                    Tool::Base,
                    ToolReading::Pose {
                        quaternion: [0.5, 0.5, -0.5, 0.5],
                        position: [10.0, 20.0, -950.0],
                        rms: 0.125,
                    },
                ),
                (
                    Tool::Front,
                    ToolReading::Pose {
                        quaternion: [1.0, 0.0, 0.0, 0.0],
                        position: [-3.0, 4.0, -880.0],
                        rms: 0.25,
                    },
                ),
            ],
        }
    }

    #[test]
    fn frames_map_tools_to_their_port_handles() {
        let frame = sim_frame(&emulated(1234));
        assert_eq!(frame.frame, 1234);
        assert_eq!(
            frame.readings,
            vec![
                SimReading::Pose(Transform {
                    q: [0.5, 0.5, -0.5, 0.5],
                    t: [10.0, 20.0, -950.0],
                    rms: 0.125
                }),
                SimReading::Pose(Transform {
                    q: [1.0, 0.0, 0.0, 0.0],
                    t: [-3.0, 4.0, -880.0],
                    rms: 0.25
                }),
                SimReading::Missing,
                SimReading::Point {
                    position: [1.5, -2.0, -900.25],
                    rms: 0.0
                },
            ]
        );
    }

    #[test]
    fn only_frames_that_have_arrived_are_served() {
        let mut queue = FrameQueue::default();
        assert_eq!(queue.latest_at(1_000), None);
        queue.push(100, sim_frame(&emulated(1)));
        queue.push(150, sim_frame(&emulated(2)));
        queue.push(300, sim_frame(&emulated(3)));
        assert_eq!(queue.latest_at(99), None);
        assert_eq!(queue.latest_at(100).map(|f| f.frame), Some(1));
        assert_eq!(queue.latest_at(299).map(|f| f.frame), Some(2));
        // The newest arrived frame stays the answer until the next arrives.
        assert_eq!(queue.latest_at(299).map(|f| f.frame), Some(2));
        assert_eq!(queue.latest_at(10_000).map(|f| f.frame), Some(3));
    }

    #[test]
    fn device_path_replaces_stale_links_but_not_files() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("polaris-tty");
        replace_symlink(&link, Path::new("/dev/null")).unwrap();
        replace_symlink(&link, Path::new("/dev/zero")).unwrap();
        assert_eq!(std::fs::read_link(&link).unwrap(), Path::new("/dev/zero"));
        let file = dir.path().join("plain");
        std::fs::write(&file, "keep me").unwrap();
        let error = replace_symlink(&file, Path::new("/dev/null")).unwrap_err();
        assert!(error.to_string().contains("not a symlink"), "{error}");
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "keep me");
    }

    #[test]
    fn served_port_answers_the_driver_and_cleans_up() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("polaris-tty");
        let frames = SharedFrames::default();
        frames.lock().push(0, sim_frame(&emulated(77)));
        let port = TrackerPort::start(&link, frames).unwrap();
        assert!(port.is_serving());
        assert_eq!(std::fs::read_link(&link).unwrap(), port.slave_path());
        let config = sabr_ndi::DriverConfig::new(link.to_string_lossy());
        let mut driver = sabr_ndi::NdiDriver::connect(config).unwrap();
        let stamped = driver.next_frame().unwrap();
        assert_eq!(stamped.reply.frame(), Some(77));
        let base = stamped.reply.handle(1).unwrap().transform.unwrap();
        assert_eq!(base.t, [10.0, 20.0, -950.0]);
        driver.stop().unwrap();
        let stats = port.finish().unwrap();
        assert!(stats.bytes_out > 0);
        assert!(std::fs::symlink_metadata(&link).is_err(), "link removed");
    }
}
