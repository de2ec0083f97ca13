//! Splitting the device's byte stream into replies.
//!
//! Two framings share the wire: ASCII replies (printable text and LF, 4 upper-case hex digits of
//! CRC, CR) and binary BX replies (`C4 A5`, length, header CRC, body, body CRC). A `C4 A5` pair
//! always starts a binary reply (it cannot occur in ASCII text); bytes before it that end no
//! ASCII reply are garbage. After a bad binary header the framer skips one byte and looks again,
//! so it resynchronises on the next reply. Every rejected reply or stretch of garbage is
//! returned as an error and counted.

use crate::bx::{check_body_crc, check_header, BX_CRC_LEN, BX_HEADER_LEN, BX_START};
use crate::error::ReplyError;
use crate::text::{check_text_reply, unexpected};
use std::io::{self, Read};
use thiserror::Error;

/// Longest ASCII reply accepted (a TX reply with many handles and strays stays far below).
pub const MAX_TEXT_REPLY: usize = 8192;

/// One complete reply whose CRC checked out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RawReply {
    /// An ASCII reply without its CRC and CR (may contain LF).
    Text(String),
    /// The body of a binary (BX) reply, without header and CRC.
    Binary(Vec<u8>),
}

impl RawReply {
    /// The text of an ASCII reply; a binary reply is [`ReplyError::Unexpected`].
    pub fn into_text(self) -> Result<String, ReplyError> {
        match self {
            RawReply::Text(text) => Ok(text),
            RawReply::Binary(body) => Err(unexpected(
                "an ASCII reply",
                &format!("binary reply of {} bytes", body.len()),
            )),
        }
    }
}

/// Counters of what a framer has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FramerStats {
    /// Replies that checked out.
    pub replies: u64,
    /// Rejected replies and stretches of garbage (each returned as an error).
    pub bad_replies: u64,
    /// Bytes discarded while rejecting or resynchronising.
    pub discarded_bytes: u64,
}

/// A push-based framer: feed it bytes with [`push`](Self::push), take replies with
/// [`next_reply`](Self::next_reply). It does no I/O, so the driver can put deadlines around it.
#[derive(Debug, Default)]
pub struct ReplyFramer {
    buf: Vec<u8>,
    stats: FramerStats,
}

impl ReplyFramer {
    /// An empty framer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// Bytes received but not yet part of a complete reply.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// What the framer has counted so far.
    pub fn stats(&self) -> FramerStats {
        self.stats
    }

    /// Drops pending bytes (after a time-out, or before a new command); a non-empty drop counts
    /// as one bad reply and is returned as [`ReplyError::Incomplete`].
    pub fn discard_pending(&mut self) -> Option<ReplyError> {
        if self.buf.is_empty() {
            return None;
        }
        let pending = self.buf.len();
        Some(self.reject(pending, ReplyError::Incomplete { pending }))
    }

    /// The next complete reply, an error for a rejected one, or `None` if more bytes are needed.
    pub fn next_reply(&mut self) -> Option<Result<RawReply, ReplyError>> {
        if self.buf.is_empty() {
            return None;
        }
        if self.buf.starts_with(&BX_START) {
            return self.next_binary();
        }
        self.next_text()
    }

    fn next_binary(&mut self) -> Option<Result<RawReply, ReplyError>> {
        let header: &[u8; BX_HEADER_LEN] = self.buf.get(..BX_HEADER_LEN)?.try_into().ok()?;
        let body_len = match check_header(header) {
            Ok(len) => len,
            // Skip the C4 and look for the next reply start.
            Err(error) => return Some(Err(self.reject(1, error))),
        };
        let total = BX_HEADER_LEN + body_len + BX_CRC_LEN;
        if self.buf.len() < total {
            return None;
        }
        let body = &self.buf[BX_HEADER_LEN..BX_HEADER_LEN + body_len];
        let result = check_body_crc(body, [self.buf[total - 2], self.buf[total - 1]]);
        Some(match result {
            Ok(()) => {
                let body = body.to_vec();
                self.accept(total);
                Ok(RawReply::Binary(body))
            }
            Err(error) => Err(self.reject(total, error)),
        })
    }

