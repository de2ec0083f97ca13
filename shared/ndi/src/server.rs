//! The device side: an NDI Combined API tracker state machine for the simulated rig.
//!
//! [`NdiServer`] takes command bytes and produces reply bytes exactly as a Polaris would for the
//! commands the host driver uses: INIT, RESET, COMM (acknowledged; the speed is recorded, a PTY
//! has none), VER, BEEP, PHSR, PINIT, PENA, PDIS, TSTART, TSTOP, BX and TX (every reply option:
//! 0x0001, 0x0002, 0x0004, 0x0008, 0x0800, 0x1000, in any combination). Anything else is
//! answered `ERROR01`.
//!
//! Tools are wired ports: port handle `i + 1` is tool `i` of each [`SimFrame`], occupied from
//! power-up (PHSR:02 lists them until PINIT). The rig's convention is handles 1-4 = base, front,
//! back, tip.
//!
//! **The tip sphere** is a tool handle like the others. A [`SimReading::Point`] is reported with
//! status valid and a transform whose quaternion is the identity (1, 0, 0, 0) and whose position
//! is the sphere centre; its rms is the point's rms. With reply option 0x1000 every point is also
//! listed as a stray passive marker (in volume), which is how a real Polaris would see a lone
//! sphere.
//!
//! **What the reply holds.** Every initialised port handle is reported in handle order: an
//! enabled one with its data, one that is initialised but not enabled (never enabled, or PDIS)
//! as DISABLED. A tool whose origin is outside the [`MeasurementVolume`] (unbounded unless
//! [`NdiServer::with_volume`] sets one) is reported MISSING with port status bit 6 (out of
//! volume), or valid with that bit when option 0x0800 asks for it; a tool with some markers
//! outside has bit 7 (partially out of volume). Option 0x0002 gives tool information 0x00 for a
//! seen tool and 0x02 otherwise, and marker code 3 (used) for each marker of a seen tool (marker
//! `k` in byte `9 - k/2`, low nibble for even `k`). Option 0x0004 reports the tip sphere of a
//! [`SimReading::Point`] as the handle's single active marker (valid, or out of volume with a
//! position only under 0x0800) and `00` (missing) for every other handle, as a real Polaris
//! answers for passive tools. Option 0x0008 lists a tool's markers in `S`: the marker geometry
//! given by [`NdiServer::with_tool_markers`] placed by the pose, or the sphere of a point.
//! Out-of-volume markers (tool markers and strays) are listed only with 0x0800.

use crate::bx::encode_bx;
use crate::command::{Baud, CommSettings, Command, CommandError, PhsrFilter, TrackingPriority};
use crate::error::DeviceError;
use crate::reply::{
    ActiveMarker, HandleReading, HandleStatus, MarkerPosition, ReplyOptions, ToolInfo,
    TrackingReply, Transform,
};
use crate::text::{encode_phsr, encode_text_reply, PortHandleStatus};
use crate::tx::encode_tx;

/// One simulated tool's measurement in one frame, in the tracker frame `S`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimReading {
    /// Not seen.
    Missing,
    /// A 6-DOF tool pose.
    Pose(Transform),
    /// A single sphere (the needle tip): centre in `S` (mm) and rms (mm).
    Point {
        /// Sphere centre in `S` (mm).
        position: [f32; 3],
        /// RMS error (mm).
        rms: f32,
    },
}

/// The tracker's latest measurement, as the rig provides it.
#[derive(Debug, Clone, PartialEq)]
pub struct SimFrame {
    /// The device frame counter of this measurement.
    pub frame: u32,
    /// One reading per tool; index `i` is port handle `i + 1`. Missing entries read as
    /// [`SimReading::Missing`]; extra entries are ignored.
    pub readings: Vec<SimReading>,
}

/// The simulated characterised measurement volume: an axis-aligned box in `S` (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasurementVolume {
    /// The corner with the smallest coordinates (mm).
    pub min: [f32; 3],
    /// The corner with the largest coordinates (mm).
    pub max: [f32; 3],
}

