//! BX: the binary tracking reply.
//!
//! Frame: `C4 A5`, body length (u16 LE), CRC of those 4 bytes (u16 LE), body, CRC of the body
//! (u16 LE). Body: handle count (u8); per handle: handle (u8), status (u8: 0x01 valid, 0x02
//! missing, 0x04 disabled) and, unless disabled, the data of each reply option in order —
//! 0x0001: 8 f32 LE (q0 qx qy qz, x y z mm, rms mm) if valid, then port status (u32) and frame
//! number (u32); 0x0002: tool info (u8) + marker info (10 bytes); 0x0004: marker status (u8) and,
//! when [`ActiveMarker::carries_position`], 3 f32 (mm); 0x0008: the tool's markers as a marker
//! list. After the handles, option 0x1000: the stray passive markers as a marker list. Last:
//! system status (u16 LE). A marker list is a count (u8), out-of-volume bits (⌈n/8⌉ bytes, bit j
//! of byte k = marker 8k+j), then 3 f32 per marker (mm); out-of-volume markers are listed only
//! with option 0x0800.

use crate::crc::crc16;
use crate::error::{EncodeError, ReplyError};
use crate::reply::{
    ActiveMarker, HandleReading, HandleStatus, MarkerPosition, ReplyOptions, ToolInfo,
    TrackingReply, Transform,
};

/// The two bytes every BX reply starts with.
pub const BX_START: [u8; 2] = [0xC4, 0xA5];
/// Bytes of the BX header: start, length, header CRC.
pub const BX_HEADER_LEN: usize = 6;
/// Bytes of the body CRC that follows the body.
pub const BX_CRC_LEN: usize = 2;

/// Checks a BX header (start bytes and header CRC) and returns the body length it declares.
pub fn check_header(header: &[u8; BX_HEADER_LEN]) -> Result<usize, ReplyError> {
    if header[..2] != BX_START {
        return Err(crate::text::unexpected(
            "a BX reply (C4 A5)",
            &String::from_utf8_lossy(&header[..2]),
        ));
    }
    let expected = crc16(&header[..4]);
    let actual = u16::from_le_bytes([header[4], header[5]]);
    if expected != actual {
        return Err(ReplyError::BadHeaderCrc { expected, actual });
    }
    Ok(usize::from(u16::from_le_bytes([header[2], header[3]])))
}

/// Parses a complete BX frame (header, body, body CRC) answering a command with `options`.
pub fn parse_bx_frame(frame: &[u8], options: ReplyOptions) -> Result<TrackingReply, ReplyError> {
    let header: &[u8; BX_HEADER_LEN] = frame
        .get(..BX_HEADER_LEN)
        .and_then(|h| h.try_into().ok())
        .ok_or(ReplyError::Truncated {
        what: "BX header",
        needed: BX_HEADER_LEN,
        available: frame.len(),
    })?;
    let body_len = check_header(header)?;
    let total = BX_HEADER_LEN + body_len + BX_CRC_LEN;
    if frame.len() < total {
        return Err(ReplyError::Truncated {
            what: "BX body and CRC",
            needed: total - BX_HEADER_LEN,
            available: frame.len() - BX_HEADER_LEN,
        });
    }
    if frame.len() > total {
        return Err(ReplyError::TrailingBytes {
            what: "BX reply",
            extra: frame.len() - total,
        });
    }
    let body = &frame[BX_HEADER_LEN..BX_HEADER_LEN + body_len];
    check_body_crc(body, [frame[total - 2], frame[total - 1]])?;
    parse_bx_body(body, options)
}

/// Checks the body CRC (`crc` as the two little-endian bytes that follow the body).
pub fn check_body_crc(body: &[u8], crc: [u8; 2]) -> Result<(), ReplyError> {
    let expected = crc16(body);
    let actual = u16::from_le_bytes(crc);
    if expected != actual {
        return Err(ReplyError::BadCrc { expected, actual });
    }
    Ok(())
}

/// Parses a BX body (CRC already checked) answering a command with `options`.
pub fn parse_bx_body(body: &[u8], options: ReplyOptions) -> Result<TrackingReply, ReplyError> {
    let mut b = Cursor { data: body, at: 0 };
    let count = b.u8("handle count")?;
    let mut handles = Vec::with_capacity(usize::from(count));
    for _ in 0..count {
        handles.push(parse_handle(&mut b, options)?);
    }
    let stray_markers = if options.contains(ReplyOptions::PASSIVE_STRAYS) {
        Some(parse_markers(&mut b, 0, "stray marker")?)
    } else {
        None
    };
    let system_status = b.u16("system status")?;
    if b.remaining() > 0 {
        return Err(ReplyError::TrailingBytes {
            what: "BX body",
            extra: b.remaining(),
        });
    }
    Ok(TrackingReply {
        options,
        handles,
        stray_markers,
        system_status,
    })
}

