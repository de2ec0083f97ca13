//! Test helpers: the real Polaris log and the hand-picked replies, both in `tests/fixtures/`.
#![allow(dead_code)]

/// One command and the device's reply to it, as recorded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Exchange {
    /// Sequence number in the log.
    pub seq: u32,
    /// Command bytes including the CR (empty for unsolicited replies).
    pub command: Vec<u8>,
    /// Reply bytes (all reads of the exchange, concatenated).
    pub reply: Vec<u8>,
}

impl Exchange {
    /// The command text without its CR.
    pub fn command_text(&self) -> &str {
        std::str::from_utf8(&self.command)
            .unwrap()
            .trim_end_matches('\r')
    }
}

/// The real log's `.bin` form, kept in `tests/fixtures/` (BSD licence, IGSTK).
pub const LOG_BIN: &[u8] =
    include_bytes!("../fixtures/polaris_stream_08_31_2005_NDICommandInterpreter.bin");

/// The real log's `.txt` form (non-printable bytes escaped, so ASCII).
pub const LOG_TXT: &str =
    include_str!("../fixtures/polaris_stream_08_31_2005_NDICommandInterpreter.txt");

/// Every exchange of the real log, read from its `.bin` form.
pub fn log_exchanges() -> Vec<Exchange> {
    parse_bin(LOG_BIN).unwrap_or_else(|e| panic!("the .bin fixture: {e}"))
}

/// Records of the `.bin` form: `N. command[len] ` or `N. receive[len] `, `len` raw bytes, LF;
/// lines starting with `#` and blank CR/LF between records are skipped.
pub fn parse_bin(data: &[u8]) -> Result<Vec<Exchange>, String> {
    let mut records = Vec::new();
    let mut i = 0;
    while i < data.len() {
        match data[i] {
            b'#' => {
                let end = data[i..]
                    .iter()
                    .position(|&b| b == b'\n')
                    .ok_or("unterminated comment")?;
                i += end + 1;
            }
            b'\r' | b'\n' => i += 1,
            _ => {
                let header_end = data[i..]
                    .iter()
                    .position(|&b| b == b']')
                    .ok_or_else(|| format!("offset {i}: no ']'"))?;
                let header = std::str::from_utf8(&data[i..i + header_end])
                    .map_err(|_| format!("offset {i}: header not UTF-8"))?;
                let (seq, kind, len) = parse_record_header(header)
                    .ok_or_else(|| format!("offset {i}: bad header {header:?}"))?;
                let start = i + header_end + 2; // "] "
                let end = start + len;
                if data.get(end) != Some(&b'\n') {
                    return Err(format!(
                        "offset {i}: record of {len} bytes not followed by LF"
                    ));
                }
                records.push((seq, kind, data[start..end].to_vec()));
                i = end + 1;
            }
        }
    }
    Ok(group(records))
}

/// `N. kind[len` → (N, kind, len).
fn parse_record_header(header: &str) -> Option<(u32, String, usize)> {
    let (seq, rest) = header.split_once(". ")?;
    let (kind, len) = rest.split_once('[')?;
    Some((seq.parse().ok()?, kind.to_owned(), len.parse().ok()?))
}

/// The `.txt` form: `TIME  :    (LEVEL) N. kind[len] TEXT` with `\xNN` and `\\` escapes.
pub fn parse_txt(text: &str) -> Result<Vec<Exchange>, String> {
    let mut records = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let Some((_, rest)) = line.split_once(") ") else {
            return Err(format!("line {}: no level", n + 1));
        };
        if rest.starts_with('#') {
            continue;
        }
        let (header, escaped) = rest
            .split_once("] ")
            .ok_or(format!("line {}: no ']'", n + 1))?;
        let (seq, kind, len) =
            parse_record_header(header).ok_or(format!("line {}: bad header", n + 1))?;
        let bytes = unescape(escaped).ok_or(format!("line {}: bad escape", n + 1))?;
        if bytes.len() != len {
            return Err(format!(
                "line {}: {} bytes, header says {len}",
                n + 1,
                bytes.len()
            ));
        }
        records.push((seq, kind, bytes));
    }
    Ok(group(records))
}

fn unescape(text: &str) -> Option<Vec<u8>> {
    let b = text.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'\\' {
            match b.get(i + 1)? {
                b'\\' => {
                    out.push(b'\\');
                    i += 2;
                }
                b'x' => {
                    let hex = std::str::from_utf8(b.get(i + 2..i + 4)?).ok()?;
                    out.push(u8::from_str_radix(hex, 16).ok()?);
                    i += 4;
                }
                _ => return None,
            }
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    Some(out)
}

fn group(records: Vec<(u32, String, Vec<u8>)>) -> Vec<Exchange> {
    let mut exchanges: Vec<Exchange> = Vec::new();
    for (seq, kind, bytes) in records {
        if exchanges.last().is_none_or(|e| e.seq != seq) {
            exchanges.push(Exchange {
                seq,
                command: Vec::new(),
                reply: Vec::new(),
            });
        }
        let exchange = exchanges.last_mut().unwrap();
        match kind.as_str() {
            "command" => exchange.command.extend(bytes),
            "receive" => exchange.reply.extend(bytes),
            other => panic!("unknown record kind {other:?}"),
        }
    }
    exchanges
}

/// The representative exchanges kept in `tests/fixtures/polaris_replies.txt`.
pub fn fixtures() -> Vec<Exchange> {
    let text = include_str!("../fixtures/polaris_replies.txt");
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
        .map(|line| {
            let fields: Vec<&str> = line.split(' ').collect();
            let [seq, command, hex] = fields[..] else {
                panic!("fixture line {line:?}: expected 3 fields");
            };
            let reply = (0..hex.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
                .collect();
            let command = match command {
                "-" => Vec::new(),
                c => format!("{c}\r").into_bytes(),
            };
            Exchange {
                seq: seq.parse().unwrap(),
                command,
                reply,
            }
        })
        .collect()
}