impl MeasurementVolume {
    /// Whether `point` (in `S`, mm) is inside the box (faces included).
    pub fn contains(&self, point: [f32; 3]) -> bool {
        (0..3).all(|k| self.min[k] <= point[k] && point[k] <= self.max[k])
    }
}

/// Where the server gets the current frame when a BX or TX command arrives.
pub trait FrameSource {
    /// The latest completed frame, or `None` before the first one (then every handle is
    /// reported missing at frame 0).
    fn latest_frame(&mut self) -> Option<SimFrame>;
}

impl<F: FnMut() -> Option<SimFrame>> FrameSource for F {
    fn latest_frame(&mut self) -> Option<SimFrame> {
        self()
    }
}

/// Operating mode of the simulated device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServerMode {
    /// After power-up or RESET: INIT needed.
    Uninitialized,
    /// Initialised, not tracking: port handles can be set up.
    Setup,
    /// Tracking: BX and TX answer.
    Tracking,
}

/// Counters of the simulated device.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServerStats {
    /// Command lines received.
    pub commands: u64,
    /// Commands answered with `ERRORxx`.
    pub errors: u64,
    /// BX and TX replies sent.
    pub tracking_replies: u64,
}

#[derive(Debug, Clone, Copy, Default)]
struct Port {
    initialized: bool,
    enabled: bool,
}

/// Port status bits: occupied, initialised, enabled, out of volume, partially out of volume.
const OCCUPIED: u16 = 0x001;
const INITIALIZED: u16 = 0x010;
const ENABLED: u16 = 0x020;
const OUT_OF_VOLUME: u32 = 0x040;
const PARTIALLY_OUT_OF_VOLUME: u32 = 0x080;
/// Tool information of a tool that is not seen (too few markers).
const TOOL_NOT_SEEN: u8 = 0x02;
/// Marker information code of a marker used in the transform.
const MARKER_USED: u8 = 0x3;
/// Longest command line accepted (PVWR lines are 144 bytes).
const MAX_COMMAND: usize = 1024;
/// What VER answers.
const VERSION: &str =
    "SABR simulated Polaris\nNDI S/N: SIM-00001\nFreeze Tag: SABR sim 1\n(C) SABR project";

/// The simulated tracker: command bytes in, reply bytes out.
#[derive(Debug)]
pub struct NdiServer<S> {
    source: S,
    ports: Vec<Port>,
    volume: Option<MeasurementVolume>,
    tool_markers: Vec<Vec<[f32; 3]>>,
    mode: ServerMode,
    comm: CommSettings,
    line: Vec<u8>,
    overlong: bool,
    stats: ServerStats,
}

impl<S: FrameSource> NdiServer<S> {
    /// A device with `tool_count` wired tools (handles 1..=tool_count), just powered up.
    pub fn new(tool_count: u8, source: S) -> Self {
        NdiServer {
            source,
            ports: vec![Port::default(); usize::from(tool_count)],
            volume: None,
            tool_markers: vec![Vec::new(); usize::from(tool_count)],
            mode: ServerMode::Uninitialized,
            comm: CommSettings::eight_n_one(Baud::B9600),
            line: Vec::new(),
            overlong: false,
            stats: ServerStats::default(),
        }
    }

    /// Bounds the measurement volume (default: unbounded).
    pub fn with_volume(mut self, volume: MeasurementVolume) -> Self {
        self.volume = Some(volume);
        self
    }

    /// Gives the tool of port handle `handle` its marker positions in the tool frame (mm), for
    /// option 0x0008 and the marker information of 0x0002. A handle the device does not have
    /// is left alone.
    pub fn with_tool_markers(mut self, handle: u8, markers: Vec<[f32; 3]>) -> Self {
        if let Some(slot) = usize::from(handle)
            .checked_sub(1)
            .and_then(|i| self.tool_markers.get_mut(i))
        {
            *slot = markers;
        }
        self
    }

    /// The current mode.
    pub fn mode(&self) -> ServerMode {
        self.mode
    }

    /// The serial settings last set by COMM (9600 8N1 after power-up and RESET).
    pub fn comm(&self) -> CommSettings {
        self.comm
    }

    /// Counters.
    pub fn stats(&self) -> ServerStats {
        self.stats
    }