fn parse_handle(b: &mut Cursor<'_>, options: ReplyOptions) -> Result<HandleReading, ReplyError> {
    let handle = b.u8("handle")?;
    let status = match b.u8("handle status")? {
        0x01 => HandleStatus::Valid,
        0x02 => HandleStatus::Missing,
        0x04 => HandleStatus::Disabled,
        status => return Err(ReplyError::UnknownStatus { handle, status }),
    };
    let mut reading = HandleReading::bare(handle, status);
    if status == HandleStatus::Disabled {
        return Ok(reading);
    }
    if options.contains(ReplyOptions::TRANSFORMS) {
        if status == HandleStatus::Valid {
            reading.transform = Some(Transform {
                q: [
                    b.f32(handle, "q0")?,
                    b.f32(handle, "qx")?,
                    b.f32(handle, "qy")?,
                    b.f32(handle, "qz")?,
                ],
                t: b.point(handle, "position")?,
                rms: b.f32(handle, "rms")?,
            });
        }
        reading.port_status = Some(b.u32("port status")?);
        reading.frame = Some(b.u32("frame number")?);
    }
    if options.contains(ReplyOptions::TOOL_INFO) {
        let tool = b.u8("tool information")?;
        let mut markers = [0u8; 10];
        markers.copy_from_slice(b.take(10, "marker information")?);
        reading.tool_info = Some(ToolInfo { tool, markers });
    }
    if options.contains(ReplyOptions::SINGLE_STRAY) {
        let status = b.u8("active marker status")?;
        let position = if ActiveMarker::carries_position(status, options) {
            Some(b.point(handle, "active marker position")?)
        } else {
            None
        };
        reading.active_marker = Some(ActiveMarker { status, position });
    }
    if options.contains(ReplyOptions::TOOL_MARKERS) {
        reading.tool_markers = Some(parse_markers(b, handle, "tool marker")?);
    }
    Ok(reading)
}

/// A marker list: count, out-of-volume bits, positions. `handle` is 0 for stray markers.
fn parse_markers(
    b: &mut Cursor<'_>,
    handle: u8,
    what: &'static str,
) -> Result<Vec<MarkerPosition>, ReplyError> {
    let count = usize::from(b.u8(what)?);
    let oov = b.take(count.div_ceil(8), "out-of-volume bits")?;
    (0..count)
        .map(|i| {
            Ok(MarkerPosition {
                out_of_volume: oov[i / 8] & (1 << (i % 8)) != 0,
                position: b.point(handle, what)?,
            })
        })
        .collect()
}

/// Encodes `reply` as a complete BX frame (header, body, CRCs), laid out by `reply.options`.
///
/// Emits what the options and each status call for; fields they do not call for are ignored.
pub fn encode_bx(reply: &TrackingReply) -> Result<Vec<u8>, EncodeError> {
    let options = reply.options;
    let mut body = Vec::with_capacity(16 + reply.handles.len() * 48);
    body.push(count_byte(reply.handles.len(), "handles")?);
    for reading in &reply.handles {
        encode_handle(&mut body, reading, options)?;
    }
    if options.contains(ReplyOptions::PASSIVE_STRAYS) {
        let strays = reply
            .stray_markers
            .as_deref()
            .ok_or_else(|| missing(0, ReplyOptions::PASSIVE_STRAYS, "stray markers"))?;
        encode_markers(&mut body, strays, "stray markers")?;
    }
    body.extend_from_slice(&reply.system_status.to_le_bytes());
    let len = u16::try_from(body.len()).map_err(|_| EncodeError::TooLong(body.len()))?;
    let mut frame = Vec::with_capacity(BX_HEADER_LEN + body.len() + BX_CRC_LEN);
    frame.extend_from_slice(&BX_START);
    frame.extend_from_slice(&len.to_le_bytes());
    let header_crc = crc16(&frame);
    frame.extend_from_slice(&header_crc.to_le_bytes());
    frame.extend_from_slice(&body);
    frame.extend_from_slice(&crc16(&body).to_le_bytes());
    Ok(frame)
}

