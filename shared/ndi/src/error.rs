//! Errors of reply parsing and encoding.

use std::fmt;
use thiserror::Error;

/// Why a reply (or a stretch of the byte stream) was rejected.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ReplyError {
    /// The CRC carried by the reply does not match the one computed over its content.
    #[error("bad CRC: computed {expected:04X}, reply carries {actual:04X}")]
    BadCrc {
        /// CRC computed over the received content.
        expected: u16,
        /// CRC the reply carries.
        actual: u16,
    },
    /// The CRC of a BX header (`C4 A5`, length) does not match.
    #[error("bad BX header CRC: computed {expected:04X}, header carries {actual:04X}")]
    BadHeaderCrc {
        /// CRC computed over the 4 header bytes.
        expected: u16,
        /// CRC the header carries.
        actual: u16,
    },
    /// The reply ended before a field was complete.
    #[error("truncated reply: {what} needs {needed} more bytes, {available} left")]
    Truncated {
        /// The field being read.
        what: &'static str,
        /// Bytes the field needs.
        needed: usize,
        /// Bytes that were left.
        available: usize,
    },
    /// Bytes were left over after the last field of the reply.
    #[error("{extra} unexpected bytes after the end of the {what}")]
    TrailingBytes {
        /// What was complete.
        what: &'static str,
        /// How many bytes were left over.
        extra: usize,
    },
    /// A field that must be upper-case hexadecimal is not.
    #[error("bad hex in {field}: {text:?}")]
    BadHex {
        /// The field.
        field: &'static str,
        /// Its text.
        text: String,
    },
    /// A signed decimal field (sign and digits) is malformed.
    #[error("bad number in {field}: {text:?}")]
    BadNumber {
        /// The field.
        field: &'static str,
        /// Its text.
        text: String,
    },
    /// A binary float field is NaN or infinite.
    #[error("handle {handle:02X}: {field} is not finite ({value})")]
    NonFinite {
        /// The port handle whose data holds it (0 for stray markers).
        handle: u8,
        /// The field.
        field: &'static str,
        /// The value read.
        value: f32,
    },
    /// A BX handle status byte other than 0x01 (valid), 0x02 (missing), 0x04 (disabled).
    #[error("handle {handle:02X}: unknown status 0x{status:02X}")]
    UnknownStatus {
        /// The port handle.
        handle: u8,
        /// The status byte.
        status: u8,
    },
    /// A TX handle entry that is neither a transform nor MISSING / DISABLED / UNOCCUPIED.
    #[error("handle {handle:02X}: unknown entry {text:?}")]
    UnknownEntry {
        /// The port handle.
        handle: u8,
        /// The start of the entry.
        text: String,
    },
    /// The device answered `ERRORxx`.
    #[error("device error: {0}")]
    Device(DeviceError),
    /// A well-formed reply of the wrong kind (e.g. text where a BX binary reply was expected).
    #[error("expected {expected}, got {got:?}")]
    Unexpected {
        /// What the command calls for.
        expected: &'static str,
        /// What came (possibly shortened).
        got: String,
    },
    /// An ASCII reply holds a byte that is neither printable ASCII nor LF.
    #[error("byte 0x{byte:02X} at offset {offset} is not allowed in an ASCII reply")]
    NonAscii {
        /// The byte.
        byte: u8,
        /// Its offset in the reply.
        offset: usize,
    },
    /// An ASCII reply is too short to carry its 4-digit CRC.
    #[error("ASCII reply of {len} bytes is too short for a CRC")]
    NoCrc {
        /// Length of the reply before the CR.
        len: usize,
    },
    /// No CR within the longest ASCII reply the protocol produces.
    #[error("no CR within {len} bytes: not a reply")]
    TooLong {
        /// Bytes discarded.
        len: usize,
    },
    /// Bytes before the start of a binary reply that belong to no reply.
    #[error("{len} bytes of garbage before a reply")]
    Garbage {
        /// Bytes discarded.
        len: usize,
    },
    /// The stream ended inside a reply.
    #[error("stream ended inside a reply ({pending} bytes pending)")]
    Incomplete {
        /// Bytes of the unfinished reply.
        pending: usize,
    },
    /// Reply-option bits this implementation does not parse.
    #[error("reply option bits 0x{0:04X} are not supported")]
    UnsupportedOptions(u16),
}

