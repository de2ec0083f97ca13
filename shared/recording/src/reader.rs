//! Streaming readers: one row at a time through a fixed-size buffer, so reading a long
//! `encoders.csv` takes memory that does not grow with the file. They check the header when
//! opened, then yield parsed, checked rows.

use std::fs::File;
use std::io::{self, Read};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use csv::ByteRecord;

use crate::encoders::EncodersCsv;
use crate::error::{DroppedTail, Problem, RecordingError};
use crate::format::{CsvFormat, Fields};
use crate::phases::PhasesCsv;
use crate::tracker::TrackerCsv;

/// Read buffer size: large enough that reading is not dominated by system calls.
const BUFFER_BYTES: usize = 1 << 16;

/// How strictly to read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Accept a file whose final line has no line terminator (cut off mid-write, e.g. by
    /// SIGKILL): that line is dropped and reported by [`RowReader::dropped_tail`] instead of
    /// being an error [`RecordingError::TruncatedTail`]. Every complete row before it is read
    /// and checked as usual.
    pub allow_truncated_tail: bool,
}

/// Streams the rows of one CSV file of format `F` from `R`. Yields `Ok(row)` per row, or one
/// `Err` naming the file, line and reason, after which it yields nothing more.
pub struct RowReader<F: CsvFormat, R: Read = File> {
    path: PathBuf,
    reader: csv::Reader<InputTap<R>>,
    record: ByteRecord,
    state: F::State,
    options: ReadOptions,
    dropped: Option<DroppedTail>,
    finished: bool,
    /// The format's columns the header has (the current ones or an earlier version's).
    columns: &'static [&'static str],
    format: PhantomData<F>,
}

/// Streams `encoders.csv` rows ([`crate::EncoderRow`]).
pub type EncoderReader<R = File> = RowReader<EncodersCsv, R>;
/// Streams `tracker.csv` rows ([`crate::TrackerRow`]).
pub type TrackerReader<R = File> = RowReader<TrackerCsv, R>;
/// Streams `phases.csv` rows ([`crate::PhaseRow`]).
pub type PhaseReader<R = File> = RowReader<PhasesCsv, R>;

impl<F: CsvFormat> RowReader<F, File> {
    /// Opens `path` strictly and checks its header.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, RecordingError> {
        Self::open_with(path, ReadOptions::default())
    }

    /// Opens `path` with `options` and checks its header.
    pub fn open_with(path: impl AsRef<Path>, options: ReadOptions) -> Result<Self, RecordingError> {
        let path = path.as_ref();
        let file =
            File::open(path).map_err(|e| RecordingError::open(path.to_path_buf(), "open", e))?;
        Self::from_reader(file, path, options)
    }
}

impl<F: CsvFormat, R: Read> RowReader<F, R> {
    /// Reads from `input`, naming it `path` in errors, and checks the header.
    pub fn from_reader(
        input: R,
        path: impl Into<PathBuf>,
        options: ReadOptions,
    ) -> Result<Self, RecordingError> {
        let reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .buffer_capacity(BUFFER_BYTES)
            .from_reader(InputTap::new(input));
        let mut this = RowReader {
            path: path.into(),
            reader,
            record: ByteRecord::new(),
            state: F::State::default(),
            options,
            dropped: None,
            finished: false,
            columns: F::COLUMNS,
            format: PhantomData,
        };
        this.read_header()?;
        Ok(this)
    }

    /// The file being read (as named in errors).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The truncated final line a lenient read dropped, once the reader has reached it.
    pub fn dropped_tail(&self) -> Option<&DroppedTail> {
        self.dropped.as_ref()
    }

    fn read_header(&mut self) -> Result<(), RecordingError> {
        let expected = F::header();
        let Some(span) = self.read_record()? else {
            self.finished = true;
            return if self.options.allow_truncated_tail {
                self.drop_tail(1, String::new());
                Ok(())
            } else {
                Err(self.malformed(1, Problem::EmptyFile { expected }))
            };
        };
        if !(span.unterminated && expected.starts_with(&span.text)) {
            self.columns = self.check_header(span.line, expected, &span.text)?;
        }
        if span.unterminated {
            self.finished = true;
            self.truncated_tail(span)?;
        }
        Ok(())
    }