    /// Feeds received bytes; returns the replies to every command completed by a CR. LF bytes
    /// are ignored (terminal line endings); a line longer than 1024 bytes is answered `ERROR02`.
    pub fn feed(&mut self, bytes: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        for &byte in bytes {
            match byte {
                b'\r' if self.overlong => {
                    self.overlong = false;
                    self.stats.commands += 1;
                    out.extend(self.error(DeviceError::TOO_LONG));
                }
                b'\r' => {
                    let line = std::mem::take(&mut self.line);
                    out.extend(self.respond(&line));
                }
                b'\n' => {}
                _ if self.line.len() >= MAX_COMMAND => {
                    self.overlong = true;
                    self.line.clear();
                }
                _ if !self.overlong => self.line.push(byte),
                _ => {}
            }
        }
        out
    }

    /// The reply to one command line (without its CR).
    pub fn respond(&mut self, line: &[u8]) -> Vec<u8> {
        self.stats.commands += 1;
        let command = match Command::decode(line) {
            Ok(command) => command,
            Err(error) => return self.error(command_error_code(&error)),
        };
        match self.execute(command) {
            Ok(reply) => reply,
            Err(error) => self.error(error),
        }
    }

    fn execute(&mut self, command: Command) -> Result<Vec<u8>, DeviceError> {
        let okay = || Ok(encode_text_reply("OKAY"));
        match command {
            Command::Init => {
                self.mode = ServerMode::Setup;
                self.ports.fill(Port::default());
                okay()
            }
            Command::Reset => {
                self.mode = ServerMode::Uninitialized;
                self.ports.fill(Port::default());
                self.comm = CommSettings::eight_n_one(Baud::B9600);
                Ok(encode_text_reply("RESET"))
            }
            Command::Comm(settings) => {
                self.comm = settings;
                okay()
            }
            Command::Ver(_) => Ok(encode_text_reply(VERSION)),
            Command::Beep(_) => Ok(encode_text_reply("1")),
            Command::Phsr(filter) => {
                self.require_initialized()?;
                Ok(encode_text_reply(&encode_phsr(&self.port_list(filter))))
            }
            Command::Pinit(handle) => {
                self.require_setup()?;
                self.port(handle)?.initialized = true;
                okay()
            }
            Command::Pena(handle, priority) => {
                self.require_setup()?;
                let port = self.port(handle)?;
                if !port.initialized {
                    return Err(DeviceError::NOT_INITIALIZED);
                }
                if priority == TrackingPriority::ButtonBox {
                    return Err(DeviceError::INVALID_PRIORITY);
                }
                port.enabled = true;
                okay()
            }
            Command::Pdis(handle) => {
                self.require_setup()?;
                self.port(handle)?.enabled = false;
                okay()
            }
            Command::Tstart => {
                self.require_setup()?;
                self.mode = ServerMode::Tracking;
                okay()
            }
            Command::Tstop => {
                if self.mode != ServerMode::Tracking {
                    return Err(DeviceError::WRONG_MODE);
                }
                self.mode = ServerMode::Setup;
                okay()
            }
            Command::Bx(options) | Command::Tx(options) => {
                let binary = matches!(command, Command::Bx(_));
                self.tracking_reply(options, binary)
            }
            Command::Phrq(_) | Command::Phf(_) | Command::Other { .. } => {
                Err(DeviceError::INVALID_COMMAND)
            }
        }
    }

    fn tracking_reply(
        &mut self,
        options: ReplyOptions,
        binary: bool,
    ) -> Result<Vec<u8>, DeviceError> {
        if self.mode != ServerMode::Tracking {
            return Err(DeviceError::WRONG_MODE);
        }
        let frame = self.source.latest_frame();
        let device = Device {
            ports: &self.ports,
            volume: self.volume,
            tool_markers: &self.tool_markers,
        };
        let reply = device.reply(frame.as_ref(), options, binary);
        let encoded = if binary {
            encode_bx(&reply)
        } else {
            encode_tx(&reply)
        };
        // Only a tool far outside any real volume (TX fixed width) fails to encode.
        let bytes = encoded.map_err(|_| DeviceError { code: 0x1A })?;
        self.stats.tracking_replies += 1;
        Ok(bytes)
    }

