//! `encoders.csv`: `t_ns,c1,c2,c3,c4,c5`, one row per encoder sample, raw counts, time stamps
//! strictly increasing.

use crate::error::{Problem, RecordingError};
use crate::format::{CsvFormat, Fields, RecordBuilder};
use crate::rows::EncoderRow;

/// The `encoders.csv` format.
#[derive(Debug, Clone, Copy, Default)]
pub struct EncodersCsv;

impl CsvFormat for EncodersCsv {
    const FILE_NAME: &'static str = "encoders.csv";
    const COLUMNS: &'static [&'static str] = &["t_ns", "c1", "c2", "c3", "c4", "c5"];
    type Row = EncoderRow;
    /// The previous row's time stamp (ns).
    type State = Option<i64>;

    fn parse(fields: &Fields<'_>) -> Result<EncoderRow, RecordingError> {
        let t_ns = fields.integer(0)?;
        let mut counts = [0; 5];
        for (index, count) in counts.iter_mut().enumerate() {
            *count = fields.integer(index + 1)?;
        }
        Ok(EncoderRow { t_ns, counts })
    }

    fn check(row: &EncoderRow, previous_t_ns: &mut Option<i64>) -> Result<(), Problem> {
        if let Some(previous_t_ns) = *previous_t_ns {
            if row.t_ns <= previous_t_ns {
                return Err(Problem::NonMonotonicTime {
                    t_ns: row.t_ns,
                    previous_t_ns,
                });
            }
        }
        *previous_t_ns = Some(row.t_ns);
        Ok(())
    }

    fn write(row: &EncoderRow, out: &mut RecordBuilder) {
        out.integer(row.t_ns);
        for count in row.counts {
            out.integer(count);
        }
    }
}