    fn next_text(&mut self) -> Option<Result<RawReply, ReplyError>> {
        for (i, &byte) in self.buf.iter().enumerate() {
            if byte == b'\r' {
                let result = check_text_reply(&self.buf[..i]);
                return Some(match result {
                    Ok(text) => {
                        self.accept(i + 1);
                        Ok(RawReply::Text(text))
                    }
                    Err(error) => Err(self.reject(i + 1, error)),
                });
            }
            if byte == BX_START[0] && i > 0 {
                match self.buf.get(i + 1) {
                    Some(&next) if next == BX_START[1] => {
                        return Some(Err(self.reject(i, ReplyError::Garbage { len: i })));
                    }
                    Some(_) => {}
                    // Possibly the start of a binary reply: wait for the next byte.
                    None => return None,
                }
            }
        }
        if self.buf.len() > MAX_TEXT_REPLY {
            let len = self.buf.len();
            return Some(Err(self.reject(len, ReplyError::TooLong { len })));
        }
        None
    }

    fn accept(&mut self, len: usize) {
        self.buf.drain(..len);
        self.stats.replies += 1;
    }

    fn reject(&mut self, len: usize, error: ReplyError) -> ReplyError {
        self.buf.drain(..len);
        self.stats.bad_replies += 1;
        self.stats.discarded_bytes += len as u64;
        error
    }
}

/// Decodes `bytes` as exactly one complete reply (nothing missing, nothing left over).
pub fn decode_reply(bytes: &[u8]) -> Result<RawReply, ReplyError> {
    let mut framer = ReplyFramer::new();
    framer.push(bytes);
    let reply = match framer.next_reply() {
        Some(result) => result?,
        None => {
            return Err(ReplyError::Incomplete {
                pending: bytes.len(),
            })
        }
    };
    if framer.pending() > 0 {
        return Err(ReplyError::TrailingBytes {
            what: "reply",
            extra: framer.pending(),
        });
    }
    Ok(reply)
}

