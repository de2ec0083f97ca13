//! ASCII replies other than TX: `OKAY`, `WARNINGxx`, `ERRORxx`, `RESET`, PHSR handle lists, and the
//! CRC + CR framing every ASCII reply shares.

use crate::crc::crc16;
use crate::error::{DeviceError, ReplyError};

/// A positive answer to a command that returns no data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Acknowledgement {
    /// `OKAY`.
    Okay,
    /// `WARNINGxx`: done, with a warning (e.g. a tool that violates design constraints).
    Warning(u8),
}

/// One entry of a PHSR reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PortHandleStatus {
    /// The port handle.
    pub handle: u8,
    /// Port status, 12 bits: 0x001 occupied, 0x010 initialised, 0x020 enabled, ...
    pub status: u16,
}

/// The bytes of an ASCII reply: `text`, its CRC as 4 upper-case hex digits, CR.
pub fn encode_text_reply(text: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(text.len() + 5);
    out.extend_from_slice(text.as_bytes());
    out.extend_from_slice(format!("{:04X}", crc16(text.as_bytes())).as_bytes());
    out.push(b'\r');
    out
}

/// Checks an ASCII reply line (everything before the CR): printable ASCII or LF only, and a
/// valid upper-case hex CRC at the end. Returns the text without the CRC.
pub fn check_text_reply(line: &[u8]) -> Result<String, ReplyError> {
    if let Some((offset, &byte)) = line
        .iter()
        .enumerate()
        .find(|&(_, &b)| !(b == b'\n' || (0x20..0x7F).contains(&b)))
    {
        return Err(ReplyError::NonAscii { byte, offset });
    }
    if line.len() < 4 {
        return Err(ReplyError::NoCrc { len: line.len() });
    }
    let (content, crc_text) = line.split_at(line.len() - 4);
    let actual = parse_hex(crc_text, "reply CRC")?;
    let expected = crc16(content);
    if u32::from(expected) != actual {
        return Err(ReplyError::BadCrc {
            expected,
            actual: actual as u16,
        });
    }
    // Checked above: printable ASCII and LF only.
    Ok(content.iter().map(|&b| char::from(b)).collect())
}

/// Upper-case hexadecimal digits (at most 8) to a number.
pub(crate) fn parse_hex(digits: &[u8], field: &'static str) -> Result<u32, ReplyError> {
    let valid = !digits.is_empty()
        && digits.len() <= 8
        && digits
            .iter()
            .all(|b| b.is_ascii_digit() || (b'A'..=b'F').contains(b));
    if !valid {
        return Err(ReplyError::BadHex {
            field,
            text: String::from_utf8_lossy(digits).into_owned(),
        });
    }
    Ok(digits.iter().fold(0u32, |acc, &b| {
        let digit = if b.is_ascii_digit() {
            b - b'0'
        } else {
            b - b'A' + 10
        };
        (acc << 4) | u32::from(digit)
    }))
}

/// `Some(error)` if the reply text is `ERRORxx`.
pub fn device_error(text: &str) -> Option<Result<DeviceError, ReplyError>> {
    let code = text.strip_prefix("ERROR")?;
    Some(parse_code(code, "error code").map(|code| DeviceError { code }))
}

fn parse_code(text: &str, field: &'static str) -> Result<u8, ReplyError> {
    if text.len() != 2 {
        return Err(ReplyError::BadHex {
            field,
            text: text.to_owned(),
        });
    }
    parse_hex(text.as_bytes(), field).map(|v| v as u8)
}

/// Turns `ERRORxx` into [`ReplyError::Device`]; any other text passes through.
pub fn reject_device_error(text: &str) -> Result<&str, ReplyError> {
    match device_error(text) {
        Some(Ok(error)) => Err(ReplyError::Device(error)),
        Some(Err(bad)) => Err(bad),
        None => Ok(text),
    }
}

/// Parses the reply to a command that returns no data: `OKAY` or `WARNINGxx`.
pub fn parse_acknowledgement(text: &str) -> Result<Acknowledgement, ReplyError> {
    let text = reject_device_error(text)?;
    if text == "OKAY" {
        return Ok(Acknowledgement::Okay);
    }
    if let Some(code) = text.strip_prefix("WARNING") {
        return parse_code(code, "warning code").map(Acknowledgement::Warning);
    }
    Err(unexpected("OKAY", text))
}