    fn require_initialized(&self) -> Result<(), DeviceError> {
        if self.mode == ServerMode::Uninitialized {
            return Err(DeviceError::SYSTEM_NOT_INITIALIZED);
        }
        Ok(())
    }

    fn require_setup(&self) -> Result<(), DeviceError> {
        match self.mode {
            ServerMode::Uninitialized => Err(DeviceError::SYSTEM_NOT_INITIALIZED),
            ServerMode::Tracking => Err(DeviceError::WRONG_MODE),
            ServerMode::Setup => Ok(()),
        }
    }

    fn port(&mut self, handle: u8) -> Result<&mut Port, DeviceError> {
        usize::from(handle)
            .checked_sub(1)
            .and_then(|i| self.ports.get_mut(i))
            .ok_or(DeviceError::INVALID_HANDLE)
    }

    fn port_list(&self, filter: PhsrFilter) -> Vec<PortHandleStatus> {
        self.ports
            .iter()
            .enumerate()
            .filter(|(_, p)| match filter {
                PhsrFilter::All => true,
                PhsrFilter::ToBeFreed => false,
                PhsrFilter::OccupiedNotInitialized => !p.initialized,
                PhsrFilter::InitializedNotEnabled => p.initialized && !p.enabled,
                PhsrFilter::Enabled => p.enabled,
            })
            .map(|(i, p)| PortHandleStatus {
                handle: i as u8 + 1,
                status: port_status(p),
            })
            .collect()
    }

    fn error(&mut self, error: DeviceError) -> Vec<u8> {
        self.stats.errors += 1;
        encode_text_reply(&format!("ERROR{:02X}", error.code))
    }
}

fn port_status(port: &Port) -> u16 {
    let mut status = OCCUPIED;
    if port.initialized {
        status |= INITIALIZED;
    }
    if port.enabled {
        status |= ENABLED;
    }
    status
}

fn command_error_code(error: &CommandError) -> DeviceError {
    match error {
        CommandError::Malformed(_) => DeviceError::INVALID_COMMAND,
        CommandError::TooShort(_) => DeviceError::TOO_SHORT,
        CommandError::BadCrc { .. } => DeviceError::BAD_CRC,
        CommandError::BadParameters { command, .. } if command == "COMM" => DeviceError::BAD_COMM,
        CommandError::BadParameters { .. } => DeviceError::BAD_PARAMETERS,
    }
}

/// What the device knows when it builds a reply.
struct Device<'a> {
    ports: &'a [Port],
    volume: Option<MeasurementVolume>,
    tool_markers: &'a [Vec<[f32; 3]>],
}