/// Why a reply could not be encoded (device side).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EncodeError {
    /// The reply options call for a field the reading does not have.
    #[error("handle {handle:02X}: reply option 0x{option:04X} needs {field}, which is absent")]
    MissingField {
        /// The port handle (0 for stray markers).
        handle: u8,
        /// The option that calls for it.
        option: u16,
        /// The field.
        field: &'static str,
    },
    /// A status that the reply format cannot carry (e.g. `NotReported` in a BX reply).
    #[error("handle {handle:02X}: status {status} cannot be encoded in a {format} reply")]
    BadStatus {
        /// The port handle.
        handle: u8,
        /// The status.
        status: &'static str,
        /// BX or TX.
        format: &'static str,
    },
    /// A value outside the fixed-width TX format (or not finite).
    #[error("{field} = {value} does not fit the TX format")]
    OutOfRange {
        /// The field.
        field: &'static str,
        /// The value.
        value: f64,
    },
    /// More items than a count field can hold.
    #[error("{count} {what} do not fit a one-byte count")]
    TooMany {
        /// What is counted.
        what: &'static str,
        /// How many there are.
        count: usize,
    },
    /// A BX body longer than its 16-bit length field.
    #[error("BX body of {0} bytes exceeds 65535")]
    TooLong(usize),
}

/// An `ERRORxx` reply: the device refused the command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceError {
    /// The error code (the two hex digits after `ERROR`).
    pub code: u8,
}

impl DeviceError {
    /// 0x01: the device does not know the command.
    pub const INVALID_COMMAND: DeviceError = DeviceError { code: 0x01 };
    /// 0x02: the command line is too long.
    pub const TOO_LONG: DeviceError = DeviceError { code: 0x02 };
    /// 0x03: the command line is too short.
    pub const TOO_SHORT: DeviceError = DeviceError { code: 0x03 };
    /// 0x04: the command's CRC is wrong.
    pub const BAD_CRC: DeviceError = DeviceError { code: 0x04 };
    /// 0x06: the COMM parameters are out of range.
    pub const BAD_COMM: DeviceError = DeviceError { code: 0x06 };
    /// 0x07: wrong number or form of parameters.
    pub const BAD_PARAMETERS: DeviceError = DeviceError { code: 0x07 };
    /// 0x08: no such port handle.
    pub const INVALID_HANDLE: DeviceError = DeviceError { code: 0x08 };
    /// 0x09: invalid tracking priority.
    pub const INVALID_PRIORITY: DeviceError = DeviceError { code: 0x09 };
    /// 0x0C: the command is not allowed in the current mode (setup / tracking).
    pub const WRONG_MODE: DeviceError = DeviceError { code: 0x0C };
    /// 0x0E: the port handle is not initialised.
    pub const NOT_INITIALIZED: DeviceError = DeviceError { code: 0x0E };
    /// 0x10: the system is not initialised (INIT first).
    pub const SYSTEM_NOT_INITIALIZED: DeviceError = DeviceError { code: 0x10 };

    /// What the code means (NDI Combined API error table).
    pub fn description(self) -> &'static str {
        match self.code {
            0x01 => "invalid command",
            0x02 => "command too long",
            0x03 => "command too short",
            0x04 => "invalid CRC calculated for command",
            0x05 => "time-out on command execution",
            0x06 => "unable to set up new communication parameters",
            0x07 => "incorrect number of parameters",
            0x08 => "invalid port handle selected",
            0x09 => "invalid tracking priority selected",
            0x0A => "invalid LED selected",
            0x0B => "invalid LED state selected",
            0x0C => "command is invalid while in the current mode",
            0x0D => "no tool is assigned to the selected port handle",
            0x0E => "selected port handle not initialized",
            0x0F => "selected port handle not enabled",
            0x10 => "system not initialized",
            0x11 => "unable to stop tracking",
            0x12 => "unable to start tracking",
            0x13 => "unable to initialize the port handle",
            _ => "see the NDI API guide",
        }
    }
}

impl fmt::Display for DeviceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ERROR{:02X} ({})", self.code, self.description())
    }
}
