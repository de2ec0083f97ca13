//! Writing a recording row by row, buffered, optionally flushing continuously for a live
//! recorder. The writer applies the readers' rules, so whatever it writes reads back.

use std::fs::{self, File};
use std::io::Write as _;
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::error::RecordingError;
use crate::format::{CsvFormat, RecordBuilder, ROBOT_TOML};
use crate::rows::{EncoderRow, PhaseRow, Recording, TrackerRow};
use crate::{EncodersCsv, PhasesCsv, TrackerCsv};

/// Write buffer size per file.
const BUFFER_BYTES: usize = 1 << 16;

/// When the writer hands buffered rows to the operating system. Flushed rows survive the
/// writing process being killed (SIGKILL); [`RecordingWriter::finish`] also syncs them to disk.
/// A buffer that fills is written out under every policy, possibly ending mid-row: a reader
/// with [`crate::ReadOptions::allow_truncated_tail`] drops such a partial final line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum FlushPolicy {
    /// Only when a buffer fills, on [`RecordingWriter::flush`] and on
    /// [`RecordingWriter::finish`]: the fastest, for writing a recording offline.
    #[default]
    OnRequest,
    /// After every `n`-th row written to a file (`n` = 1: after every row), so a killed
    /// recorder loses at most the last `n - 1` rows of each file.
    EveryRows(NonZeroUsize),
    /// When a row is written to a file and this long has passed since that file was last
    /// flushed. Rows written just before a pause wait for the next row: a live recorder should
    /// also call [`RecordingWriter::flush`] when idle.
    Interval(Duration),
}

/// Writes a recording directory: `robot.toml`, then rows to `encoders.csv`, `tracker.csv` and
/// `phases.csv` in any interleaving. Each file's header is on disk as soon as it is created.
/// Dropping the writer flushes it but ignores errors: call [`RecordingWriter::finish`].
#[derive(Debug)]
pub struct RecordingWriter {
    dir: PathBuf,
    encoders: CsvSink<EncodersCsv>,
    tracker: CsvSink<TrackerCsv>,
    phases: CsvSink<PhasesCsv>,
}

impl RecordingWriter {
    /// Creates the recording in `dir` (made if absent) with `robot_toml` as the nominal model,
    /// flushing on request only. Refuses to overwrite any file of an existing recording.
    pub fn create(dir: &Path, robot_toml: &str) -> Result<Self, RecordingError> {
        Self::create_with(dir, robot_toml, FlushPolicy::default())
    }

    /// Like [`RecordingWriter::create`], flushing by `policy`.
    pub fn create_with(
        dir: &Path,
        robot_toml: &str,
        policy: FlushPolicy,
    ) -> Result<Self, RecordingError> {
        fs::create_dir_all(dir).map_err(|source| RecordingError::Io {
            path: dir.to_path_buf(),
            action: "create the directory",
            source,
        })?;
        let toml_path = dir.join(ROBOT_TOML);
        let io_error = |action| {
            let path = toml_path.clone();
            move |source| RecordingError::Io {
                path,
                action,
                source,
            }
        };
        let mut toml_file = File::create_new(&toml_path).map_err(io_error("create"))?;
        toml_file
            .write_all(robot_toml.as_bytes())
            .map_err(io_error("write"))?;
        toml_file.sync_all().map_err(io_error("sync"))?;
        Ok(RecordingWriter {
            dir: dir.to_path_buf(),
            encoders: CsvSink::create(dir, policy)?,
            tracker: CsvSink::create(dir, policy)?,
            phases: CsvSink::create(dir, policy)?,
        })
    }

    /// The recording directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Appends an encoder sample; refused if its time stamp is not after the previous one.
    pub fn write_encoder(&mut self, row: &EncoderRow) -> Result<(), RecordingError> {
        self.encoders.write(row)
    }

    /// Appends a tracker row; refused if a number is not finite or the reading does not fit
    /// the tool (a pose for the tip, a point for a marker).
    pub fn write_tracker(&mut self, row: &TrackerRow) -> Result<(), RecordingError> {
        self.tracker.write(row)
    }

