//! Host commands: encoding with CRC (host side) and decoding (device side).
//!
//! A command is `NAME:params` followed by the CRC of that text as 4 upper-case hex digits and a
//! CR (`INIT:E3A5\r`). The device also accepts `NAME params\r` without a CRC.

use crate::crc::crc16;
use crate::reply::ReplyOptions;
use std::fmt;
use thiserror::Error;

/// Serial speed codes of the COMM command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Baud {
    /// 9600 bit/s, the speed after power-up and reset.
    B9600,
    /// 14400 bit/s.
    B14400,
    /// 19200 bit/s.
    B19200,
    /// 38400 bit/s.
    B38400,
    /// 57600 bit/s.
    B57600,
    /// 115200 bit/s.
    B115200,
    /// 921600 bit/s.
    B921600,
    /// 1228739 bit/s.
    B1228739,
}

impl Baud {
    const ALL: [Baud; 8] = [
        Baud::B9600,
        Baud::B14400,
        Baud::B19200,
        Baud::B38400,
        Baud::B57600,
        Baud::B115200,
        Baud::B921600,
        Baud::B1228739,
    ];

    /// The digit sent in COMM.
    pub fn code(self) -> u8 {
        Baud::ALL.iter().position(|&b| b == self).unwrap_or(0) as u8
    }

    /// The speed for a COMM digit.
    pub fn from_code(code: u8) -> Option<Baud> {
        Baud::ALL.get(usize::from(code)).copied()
    }

    /// Bits per second.
    pub fn bits_per_second(self) -> u32 {
        match self {
            Baud::B9600 => 9600,
            Baud::B14400 => 14400,
            Baud::B19200 => 19200,
            Baud::B38400 => 38400,
            Baud::B57600 => 57600,
            Baud::B115200 => 115_200,
            Baud::B921600 => 921_600,
            Baud::B1228739 => 1_228_739,
        }
    }

    /// The speed with exactly `bits_per_second`, if the device offers it.
    pub fn from_bits_per_second(bits_per_second: u32) -> Option<Baud> {
        Baud::ALL
            .into_iter()
            .find(|b| b.bits_per_second() == bits_per_second)
    }
}

/// Data bits of the COMM command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataBits {
    /// 8 data bits (code 0); needed for binary BX replies.
    Eight,
    /// 7 data bits (code 1).
    Seven,
}

/// Parity of the COMM command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Parity {
    /// No parity (code 0).
    None,
    /// Odd parity (code 1).
    Odd,
    /// Even parity (code 2).
    Even,
}

/// Stop bits of the COMM command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopBits {
    /// One stop bit (code 0).
    One,
    /// Two stop bits (code 1).
    Two,
}

/// The serial settings a COMM command asks the device to switch to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CommSettings {
    /// Speed.
    pub baud: Baud,
    /// Data bits.
    pub data_bits: DataBits,
    /// Parity.
    pub parity: Parity,
    /// Stop bits.
    pub stop_bits: StopBits,
    /// RTS/CTS hardware handshaking.
    pub handshake: bool,
}

impl CommSettings {
    /// 8 data bits, no parity, 1 stop bit, no handshake, at `baud`.
    pub fn eight_n_one(baud: Baud) -> Self {
        CommSettings {
            baud,
            data_bits: DataBits::Eight,
            parity: Parity::None,
            stop_bits: StopBits::One,
            handshake: false,
        }
    }
}

/// Tracking priority of PENA.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TrackingPriority {
    /// `S`: a static tool (reference).
    Static,
    /// `D`: a dynamic tool.
    Dynamic,
    /// `B`: a button box (no markers).
    ButtonBox,
}

impl TrackingPriority {
    fn letter(self) -> char {
        match self {
            TrackingPriority::Static => 'S',
            TrackingPriority::Dynamic => 'D',
            TrackingPriority::ButtonBox => 'B',
        }
    }
}