    /// The format's columns the header in `self.record` starts with: the current ones, else
    /// the first earlier version's that fit; if none fit, the error is about the current ones.
    fn check_header(
        &self,
        line: u64,
        expected: String,
        found: &str,
    ) -> Result<&'static [&'static str], RecordingError> {
        let problem = match self.header_problem(F::COLUMNS, expected, found) {
            None => return Ok(F::COLUMNS),
            Some(problem) => problem,
        };
        F::EARLIER_COLUMNS
            .iter()
            .find(|columns| self.header_problem(columns, String::new(), found).is_none())
            .copied()
            .ok_or_else(|| self.malformed(line, problem))
    }

    /// What keeps the header in `self.record` from starting with `columns`, if anything.
    fn header_problem(
        &self,
        columns: &'static [&'static str],
        expected: String,
        found: &str,
    ) -> Option<Problem> {
        for (index, &column) in columns.iter().enumerate() {
            match self.record.get(index) {
                None => {
                    let found = self.record.len();
                    return Some(Problem::MissingColumn { column, found });
                }
                Some(field) if field != column.as_bytes() => {
                    let found = found.to_owned();
                    return Some(Problem::WrongHeader { expected, found });
                }
                Some(_) => {}
            }
        }
        None
    }

    /// Reads the next record into `self.record`; `None` at the end of the input.
    fn read_record(&mut self) -> Result<Option<RecordSpan>, RecordingError> {
        let more = self
            .reader
            .read_byte_record(&mut self.record)
            .map_err(|e| RecordingError::csv(self.path.clone(), "read", e))?;
        if !more {
            return Ok(None);
        }
        let end = self.reader.position().byte();
        Ok(Some(self.reader.get_mut().record_ending_at(end)))
    }

    /// A final line cut off mid-write: an error, or dropped if the options allow it.
    fn truncated_tail(&mut self, span: RecordSpan) -> Result<(), RecordingError> {
        if self.options.allow_truncated_tail {
            self.drop_tail(span.line, span.text);
            Ok(())
        } else {
            Err(RecordingError::TruncatedTail {
                path: self.path.clone(),
                line: span.line,
                text: span.text,
            })
        }
    }

    fn drop_tail(&mut self, line: u64, text: String) {
        self.dropped = Some(DroppedTail {
            path: self.path.clone(),
            line,
            text,
        });
    }

    fn malformed(&self, line: u64, problem: Problem) -> RecordingError {
        RecordingError::Malformed {
            path: self.path.clone(),
            line,
            problem,
        }
    }

    fn next_row(&mut self) -> Option<Result<F::Row, RecordingError>> {
        let span = match self.read_record() {
            Err(error) => return Some(Err(error)),
            Ok(None) => return None,
            Ok(Some(span)) => span,
        };
        if span.unterminated {
            return self.truncated_tail(span).err().map(Err);
        }
        let fields = Fields::new(&self.path, span.line, &self.record, self.columns);
        let row = F::parse(&fields).and_then(|row| match F::check(&row, &mut self.state) {
            Ok(()) => Ok(row),
            Err(problem) => Err(fields.error(problem)),
        });
        Some(row)
    }
}

impl<F: CsvFormat, R: Read> Iterator for RowReader<F, R> {
    type Item = Result<F::Row, RecordingError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.finished {
            return None;
        }
        let item = self.next_row();
        self.finished = !matches!(item, Some(Ok(_)));
        item
    }
}

/// Passes reads through and keeps the bytes the CSV parser has not yet accounted for, so
/// that line numbers count every line (the `csv` crate's skip blank lines and CRLF
/// terminators) and a final line cut off mid-write (no terminator) can be told apart.
struct InputTap<R> {
    inner: R,
    /// Bytes read from `inner` and not yet accounted for start at `pending[cursor]`.
    pending: Vec<u8>,
    cursor: usize,
    /// Bytes accounted for: every record up to here has been given its line.
    accounted: u64,
    /// Newlines (`\n`) among the accounted bytes.
    newlines: u64,
    /// Bytes read from `inner`.
    bytes_read: u64,
    /// `inner` reported its end.
    ended: bool,
}

/// Accounted bytes kept in `InputTap::pending` before they are dropped.
const COMPACT_BYTES: usize = 1 << 16;

/// What the tap knows about the record that ended at a given offset.
struct RecordSpan {
    /// 1-based line of the record's first byte.
    line: u64,
    /// The record's text as read, without blank lines before it.
    text: String,
    /// The input ended right after the record, without a line terminator.
    unterminated: bool,
}

impl<R> InputTap<R> {
    fn new(inner: R) -> Self {
        InputTap {
            inner,
            pending: Vec::new(),
            cursor: 0,
            accounted: 0,
            newlines: 0,
            bytes_read: 0,
            ended: false,
        }
    }

    /// Accounts for the bytes up to offset `end`, where the record just parsed ends (after
    /// its terminator, if it had one).
    fn record_ending_at(&mut self, end: u64) -> RecordSpan {
        let length = usize::try_from(end - self.accounted).expect("a record fits in memory");
        let bytes = &self.pending[self.cursor..self.cursor + length];
        let blank = bytes
            .iter()
            .take_while(|&&byte| byte == b'\n' || byte == b'\r')
            .count();
        let newlines_in = |bytes: &[u8]| bytes.iter().filter(|&&byte| byte == b'\n').count() as u64;
        let line = self.newlines + newlines_in(&bytes[..blank]) + 1;
        let record = &bytes[blank..];
        let terminated = matches!(record.last(), Some(b'\n' | b'\r'));
        let at_end = self.ended && end == self.bytes_read;
        // At the end of the input, an odd number of quotes means a quoted field was cut off
        // (possibly just after a newline inside it).
        let open_quote = at_end && record.iter().filter(|&&byte| byte == b'"').count() % 2 == 1;
        let unterminated = at_end && (!terminated || open_quote);
        let text = String::from_utf8_lossy(record);
        let text = if unterminated {
            text.into_owned()
        } else {
            text.trim_end_matches(['\r', '\n']).to_owned()
        };
        self.newlines += newlines_in(bytes);
        self.accounted = end;
        self.cursor += length;
        if self.cursor >= COMPACT_BYTES {
            self.pending.drain(..self.cursor);
            self.cursor = 0;
        }
        RecordSpan {
            line,
            text,
            unterminated,
        }
    }
}

impl<R: Read> Read for InputTap<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let count = self.inner.read(buf)?;
        if count > 0 {
            self.pending.extend_from_slice(&buf[..count]);
            self.bytes_read += count as u64;
        } else if !buf.is_empty() {
            self.ended = true;
        }
        Ok(count)
    }
}
