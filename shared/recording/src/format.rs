//! What the three CSV files of a recording have in common: a file name, a header, and rows
//! that are parsed from fields, checked against the format's rules and written as fields.
//! Reader and writer apply the same [`CsvFormat::check`], so the writer never writes a row
//! the reader would reject.

use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

use csv::ByteRecord;

use crate::error::{Problem, RecordingError};

/// File name of the nominal robot model in a recording directory.
pub const ROBOT_TOML: &str = "robot.toml";

/// One CSV file format of a recording: `encoders.csv`, `tracker.csv` or `phases.csv`.
pub trait CsvFormat {
    /// The file's name inside the recording directory.
    const FILE_NAME: &'static str;
    /// The header's columns, in order, as written. Files may carry extra columns after them.
    const COLUMNS: &'static [&'static str];
    /// The columns of earlier versions of the file that are still read, newest first (a
    /// header is matched against [`Self::COLUMNS`] first); [`Fields::columns`] tells
    /// [`Self::parse`] which the file has.
    const EARLIER_COLUMNS: &'static [&'static [&'static str]] = &[];
    /// One row.
    type Row;
    /// What the rules carry from one row to the next (the previous time stamp).
    type State: Default;

    /// Parses one row's fields (syntax only: numbers, names, which fields are empty).
    fn parse(fields: &Fields<'_>) -> Result<Self::Row, RecordingError>;

    /// Checks `row` against the format's rules given the rows before it (`state`), and on
    /// success updates `state` to include it.
    fn check(row: &Self::Row, state: &mut Self::State) -> Result<(), Problem>;

    /// Appends `row`'s fields to `out`, one per column.
    fn write(row: &Self::Row, out: &mut RecordBuilder);

    /// The header line without its terminator, e.g. `t_start_ns,t_end_ns,phase`.
    fn header() -> String {
        Self::COLUMNS.join(",")
    }
}

/// The fields of one CSV line, with what is needed to name a bad one in an error.
#[derive(Debug, Clone, Copy)]
pub struct Fields<'a> {
    path: &'a Path,
    line: u64,
    record: &'a ByteRecord,
    columns: &'static [&'static str],
}

impl<'a> Fields<'a> {
    /// Fields of `record`, line `line` (1-based) of `path`, in a file with `columns`.
    pub fn new(
        path: &'a Path,
        line: u64,
        record: &'a ByteRecord,
        columns: &'static [&'static str],
    ) -> Self {
        Fields {
            path,
            line,
            record,
            columns,
        }
    }

    /// An error about this line.
    pub fn error(&self, problem: Problem) -> RecordingError {
        RecordingError::Malformed {
            path: self.path.to_path_buf(),
            line: self.line,
            problem,
        }
    }

    /// The name of column `index`.
    pub fn column(&self, index: usize) -> &'static str {
        self.columns[index]
    }

    /// The format's columns this file's header has: [`CsvFormat::COLUMNS`], or one of
    /// [`CsvFormat::EARLIER_COLUMNS`] for a file of an earlier version.
    pub fn columns(&self) -> &'static [&'static str] {
        self.columns
    }

    /// The bytes of field `index`; an error if the line has no such field.
    pub fn raw(&self, index: usize) -> Result<&'a [u8], RecordingError> {
        self.record.get(index).ok_or_else(|| {
            self.error(Problem::MissingColumn {
                column: self.column(index),
                found: self.record.len(),
            })
        })
    }

    /// Field `index` as text.
    pub fn text(&self, index: usize) -> Result<&'a str, RecordingError> {
        std::str::from_utf8(self.raw(index)?).map_err(|_| {
            self.error(Problem::InvalidUtf8 {
                column: self.column(index),
            })
        })
    }

    /// Field `index` as a decimal integer.
    pub fn integer<T: FromStr>(&self, index: usize) -> Result<T, RecordingError> {
        let raw = self.nonempty(index)?;
        std::str::from_utf8(raw)
            .ok()
            .and_then(|text| text.parse().ok())
            .ok_or_else(|| {
                self.error(Problem::InvalidInteger {
                    column: self.column(index),
                    value: String::from_utf8_lossy(raw).into_owned(),
                })
            })
    }

    /// Field `index` as a float (finiteness is a rule, checked by [`CsvFormat::check`]).
    pub fn float(&self, index: usize) -> Result<f64, RecordingError> {
        let raw = self.nonempty(index)?;
        std::str::from_utf8(raw)
            .ok()
            .and_then(|text| text.parse().ok())
            .ok_or_else(|| {
                self.error(Problem::InvalidFloat {
                    column: self.column(index),
                    value: String::from_utf8_lossy(raw).into_owned(),
                })
            })
    }

    /// Requires field `index` to be empty, else the error `problem(column, text)`.
    pub fn expect_empty(
        &self,
        index: usize,
        problem: fn(&'static str, String) -> Problem,
    ) -> Result<(), RecordingError> {
        let raw = self.raw(index)?;
        if raw.is_empty() {
            Ok(())
        } else {
            let text = String::from_utf8_lossy(raw).into_owned();
            Err(self.error(problem(self.column(index), text)))
        }
    }

    fn nonempty(&self, index: usize) -> Result<&'a [u8], RecordingError> {
        let raw = self.raw(index)?;
        if raw.is_empty() {
            Err(self.error(Problem::MissingNumber {
                column: self.column(index),
            }))
        } else {
            Ok(raw)
        }
    }
}

/// Builds the fields of one CSV row; numbers in their shortest round-trip decimal form.
#[derive(Debug, Default)]
pub struct RecordBuilder {
    record: ByteRecord,
    scratch: String,
}

impl RecordBuilder {
    /// Appends an integer field.
    pub fn integer(&mut self, value: i64) {
        self.scratch.clear();
        // Writing to a String cannot fail.
        let _ = write!(self.scratch, "{value}");
        self.record.push_field(self.scratch.as_bytes());
    }

    /// Appends a float field in Rust's shortest representation that parses back to the same
    /// `f64`.
    pub fn float(&mut self, value: f64) {
        self.scratch.clear();
        let _ = write!(self.scratch, "{value}");
        self.record.push_field(self.scratch.as_bytes());
    }

    /// Appends a text field (quoted on output if it needs it).
    pub fn text(&mut self, value: &str) {
        self.record.push_field(value.as_bytes());
    }

    /// Appends an empty field.
    pub fn empty(&mut self) {
        self.record.push_field(b"");
    }

    /// Starts a new row.
    pub(crate) fn clear(&mut self) {
        self.record.clear();
    }

    /// The row built so far.
    pub(crate) fn record(&self) -> &ByteRecord {
        &self.record
    }
}