/// Which port handles a PHSR command lists.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PhsrFilter {
    /// 00: all allocated port handles.
    All,
    /// 01: port handles that need to be freed.
    ToBeFreed,
    /// 02: occupied port handles that are not initialised.
    OccupiedNotInitialized,
    /// 03: initialised port handles that are not enabled.
    InitializedNotEnabled,
    /// 04: enabled port handles.
    Enabled,
}

impl PhsrFilter {
    const ALL: [PhsrFilter; 5] = [
        PhsrFilter::All,
        PhsrFilter::ToBeFreed,
        PhsrFilter::OccupiedNotInitialized,
        PhsrFilter::InitializedNotEnabled,
        PhsrFilter::Enabled,
    ];

    /// The two-digit code sent in PHSR.
    pub fn code(self) -> u8 {
        PhsrFilter::ALL.iter().position(|&f| f == self).unwrap_or(0) as u8
    }
}

/// A host command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `INIT:` initialise the system.
    Init,
    /// `RESET:` reset the system (it then answers `RESET` at 9600 baud, as after a serial break).
    Reset,
    /// `COMM:` change the serial settings (the device answers at the old settings, then switches).
    Comm(CommSettings),
    /// `VER:` firmware version of a processor (0 = control processor).
    Ver(u8),
    /// `BEEP:` beep 1-9 times.
    Beep(u8),
    /// `PHSR:` list port handles by status.
    Phsr(PhsrFilter),
    /// `PHRQ:` request a port handle; the 14 request characters (hardware device 8, system type
    /// 1, tool type 1, port number 2, dummy tool 2; `*` = any).
    Phrq(String),
    /// `PINIT:` initialise a port handle.
    Pinit(u8),
    /// `PENA:` enable a port handle for tracking.
    Pena(u8, TrackingPriority),
    /// `PDIS:` disable a port handle.
    Pdis(u8),
    /// `PHF:` free a port handle.
    Phf(u8),
    /// `TSTART:` enter tracking mode.
    Tstart,
    /// `TSTOP:` leave tracking mode.
    Tstop,
    /// `BX:` binary tracking data.
    Bx(ReplyOptions),
    /// `TX:` text tracking data.
    Tx(ReplyOptions),
    /// Any other command, sent as `NAME:params` (e.g. PHINF, PVWR, SSTAT).
    Other {
        /// Upper-case command name.
        name: String,
        /// Parameter text.
        params: String,
    },
}

/// Why a command line could not be decoded (device side).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CommandError {
    /// Not a `NAME:params` or `NAME params` line.
    #[error("not a command: {0:?}")]
    Malformed(String),
    /// `NAME:` form without room for the 4 CRC digits.
    #[error("command too short for its CRC: {0:?}")]
    TooShort(String),
    /// The CRC digits do not match the command text.
    #[error("command CRC: computed {expected:04X}, command carries {actual:04X}")]
    BadCrc {
        /// CRC of the command text.
        expected: u16,
        /// CRC the command carries.
        actual: u16,
    },
    /// The parameters do not fit the command.
    #[error("{command}: bad parameters {params:?}: {reason}")]
    BadParameters {
        /// Command name.
        command: String,
        /// Parameter text.
        params: String,
        /// What is wrong.
        reason: &'static str,
    },
}

impl Command {
    /// The command name (`BX`, `INIT`, ...).
    pub fn name(&self) -> &str {
        match self {
            Command::Init => "INIT",
            Command::Reset => "RESET",
            Command::Comm(_) => "COMM",
            Command::Ver(_) => "VER",
            Command::Beep(_) => "BEEP",
            Command::Phsr(_) => "PHSR",
            Command::Phrq(_) => "PHRQ",
            Command::Pinit(_) => "PINIT",
            Command::Pena(..) => "PENA",
            Command::Pdis(_) => "PDIS",
            Command::Phf(_) => "PHF",
            Command::Tstart => "TSTART",
            Command::Tstop => "TSTOP",
            Command::Bx(_) => "BX",
            Command::Tx(_) => "TX",
            Command::Other { name, .. } => name,
        }
    }

