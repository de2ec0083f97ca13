//! Typed tracking replies, shared by the BX (binary) and TX (text) formats.

use crate::error::ReplyError;
use std::fmt;
use std::ops::BitOr;

/// Reply options of a BX or TX command (a 16-bit mask, sent as 4 hex digits).
///
/// [`ReplyOptions::new`] rejects any bit that is not a BX/TX reply option.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ReplyOptions(u16);

impl ReplyOptions {
    /// 0x0001: per handle, the transform (if valid), port status and frame number.
    pub const TRANSFORMS: ReplyOptions = ReplyOptions(0x0001);
    /// 0x0002: per handle, tool information and marker information.
    pub const TOOL_INFO: ReplyOptions = ReplyOptions(0x0002);
    /// 0x0004: per handle, the position of a single stray active marker.
    pub const SINGLE_STRAY: ReplyOptions = ReplyOptions(0x0004);
    /// 0x0008: per handle, the 3D positions of the markers of its tool.
    pub const TOOL_MARKERS: ReplyOptions = ReplyOptions(0x0008);
    /// 0x0800: also report what is normally withheld because it is out of the measurement
    /// volume: transforms of tools outside it (port status bit 6 set), out-of-volume markers.
    pub const OUT_OF_VOLUME: ReplyOptions = ReplyOptions(0x0800);
    /// 0x1000: after the handles, the stray passive markers.
    pub const PASSIVE_STRAYS: ReplyOptions = ReplyOptions(0x1000);
    /// Every bit of the Combined API's BX and TX reply options; this crate parses them all.
    pub const SUPPORTED: u16 = 0x0001 | 0x0002 | 0x0004 | 0x0008 | 0x0800 | 0x1000;
    /// Each option bit on its own, in the order their data comes in a reply.
    pub const EACH: [ReplyOptions; 6] = [
        ReplyOptions::TRANSFORMS,
        ReplyOptions::TOOL_INFO,
        ReplyOptions::SINGLE_STRAY,
        ReplyOptions::TOOL_MARKERS,
        ReplyOptions::OUT_OF_VOLUME,
        ReplyOptions::PASSIVE_STRAYS,
    ];

    /// Options from the mask sent in a command; unknown bits are an error.
    pub fn new(bits: u16) -> Result<Self, ReplyError> {
        if bits & !Self::SUPPORTED != 0 {
            return Err(ReplyError::UnsupportedOptions(bits & !Self::SUPPORTED));
        }
        Ok(ReplyOptions(bits))
    }

    /// The mask as sent in a command.
    pub fn bits(self) -> u16 {
        self.0
    }

    /// Whether every bit of `other` is set.
    pub fn contains(self, other: ReplyOptions) -> bool {
        self.0 & other.0 == other.0
    }
}

impl Default for ReplyOptions {
    /// 0x0001, what the device uses when a BX or TX command carries no option.
    fn default() -> Self {
        ReplyOptions::TRANSFORMS
    }
}

impl BitOr for ReplyOptions {
    type Output = ReplyOptions;
    fn bitor(self, rhs: ReplyOptions) -> ReplyOptions {
        ReplyOptions(self.0 | rhs.0)
    }
}

impl fmt::Display for ReplyOptions {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:04X}", self.0)
    }
}

/// A tool's pose in the tracker frame `S`, as the device reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Rotation quaternion (q0, qx, qy, qz), scalar first.
    pub q: [f32; 4],
    /// Position of the tool origin in `S` (mm).
    pub t: [f32; 3],
    /// RMS fit error of the markers (mm).
    pub rms: f32,
}

/// The status of one port handle in a tracking reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HandleStatus {
    /// Seen: a transform is reported (BX status 0x01).
    Valid,
    /// Not seen in this frame (BX 0x02, TX `MISSING`).
    Missing,
    /// The handle is disabled; no further data (BX 0x04, TX `DISABLED`).
    Disabled,
    /// TX only: `UNOCCUPIED`, no tool in the port; no further data.
    Unoccupied,
    /// TX only: the reply options did not include 0x0001, so TX carries no status.
    NotReported,
}

impl HandleStatus {
    /// The status name, for messages.
    pub fn name(self) -> &'static str {
        match self {
            HandleStatus::Valid => "valid",
            HandleStatus::Missing => "missing",
            HandleStatus::Disabled => "disabled",
            HandleStatus::Unoccupied => "unoccupied",
            HandleStatus::NotReported => "not reported",
        }
    }
}

