//! `phases.csv`: `t_start_ns,t_end_ns,phase`. Phase names are free text (homing, excitation,
//! tip, validation, or the user's own) but not empty.

use crate::error::{Problem, RecordingError};
use crate::format::{CsvFormat, Fields, RecordBuilder};
use crate::rows::PhaseRow;

/// The `phases.csv` format.
#[derive(Debug, Clone, Copy, Default)]
pub struct PhasesCsv;

impl CsvFormat for PhasesCsv {
    const FILE_NAME: &'static str = "phases.csv";
    const COLUMNS: &'static [&'static str] = &["t_start_ns", "t_end_ns", "phase"];
    type Row = PhaseRow;
    /// Phases are independent of each other.
    type State = ();

    fn parse(fields: &Fields<'_>) -> Result<PhaseRow, RecordingError> {
        Ok(PhaseRow {
            t_start_ns: fields.integer(0)?,
            t_end_ns: fields.integer(1)?,
            phase: fields.text(2)?.to_owned(),
        })
    }

    fn check(row: &PhaseRow, _: &mut ()) -> Result<(), Problem> {
        if row.t_end_ns < row.t_start_ns {
            return Err(Problem::EndBeforeStart {
                t_start_ns: row.t_start_ns,
                t_end_ns: row.t_end_ns,
            });
        }
        if row.phase.is_empty() {
            return Err(Problem::EmptyPhaseName);
        }
        Ok(())
    }

    fn write(row: &PhaseRow, out: &mut RecordBuilder) {
        out.integer(row.t_start_ns);
        out.integer(row.t_end_ns);
        out.text(&row.phase);
    }
}
