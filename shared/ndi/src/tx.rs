//! TX: the text tracking reply.
//!
//! Handle count (2 hex); per handle: handle (2 hex), then `UNOCCUPIED` + LF, `DISABLED` + LF
//! (with any reply options; port status and frame number are accepted after it when 0x0001 is
//! requested), or the data of each reply option in order — 0x0001: `MISSING` or a 51-character
//! transform (q0 qx qy qz as sign + 5 digits × 1e-4; x y z as sign + 6 digits × 1e-2 mm; rms as
//! sign + 5 digits × 1e-4 mm), then port status (8 hex) and frame number (8 hex); 0x0002: tool
//! info (2 hex) + marker info (20 hex); 0x0004: marker status (2 hex) and, when
//! [`ActiveMarker::carries_position`], a position (3 × sign + 6 digits × 1e-2 mm); 0x0008: the
//! tool's markers as a marker list — and LF. After the handles, option 0x1000: the stray passive
//! markers as a marker list. Last: system status (4 hex). A marker list is a count (2 hex),
//! out-of-volume bits (⌈n/4⌉ hex digits; the last digit holds markers 0-3, bit j = marker j)
//! and a position per marker; out-of-volume markers are listed only with option 0x0800.

use crate::bx::{count_byte, missing};
use crate::error::{EncodeError, ReplyError};
use crate::reply::{
    ActiveMarker, HandleReading, HandleStatus, MarkerPosition, ReplyOptions, ToolInfo,
    TrackingReply, Transform,
};
use crate::text::{encode_text_reply, parse_hex, unexpected};
use std::fmt::Write as _;

/// Parses the text of a TX reply (CRC already checked and removed) answering a command with
/// `options`.
pub fn parse_tx(text: &str, options: ReplyOptions) -> Result<TrackingReply, ReplyError> {
    let text = crate::text::reject_device_error(text)?;
    let mut c = Text {
        data: text.as_bytes(),
        at: 0,
    };
    let count = c.hex(2, "handle count")?;
    let mut handles = Vec::with_capacity(count as usize);
    for _ in 0..count {
        handles.push(parse_handle(&mut c, options)?);
    }
    let stray_markers = if options.contains(ReplyOptions::PASSIVE_STRAYS) {
        Some(parse_markers(&mut c, "stray marker")?)
    } else {
        None
    };
    let system_status = c.hex(4, "system status")? as u16;
    if c.remaining() > 0 {
        return Err(ReplyError::TrailingBytes {
            what: "TX reply",
            extra: c.remaining(),
        });
    }
    Ok(TrackingReply {
        options,
        handles,
        stray_markers,
        system_status,
    })
}

fn parse_handle(c: &mut Text<'_>, options: ReplyOptions) -> Result<HandleReading, ReplyError> {
    let handle = c.hex(2, "handle")? as u8;
    if c.eat("UNOCCUPIED") {
        c.lf()?;
        return Ok(HandleReading::bare(handle, HandleStatus::Unoccupied));
    }
    if c.eat("DISABLED") {
        let mut reading = HandleReading::bare(handle, HandleStatus::Disabled);
        if options.contains(ReplyOptions::TRANSFORMS) && c.peek() != Some(b'\n') {
            reading.port_status = Some(c.hex(8, "port status")?);
            reading.frame = Some(c.hex(8, "frame number")?);
        }
        c.lf()?;
        return Ok(reading);
    }
    let mut reading = HandleReading::bare(handle, HandleStatus::NotReported);
    if options.contains(ReplyOptions::TRANSFORMS) {
        if c.eat("MISSING") {
            reading.status = HandleStatus::Missing;
        } else if matches!(c.peek(), Some(b'+' | b'-')) {
            reading.status = HandleStatus::Valid;
            reading.transform = Some(Transform {
                q: [
                    c.signed(5, 1e4, "q0")?,
                    c.signed(5, 1e4, "qx")?,
                    c.signed(5, 1e4, "qy")?,
                    c.signed(5, 1e4, "qz")?,
                ],
                t: c.point("position")?,
                rms: c.signed(5, 1e4, "rms")?,
            });
        } else {
            return Err(ReplyError::UnknownEntry {
                handle,
                text: c.rest().chars().take(12).collect(),
            });
        }
        reading.port_status = Some(c.hex(8, "port status")?);
        reading.frame = Some(c.hex(8, "frame number")?);
    }
    if options.contains(ReplyOptions::TOOL_INFO) {
        let tool = c.hex(2, "tool information")? as u8;
        let mut markers = [0u8; 10];
        for byte in &mut markers {
            *byte = c.hex(2, "marker information")? as u8;
        }
        reading.tool_info = Some(ToolInfo { tool, markers });
    }
    if options.contains(ReplyOptions::SINGLE_STRAY) {
        let status = c.hex(2, "active marker status")? as u8;
        let position = if ActiveMarker::carries_position(status, options) {
            Some(c.point("active marker position")?)
        } else {
            None
        };
        reading.active_marker = Some(ActiveMarker { status, position });
    }
    if options.contains(ReplyOptions::TOOL_MARKERS) {
        reading.tool_markers = Some(parse_markers(c, "tool marker")?);
    }
    c.lf()?;
    Ok(reading)
}