/// Parses a PHSR reply: 2 hex digits of count, then per handle 2 hex digits of handle and
/// 3 hex digits of port status.
pub fn parse_phsr(text: &str) -> Result<Vec<PortHandleStatus>, ReplyError> {
    let text = reject_device_error(text)?.as_bytes();
    let count = field(text, 0, 2, "PHSR handle count")? as usize;
    let expected_len = 2 + count * 5;
    if text.len() < expected_len {
        return Err(ReplyError::Truncated {
            what: "PHSR handle list",
            needed: expected_len - text.len(),
            available: 0,
        });
    }
    if text.len() > expected_len {
        return Err(ReplyError::TrailingBytes {
            what: "PHSR handle list",
            extra: text.len() - expected_len,
        });
    }
    (0..count)
        .map(|i| {
            let at = 2 + i * 5;
            Ok(PortHandleStatus {
                handle: field(text, at, 2, "PHSR handle")? as u8,
                status: field(text, at + 2, 3, "PHSR port status")? as u16,
            })
        })
        .collect()
}

/// The text of a PHSR reply listing `handles`.
pub fn encode_phsr(handles: &[PortHandleStatus]) -> String {
    let mut text = format!("{:02X}", handles.len());
    for h in handles {
        text.push_str(&format!("{:02X}{:03X}", h.handle, h.status & 0xFFF));
    }
    text
}

fn field(text: &[u8], at: usize, len: usize, name: &'static str) -> Result<u32, ReplyError> {
    let slice = text.get(at..at + len).ok_or(ReplyError::Truncated {
        what: name,
        needed: len,
        available: text.len().saturating_sub(at),
    })?;
    parse_hex(slice, name)
}

/// An [`ReplyError::Unexpected`] quoting at most 40 characters of `got`.
pub(crate) fn unexpected(expected: &'static str, got: &str) -> ReplyError {
    ReplyError::Unexpected {
        expected,
        got: got.chars().take(40).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn okay_and_reset_from_the_log() {
        assert_eq!(encode_text_reply("OKAY"), b"OKAYA896\r");
        assert_eq!(encode_text_reply("RESET"), b"RESETBE6F\r");
        assert_eq!(check_text_reply(b"OKAYA896").unwrap(), "OKAY");
        assert_eq!(
            parse_acknowledgement("OKAY").unwrap(),
            Acknowledgement::Okay
        );
        assert_eq!(
            parse_acknowledgement("WARNING02").unwrap(),
            Acknowledgement::Warning(2)
        );
    }

    #[test]
    fn bad_crc_names_both_values() {
        assert_eq!(
            check_text_reply(b"OKAYA897"),
            Err(ReplyError::BadCrc {
                expected: 0xA896,
                actual: 0xA897
            })
        );
        // Lower-case CRC digits are not what the device sends.
        assert!(matches!(
            check_text_reply(b"OKAYa896"),
            Err(ReplyError::BadHex { .. })
        ));
        assert_eq!(check_text_reply(b"OK"), Err(ReplyError::NoCrc { len: 2 }));
        assert_eq!(
            check_text_reply(b"OK\x01YA896"),
            Err(ReplyError::NonAscii { byte: 1, offset: 2 })
        );
    }

    #[test]
    fn errors_are_typed() {
        assert_eq!(
            parse_acknowledgement("ERROR0C"),
            Err(ReplyError::Device(DeviceError::WRONG_MODE))
        );
        assert!(matches!(
            parse_acknowledgement("ERRORZZ"),
            Err(ReplyError::BadHex { .. })
        ));
        assert!(matches!(
            parse_acknowledgement("OKAX"),
            Err(ReplyError::Unexpected { .. })
        ));
        assert_eq!(
            DeviceError::WRONG_MODE.to_string(),
            "ERROR0C (command is invalid while in the current mode)"
        );
    }

    #[test]
    fn phsr_from_the_log() {
        // Exchange 31: PHSR:02 → two handles occupied, not initialised.
        let text = check_text_reply(b"020100102001C741").unwrap();
        let handles = parse_phsr(&text).unwrap();
        assert_eq!(
            handles,
            vec![
                PortHandleStatus {
                    handle: 1,
                    status: 0x001
                },
                PortHandleStatus {
                    handle: 2,
                    status: 0x001
                }
            ]
        );
        assert_eq!(encode_phsr(&handles), text);
        // Exchange 34: PHSR:03 → both initialised.
        let text = check_text_reply(b"0201011020119750").unwrap();
        assert!(parse_phsr(&text).unwrap().iter().all(|h| h.status == 0x011));
        assert_eq!(parse_phsr("00").unwrap(), vec![]);
        assert!(matches!(
            parse_phsr("0201001"),
            Err(ReplyError::Truncated { .. })
        ));
        assert!(matches!(
            parse_phsr("010100100"),
            Err(ReplyError::TrailingBytes { .. })
        ));
    }
}
