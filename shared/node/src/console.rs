//! Standard output and error of every SABR process — the command-line tools (`sabr`,
//! `sabr-lab`) and the services alike: what they print for a reader, written so that a reader
//! who leaves early (`sabr calibrate … | head`) ends the printing, never the work.
//!
//! Rust ignores `SIGPIPE`, so a write to a closed pipe fails with `EPIPE`, and `println!`
//! panics on it: a calibration piped into `head` died after its first lines, before its
//! report was written. Here a closed pipe silences the rest of the output quietly, as `git`
//! or `grep` end; the process still finishes its work and writes its files, and exits as it
//! would have. Any other write error (a full disk behind `> file`, or behind a service's log)
//! also silences the output, and is kept for [`finish`]: a command-line tool's `main` reports
//! it last ([`exit_status`]), a service logs it as it leaves ([`crate::service_main`]).
//!
//! Standard error (progress lines, warnings, the final error) goes the same way through
//! [`errln!`](crate::errln), except that its failures are not reported: there is nowhere left
//! to report them. That matters most to `sabr launch 2>&1 | head`: the launcher supervising a
//! graph must not die because the terminal's reader went away.

use std::io::{self, Write};
use std::process::ExitCode;
use std::sync::Mutex;

/// What became of one standard stream so far.
#[derive(Debug)]
struct State {
    /// The reader left (`EPIPE`): nothing more is written, and that is not an error.
    reader_left: bool,
    /// The first other write error: nothing more is written, and [`finish`] reports it.
    failed: Option<io::Error>,
}

impl State {
    /// Writes `bytes` to `out` unless the output was silenced, and records how a write failed.
    fn write(&mut self, out: &mut impl Write, bytes: &[u8]) {
        if self.reader_left || self.failed.is_some() {
            return;
        }
        match out.write_all(bytes).and_then(|()| out.flush()) {
            Ok(()) => {}
            Err(error) if error.kind() == io::ErrorKind::BrokenPipe => self.reader_left = true,
            Err(error) => self.failed = Some(error),
        }
    }

    /// The kept write error, if any, as the error of the command.
    fn finish(&mut self) -> anyhow::Result<()> {
        match self.failed.take() {
            Some(error) => {
                Err(anyhow::Error::new(error).context("cannot write to standard output"))
            }
            None => Ok(()),
        }
    }
}

/// Nothing written yet.
const UNTOUCHED: State = State {
    reader_left: false,
    failed: None,
};

/// The state of this process's standard output.
static STDOUT: Mutex<State> = Mutex::new(UNTOUCHED);
/// The state of this process's standard error.
static STDERR: Mutex<State> = Mutex::new(UNTOUCHED);

fn with<R>(stream: &Mutex<State>, f: impl FnOnce(&mut State) -> R) -> R {
    // A panic elsewhere while the lock was held cannot leave `State` inconsistent.
    let mut state = stream
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    f(&mut state)
}

/// Writes `bytes` to standard output unless it was silenced.
fn write_out(bytes: &[u8]) {
    with(&STDOUT, |state| {
        state.write(&mut io::stdout().lock(), bytes)
    });
}

/// Writes `text` to standard output (used by [`out!`](crate::out) and
/// [`outln!`](crate::outln)); see the module documentation for failures.
pub fn write_str(text: &str) {
    write_out(text.as_bytes());
}

/// Writes `text` to standard error (used by [`errln!`](crate::errln)); a closed or failing
/// standard error silences the rest, unreported.
pub fn write_err_str(text: &str) {
    with(&STDERR, |state| {
        state.write(&mut io::stderr().lock(), text.as_bytes())
    });
}

/// True once nothing more will be written (the reader left, or a write failed): a command
/// that only prints (`sabr fk`) may stop early.
pub fn silenced() -> bool {
    with(&STDOUT, |state| state.reader_left || state.failed.is_some())
}

/// The first write error of standard output other than a reader who left, as an error naming
/// standard output; `Ok` otherwise.
pub fn finish() -> anyhow::Result<()> {
    with(&STDOUT, State::finish)
}

/// The exit status of the command-line tool `program` (`sabr`, `sabr-lab`) given what its
/// command returned: a standard-output write error ([`finish`]) fails a command that
/// succeeded, after the work it did; an error is printed as `program: error` on standard
/// error. The tools' `main` ends with it.
pub fn exit_status(program: &str, result: anyhow::Result<ExitCode>) -> ExitCode {
    match result.and_then(|code| finish().map(|()| code)) {
        Ok(code) => code,
        Err(error) => {
            write_err_str(&format!("{program}: {error:#}\n"));
            ExitCode::FAILURE
        }
    }
}

/// Standard output as an [`io::Write`] for writers that stream to it (a CSV writer): every
/// write goes through the same state as [`write_str`], so a reader who left makes writes
/// succeed without effect.
#[derive(Debug, Clone, Copy, Default)]
pub struct Stdout;

impl Write for Stdout {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        write_out(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// `print!` to standard output through [`console`](crate::console): never panics.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::console::write_str(&::std::format!($($arg)*))
    };
}

/// `println!` to standard output through [`console`](crate::console): never panics.
#[macro_export]
macro_rules! outln {
    () => {
        $crate::console::write_str("\n")
    };
    ($($arg:tt)*) => {
        $crate::console::write_str(&::std::format!("{}\n", ::std::format_args!($($arg)*)))
    };
}

/// `eprintln!` to standard error through [`console`](crate::console): never panics.
#[macro_export]
macro_rules! errln {
    ($($arg:tt)*) => {
        $crate::console::write_err_str(&::std::format!("{}\n", ::std::format_args!($($arg)*)))
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A writer that takes `accepts` writes, then fails every write with `error`.
    struct Failing {
        written: Vec<u8>,
        accepts: usize,
        error: io::ErrorKind,
    }

    impl Write for Failing {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            if self.accepts == 0 {
                return Err(io::Error::from(self.error));
            }
            self.accepts -= 1;
            self.written.extend_from_slice(buf);
            Ok(buf.len())
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    fn failing(accepts: usize, error: io::ErrorKind) -> Failing {
        Failing {
            written: Vec::new(),
            accepts,
            error,
        }
    }

    #[test]
    fn a_reader_who_left_silences_the_output_without_an_error() {
        let mut state = UNTOUCHED;
        let mut out = failing(1, io::ErrorKind::BrokenPipe);
        state.write(&mut out, b"first\n");
        state.write(&mut out, b"second\n");
        assert!(state.reader_left);
        // The writer would accept again; the output stays silenced.
        out.accepts = 1;
        state.write(&mut out, b"third\n");
        assert_eq!(out.written, b"first\n");
        assert!(state.finish().is_ok());
    }

    #[test]
    fn another_write_error_silences_the_output_and_is_reported_once() {
        let mut state = UNTOUCHED;
        let mut out = failing(0, io::ErrorKind::StorageFull);
        state.write(&mut out, b"lost\n");
        out.accepts = 1;
        state.write(&mut out, b"after\n");
        assert!(out.written.is_empty());
        assert!(!state.reader_left);
        let error = state.finish().expect_err("the write error is reported");
        assert!(
            format!("{error:#}").starts_with("cannot write to standard output: "),
            "{error:#}"
        );
        assert!(state.finish().is_ok(), "reported once");
    }
}
