//! The host side: an NDI tracker driver over a serial port (a real Polaris, or the rig's PTY).
//!
//! [`NdiDriver::connect`] opens the port at 9600 baud and runs the start-up sequence: INIT (on a
//! time-out: serial break, wait for `RESET`, INIT again; on `ERROR0C`, i.e. still tracking from an
//! earlier session: TSTOP, INIT again), COMM to the configured speed, VER, then PHSR/PINIT for
//! every occupied port handle and PHSR/PENA for every initialised one, and TSTART. Then
//! [`NdiDriver::next_frame`] polls BX and returns each new frame stamped twice: on the arrival
//! of the reply, and with an estimate of when the frame became available at the device.
//! [`NdiDriver::stop`] (or dropping the driver) sends TSTOP.
//!
//! Every read has a deadline: a dead tracker is a [`DriverError::Timeout`], a tracker that
//! answers but whose frame counter stands still is a [`DriverError::Stalled`]. Passive tools that
//! need their ROM uploaded (PHRQ + PVWR) are not handled: the driver enables what the device
//! reports as occupied.
//!
//! Time stamps: a poll is *sent* once the BX command has been written and flushed to the port
//! (on a serial port, its last byte has left the host), and its reply *arrives* when its last
//! byte is read, both on the host `CLOCK_MONOTONIC`. A new frame became available at the device
//! between the send times of the last answered poll that did not see its frame number yet and
//! of the poll that saw it; [`Stamped::available_ns`] is the midpoint, within ± half the gap
//! between those two polls ([`Stamped::available_half_width_ns`]; about ± ½ ms at the 1 ms
//! poll interval). The first frame after TSTART has no earlier poll: it is stamped with the
//! send time of the poll that saw it. See [`crate::availability`].

use crate::availability::AvailabilityEstimator;
use crate::bx::parse_bx_body;
use crate::command::{Baud, CommSettings, Command, PhsrFilter, TrackingPriority};
use crate::error::DeviceError;
use crate::error::ReplyError;
use crate::framing::{FramerStats, RawReply, ReplyFramer};
use crate::pacing::PollPacer;
use crate::reply::{ReplyOptions, TrackingReply};
use crate::text::{
    parse_acknowledgement, parse_phsr, reject_device_error, Acknowledgement, PortHandleStatus,
};
use serialport::{ClearBuffer, SerialPort};
use std::io::{ErrorKind, Write};
use std::time::{Duration, Instant};
use thiserror::Error;

/// How the driver talks to the tracker.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DriverConfig {
    /// Serial device path (`/dev/ttyUSB0`, or the rig's `/dev/pts/N`).
    pub path: String,
    /// Speed to switch to with COMM after INIT (the device starts at 9600).
    pub baud: Baud,
    /// BX reply options; must include 0x0001 (transforms, port status, frame numbers).
    pub options: ReplyOptions,
    /// PENA tracking priority for every handle.
    pub priority: TrackingPriority,
    /// Deadline of an ordinary reply.
    pub reply_timeout: Duration,
    /// Deadline of the slow commands (INIT, PINIT, TSTART, the RESET after a break).
    pub slow_timeout: Duration,
    /// Pause after the COMM reply before talking at the new speed.
    pub baud_settle: Duration,
    /// Pause between BX polls while the frame number has not changed.
    pub poll_interval: Duration,
    /// How long before the next frame is due (by the recent intervals between frames, less
    /// the longest recent exchange) polling resumes after a frame; until then it pauses (see
    /// [`crate::pacing`]). A lead as long as the frame period polls without pauses.
    pub poll_lead: Duration,
    /// [`NdiDriver::next_frame`] fails if no new frame number arrives within this.
    pub stall_timeout: Duration,
    /// BX polls [`NdiDriver::next_frame`] sends again after one went unanswered within
    /// `reply_timeout` (a reply lost on the line, or a host too busy to read it in time),
    /// before it gives up with [`DriverError::Timeout`]: a silent tracker is declared dead
    /// after `(1 + poll_retries) × reply_timeout`.
    pub poll_retries: u32,
}