/// Why [`ReplyReader::read_reply`] returned no reply.
#[derive(Debug, Error)]
pub enum ReadError {
    /// A reply (or garbage) was rejected; reading can go on.
    #[error(transparent)]
    Reply(#[from] ReplyError),
    /// The underlying reader failed (a time-out shows up here as `TimedOut`/`WouldBlock`).
    #[error("reading the reply stream: {0}")]
    Io(#[from] io::Error),
    /// The stream ended cleanly, between replies.
    #[error("end of the reply stream")]
    Eof,
}

/// Reads replies one at a time from any [`Read`] (a serial port, a file, a recorded stream).
#[derive(Debug)]
pub struct ReplyReader<R> {
    inner: R,
    framer: ReplyFramer,
    chunk: Vec<u8>,
}

impl<R: Read> ReplyReader<R> {
    /// A reader over `inner`.
    pub fn new(inner: R) -> Self {
        ReplyReader {
            inner,
            framer: ReplyFramer::new(),
            chunk: vec![0; 4096],
        }
    }

    /// The next reply. Errors for rejected replies leave the reader usable; at the end of the
    /// stream a partial reply is reported once as [`ReplyError::Incomplete`], then
    /// [`ReadError::Eof`].
    pub fn read_reply(&mut self) -> Result<RawReply, ReadError> {
        loop {
            if let Some(result) = self.framer.next_reply() {
                return result.map_err(ReadError::Reply);
            }
            let n = match self.inner.read(&mut self.chunk) {
                Ok(n) => n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(ReadError::Io(e)),
            };
            if n == 0 {
                return Err(match self.framer.discard_pending() {
                    Some(error) => ReadError::Reply(error),
                    None => ReadError::Eof,
                });
            }
            self.framer.push(&self.chunk[..n]);
        }
    }

    /// Replies and rejections counted so far.
    pub fn stats(&self) -> FramerStats {
        self.framer.stats()
    }

    /// The underlying reader.
    pub fn get_mut(&mut self) -> &mut R {
        &mut self.inner
    }
}

impl<R: Read> Iterator for ReplyReader<R> {
    type Item = Result<RawReply, ReadError>;

    /// Every reply or error until the end of the stream (`None`).
    fn next(&mut self) -> Option<Self::Item> {
        match self.read_reply() {
            Err(ReadError::Eof) => None,
            other => Some(other),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::text::encode_text_reply;

    fn bx_frame() -> Vec<u8> {
        vec![
            0xC4, 0xA5, 0x17, 0x00, 0x22, 0xE3, 0x02, 0x01, 0x02, 0x31, 0x00, 0x00, 0x00, 0x00,
            0x00, 0x00, 0x00, 0x02, 0x02, 0x31, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
            0x00, 0xB1, 0x37,
        ]
    }

    #[test]
    fn mixed_stream_with_garbage_resynchronises() {
        let mut stream = Vec::new();
        stream.extend(encode_text_reply("OKAY"));
        stream.extend(b"\x00\xFFnoise");
        stream.extend(bx_frame());
        stream.extend(b"junk\r");
        stream.extend(encode_text_reply("RESET"));
        let mut bad_header = bx_frame();
        bad_header[3] = 0x01;
        stream.extend(bad_header);
        // The rest of the bad frame runs into this reply, which is lost with it ...
        stream.extend(encode_text_reply("OKAY"));
        // ... and the framer is back in step for the next ones.
        stream.extend(bx_frame());
        stream.extend(encode_text_reply("RESET"));

        let results: Vec<_> = ReplyReader::new(&stream[..]).collect();
        let good: Vec<_> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
        assert_eq!(good.len(), 5, "{results:?}");
        assert_eq!(good[0], &RawReply::Text("OKAY".into()));
        assert!(matches!(good[1], RawReply::Binary(body) if body.len() == 0x17));
        assert_eq!(good[2], &RawReply::Text("RESET".into()));
        assert_eq!(good[3], good[1]);
        assert_eq!(good[4], good[2]);
        assert!(matches!(
            results[1],
            Err(ReadError::Reply(ReplyError::Garbage { len: 7 }))
        ));
        assert!(matches!(
            results[3],
            Err(ReadError::Reply(ReplyError::BadHex { .. }))
        ));
        assert!(matches!(
            results[5],
            Err(ReadError::Reply(ReplyError::BadHeaderCrc { .. }))
        ));
        let bad = results.iter().filter(|r| r.is_err()).count();
        let mut reader = ReplyReader::new(&stream[..]);
        while !matches!(reader.read_reply(), Err(ReadError::Eof)) {}
        assert_eq!(reader.stats().replies, 5);
        assert_eq!(reader.stats().bad_replies, bad as u64);
    }

    #[test]
    fn replies_split_across_reads_are_reassembled() {
        let mut stream = bx_frame();
        stream.extend(encode_text_reply("OKAY"));
        let mut framer = ReplyFramer::new();
        let mut replies = Vec::new();
        for byte in &stream {
            framer.push(std::slice::from_ref(byte));
            if let Some(result) = framer.next_reply() {
                replies.push(result.unwrap());
            }
        }
        assert_eq!(replies.len(), 2);
        assert_eq!(framer.pending(), 0);
    }

    #[test]
    fn truncated_stream_is_reported_once() {
        let frame = bx_frame();
        let mut reader = ReplyReader::new(&frame[..20]);
        assert!(matches!(
            reader.read_reply(),
            Err(ReadError::Reply(ReplyError::Incomplete { pending: 20 }))
        ));
        assert!(matches!(reader.read_reply(), Err(ReadError::Eof)));
    }

    #[test]
    fn decode_reply_wants_exactly_one_reply() {
        assert_eq!(
            decode_reply(b"OKAYA896\r").unwrap(),
            RawReply::Text("OKAY".into())
        );
        assert!(matches!(
            decode_reply(b"OKAYA896"),
            Err(ReplyError::Incomplete { .. })
        ));
        assert!(matches!(
            decode_reply(b"OKAYA896\rX"),
            Err(ReplyError::TrailingBytes { .. })
        ));
        let long = vec![b'A'; MAX_TEXT_REPLY + 1];
        assert!(matches!(
            decode_reply(&long),
            Err(ReplyError::TooLong { .. })
        ));
    }
}
