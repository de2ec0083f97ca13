//! One side of a Unix-domain-socket ping-pong: blocking writes and reads of fixed-size
//! messages over a stream socket.

use anyhow::{bail, Context};
use std::io::{ErrorKind, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// How often the pinging side looks for the connecting peer while it waits.
const ACCEPT_POLL: Duration = Duration::from_millis(1);

/// A listening socket file, removed when dropped.
pub struct SocketFile {
    listener: UnixListener,
    path: PathBuf,
}

impl SocketFile {
    /// Binds a new socket at `path` (which must not exist).
    pub fn bind(path: &Path) -> anyhow::Result<Self> {
        let listener = UnixListener::bind(path)
            .with_context(|| format!("cannot bind the Unix socket {}", path.display()))?;
        Ok(Self {
            listener,
            path: path.to_owned(),
        })
    }

    /// The socket's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Waits up to `timeout` for the peer to connect; `alive` is asked between polls and
    /// returns an error if the peer died.
    pub fn accept(
        &self,
        timeout: Duration,
        mut alive: impl FnMut() -> anyhow::Result<()>,
    ) -> anyhow::Result<UnixStream> {
        self.listener
            .set_nonblocking(true)
            .context("cannot make the listening socket non-blocking")?;
        let deadline = Instant::now() + timeout;
        loop {
            match self.listener.accept() {
                Ok((stream, _)) => {
                    stream
                        .set_nonblocking(false)
                        .context("cannot make the connection blocking")?;
                    return Ok(stream);
                }
                Err(error) if error.kind() == ErrorKind::WouldBlock => {
                    alive()?;
                    if Instant::now() >= deadline {
                        bail!(
                            "the peer did not connect to {} in {timeout:?}",
                            self.path.display()
                        );
                    }
                    std::thread::sleep(ACCEPT_POLL);
                }
                Err(error) => {
                    return Err(error)
                        .with_context(|| format!("accept on {} failed", self.path.display()))
                }
            }
        }
    }
}

impl Drop for SocketFile {
    fn drop(&mut self) {
        // Nothing to do if it is already gone.
        let _ = std::fs::remove_file(&self.path);
    }
}

/// One side of the socket ping-pong: writes `send_bytes`, reads `receive_bytes`.
pub struct UdsEnd {
    stream: UnixStream,
    outgoing: Vec<u8>,
    incoming: Vec<u8>,
}

impl UdsEnd {
    /// Wraps a connected stream; reads give up after `timeout` without data.
    pub fn new(
        stream: UnixStream,
        send_bytes: usize,
        receive_bytes: usize,
        timeout: Duration,
    ) -> anyhow::Result<Self> {
        stream
            .set_read_timeout(Some(timeout))
            .context("cannot set the socket read timeout")?;
        Ok(Self {
            stream,
            outgoing: vec![0; send_bytes],
            incoming: vec![0; receive_bytes],
        })
    }

    /// Connects to the socket at `path`.
    pub fn connect(
        path: &Path,
        send_bytes: usize,
        receive_bytes: usize,
        timeout: Duration,
    ) -> anyhow::Result<Self> {
        let stream = UnixStream::connect(path)
            .with_context(|| format!("cannot connect to {}", path.display()))?;
        Self::new(stream, send_bytes, receive_bytes, timeout)
    }

    /// Writes one message.
    pub fn send(&mut self) -> anyhow::Result<()> {
        self.stream
            .write_all(&self.outgoing)
            .context("socket write failed")
    }

    /// Reads one whole message (blocking).
    pub fn receive(&mut self) -> anyhow::Result<()> {
        self.stream
            .read_exact(&mut self.incoming)
            .context("socket read failed (peer gone or timed out)")
    }
}
