//! A pseudo-terminal to serve the simulated tracker on.
//!
//! The rig keeps the master side; the host driver opens the slave path with `serialport` like a
//! real serial device. The slave starts in raw mode (no CR/LF translation, no echo). The rig does
//! not keep the slave open itself: when the driver closes it (or is killed), the terminal is
//! fully released, so a restarted driver can open it again (exclusive locks included).

use crate::server::{FrameSource, NdiServer};
use nix::errno::Errno;
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::AsFd;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use thiserror::Error;

/// How long [`Pty::serve`] waits for input before checking its stop flag.
const POLL_PERIOD: Duration = Duration::from_millis(20);
/// Pause while no driver has the slave open.
const IDLE_PAUSE: Duration = Duration::from_millis(10);
/// How long a reply may wait for the driver to drain the terminal before it is dropped.
const WRITE_DEADLINE: Duration = Duration::from_millis(200);

/// Why the pseudo-terminal could not be created or served.
#[derive(Debug, Error)]
pub enum PtyError {
    /// A system call failed.
    #[error("pseudo-terminal: {call} failed: {errno}")]
    Sys {
        /// The call.
        call: &'static str,
        /// The error.
        errno: Errno,
    },
    /// Reading or writing the master side failed.
    #[error("pseudo-terminal master I/O: {0}")]
    Io(#[from] std::io::Error),
}

fn sys(call: &'static str) -> impl FnOnce(Errno) -> PtyError {
    move |errno| PtyError::Sys { call, errno }
}

/// What [`Pty::serve`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServeStats {
    /// Bytes received from the driver.
    pub bytes_in: u64,
    /// Reply bytes written.
    pub bytes_out: u64,
    /// Replies dropped because no driver read them in time or the driver went away.
    pub dropped_replies: u64,
}

/// A pseudo-terminal whose slave side behaves like the tracker's serial port.
#[derive(Debug)]
pub struct Pty {
    master: File,
    slave_path: PathBuf,
}

impl Pty {
    /// Opens a new pseudo-terminal with its slave in raw mode.
    pub fn open() -> Result<Pty, PtyError> {
        let pair = openpty(None, None).map_err(sys("openpty"))?;
        let mut termios = tcgetattr(&pair.slave).map_err(sys("tcgetattr"))?;
        cfmakeraw(&mut termios);
        tcsetattr(&pair.slave, SetArg::TCSANOW, &termios).map_err(sys("tcsetattr"))?;
        let slave_path = nix::unistd::ttyname(&pair.slave).map_err(sys("ttyname"))?;
        let flags = fcntl(&pair.master, FcntlArg::F_GETFL).map_err(sys("fcntl(F_GETFL)"))?;
        let flags = OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK;
        fcntl(&pair.master, FcntlArg::F_SETFL(flags)).map_err(sys("fcntl(F_SETFL)"))?;
        // pair.slave is dropped here: see the module documentation.
        Ok(Pty {
            master: File::from(pair.master),
            slave_path,
        })
    }

    /// The slave device path (e.g. `/dev/pts/7`) for the driver to open.
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// Serves `server` until `stop` is set: commands from the driver in, replies out. Returns
    /// within about 20 ms of `stop`. A driver that goes away is not an error; the next one is
    /// served when it opens the slave.
    pub fn serve<S: FrameSource>(
        &mut self,
        server: &mut NdiServer<S>,
        stop: &AtomicBool,
    ) -> Result<ServeStats, PtyError> {
        let mut stats = ServeStats::default();
        let mut buf = [0u8; 1024];
        while !stop.load(Ordering::Relaxed) {
            if !self.wait(PollFlags::POLLIN, POLL_PERIOD)? {
                continue;
            }
            match self.master.read(&mut buf) {
                Ok(0) => std::thread::sleep(IDLE_PAUSE),
                Ok(n) => {
                    stats.bytes_in += n as u64;
                    let reply = server.feed(&buf[..n]);
                    if !reply.is_empty() {
                        match self.write_reply(&reply)? {
                            true => stats.bytes_out += reply.len() as u64,
                            false => stats.dropped_replies += 1,
                        }
                    }
                }
                Err(e)
                    if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted => {}
                // EIO: no process has the slave open.
                Err(e) if e.raw_os_error() == Some(Errno::EIO as i32) => {
                    std::thread::sleep(IDLE_PAUSE)
                }
                Err(e) => return Err(PtyError::Io(e)),
            }
        }
        Ok(stats)
    }

    /// Waits up to `timeout` for `events`; `false` on time-out or hang-up (no driver: pauses).
    fn wait(&self, events: PollFlags, timeout: Duration) -> Result<bool, PtyError> {
        let mut fds = [PollFd::new(self.master.as_fd(), events)];
        let millis = u16::try_from(timeout.as_millis()).unwrap_or(u16::MAX);
        match poll(&mut fds, PollTimeout::from(millis)) {
            Ok(0) => return Ok(false),
            Ok(_) => {}
            Err(Errno::EINTR) => return Ok(false),
            Err(errno) => {
                return Err(PtyError::Sys {
                    call: "poll",
                    errno,
                })
            }
        }
        let revents = fds[0].revents().unwrap_or(PollFlags::empty());
        if revents.intersects(events) {
            return Ok(true);
        }
        // POLLHUP without data: nobody has the slave open.
        std::thread::sleep(IDLE_PAUSE);
        Ok(false)
    }

    /// Writes a whole reply; `false` if it had to be dropped.
    fn write_reply(&mut self, mut reply: &[u8]) -> Result<bool, PtyError> {
        let deadline = Instant::now() + WRITE_DEADLINE;
        while !reply.is_empty() {
            match self.master.write(reply) {
                Ok(n) => reply = &reply[n..],
                Err(e)
                    if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted =>
                {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() || !self.wait(PollFlags::POLLOUT, left)? {
                        return Ok(false);
                    }
                }
                Err(e) if e.raw_os_error() == Some(Errno::EIO as i32) => return Ok(false),
                Err(e) => return Err(PtyError::Io(e)),
            }
        }
        Ok(true)
    }
}