/// A marker list: count, out-of-volume digits, positions.
fn parse_markers(c: &mut Text<'_>, what: &'static str) -> Result<Vec<MarkerPosition>, ReplyError> {
    let count = c.hex(2, what)? as usize;
    let digits = count.div_ceil(4);
    let mut oov = vec![0u8; digits];
    for digit in &mut oov {
        *digit = c.hex(1, "out-of-volume bits")? as u8;
    }
    (0..count)
        .map(|i| {
            Ok(MarkerPosition {
                out_of_volume: oov[digits - 1 - i / 4] & (1 << (i % 4)) != 0,
                position: c.point(what)?,
            })
        })
        .collect()
}

/// Encodes `reply` as a complete TX reply (text, CRC, CR), laid out by `reply.options`.
pub fn encode_tx(reply: &TrackingReply) -> Result<Vec<u8>, EncodeError> {
    Ok(encode_text_reply(&encode_tx_text(reply)?))
}

/// The text of a TX reply (without CRC and CR).
///
/// Values are rounded to the format's precision; values that do not fit are an error. Without
/// option 0x0001 only `NotReported` and `Unoccupied` statuses can be expressed.
pub fn encode_tx_text(reply: &TrackingReply) -> Result<String, EncodeError> {
    let options = reply.options;
    let mut s = format!("{:02X}", count_byte(reply.handles.len(), "handles")?);
    for reading in &reply.handles {
        encode_handle(&mut s, reading, options)?;
    }
    if options.contains(ReplyOptions::PASSIVE_STRAYS) {
        let strays = reply
            .stray_markers
            .as_deref()
            .ok_or_else(|| missing(0, ReplyOptions::PASSIVE_STRAYS, "stray markers"))?;
        put_markers(&mut s, strays, "stray marker position")?;
    }
    let _ = write!(s, "{:04X}", reply.system_status);
    Ok(s)
}

fn encode_handle(
    s: &mut String,
    reading: &HandleReading,
    options: ReplyOptions,
) -> Result<(), EncodeError> {
    let handle = reading.handle;
    let _ = write!(s, "{handle:02X}");
    let bad_status = || EncodeError::BadStatus {
        handle,
        status: reading.status.name(),
        format: "TX",
    };
    match reading.status {
        HandleStatus::Unoccupied => {
            s.push_str("UNOCCUPIED\n");
            return Ok(());
        }
        HandleStatus::Disabled => {
            s.push_str("DISABLED\n");
            return Ok(());
        }
        _ => {}
    }
    if options.contains(ReplyOptions::TRANSFORMS) {
        let opt = ReplyOptions::TRANSFORMS;
        match reading.status {
            HandleStatus::Missing => s.push_str("MISSING"),
            HandleStatus::Valid => {
                let t = reading
                    .transform
                    .ok_or_else(|| missing(handle, opt, "transform"))?;
                for (q, name) in t.q.iter().zip(["q0", "qx", "qy", "qz"]) {
                    put_signed(s, *q, 5, 1e4, name)?;
                }
                put_point(s, &t.t, "position")?;
                put_signed(s, t.rms, 5, 1e4, "rms")?;
            }
            HandleStatus::Unoccupied | HandleStatus::Disabled | HandleStatus::NotReported => {
                return Err(bad_status())
            }
        }
        let port_status = reading
            .port_status
            .ok_or_else(|| missing(handle, opt, "port status"))?;
        let frame = reading.frame.ok_or_else(|| missing(handle, opt, "frame"))?;
        let _ = write!(s, "{port_status:08X}{frame:08X}");
    } else if reading.status != HandleStatus::NotReported {
        return Err(bad_status());
    }
    if options.contains(ReplyOptions::TOOL_INFO) {
        let info = reading
            .tool_info
            .ok_or_else(|| missing(handle, ReplyOptions::TOOL_INFO, "tool info"))?;
        let _ = write!(s, "{:02X}", info.tool);
        for byte in info.markers {
            let _ = write!(s, "{byte:02X}");
        }
    }
    if options.contains(ReplyOptions::SINGLE_STRAY) {
        let opt = ReplyOptions::SINGLE_STRAY;
        let marker = reading
            .active_marker
            .ok_or_else(|| missing(handle, opt, "active marker"))?;
        let _ = write!(s, "{:02X}", marker.status);
        if ActiveMarker::carries_position(marker.status, options) {
            let p = marker
                .position
                .ok_or_else(|| missing(handle, opt, "active marker position"))?;
            put_point(s, &p, "active marker position")?;
        }
    }
    if options.contains(ReplyOptions::TOOL_MARKERS) {
        let markers = reading
            .tool_markers
            .as_deref()
            .ok_or_else(|| missing(handle, ReplyOptions::TOOL_MARKERS, "tool markers"))?;
        put_markers(s, markers, "tool marker position")?;
    }
    s.push('\n');
    Ok(())
}

