//! `tracker.csv` (format v2): `t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms,arrival_t_ns`, one
//! row per tool per tracker frame. `t_ns` is when the frame became available at the tracker
//! (estimated on the host), `arrival_t_ns` when its reply arrived (not before `t_ns`). A
//! `missing` row leaves every number but the stamps empty; a `tip` row leaves the quaternion
//! empty.
//!
//! Format v1 files (the same columns without `arrival_t_ns`, `t_ns` the arrival stamp) are
//! still read: their rows' availability and arrival are both that stamp.

use crate::error::{Problem, RecordingError};
use crate::format::{CsvFormat, Fields, RecordBuilder};
use crate::rows::{Tool, ToolReading, TrackerRow};

/// Index of the `qw` column; the quaternion is `qw..=qz`.
const QW: usize = 4;
/// Index of the `x` column; the position is `x..=z`.
const X: usize = 8;
/// Index of the `rms` column, the last reading column.
const RMS: usize = 11;
/// Index of the `arrival_t_ns` column (format v2).
const ARRIVAL: usize = 12;

/// The `tracker.csv` format.
#[derive(Debug, Clone, Copy, Default)]
pub struct TrackerCsv;

impl CsvFormat for TrackerCsv {
    const FILE_NAME: &'static str = "tracker.csv";
    const COLUMNS: &'static [&'static str] = &[
        "t_ns",
        "frame",
        "tool",
        "status",
        "qw",
        "qx",
        "qy",
        "qz",
        "x",
        "y",
        "z",
        "rms",
        "arrival_t_ns",
    ];
    /// Format v1: no `arrival_t_ns`, `t_ns` is the arrival stamp.
    const EARLIER_COLUMNS: &'static [&'static [&'static str]] = &[&[
        "t_ns", "frame", "tool", "status", "qw", "qx", "qy", "qz", "x", "y", "z", "rms",
    ]];
    type Row = TrackerRow;
    /// Tracker rows are independent of each other.
    type State = ();

    fn parse(fields: &Fields<'_>) -> Result<TrackerRow, RecordingError> {
        let t_ns = fields.integer(0)?;
        let arrival_t_ns = match fields.columns().len() > ARRIVAL {
            true => fields.integer(ARRIVAL)?,
            false => t_ns,
        };
        let frame = fields.integer(1)?;
        let tool_name = fields.text(2)?;
        let tool = Tool::from_name(tool_name)
            .ok_or_else(|| fields.error(Problem::UnknownTool(tool_name.to_owned())))?;
        let reading = match fields.text(3)? {
            "missing" => {
                for index in QW..=RMS {
                    fields.expect_empty(index, |column, value| Problem::NumberOnMissingRow {
                        column,
                        value,
                    })?;
                }
                ToolReading::Missing
            }
            "ok" if tool == Tool::Tip => {
                for index in QW..X {
                    fields.expect_empty(index, |column, value| Problem::QuaternionOnTip {
                        column,
                        value,
                    })?;
                }
                ToolReading::Point {
                    position: floats(fields, X)?,
                    rms: fields.float(RMS)?,
                }
            }
            "ok" => ToolReading::Pose {
                quaternion: floats(fields, QW)?,
                position: floats(fields, X)?,
                rms: fields.float(RMS)?,
            },
            other => return Err(fields.error(Problem::UnknownStatus(other.to_owned()))),
        };
        Ok(TrackerRow {
            t_ns,
            arrival_t_ns,
            frame,
            tool,
            reading,
        })
    }

    fn check(row: &TrackerRow, _: &mut ()) -> Result<(), Problem> {
        if row.arrival_t_ns < row.t_ns {
            return Err(Problem::ArrivalBeforeAvailable {
                t_ns: row.t_ns,
                arrival_t_ns: row.arrival_t_ns,
            });
        }
        let (first_column, values) = match row.reading {
            ToolReading::Missing => return Ok(()),
            ToolReading::Pose { .. } if row.tool == Tool::Tip => {
                return Err(Problem::ReadingDoesNotFitTool {
                    tool: row.tool,
                    reading: "pose",
                })
            }
            ToolReading::Point { .. } if row.tool != Tool::Tip => {
                return Err(Problem::ReadingDoesNotFitTool {
                    tool: row.tool,
                    reading: "point",
                })
            }
            ToolReading::Pose {
                quaternion: q,
                position: p,
                rms,
            } => (QW, vec![q[0], q[1], q[2], q[3], p[0], p[1], p[2], rms]),
            ToolReading::Point { position: p, rms } => (X, vec![p[0], p[1], p[2], rms]),
        };
        let columns = &Self::COLUMNS[first_column..];
        match columns
            .iter()
            .zip(&values)
            .find(|(_, value)| !value.is_finite())
        {
            Some((&column, &value)) => Err(Problem::NotFinite { column, value }),
            None => Ok(()),
        }
    }

    fn write(row: &TrackerRow, out: &mut RecordBuilder) {
        out.integer(row.t_ns);
        out.integer(i64::from(row.frame));
        out.text(row.tool.name());
        match &row.reading {
            ToolReading::Missing => {
                out.text("missing");
                (QW..=RMS).for_each(|_| out.empty());
            }
            ToolReading::Pose {
                quaternion,
                position,
                rms,
            } => {
                out.text("ok");
                quaternion
                    .iter()
                    .chain(position)
                    .chain([rms])
                    .for_each(|&v| out.float(v));
            }
            ToolReading::Point { position, rms } => {
                out.text("ok");
                (QW..X).for_each(|_| out.empty());
                position.iter().chain([rms]).for_each(|&v| out.float(v));
            }
        }
        out.integer(row.arrival_t_ns);
    }
}

/// `N` consecutive float fields starting at column `first`.
fn floats<const N: usize>(fields: &Fields<'_>, first: usize) -> Result<[f64; N], RecordingError> {
    let mut values = [0.0; N];
    for (offset, value) in values.iter_mut().enumerate() {
        *value = fields.float(first + offset)?;
    }
    Ok(values)
}