impl DriverConfig {
    /// Defaults for `path`: 115200 baud, BX 0x0001, dynamic priority, 200 ms reply deadline,
    /// 3 s for slow commands, 1 ms poll interval resuming 5 ms before a frame is due, 500 ms
    /// stall limit (10 frames at 20 Hz), 2 BX polls sent again after a time-out.
    pub fn new(path: impl Into<String>) -> Self {
        DriverConfig {
            path: path.into(),
            baud: Baud::B115200,
            options: ReplyOptions::TRANSFORMS,
            priority: TrackingPriority::Dynamic,
            reply_timeout: Duration::from_millis(200),
            slow_timeout: Duration::from_secs(3),
            baud_settle: Duration::from_millis(50),
            poll_interval: Duration::from_millis(1),
            poll_lead: Duration::from_millis(5),
            stall_timeout: Duration::from_millis(500),
            poll_retries: 2,
        }
    }
}

/// Why the driver failed. Every variant names the command involved.
#[derive(Debug, Error)]
pub enum DriverError {
    /// The configuration cannot work.
    #[error("driver configuration: {0}")]
    Config(&'static str),
    /// The serial port could not be opened or configured.
    #[error("serial port {path}: {source}")]
    Open {
        /// Device path.
        path: String,
        /// Cause.
        source: serialport::Error,
    },
    /// Reading or writing the port failed (e.g. the device went away).
    #[error("{command}: serial I/O: {source}")]
    Io {
        /// The command being exchanged.
        command: String,
        /// Cause.
        source: std::io::Error,
    },
    /// No complete reply within the deadline.
    #[error("{command}: no reply within {waited:?}")]
    Timeout {
        /// The command.
        command: String,
        /// How long the driver waited.
        waited: Duration,
    },
    /// The device answered `ERRORxx`.
    #[error("{command}: {error}")]
    Device {
        /// The command.
        command: String,
        /// The device's error.
        error: DeviceError,
    },
    /// The reply was corrupt or not what the command calls for.
    #[error("{command}: bad reply: {error}")]
    Reply {
        /// The command.
        command: String,
        /// What was wrong.
        error: ReplyError,
    },
    /// The device answers but its frame counter has not advanced.
    #[error("tracker stalled: frame {last_frame:?} for {waited:?}")]
    Stalled {
        /// The last frame number seen.
        last_frame: Option<u32>,
        /// Time since it first arrived.
        waited: Duration,
    },
}

/// A tracking reply stamped on arrival, with the estimated time its frame became available.
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped {
    /// When the last byte of the reply was read.
    pub arrival: Instant,
    /// The same moment on the host `CLOCK_MONOTONIC` (ns), the clock of every message time stamp.
    pub arrival_ns: i64,
    /// When the reply's frame became available at the device, estimated from the polls around
    /// it (module documentation): host `CLOCK_MONOTONIC` ns. The same for every poll that saw
    /// the same frame number.
    pub available_ns: i64,
    /// The error bound of [`Self::available_ns`]: half the gap between the polls bracketing the
    /// frame, ns (0 for the first frame, whose bracket is unknown).
    pub available_half_width_ns: i64,
    /// The reply.
    pub reply: TrackingReply,
}

/// Driver counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DriverStats {
    /// BX commands sent.
    pub polls: u64,
    /// New frames returned by [`NdiDriver::next_frame`].
    pub frames: u64,
    /// Commands that got no reply in time.
    pub timeouts: u64,
    /// BX polls sent again after a time-out (see [`DriverConfig::poll_retries`]).
    pub retried_polls: u64,
    /// New frames that were there already at the first poll after a pause: sooner than the
    /// recent intervals between frames said (see [`crate::pacing`]).
    pub early_frames: u64,
    /// Commands answered `ERRORxx`.
    pub device_errors: u64,
    /// Framing counters: good replies, rejected replies (bad CRC, garbage, ...), bytes dropped.
    pub framing: FramerStats,
}

/// A warning the device attached to a command it carried out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CommandWarning {
    /// The command (`PINIT:01`).
    pub command: String,
    /// The warning code.
    pub code: u8,
}

/// A connected, tracking NDI device.
pub struct NdiDriver {
    port: Box<dyn SerialPort>,
    framer: ReplyFramer,
    config: DriverConfig,
    version: String,
    handles: Vec<PortHandleStatus>,
    warnings: Vec<CommandWarning>,
    tracking: bool,
    last_frame: Option<u32>,
    last_frame_at: Instant,
    pacer: PollPacer,
    availability: AvailabilityEstimator,
    stats: DriverStats,
}