    /// The parameter text after the colon.
    pub fn params(&self) -> String {
        match self {
            Command::Init | Command::Reset | Command::Tstart | Command::Tstop => String::new(),
            Command::Comm(c) => format!(
                "{}{}{}{}{}",
                c.baud.code(),
                match c.data_bits {
                    DataBits::Eight => 0,
                    DataBits::Seven => 1,
                },
                match c.parity {
                    Parity::None => 0,
                    Parity::Odd => 1,
                    Parity::Even => 2,
                },
                match c.stop_bits {
                    StopBits::One => 0,
                    StopBits::Two => 1,
                },
                u8::from(c.handshake)
            ),
            Command::Ver(n) | Command::Beep(n) => n.to_string(),
            Command::Phsr(filter) => format!("{:02X}", filter.code()),
            Command::Phrq(fields) => fields.clone(),
            Command::Pinit(h) | Command::Pdis(h) | Command::Phf(h) => format!("{h:02X}"),
            Command::Pena(h, priority) => format!("{h:02X}{}", priority.letter()),
            Command::Bx(options) | Command::Tx(options) => format!("{:04X}", options.bits()),
            Command::Other { params, .. } => params.clone(),
        }
    }

    /// The bytes to send: `NAME:params`, CRC (4 upper-case hex digits), CR.
    pub fn encode(&self) -> Vec<u8> {
        let text = self.to_string();
        let mut out = text.clone().into_bytes();
        out.extend_from_slice(format!("{:04X}", crc16(text.as_bytes())).as_bytes());
        out.push(b'\r');
        out
    }

    /// Decodes one command line (without its CR), checking the CRC of the `NAME:` form.
    pub fn decode(line: &[u8]) -> Result<Command, CommandError> {
        let text = std::str::from_utf8(line)
            .ok()
            .filter(|t| t.bytes().all(|b| (0x20..0x7F).contains(&b)))
            .ok_or_else(|| CommandError::Malformed(String::from_utf8_lossy(line).into_owned()))?;
        let name_len = text
            .find(|c: char| !c.is_ascii_alphanumeric())
            .unwrap_or(text.len());
        let name = &text[..name_len];
        let well_named = !name.is_empty()
            && name.starts_with(|c: char| c.is_ascii_uppercase())
            && !name.contains(|c: char| c.is_ascii_lowercase());
        if !well_named {
            return Err(CommandError::Malformed(text.to_owned()));
        }
        let params = match text.as_bytes().get(name_len) {
            Some(b':') => {
                let rest = &text[name_len + 1..];
                if rest.len() < 4 {
                    return Err(CommandError::TooShort(text.to_owned()));
                }
                let (params, crc_digits) = rest.split_at(rest.len() - 4);
                let actual = u16::from_str_radix(crc_digits, 16)
                    .ok()
                    .filter(|_| crc_digits.bytes().all(|b| !b.is_ascii_lowercase()))
                    .ok_or_else(|| CommandError::Malformed(text.to_owned()))?;
                let expected = crc16(&line[..line.len() - 4]);
                if expected != actual {
                    return Err(CommandError::BadCrc { expected, actual });
                }
                params
            }
            Some(b' ') => &text[name_len + 1..],
            None => "",
            Some(_) => return Err(CommandError::Malformed(text.to_owned())),
        };
        parse_command(name, params)
    }
}

impl fmt::Display for Command {
    /// `NAME:params`, the text the CRC covers.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.name(), self.params())
    }
}