fn put_markers(
    s: &mut String,
    markers: &[MarkerPosition],
    field: &'static str,
) -> Result<(), EncodeError> {
    let _ = write!(s, "{:02X}", count_byte(markers.len(), field)?);
    let digits = markers.len().div_ceil(4);
    let mut oov = vec![0u8; digits];
    for (i, marker) in markers.iter().enumerate() {
        if marker.out_of_volume {
            oov[digits - 1 - i / 4] |= 1 << (i % 4);
        }
    }
    for digit in oov {
        let _ = write!(s, "{digit:X}");
    }
    for marker in markers {
        put_point(s, &marker.position, field)?;
    }
    Ok(())
}

fn put_point(s: &mut String, p: &[f32; 3], field: &'static str) -> Result<(), EncodeError> {
    for v in p {
        put_signed(s, *v, 6, 1e2, field)?;
    }
    Ok(())
}

/// Writes `value × scale`, rounded, as a sign and exactly `digits` digits.
fn put_signed(
    s: &mut String,
    value: f32,
    digits: u32,
    scale: f64,
    field: &'static str,
) -> Result<(), EncodeError> {
    let scaled = (f64::from(value) * scale).round();
    let limit = 10f64.powi(digits as i32);
    if !scaled.is_finite() || scaled.abs() >= limit {
        return Err(EncodeError::OutOfRange {
            field,
            value: f64::from(value),
        });
    }
    let sign = if scaled < 0.0 { '-' } else { '+' };
    let _ = write!(
        s,
        "{sign}{:0width$}",
        scaled.abs() as u64,
        width = digits as usize
    );
    Ok(())
}