    /// Appends a phase; refused if it ends before it starts or has an empty name.
    pub fn write_phase(&mut self, row: &PhaseRow) -> Result<(), RecordingError> {
        self.phases.write(row)
    }

    /// Hands every buffered row of every file to the operating system.
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.encoders.flush()?;
        self.tracker.flush()?;
        self.phases.flush()
    }

    /// Flushes every file and syncs it to disk.
    pub fn finish(self) -> Result<(), RecordingError> {
        self.encoders.finish()?;
        self.tracker.finish()?;
        self.phases.finish()
    }
}

/// Writes `recording` to a new recording in `dir` (its `dir` field is not used).
pub fn write_all(recording: &Recording, dir: &Path) -> Result<(), RecordingError> {
    let mut writer = RecordingWriter::create(dir, &recording.robot_toml)?;
    for row in &recording.encoders {
        writer.write_encoder(row)?;
    }
    for row in &recording.tracker {
        writer.write_tracker(row)?;
    }
    for row in &recording.phases {
        writer.write_phase(row)?;
    }
    writer.finish()
}

/// One CSV file being written.
#[derive(Debug)]
struct CsvSink<F: CsvFormat> {
    path: PathBuf,
    writer: csv::Writer<File>,
    builder: RecordBuilder,
    state: F::State,
    /// Lines written, the header included.
    lines: u64,
    policy: FlushPolicy,
    unflushed_rows: usize,
    last_flush: Instant,
}

impl<F: CsvFormat> CsvSink<F> {
    /// Creates `dir`'s file of format `F` and writes its header through to the OS.
    fn create(dir: &Path, policy: FlushPolicy) -> Result<Self, RecordingError> {
        let path = dir.join(F::FILE_NAME);
        let file = File::create_new(&path).map_err(|source| RecordingError::Io {
            path: path.clone(),
            action: "create",
            source,
        })?;
        let writer = csv::WriterBuilder::new()
            .buffer_capacity(BUFFER_BYTES)
            .from_writer(file);
        let mut sink = CsvSink {
            path,
            writer,
            builder: RecordBuilder::default(),
            state: F::State::default(),
            lines: 1,
            policy,
            unflushed_rows: 0,
            last_flush: Instant::now(),
        };
        sink.writer
            .write_record(F::COLUMNS)
            .map_err(|e| RecordingError::csv(sink.path.clone(), "write", e))?;
        sink.flush()?;
        Ok(sink)
    }

    fn write(&mut self, row: &F::Row) -> Result<(), RecordingError> {
        let line = self.lines + 1;
        F::check(row, &mut self.state).map_err(|problem| RecordingError::Refused {
            path: self.path.clone(),
            line,
            problem,
        })?;
        self.builder.clear();
        F::write(row, &mut self.builder);
        self.writer
            .write_byte_record(self.builder.record())
            .map_err(|e| RecordingError::csv(self.path.clone(), "write", e))?;
        self.lines = line;
        self.unflushed_rows += 1;
        if self.flush_due() {
            self.flush()?;
        }
        Ok(())
    }

    fn flush_due(&self) -> bool {
        match self.policy {
            FlushPolicy::OnRequest => false,
            FlushPolicy::EveryRows(rows) => self.unflushed_rows >= rows.get(),
            FlushPolicy::Interval(interval) => self.last_flush.elapsed() >= interval,
        }
    }

    fn flush(&mut self) -> Result<(), RecordingError> {
        self.writer.flush().map_err(|source| RecordingError::Io {
            path: self.path.clone(),
            action: "write",
            source,
        })?;
        self.unflushed_rows = 0;
        self.last_flush = Instant::now();
        Ok(())
    }

    fn finish(mut self) -> Result<(), RecordingError> {
        self.flush()?;
        let io_error = |source| RecordingError::Io {
            path: self.path.clone(),
            action: "sync",
            source,
        };
        let file = self
            .writer
            .into_inner()
            .map_err(|e| io_error(e.into_error()))?;
        file.sync_all().map_err(io_error)
    }
}