impl Device<'_> {
    fn inside(&self, point: [f32; 3]) -> bool {
        self.volume.is_none_or(|v| v.contains(point))
    }

    /// The reply for the initialised ports, in handle order (see the module documentation).
    fn reply(
        &self,
        frame: Option<&SimFrame>,
        options: ReplyOptions,
        binary: bool,
    ) -> TrackingReply {
        let reading_of = |i: usize| {
            frame
                .and_then(|f| f.readings.get(i))
                .copied()
                .unwrap_or(SimReading::Missing)
        };
        let frame_number = frame.map_or(0, |f| f.frame);
        let handles = self
            .ports
            .iter()
            .enumerate()
            .filter(|(_, p)| p.initialized)
            .map(|(i, port)| {
                let handle = i as u8 + 1;
                if port.enabled {
                    self.handle_reading(handle, port, reading_of(i), frame_number, options, binary)
                } else {
                    HandleReading::bare(handle, HandleStatus::Disabled)
                }
            })
            .collect();
        let all = options.contains(ReplyOptions::OUT_OF_VOLUME);
        let stray_markers = options.contains(ReplyOptions::PASSIVE_STRAYS).then(|| {
            (0..self.ports.len())
                .filter_map(|i| match reading_of(i) {
                    SimReading::Point { position, .. } => Some(MarkerPosition {
                        position,
                        out_of_volume: !self.inside(position),
                    }),
                    _ => None,
                })
                .filter(|m| all || !m.out_of_volume)
                .collect()
        });
        TrackingReply {
            options,
            handles,
            stray_markers,
            system_status: 0,
        }
    }

    fn handle_reading(
        &self,
        handle: u8,
        port: &Port,
        reading: SimReading,
        frame: u32,
        options: ReplyOptions,
        binary: bool,
    ) -> HandleReading {
        let all = options.contains(ReplyOptions::OUT_OF_VOLUME);
        let (transform, markers) = match reading {
            SimReading::Missing => (None, Vec::new()),
            SimReading::Pose(t) => {
                let geometry = &self.tool_markers[usize::from(handle) - 1];
                (Some(t), geometry.iter().map(|p| place(&t, *p)).collect())
            }
            SimReading::Point { position, rms } => (
                Some(Transform {
                    q: [1.0, 0.0, 0.0, 0.0],
                    t: position,
                    rms,
                }),
                vec![position],
            ),
        };
        let markers: Vec<MarkerPosition> = markers
            .into_iter()
            .map(|position| MarkerPosition {
                position,
                out_of_volume: !self.inside(position),
            })
            .collect();
        let origin_inside = transform.is_none_or(|t| self.inside(t.t));
        let seen = transform.is_some() && (origin_inside || all);
        let mut port_status = u32::from(port_status(port));
        if transform.is_some() && !origin_inside {
            port_status |= OUT_OF_VOLUME;
        } else if markers.iter().any(|m| m.out_of_volume) {
            port_status |= PARTIALLY_OUT_OF_VOLUME;
        }
        let status = if seen {
            HandleStatus::Valid
        } else {
            HandleStatus::Missing
        };
        // TX carries no status without option 0x0001; BX still does.
        let reported = if options.contains(ReplyOptions::TRANSFORMS) || binary {
            status
        } else {
            HandleStatus::NotReported
        };
        let mut reading_out = HandleReading::bare(handle, reported);
        if options.contains(ReplyOptions::TRANSFORMS) {
            reading_out.transform = transform.filter(|_| seen);
            reading_out.port_status = Some(port_status);
            reading_out.frame = Some(frame);
        }
        if options.contains(ReplyOptions::TOOL_INFO) {
            let mut codes = [0u8; 10];
            if seen {
                for k in 0..markers.len().min(20) {
                    codes[9 - k / 2] |= MARKER_USED << (4 * (k % 2));
                }
            }
            reading_out.tool_info = Some(ToolInfo {
                tool: if seen { 0x00 } else { TOOL_NOT_SEEN },
                markers: codes,
            });
        }
        if options.contains(ReplyOptions::SINGLE_STRAY) {
            reading_out.active_marker = Some(match reading {
                SimReading::Point { position, .. } => {
                    let status = if self.inside(position) {
                        ActiveMarker::VALID
                    } else {
                        ActiveMarker::VALID | ActiveMarker::OUT_OF_VOLUME
                    };
                    ActiveMarker {
                        status,
                        position: ActiveMarker::carries_position(status, options)
                            .then_some(position),
                    }
                }
                _ => ActiveMarker {
                    status: ActiveMarker::MISSING,
                    position: None,
                },
            });
        }
        if options.contains(ReplyOptions::TOOL_MARKERS) {
            reading_out.tool_markers = Some(
                markers
                    .into_iter()
                    .filter(|m| all || !m.out_of_volume)
                    .collect(),
            );
        }
        reading_out
    }
}