fn parse_command(name: &str, params: &str) -> Result<Command, CommandError> {
    let bad = |reason| CommandError::BadParameters {
        command: name.to_owned(),
        params: params.to_owned(),
        reason,
    };
    let none = |command: Command| {
        if params.is_empty() {
            Ok(command)
        } else {
            Err(bad("takes no parameters"))
        }
    };
    let handle = || {
        hex_exact(params, 2)
            .map(|h| h as u8)
            .ok_or(bad("expects a 2-digit hex handle"))
    };
    let options = || {
        if params.is_empty() {
            return Ok(ReplyOptions::default());
        }
        let bits = hex_exact(params, 4).ok_or(bad("expects 4 hex digits of reply options"))?;
        ReplyOptions::new(bits as u16).map_err(|_| bad("unsupported reply option bits"))
    };
    let digit = || match params.as_bytes() {
        [d] if d.is_ascii_digit() => Ok(d - b'0'),
        _ => Err(bad("expects one decimal digit")),
    };
    match name {
        "INIT" => none(Command::Init),
        "RESET" => none(Command::Reset),
        "TSTART" => none(Command::Tstart),
        "TSTOP" => none(Command::Tstop),
        "COMM" => {
            parse_comm(params).ok_or(bad("expects 5 digits: baud, data, parity, stop, handshake"))
        }
        "VER" => digit().map(Command::Ver),
        "BEEP" => match digit()? {
            n @ 1..=9 => Ok(Command::Beep(n)),
            _ => Err(bad("beeps 1 to 9 times")),
        },
        "PHSR" => match params {
            "" => Ok(PhsrFilter::All),
            _ => hex_exact(params, 2)
                .and_then(|code| PhsrFilter::ALL.get(code as usize).copied())
                .ok_or(bad("expects a filter 00-04")),
        }
        .map(Command::Phsr),
        "PHRQ" => {
            if params.len() == 14 {
                Ok(Command::Phrq(params.to_owned()))
            } else {
                Err(bad("expects 14 request characters"))
            }
        }
        "PINIT" => handle().map(Command::Pinit),
        "PDIS" => handle().map(Command::Pdis),
        "PHF" => handle().map(Command::Phf),
        "PENA" => {
            let (h, p) = params.split_at(params.len().min(2));
            let handle = hex_exact(h, 2).ok_or(bad("expects a 2-digit hex handle"))? as u8;
            let priority = match p {
                "S" => TrackingPriority::Static,
                "D" => TrackingPriority::Dynamic,
                "B" => TrackingPriority::ButtonBox,
                _ => return Err(bad("expects a priority S, D or B")),
            };
            Ok(Command::Pena(handle, priority))
        }
        "BX" => options().map(Command::Bx),
        "TX" => options().map(Command::Tx),
        _ => Ok(Command::Other {
            name: name.to_owned(),
            params: params.to_owned(),
        }),
    }
}

fn parse_comm(params: &str) -> Option<Command> {
    let digits: Vec<u8> = params
        .bytes()
        .map(|b| b.is_ascii_digit().then(|| b - b'0'))
        .collect::<Option<_>>()?;
    let [baud, data, parity, stop, handshake] = digits[..] else {
        return None;
    };
    Some(Command::Comm(CommSettings {
        baud: Baud::from_code(baud)?,
        data_bits: [DataBits::Eight, DataBits::Seven]
            .get(usize::from(data))
            .copied()?,
        parity: [Parity::None, Parity::Odd, Parity::Even]
            .get(usize::from(parity))
            .copied()?,
        stop_bits: [StopBits::One, StopBits::Two]
            .get(usize::from(stop))
            .copied()?,
        handshake: match handshake {
            0 => false,
            1 => true,
            _ => return None,
        },
    }))
}