fn encode_handle(
    body: &mut Vec<u8>,
    reading: &HandleReading,
    options: ReplyOptions,
) -> Result<(), EncodeError> {
    let handle = reading.handle;
    let status = match reading.status {
        HandleStatus::Valid => 0x01,
        HandleStatus::Missing => 0x02,
        HandleStatus::Disabled => 0x04,
        other => {
            return Err(EncodeError::BadStatus {
                handle,
                status: other.name(),
                format: "BX",
            })
        }
    };
    body.extend_from_slice(&[handle, status]);
    if reading.status == HandleStatus::Disabled {
        return Ok(());
    }
    if options.contains(ReplyOptions::TRANSFORMS) {
        let opt = ReplyOptions::TRANSFORMS;
        if reading.status == HandleStatus::Valid {
            let t = reading
                .transform
                .ok_or_else(|| missing(handle, opt, "transform"))?;
            put_f32s(body, &t.q);
            put_f32s(body, &t.t);
            put_f32s(body, &[t.rms]);
        }
        let port_status = reading
            .port_status
            .ok_or_else(|| missing(handle, opt, "port status"))?;
        let frame = reading.frame.ok_or_else(|| missing(handle, opt, "frame"))?;
        body.extend_from_slice(&port_status.to_le_bytes());
        body.extend_from_slice(&frame.to_le_bytes());
    }
    if options.contains(ReplyOptions::TOOL_INFO) {
        let info = reading
            .tool_info
            .ok_or_else(|| missing(handle, ReplyOptions::TOOL_INFO, "tool info"))?;
        body.push(info.tool);
        body.extend_from_slice(&info.markers);
    }
    if options.contains(ReplyOptions::SINGLE_STRAY) {
        let opt = ReplyOptions::SINGLE_STRAY;
        let marker = reading
            .active_marker
            .ok_or_else(|| missing(handle, opt, "active marker"))?;
        body.push(marker.status);
        if ActiveMarker::carries_position(marker.status, options) {
            let p = marker
                .position
                .ok_or_else(|| missing(handle, opt, "active marker position"))?;
            put_f32s(body, &p);
        }
    }
    if options.contains(ReplyOptions::TOOL_MARKERS) {
        let markers = reading
            .tool_markers
            .as_deref()
            .ok_or_else(|| missing(handle, ReplyOptions::TOOL_MARKERS, "tool markers"))?;
        encode_markers(body, markers, "tool markers")?;
    }
    Ok(())
}

fn encode_markers(
    body: &mut Vec<u8>,
    markers: &[MarkerPosition],
    what: &'static str,
) -> Result<(), EncodeError> {
    body.push(count_byte(markers.len(), what)?);
    let mut oov = vec![0u8; markers.len().div_ceil(8)];
    for (i, marker) in markers.iter().enumerate() {
        if marker.out_of_volume {
            oov[i / 8] |= 1 << (i % 8);
        }
    }
    body.extend_from_slice(&oov);
    for marker in markers {
        put_f32s(body, &marker.position);
    }
    Ok(())
}

pub(crate) fn missing(handle: u8, option: ReplyOptions, field: &'static str) -> EncodeError {
    EncodeError::MissingField {
        handle,
        option: option.bits(),
        field,
    }
}

pub(crate) fn count_byte(count: usize, what: &'static str) -> Result<u8, EncodeError> {
    u8::try_from(count).map_err(|_| EncodeError::TooMany { what, count })
}