/// Reads fixed-width fields off a TX reply.
struct Text<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Text<'a> {
    fn remaining(&self) -> usize {
        self.data.len() - self.at
    }

    fn rest(&self) -> String {
        String::from_utf8_lossy(&self.data[self.at..]).into_owned()
    }

    fn peek(&self) -> Option<u8> {
        self.data.get(self.at).copied()
    }

    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], ReplyError> {
        if self.remaining() < n {
            return Err(ReplyError::Truncated {
                what,
                needed: n,
                available: self.remaining(),
            });
        }
        let slice = &self.data[self.at..self.at + n];
        self.at += n;
        Ok(slice)
    }

    fn eat(&mut self, literal: &str) -> bool {
        let found = self.data[self.at..].starts_with(literal.as_bytes());
        if found {
            self.at += literal.len();
        }
        found
    }

    fn lf(&mut self) -> Result<(), ReplyError> {
        if self.eat("\n") {
            Ok(())
        } else {
            Err(unexpected("LF after a handle", &self.rest()))
        }
    }

    fn hex(&mut self, n: usize, field: &'static str) -> Result<u32, ReplyError> {
        parse_hex(self.take(n, field)?, field)
    }

    /// Sign and `digits` decimal digits, divided by `scale`.
    fn signed(
        &mut self,
        digits: usize,
        scale: f64,
        field: &'static str,
    ) -> Result<f32, ReplyError> {
        let raw = self.take(digits + 1, field)?;
        let bad = || ReplyError::BadNumber {
            field,
            text: String::from_utf8_lossy(raw).into_owned(),
        };
        let sign = match raw[0] {
            b'+' => 1.0,
            b'-' => -1.0,
            _ => return Err(bad()),
        };
        if !raw[1..].iter().all(u8::is_ascii_digit) {
            return Err(bad());
        }
        let magnitude = raw[1..]
            .iter()
            .fold(0u64, |acc, &d| acc * 10 + u64::from(d - b'0'));
        Ok((sign * magnitude as f64 / scale) as f32)
    }

    fn point(&mut self, field: &'static str) -> Result<[f32; 3], ReplyError> {
        Ok([
            self.signed(6, 1e2, field)?,
            self.signed(6, 1e2, field)?,
            self.signed(6, 1e2, field)?,
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Log exchange 192 (TX:0001), CRC and CR removed.
    const TX_192: &str = "0201MISSING000000310000024B\n02+05029+04875+04692+05377-008481+014804-210619+00356000000310000024A\n0000";

    #[test]
    fn transform_reply_from_the_log() {
        let reply = parse_tx(TX_192, ReplyOptions::TRANSFORMS).unwrap();
        let missing = reply.handle(1).unwrap();
        assert_eq!(missing.status, HandleStatus::Missing);
        assert_eq!(missing.frame, Some(0x24B));
        let valid = reply.handle(2).unwrap();
        let t = valid.transform.unwrap();
        assert_eq!(t.q, [0.5029, 0.4875, 0.4692, 0.5377]);
        assert_eq!(t.t, [-84.81, 148.04, -2106.19]);
        assert_eq!(t.rms, 0.0356);
        assert_eq!(valid.port_status, Some(0x31));
        assert_eq!(valid.frame, Some(0x24A));
        assert_eq!(reply.frame(), Some(0x24B));
        assert_eq!(encode_tx_text(&reply).unwrap(), TX_192);
    }

    #[test]
    fn malformed_text_is_a_typed_error() {
        let opts = ReplyOptions::TRANSFORMS;
        assert!(matches!(
            parse_tx(&TX_192.replace("+05029", "+0502x"), opts),
            Err(ReplyError::BadNumber { field: "q0", .. })
        ));
        assert!(matches!(
            parse_tx(&TX_192.replace("+05029", "*05029"), opts),
            Err(ReplyError::UnknownEntry { handle: 2, .. })
        ));
        assert!(matches!(
            parse_tx(&TX_192.replace("MISSING", "MISSINX"), opts),
            Err(ReplyError::UnknownEntry { handle: 1, .. })
        ));
        assert!(matches!(
            parse_tx(&TX_192[..60], opts),
            Err(ReplyError::Truncated { .. })
        ));
        assert!(matches!(
            parse_tx(&format!("{TX_192}0"), opts),
            Err(ReplyError::TrailingBytes { .. })
        ));
        assert!(matches!(
            parse_tx(&TX_192.replace("\n02+", "02+"), opts),
            Err(ReplyError::Unexpected { .. })
        ));
        assert!(matches!(
            parse_tx("ERROR0D", opts),
            Err(ReplyError::Device(_))
        ));
    }

    #[test]
    fn a_marker_status_without_position_and_a_disabled_handle() {
        // TX:0005 as firmware Rev 021 answers it: handle 2's single active marker is out of
        // volume (status 05), so no position follows without option 0x0800.
        let text = "0201MISSING000000310000037700\n02+04985+04691+04244+05926-007836+009627-209044+00509000000310000037605\n0000";
        let options = ReplyOptions::TRANSFORMS | ReplyOptions::SINGLE_STRAY;
        let reply = parse_tx(text, options).unwrap();
        let marker = reply.handle(2).unwrap().active_marker.unwrap();
        assert_eq!((marker.status, marker.position), (0x05, None));
        assert_eq!(encode_tx_text(&reply).unwrap(), text);
        // With 0x0800 the same status carries its position.
        let all = options | ReplyOptions::OUT_OF_VOLUME;
        let text = "0101MISSING000000310000037705+012000-000450-250000\n0000";
        let marker = parse_tx(text, all).unwrap().handles[0]
            .active_marker
            .unwrap();
        assert_eq!(marker.position, Some([120.0, -4.5, -2500.0]));
        // TX:1000 with a disabled handle between two reported ones.
        let text = "0301\n02DISABLED\n03\n030+015360+030698-223261+015173+022199-225596+007159+026725-2274150000";
        let reply = parse_tx(text, ReplyOptions::PASSIVE_STRAYS).unwrap();
        let statuses: Vec<_> = reply.handles.iter().map(|h| h.status).collect();
        assert_eq!(
            statuses,
            [
                HandleStatus::NotReported,
                HandleStatus::Disabled,
                HandleStatus::NotReported
            ]
        );
        assert_eq!(reply.stray_markers.as_ref().unwrap().len(), 3);
        assert_eq!(encode_tx_text(&reply).unwrap(), text);
    }

    #[test]
    fn values_outside_the_format_are_refused() {
        let reply = TrackingReply {
            options: ReplyOptions::TRANSFORMS,
            handles: vec![HandleReading {
                transform: Some(Transform {
                    q: [1.0, 0.0, 0.0, 0.0],
                    t: [10_000.0, 0.0, 0.0],
                    rms: 0.1,
                }),
                port_status: Some(0x31),
                frame: Some(1),
                ..HandleReading::bare(1, HandleStatus::Valid)
            }],
            stray_markers: None,
            system_status: 0,
        };
        assert!(matches!(
            encode_tx_text(&reply),
            Err(EncodeError::OutOfRange {
                field: "position",
                ..
            })
        ));
    }
}