/// Exactly `len` upper-case hex digits.
fn hex_exact(text: &str, len: usize) -> Option<u32> {
    let ok = text.len() == len
        && text
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'A'..=b'F').contains(&b));
    ok.then(|| u32::from_str_radix(text, 16).ok()).flatten()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encoded(command: Command) -> String {
        String::from_utf8(command.encode()).unwrap()
    }

    #[test]
    fn commands_as_the_real_host_sent_them() {
        assert_eq!(encoded(Command::Init), "INIT:E3A5\r");
        assert_eq!(
            encoded(Command::Comm(CommSettings::eight_n_one(Baud::B38400))),
            "COMM:3000000C0\r"
        );
        assert_eq!(encoded(Command::Beep(2)), "BEEP:28544\r");
        assert_eq!(encoded(Command::Ver(0)), "VER:065EE\r");
        assert_eq!(
            encoded(Command::Phrq("**********0A**".into())),
            "PHRQ:**********0A**62D3\r"
        );
        assert_eq!(
            encoded(Command::Phsr(PhsrFilter::OccupiedNotInitialized)),
            "PHSR:02E17E\r"
        );
        assert_eq!(
            encoded(Command::Phsr(PhsrFilter::InitializedNotEnabled)),
            "PHSR:0321BF\r"
        );
        assert_eq!(encoded(Command::Pinit(1)), "PINIT:0131EA\r");
        assert_eq!(encoded(Command::Pinit(2)), "PINIT:0230AA\r");
        assert_eq!(
            encoded(Command::Pena(1, TrackingPriority::Dynamic)),
            "PENA:01D6D3B\r"
        );
        assert_eq!(encoded(Command::Tstart), "TSTART:5423\r");
        assert_eq!(encoded(Command::Tstop), "TSTOP:2C14\r");
        assert_eq!(
            encoded(Command::Bx(ReplyOptions::TRANSFORMS)),
            "BX:0001C26D\r"
        );
        assert_eq!(
            encoded(Command::Bx(
                ReplyOptions::TRANSFORMS | ReplyOptions::SINGLE_STRAY
            )),
            "BX:0005016C\r"
        );
        assert_eq!(
            encoded(Command::Tx(ReplyOptions::PASSIVE_STRAYS)),
            "TX:10003FDA\r"
        );
        assert_eq!(encoded(Command::Pdis(1)), "PDIS:011266\r");
        assert_eq!(encoded(Command::Phf(2)), "PHF:02CE4C\r");
    }

    #[test]
    fn decode_inverts_encode() {
        let commands = [
            Command::Init,
            Command::Reset,
            Command::Comm(CommSettings {
                baud: Baud::B115200,
                data_bits: DataBits::Seven,
                parity: Parity::Even,
                stop_bits: StopBits::Two,
                handshake: true,
            }),
            Command::Ver(4),
            Command::Beep(9),
            Command::Phsr(PhsrFilter::Enabled),
            Command::Phrq("*********1****".into()),
            Command::Pinit(0x0A),
            Command::Pena(0xFF, TrackingPriority::Static),
            Command::Pdis(3),
            Command::Phf(4),
            Command::Tstart,
            Command::Tstop,
            Command::Bx(ReplyOptions::TRANSFORMS | ReplyOptions::OUT_OF_VOLUME),
            Command::Tx(ReplyOptions::TOOL_INFO),
            Command::Other {
                name: "PHINF".into(),
                params: "01002D".into(),
            },
        ];
        for command in commands {
            let bytes = command.encode();
            let line = &bytes[..bytes.len() - 1];
            assert_eq!(Command::decode(line).unwrap(), command);
        }
    }

    #[test]
    fn bad_command_lines_are_typed_errors() {
        assert_eq!(
            Command::decode(b"INIT:E3A6"),
            Err(CommandError::BadCrc {
                expected: 0xE3A5,
                actual: 0xE3A6
            })
        );
        assert!(matches!(
            Command::decode(b"INIT:E3"),
            Err(CommandError::TooShort(_))
        ));
        assert!(matches!(
            Command::decode(b"init:E3A5"),
            Err(CommandError::Malformed(_))
        ));
        assert!(matches!(
            Command::decode(b"\x01INIT"),
            Err(CommandError::Malformed(_))
        ));
        assert!(matches!(
            Command::decode(b""),
            Err(CommandError::Malformed(_))
        ));
        assert!(matches!(
            Command::decode(b"PINIT 1"),
            Err(CommandError::BadParameters { .. })
        ));
        assert!(matches!(
            Command::decode(b"BX 0010"),
            Err(CommandError::BadParameters { .. })
        ));
        assert!(matches!(
            Command::decode(b"COMM 80000"),
            Err(CommandError::BadParameters { .. })
        ));
        // The CRC-less form is accepted.
        assert_eq!(
            Command::decode(b"BX 0801").unwrap(),
            Command::Bx(ReplyOptions::new(0x0801).unwrap())
        );
        assert_eq!(
            Command::decode(b"BX").unwrap(),
            Command::Bx(ReplyOptions::TRANSFORMS)
        );
    }
}