impl std::fmt::Debug for NdiDriver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NdiDriver")
            .field("path", &self.config.path)
            .field("handles", &self.handles)
            .field("tracking", &self.tracking)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl NdiDriver {
    /// Opens the port and brings the device into tracking (see the module documentation).
    pub fn connect(config: DriverConfig) -> Result<NdiDriver, DriverError> {
        if !config.options.contains(ReplyOptions::TRANSFORMS) {
            return Err(DriverError::Config(
                "BX options must include 0x0001: frames are told apart by their frame numbers",
            ));
        }
        let port = serialport::new(&config.path, Baud::B9600.bits_per_second())
            .timeout(config.reply_timeout)
            .open()
            .map_err(|source| DriverError::Open {
                path: config.path.clone(),
                source,
            })?;
        let pacer = PollPacer::new(config.poll_interval, config.poll_lead);
        let mut driver = NdiDriver {
            port,
            framer: ReplyFramer::new(),
            config,
            version: String::new(),
            handles: Vec::new(),
            warnings: Vec::new(),
            tracking: false,
            last_frame: None,
            last_frame_at: Instant::now(),
            pacer,
            availability: AvailabilityEstimator::new(),
            stats: DriverStats::default(),
        };
        driver.start_up()?;
        Ok(driver)
    }

    fn start_up(&mut self) -> Result<(), DriverError> {
        self.initialize()?;
        if self.config.baud != Baud::B9600 {
            let settings = CommSettings::eight_n_one(self.config.baud);
            self.acknowledge(&Command::Comm(settings), self.config.reply_timeout)?;
            std::thread::sleep(self.config.baud_settle);
            let bps = self.config.baud.bits_per_second();
            self.port
                .set_baud_rate(bps)
                .map_err(|source| DriverError::Open {
                    path: self.config.path.clone(),
                    source,
                })?;
        }
        self.version = self.text(&Command::Ver(0), self.config.reply_timeout)?;
        let slow = self.config.slow_timeout;
        for handle in self.list(PhsrFilter::OccupiedNotInitialized)? {
            self.acknowledge(&Command::Pinit(handle.handle), slow)?;
        }
        for handle in self.list(PhsrFilter::InitializedNotEnabled)? {
            let command = Command::Pena(handle.handle, self.config.priority);
            self.acknowledge(&command, self.config.reply_timeout)?;
        }
        self.handles = self.list(PhsrFilter::Enabled)?;
        self.acknowledge(&Command::Tstart, slow)?;
        self.tracking = true;
        self.last_frame_at = Instant::now();
        Ok(())
    }

    /// INIT, recovering from a device at another speed (break → RESET) or still tracking.
    fn initialize(&mut self) -> Result<(), DriverError> {
        let slow = self.config.slow_timeout;
        match self.acknowledge(&Command::Init, slow) {
            Ok(()) => Ok(()),
            Err(DriverError::Device { error, .. }) if error == DeviceError::WRONG_MODE => {
                self.acknowledge(&Command::Tstop, self.config.reply_timeout)?;
                self.acknowledge(&Command::Init, slow)
            }
            Err(timeout @ DriverError::Timeout { .. }) => {
                // The device may be at another speed: a break resets it to 9600 baud.
                if self.send_break().is_err() {
                    return Err(timeout);
                }
                let reset = self.read_reply("serial break", slow)?.0.into_text();
                match reset.as_deref() {
                    Ok("RESET") => self.acknowledge(&Command::Init, slow),
                    Ok(other) => {
                        Err(self
                            .reply_error("serial break", crate::text::unexpected("RESET", other)))
                    }
                    Err(error) => Err(self.reply_error("serial break", error.clone())),
                }
            }
            Err(other) => Err(other),
        }
    }

    fn send_break(&mut self) -> Result<(), serialport::Error> {
        self.port.set_baud_rate(Baud::B9600.bits_per_second())?;
        self.port.set_break()?;
        std::thread::sleep(Duration::from_millis(250));
        self.port.clear_break()
    }

    /// The VER:0 answer (firmware description lines).
    pub fn version(&self) -> &str {
        &self.version
    }

    /// The enabled port handles (PHSR:04 after start-up).
    pub fn handles(&self) -> &[PortHandleStatus] {
        &self.handles
    }

    /// Warnings the device attached to start-up commands.
    pub fn warnings(&self) -> &[CommandWarning] {
        &self.warnings
    }

    /// Counters so far.
    pub fn stats(&self) -> DriverStats {
        DriverStats {
            framing: self.framer.stats(),
            ..self.stats
        }
    }

    /// One BX exchange: the current tracking data, stamped on arrival and with the estimated
    /// availability of its frame (possibly the same frame as the previous poll).
    pub fn poll(&mut self) -> Result<Stamped, DriverError> {
        let command = Command::Bx(self.config.options);
        self.stats.polls += 1;
        let exchange = self.exchange(&command, self.config.reply_timeout)?;
        let arrival_ns = monotonic_ns();
        let reply = match exchange.reply {
            RawReply::Binary(body) => parse_bx_body(&body, self.config.options),
            RawReply::Text(text) => reject_device_error(&text)
                .and_then(|text| Err(crate::text::unexpected("a binary BX reply", text))),
        };
        let reply = reply.map_err(|error| self.reply_error(&command.to_string(), error))?;
        let availability = self.availability.observe(exchange.sent_ns, reply.frame());
        Ok(Stamped {
            arrival: exchange.arrival,
            arrival_ns,
            available_ns: availability.estimate_ns,
            available_half_width_ns: availability.half_width_ns(),
            reply,
        })
    }

    /// Polls until the frame number differs from the last one returned, waiting
    /// `poll_interval` between polls. The first poll waits until `poll_lead` plus the longest
    /// recent exchange before the next frame is due by the recent intervals between frames,
    /// at least `poll_interval` after the arrival of the last frame returned (see
    /// [`crate::pacing`]). A bad reply is
    /// returned as an error (and counted); the next call goes on polling. An unanswered poll
    /// is sent again up to [`DriverConfig::poll_retries`] times in a row (counted) before it
    /// is [`DriverError::Timeout`]. No new frame within `stall_timeout` of the last one (or of
    /// TSTART) is [`DriverError::Stalled`].
    pub fn next_frame(&mut self) -> Result<Stamped, DriverError> {
        self.next_frame_with(|| ())
    }

    /// [`NdiDriver::next_frame`], calling `before_poll` right before every BX poll it sends:
    /// the new frame comes with one of them, so a consumer can prepare for it there (the
    /// tracker service warms the path its frame is published on).
    pub fn next_frame_with(
        &mut self,
        mut before_poll: impl FnMut(),
    ) -> Result<Stamped, DriverError> {
        // Polling sooner would only find the frame returned last again, and would keep the
        // CPU and the port busy while the consumers of that frame wait to run.
        let first_poll = self.last_frame_at + self.pacer.pause();
        std::thread::sleep(first_poll.saturating_duration_since(Instant::now()));
        let mut unanswered = 0;
        let mut answered = 0;
        loop {
            before_poll();
            let started = Instant::now();
            let stamped = match self.poll() {
                Ok(stamped) => stamped,
                Err(DriverError::Timeout { .. }) if unanswered < self.config.poll_retries => {
                    unanswered += 1;
                    self.stats.retried_polls += 1;
                    continue;
                }
                Err(error) => return Err(error),
            };
            unanswered = 0;
            answered += 1;
            let frame = stamped.reply.frame();
            if frame != self.last_frame {
                self.last_frame = frame;
                self.last_frame_at = stamped.arrival;
                self.stats.frames += 1;
                let exchange = stamped.arrival.saturating_duration_since(started);
                if self
                    .pacer
                    .frame_arrived(stamped.arrival, exchange, answered == 1)
                {
                    self.stats.early_frames += 1;
                }
                return Ok(stamped);
            }
            let waited = stamped
                .arrival
                .saturating_duration_since(self.last_frame_at);
            if waited > self.config.stall_timeout {
                return Err(DriverError::Stalled {
                    last_frame: self.last_frame,
                    waited,
                });
            }
            std::thread::sleep(self.config.poll_interval);
        }
    }

    /// Leaves tracking mode (TSTOP) and closes the port.
    pub fn stop(mut self) -> Result<(), DriverError> {
        self.tracking = false;
        self.acknowledge(&Command::Tstop, self.config.reply_timeout)
    }

    /// Sends any command and returns its reply (an `ERRORxx` reply is [`DriverError::Device`]).
    pub fn command(
        &mut self,
        command: &Command,
        timeout: Duration,
    ) -> Result<RawReply, DriverError> {
        let raw = self.exchange(command, timeout)?.reply;
        if let RawReply::Text(text) = &raw {
            reject_device_error(text)
                .map_err(|error| self.reply_error(&command.to_string(), error))?;
        }
        Ok(raw)
    }

    fn text(&mut self, command: &Command, timeout: Duration) -> Result<String, DriverError> {
        self.command(command, timeout)?
            .into_text()
            .map_err(|error| self.reply_error(&command.to_string(), error))
    }

    fn acknowledge(&mut self, command: &Command, timeout: Duration) -> Result<(), DriverError> {
        let text = self.text(command, timeout)?;
        match parse_acknowledgement(&text) {
            Ok(Acknowledgement::Okay) => Ok(()),
            Ok(Acknowledgement::Warning(code)) => {
                self.warnings.push(CommandWarning {
                    command: command.to_string(),
                    code,
                });
                Ok(())
            }
            Err(error) => Err(self.reply_error(&command.to_string(), error)),
        }
    }

    fn list(&mut self, filter: PhsrFilter) -> Result<Vec<PortHandleStatus>, DriverError> {
        let command = Command::Phsr(filter);
        let text = self.text(&command, self.config.reply_timeout)?;
        parse_phsr(&text).map_err(|error| self.reply_error(&command.to_string(), error))
    }

    /// Sends `command` (after dropping stale input) and reads its reply.
    fn exchange(&mut self, command: &Command, timeout: Duration) -> Result<Exchange, DriverError> {
        let name = command.to_string();
        // The device only speaks when spoken to: anything unread now is stale.
        let _ = self.port.clear(ClearBuffer::Input);
        self.framer.discard_pending();
        self.port
            .write_all(&command.encode())
            .and_then(|()| self.port.flush())
            .map_err(|source| DriverError::Io {
                command: name.clone(),
                source,
            })?;
        let sent_ns = monotonic_ns();
        let (reply, arrival) = self.read_reply(&name, timeout)?;
        Ok(Exchange {
            reply,
            sent_ns,
            arrival,
        })
    }

    /// Reads one reply within `timeout`; garbage before it is counted and skipped.
    fn read_reply(
        &mut self,
        command: &str,
        timeout: Duration,
    ) -> Result<(RawReply, Instant), DriverError> {
        let deadline = Instant::now() + timeout;
        let mut buf = [0u8; 512];
        let mut last_look_taken = false;
        loop {
            match self.framer.next_reply() {
                Some(Ok(raw)) => return Ok((raw, Instant::now())),
                Some(Err(ReplyError::Garbage { .. })) => continue,
                Some(Err(error)) => return Err(self.reply_error(command, error)),
                None => {}
            }
            let mut left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() && !last_look_taken {
                // The deadline may have passed while this process was not scheduled: take
                // one short last look at the port before calling the tracker silent.
                last_look_taken = true;
                left = LAST_LOOK;
            } else if left.is_zero() {
                self.stats.timeouts += 1;
                self.framer.discard_pending();
                return Err(DriverError::Timeout {
                    command: command.to_owned(),
                    waited: timeout,
                });
            }
            let io_error = |source| DriverError::Io {
                command: command.to_owned(),
                source,
            };
            self.port
                .set_timeout(left)
                .map_err(|e| io_error(std::io::Error::other(e)))?;
            match self.port.read(&mut buf) {
                Ok(0) => return Err(io_error(ErrorKind::UnexpectedEof.into())),
                Ok(n) => self.framer.push(&buf[..n]),
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::Interrupted) => {}
                Err(e) => return Err(io_error(e)),
            }
        }
    }

    fn reply_error(&mut self, command: &str, error: ReplyError) -> DriverError {
        match error {
            ReplyError::Device(error) => {
                self.stats.device_errors += 1;
                DriverError::Device {
                    command: command.to_owned(),
                    error,
                }
            }
            error => DriverError::Reply {
                command: command.to_owned(),
                error,
            },
        }
    }
}

impl Drop for NdiDriver {
    /// Best effort: leave tracking mode so the device is ready for the next session.
    fn drop(&mut self) {
        if self.tracking {
            let timeout = self.config.reply_timeout;
            let _ = self.acknowledge(&Command::Tstop, timeout);
        }
    }
}

/// One command and its reply.
struct Exchange {
    /// The reply.
    reply: RawReply,
    /// When the command had been written and flushed, host `CLOCK_MONOTONIC` ns.
    sent_ns: i64,
    /// When the last byte of the reply was read.
    arrival: Instant,
}

/// How long the last look at the port waits once a reply's deadline has passed.
const LAST_LOOK: Duration = Duration::from_millis(1);

/// Host `CLOCK_MONOTONIC` now, in ns.
fn monotonic_ns() -> i64 {
    use nix::time::{clock_gettime, ClockId};
    clock_gettime(ClockId::CLOCK_MONOTONIC)
        .map(|t| t.tv_sec() * 1_000_000_000 + t.tv_nsec())
        .unwrap_or(0)
}