/// A tool-frame point placed in `S` by the tool's pose: `R(q)·p + t`.
fn place(pose: &Transform, p: [f32; 3]) -> [f32; 3] {
    let [w, x, y, z] = pose.q;
    let norm = (w * w + x * x + y * y + z * z).sqrt();
    let (w, x, y, z) = if norm > 0.0 {
        (w / norm, x / norm, y / norm, z / norm)
    } else {
        (1.0, 0.0, 0.0, 0.0)
    };
    let r = [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ];
    std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + pose.t[i])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bx::parse_bx_frame;
    use crate::framing::{decode_reply, RawReply};
    use crate::text::{parse_acknowledgement, parse_phsr, Acknowledgement};
    use crate::tx::parse_tx;
    use crate::ReplyError;

    fn pose(x: f32) -> Transform {
        Transform {
            q: [0.5, 0.5, -0.5, 0.5],
            t: [x, -20.25, -1500.5],
            rms: 0.125,
        }
    }

    fn server() -> NdiServer<impl FrameSource> {
        let mut frame = 100u32;
        NdiServer::new(4, move || {
            frame += 3;
            Some(SimFrame {
                frame,
                readings: vec![
                    SimReading::Pose(pose(1.0)),
                    SimReading::Missing,
                    SimReading::Pose(pose(3.0)),
                    SimReading::Point {
                        position: [4.0, 5.0, -1600.0],
                        rms: 0.25,
                    },
                ],
            })
        })
    }

    fn ask<S: FrameSource>(server: &mut NdiServer<S>, command: Command) -> RawReply {
        decode_reply(&server.feed(&command.encode())).unwrap()
    }

    fn ack<S: FrameSource>(
        server: &mut NdiServer<S>,
        command: Command,
    ) -> Result<Acknowledgement, ReplyError> {
        parse_acknowledgement(&ask(server, command).into_text().unwrap())
    }

    fn start<S: FrameSource>(server: &mut NdiServer<S>) {
        ack(server, Command::Init).unwrap();
        for handle in 1..=4 {
            ack(server, Command::Pinit(handle)).unwrap();
            ack(server, Command::Pena(handle, TrackingPriority::Dynamic)).unwrap();
        }
        ack(server, Command::Tstart).unwrap();
    }

    #[test]
    fn setup_sequence_walks_the_port_states() {
        let mut s = server();
        assert_eq!(
            ack(&mut s, Command::Phsr(PhsrFilter::All)),
            Err(ReplyError::Device(DeviceError::SYSTEM_NOT_INITIALIZED))
        );
        ack(&mut s, Command::Init).unwrap();
        ack(
            &mut s,
            Command::Comm(CommSettings::eight_n_one(Baud::B115200)),
        )
        .unwrap();
        assert_eq!(s.comm().baud, Baud::B115200);
        let list = |s: &mut NdiServer<_>, f| {
            parse_phsr(&ask(s, Command::Phsr(f)).into_text().unwrap()).unwrap()
        };
        assert_eq!(list(&mut s, PhsrFilter::OccupiedNotInitialized).len(), 4);
        assert_eq!(
            ack(&mut s, Command::Pena(1, TrackingPriority::Dynamic)),
            Err(ReplyError::Device(DeviceError::NOT_INITIALIZED))
        );
        assert_eq!(
            ack(&mut s, Command::Pinit(5)),
            Err(ReplyError::Device(DeviceError::INVALID_HANDLE))
        );
        ack(&mut s, Command::Pinit(1)).unwrap();
        assert_eq!(list(&mut s, PhsrFilter::OccupiedNotInitialized).len(), 3);
        let ready = list(&mut s, PhsrFilter::InitializedNotEnabled);
        assert_eq!(
            ready,
            vec![PortHandleStatus {
                handle: 1,
                status: 0x011
            }]
        );
        ack(&mut s, Command::Pena(1, TrackingPriority::Static)).unwrap();
        assert_eq!(list(&mut s, PhsrFilter::Enabled)[0].status, 0x031);
        assert_eq!(
            ack(&mut s, Command::Bx(ReplyOptions::TRANSFORMS)),
            Err(ReplyError::Device(DeviceError::WRONG_MODE))
        );
        ack(&mut s, Command::Tstart).unwrap();
        assert_eq!(s.mode(), ServerMode::Tracking);
        assert_eq!(
            ack(&mut s, Command::Pinit(2)),
            Err(ReplyError::Device(DeviceError::WRONG_MODE))
        );
        ack(&mut s, Command::Tstop).unwrap();
        assert_eq!(s.mode(), ServerMode::Setup);
        assert_eq!(ask(&mut s, Command::Reset), RawReply::Text("RESET".into()));
        assert_eq!(s.mode(), ServerMode::Uninitialized);
        assert_eq!(s.comm().baud, Baud::B9600);
    }

    #[test]
    fn bx_and_tx_report_the_source_frame() {
        let mut s = server();
        start(&mut s);
        let options = ReplyOptions::TRANSFORMS | ReplyOptions::PASSIVE_STRAYS;
        let bytes = s.feed(&Command::Bx(options).encode());
        let bx = parse_bx_frame(&bytes, options).unwrap();
        assert_eq!(bx.frame(), Some(103));
        assert_eq!(bx.handles.len(), 4);
        assert_eq!(bx.handle(1).unwrap().transform, Some(pose(1.0)));
        assert_eq!(bx.handle(2).unwrap().status, HandleStatus::Missing);
        let tip = bx.handle(4).unwrap().transform.unwrap();
        assert_eq!(
            (tip.q, tip.t, tip.rms),
            ([1.0, 0.0, 0.0, 0.0], [4.0, 5.0, -1600.0], 0.25)
        );
        assert_eq!(bx.handle(4).unwrap().port_status, Some(0x31));
        let strays = bx.stray_markers.unwrap();
        assert_eq!(strays.len(), 1);
        assert_eq!(strays[0].position, [4.0, 5.0, -1600.0]);

        let text = ask(&mut s, Command::Tx(ReplyOptions::TRANSFORMS))
            .into_text()
            .unwrap();
        let tx = parse_tx(&text, ReplyOptions::TRANSFORMS).unwrap();
        assert_eq!(tx.frame(), Some(106));
        let t = tx.handle(3).unwrap().transform.unwrap();
        assert_eq!(t.t, [3.0, -20.25, -1500.5]);
        assert_eq!(t.q, [0.5, 0.5, -0.5, 0.5]);

        let text = ask(&mut s, Command::Tx(ReplyOptions::PASSIVE_STRAYS))
            .into_text()
            .unwrap();
        let tx = parse_tx(&text, ReplyOptions::PASSIVE_STRAYS).unwrap();
        assert!(tx
            .handles
            .iter()
            .all(|h| h.status == HandleStatus::NotReported));
        assert_eq!(tx.stray_markers.unwrap().len(), 1);
        assert_eq!(s.stats().tracking_replies, 3);
    }

    #[test]
    fn bad_commands_get_device_errors() {
        let mut s = server();
        let reply = |s: &mut NdiServer<_>, bytes: &[u8]| {
            decode_reply(&s.feed(bytes)).unwrap().into_text().unwrap()
        };
        assert_eq!(reply(&mut s, b"INIT:E3A6\r"), "ERROR04");
        assert_eq!(reply(&mut s, b"FOO:1234\r"), "ERROR04");
        assert_eq!(reply(&mut s, b"\x01\x02\r"), "ERROR01");
        assert_eq!(reply(&mut s, b"PHINF 01\r"), "ERROR01");
        assert_eq!(reply(&mut s, b"COMM 90000\r"), "ERROR06");
        assert_eq!(reply(&mut s, b"BX 00\r"), "ERROR07");
        assert!(s.feed(&vec![b'A'; 5000]).is_empty());
        assert_eq!(reply(&mut s, b"\r"), "ERROR02");
        start(&mut s);
        assert_eq!(reply(&mut s, b"BX 0010\r"), "ERROR07");
        assert_eq!(s.stats().errors, 8);
    }

    #[test]
    fn no_frame_yet_reports_missing_at_frame_zero() {
        let mut s = NdiServer::new(2, || None);
        start_two(&mut s);
        let bytes = s.feed(&Command::Bx(ReplyOptions::TRANSFORMS).encode());
        let reply = parse_bx_frame(&bytes, ReplyOptions::TRANSFORMS).unwrap();
        assert_eq!(reply.frame(), Some(0));
        assert!(reply
            .handles
            .iter()
            .all(|h| h.status == HandleStatus::Missing));
    }

    fn start_two<S: FrameSource>(s: &mut NdiServer<S>) {
        ack(s, Command::Init).unwrap();
        for handle in 1..=2 {
            ack(s, Command::Pinit(handle)).unwrap();
            ack(s, Command::Pena(handle, TrackingPriority::Dynamic)).unwrap();
        }
        ack(s, Command::Tstart).unwrap();
    }
}