/// Reply option 0x0002: tool information and the per-marker information.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ToolInfo {
    /// Tool information bits (bad fit, too few markers, IR interference, ...).
    pub tool: u8,
    /// Marker information: 20 four-bit codes in the order the device sends them (BX: 10 bytes;
    /// TX: the same 10 bytes as 20 hex digits).
    pub markers: [u8; 10],
}

/// Reply option 0x0004: a single stray active marker of a handle.
///
/// A position follows the status only for a marker that was seen inside the measurement
/// volume, or seen outside it when option 0x0800 asks for what is normally withheld: a real
/// Polaris (firmware Rev 020) answers `00` alone for a handle without one, and Rev 021 sends an
/// out-of-volume status without a position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActiveMarker {
    /// Marker status bits: [`ActiveMarker::VALID`], [`ActiveMarker::OUT_OF_VOLUME`]; 0x00 is
    /// missing.
    pub status: u8,
    /// Position in `S` (mm), exactly when [`ActiveMarker::carries_position`] says so.
    pub position: Option<[f32; 3]>,
}

impl ActiveMarker {
    /// Status 0x00: no marker seen.
    pub const MISSING: u8 = 0x00;
    /// Status bit 0: the marker was seen.
    pub const VALID: u8 = 0x01;
    /// Status bit 2: the marker is outside the characterised measurement volume.
    pub const OUT_OF_VOLUME: u8 = 0x04;

    /// Whether a position follows a marker `status` in a reply with `options`.
    pub fn carries_position(status: u8, options: ReplyOptions) -> bool {
        if status & Self::OUT_OF_VOLUME != 0 {
            options.contains(ReplyOptions::OUT_OF_VOLUME)
        } else {
            status & Self::VALID != 0
        }
    }
}

/// One marker of a marker list: a tool's markers (option 0x0008) or the stray passive markers
/// (option 0x1000). Out-of-volume markers are listed only with option 0x0800.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkerPosition {
    /// Position in `S` (mm).
    pub position: [f32; 3],
    /// The marker is outside the characterised measurement volume.
    pub out_of_volume: bool,
}

/// What a tracking reply says about one port handle.
#[derive(Debug, Clone, PartialEq)]
pub struct HandleReading {
    /// The port handle (1-255).
    pub handle: u8,
    /// Valid, missing, disabled, ...
    pub status: HandleStatus,
    /// Option 0x0001, status valid: the pose.
    pub transform: Option<Transform>,
    /// Option 0x0001, not disabled: the 32-bit port status (bit 0 occupied, 4 initialised,
    /// 5 enabled, 6 out of volume, 7 partially out of volume, ...).
    pub port_status: Option<u32>,
    /// Option 0x0001, not disabled: the device's frame counter for this handle's data.
    pub frame: Option<u32>,
    /// Option 0x0002, not disabled.
    pub tool_info: Option<ToolInfo>,
    /// Option 0x0004, not disabled.
    pub active_marker: Option<ActiveMarker>,
    /// Option 0x0008, not disabled: the markers of the handle's tool, in the tool definition's
    /// order.
    pub tool_markers: Option<Vec<MarkerPosition>>,
}

impl HandleReading {
    /// A reading with only a handle and a status (no option data).
    pub fn bare(handle: u8, status: HandleStatus) -> Self {
        HandleReading {
            handle,
            status,
            transform: None,
            port_status: None,
            frame: None,
            tool_info: None,
            active_marker: None,
            tool_markers: None,
        }
    }
}

/// One BX or TX reply: every port handle's reading plus system-wide data.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackingReply {
    /// The reply options of the command this answers (they define the layout).
    pub options: ReplyOptions,
    /// The handles in the order the device sent them.
    pub handles: Vec<HandleReading>,
    /// Option 0x1000: the stray passive markers; `None` when not requested.
    pub stray_markers: Option<Vec<MarkerPosition>>,
    /// System status bits (communication sync error, CRC error, ...).
    pub system_status: u16,
}

impl TrackingReply {
    /// The reply's frame number: the highest frame number any handle carries (handles may carry
    /// different ones: a missing handle is stamped with the last frame processed). `None` without
    /// option 0x0001 or without handles.
    pub fn frame(&self) -> Option<u32> {
        self.handles.iter().filter_map(|h| h.frame).max()
    }

    /// The reading of port handle `handle`, if the reply has one.
    pub fn handle(&self, handle: u8) -> Option<&HandleReading> {
        self.handles.iter().find(|h| h.handle == handle)
    }
}