fn put_f32s(out: &mut Vec<u8>, values: &[f32]) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// Reads little-endian fields off a byte slice, every shortfall a [`ReplyError::Truncated`].
struct Cursor<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn remaining(&self) -> usize {
        self.data.len() - self.at
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

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], ReplyError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N, what)?);
        Ok(out)
    }

    fn u8(&mut self, what: &'static str) -> Result<u8, ReplyError> {
        Ok(self.array::<1>(what)?[0])
    }

    fn u16(&mut self, what: &'static str) -> Result<u16, ReplyError> {
        self.array(what).map(u16::from_le_bytes)
    }

    fn u32(&mut self, what: &'static str) -> Result<u32, ReplyError> {
        self.array(what).map(u32::from_le_bytes)
    }

    fn f32(&mut self, handle: u8, field: &'static str) -> Result<f32, ReplyError> {
        let value = f32::from_le_bytes(self.array(field)?);
        if !value.is_finite() {
            return Err(ReplyError::NonFinite {
                handle,
                field,
                value,
            });
        }
        Ok(value)
    }

    fn point(&mut self, handle: u8, field: &'static str) -> Result<[f32; 3], ReplyError> {
        Ok([
            self.f32(handle, field)?,
            self.f32(handle, field)?,
            self.f32(handle, field)?,
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Log exchange 41 (BX:0001): both handles missing, frame 0.
    const BX_41: [u8; 33] = [
        0xC4, 0xA5, 0x17, 0x00, 0x22, 0xE3, 0x02, 0x01, 0x02, 0x31, 0x00, 0x00, 0x00, 0x00, 0x00,
        0x00, 0x00, 0x02, 0x02, 0x31, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xB1,
        0x37, 0, 0,
    ];

    #[test]
    fn both_missing_reply_from_the_log() {
        let frame = &BX_41[..31];
        let reply = parse_bx_frame(frame, ReplyOptions::TRANSFORMS).unwrap();
        assert_eq!(reply.handles.len(), 2);
        for (reading, handle) in reply.handles.iter().zip([1, 2]) {
            assert_eq!(reading.handle, handle);
            assert_eq!(reading.status, HandleStatus::Missing);
            assert_eq!(reading.transform, None);
            assert_eq!(reading.port_status, Some(0x31));
            assert_eq!(reading.frame, Some(0));
        }
        assert_eq!(reply.system_status, 0);
        assert_eq!(encode_bx(&reply).unwrap(), frame);
    }

    #[test]
    fn malformed_frames_are_typed_errors() {
        let frame = &BX_41[..31];
        assert!(matches!(
            parse_bx_frame(&frame[..30], ReplyOptions::TRANSFORMS),
            Err(ReplyError::Truncated { .. })
        ));
        assert!(matches!(
            parse_bx_frame(&BX_41, ReplyOptions::TRANSFORMS),
            Err(ReplyError::TrailingBytes { .. })
        ));
        let mut bad = frame.to_vec();
        bad[8] = 0x03; // status of handle 1
        assert!(matches!(
            parse_bx_frame(&bad, ReplyOptions::TRANSFORMS),
            Err(ReplyError::BadCrc { .. })
        ));
        let body = &frame[6..29];
        let mut body = body.to_vec();
        body[2] = 0x03;
        assert_eq!(
            parse_bx_body(&body, ReplyOptions::TRANSFORMS),
            Err(ReplyError::UnknownStatus {
                handle: 1,
                status: 3
            })
        );
        let mut header = frame.to_vec();
        header[2] = 0x18;
        assert!(matches!(
            parse_bx_frame(&header, ReplyOptions::TRANSFORMS),
            Err(ReplyError::BadHeaderCrc { .. })
        ));
        // Parsed with the wrong options, the same body does not add up.
        assert!(parse_bx_frame(frame, ReplyOptions::TRANSFORMS | ReplyOptions::TOOL_INFO).is_err());
    }

    #[test]
    fn non_finite_floats_are_rejected() {
        let reply = TrackingReply {
            options: ReplyOptions::TRANSFORMS,
            handles: vec![HandleReading {
                transform: Some(Transform {
                    q: [1.0, 0.0, 0.0, 0.0],
                    t: [f32::NAN, 0.0, 0.0],
                    rms: 0.1,
                }),
                port_status: Some(0x31),
                frame: Some(7),
                ..HandleReading::bare(1, HandleStatus::Valid)
            }],
            stray_markers: None,
            system_status: 0,
        };
        let frame = encode_bx(&reply).unwrap();
        assert!(matches!(
            parse_bx_frame(&frame, ReplyOptions::TRANSFORMS),
            Err(ReplyError::NonFinite {
                handle: 1,
                field: "position",
                ..
            })
        ));
    }

    #[test]
    fn encoding_needs_the_fields_the_options_call_for() {
        let reply = TrackingReply {
            options: ReplyOptions::TRANSFORMS,
            handles: vec![HandleReading::bare(1, HandleStatus::Valid)],
            stray_markers: None,
            system_status: 0,
        };
        assert!(matches!(
            encode_bx(&reply),
            Err(EncodeError::MissingField {
                field: "transform",
                ..
            })
        ));
        let reply = TrackingReply {
            handles: vec![HandleReading::bare(1, HandleStatus::NotReported)],
            ..reply
        };
        assert!(matches!(
            encode_bx(&reply),
            Err(EncodeError::BadStatus { .. })
        ));
    }
}
