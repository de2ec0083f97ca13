//! Reading and writing the rows of `poses.csv`.

use std::collections::HashMap;
use std::path::Path;

use csv::StringRecord;

use super::header::{
    PosesHeader, TargetColumns, INDEX, JOINT_PREFIX, ORIENTATION_STD, POSITION, POSITION_STD,
    QUATERNION, SEQUENCE, SETUP, TEMPERATURE,
};
use super::{PoseRow, PosesRecording, TargetMeasurement, UNIT_QUATERNION_TOLERANCE};
use crate::error::{Problem, RecordingError};
use crate::robot_toml::poses::{Measured, PosesRobot};

/// Reads `path`: the joint names of its joint columns and every row, checked.
pub(crate) fn read(
    path: &Path,
    robot: &PosesRobot,
) -> Result<(Vec<String>, Vec<PoseRow>), RecordingError> {
    let bytes =
        std::fs::read(path).map_err(|e| RecordingError::open(path.to_path_buf(), "read", e))?;
    // The csv crate counts a CRLF line end as two lines; with LF only its line numbers are
    // the file's.
    let bytes = crlf_to_lf(bytes);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(bytes.as_slice());
    let malformed = |line: u64, problem: Problem| RecordingError::Malformed {
        path: path.to_path_buf(),
        line,
        problem,
    };
    let mut record = StringRecord::new();
    let csv_error = |e: csv::Error| match e.kind() {
        csv::ErrorKind::Utf8 { pos, .. } => malformed(
            pos.as_ref().map_or(0, |p| p.line()),
            Problem::BadField {
                column: "?".into(),
                reason: "not valid UTF-8".into(),
            },
        ),
        _ => RecordingError::csv(path.to_path_buf(), "read", e),
    };
    if !reader.read_record(&mut record).map_err(csv_error)? {
        return Err(malformed(
            1,
            Problem::BadColumn {
                column: SETUP.into(),
                reason: "empty file: expected a header".into(),
            },
        ));
    }
    let names = record.iter().map(str::to_owned).collect();
    let header = PosesHeader::parse(names, robot).map_err(|problem| malformed(1, problem))?;
    let joint_names = header.joints.iter().map(|(name, _)| name.clone()).collect();
    let mut last_index: HashMap<String, u64> = HashMap::new();
    let mut rows = Vec::new();
    while reader.read_record(&mut record).map_err(csv_error)? {
        let line = record.position().map_or(0, |p| p.line());
        let row = parse_row(&header, robot, &record, line)
            .and_then(|row| check_order(&row, &mut last_index).map(|()| row))
            .map_err(|problem| malformed(line, problem))?;
        rows.push(row);
    }
    Ok((joint_names, rows))
}

/// `bytes` with every CRLF pair replaced by LF.
fn crlf_to_lf(mut bytes: Vec<u8>) -> Vec<u8> {
    if !bytes.contains(&b'\r') {
        return bytes;
    }
    let mut write = 0;
    for read in 0..bytes.len() {
        let byte = bytes[read];
        if byte == b'\r' && bytes.get(read + 1) == Some(&b'\n') {
            continue;
        }
        bytes[write] = byte;
        write += 1;
    }
    bytes.truncate(write);
    bytes
}

/// The fields of one row, by column.
struct RowFields<'a> {
    header: &'a PosesHeader,
    record: &'a StringRecord,
}

impl RowFields<'_> {
    fn name(&self, column: usize) -> String {
        self.header.names[column].clone()
    }

    fn text(&self, column: usize) -> Result<&str, Problem> {
        self.record.get(column).ok_or_else(|| Problem::BadField {
            column: self.name(column),
            reason: format!("missing (the row has {} fields)", self.record.len()),
        })
    }

    fn nonempty_text(&self, column: usize) -> Result<&str, Problem> {
        let text = self.text(column)?;
        if text.is_empty() {
            Err(self.bad(column, "empty".into()))
        } else {
            Ok(text)
        }
    }

    fn bad(&self, column: usize, reason: String) -> Problem {
        Problem::BadField {
            column: self.name(column),
            reason,
        }
    }

    /// A finite float; `None` if the field is empty.
    fn optional_float(&self, column: usize) -> Result<Option<f64>, Problem> {
        let text = self.text(column)?;
        if text.is_empty() {
            return Ok(None);
        }
        let value: f64 = text
            .trim()
            .parse()
            .map_err(|_| self.bad(column, format!("invalid number {text:?}")))?;
        if value.is_finite() {
            Ok(Some(value))
        } else {
            Err(self.bad(column, format!("{value} is not a finite number")))
        }
    }

    fn float(&self, column: usize) -> Result<f64, Problem> {
        self.optional_float(column)?
            .ok_or_else(|| self.bad(column, "empty, expected a number".into()))
    }

    /// A group of columns that are all empty (`None`) or all numbers.
    fn group<const N: usize>(
        &self,
        columns: &[Option<usize>; N],
    ) -> Result<Option<[f64; N]>, Problem> {
        let Some(first) = columns[0] else {
            return Ok(None);
        };
        let values = columns
            .map(|c| c.expect("a header group is complete or absent"))
            .map(|c| self.optional_float(c));
        let mut out = [0.0; N];
        let mut present = 0;
        for (i, value) in values.into_iter().enumerate() {
            if let Some(v) = value? {
                out[i] = v;
                present += 1;
            }
        }
        match present {
            0 => Ok(None),
            p if p == N => Ok(Some(out)),
            _ => {
                let empty = columns
                    .iter()
                    .flatten()
                    .find(|&&c| self.text(c).is_ok_and(str::is_empty))
                    .copied()
                    .unwrap_or(first);
                Err(self.bad(
                    empty,
                    "empty while the other fields of its group are set".into(),
                ))
            }
        }
    }
}

fn parse_row(
    header: &PosesHeader,
    robot: &PosesRobot,
    record: &StringRecord,
    line: u64,
) -> Result<PoseRow, Problem> {
    let fields = RowFields { header, record };
    let setup = fields.nonempty_text(header.setup)?.to_owned();
    let sequence = fields.nonempty_text(header.sequence)?.to_owned();
    let index_text = fields.nonempty_text(header.index)?;
    let index = index_text.parse().map_err(|_| {
        fields.bad(
            header.index,
            format!("invalid order index {index_text:?} (expected an integer ≥ 0)"),
        )
    })?;
    let joints = header
        .joints
        .iter()
        .map(|&(_, column)| fields.float(column))
        .collect::<Result<Vec<_>, _>>()?;
    let mut targets = Vec::with_capacity(robot.targets.len());
    for (target, columns) in robot.targets.iter().zip(&header.targets) {
        targets.push(target_measurement(&fields, columns, target.measured)?);
    }
    if targets.iter().all(Option::is_none) {
        let column = header.targets[0].position[0].expect("position columns are required");
        return Err(fields.bad(column, "no target is measured at this pose".into()));
    }
    let temperature_c = header
        .temperature
        .map(|c| fields.optional_float(c))
        .transpose()?
        .flatten();
    Ok(PoseRow {
        line,
        setup,
        sequence,
        index,
        joints,
        targets,
        temperature_c,
    })
}

fn target_measurement(
    fields: &RowFields<'_>,
    columns: &TargetColumns,
    measured: Measured,
) -> Result<Option<TargetMeasurement>, Problem> {
    let position = fields.group(&columns.position)?;
    let orientation = fields.group(&columns.quaternion)?;
    let position_std = fields.group(&columns.position_std)?;
    let orientation_std = fields.group(&columns.orientation_std)?;
    let Some(position_mm) = position else {
        // Not measured here: every other field of the target must be empty too.
        let set = [
            orientation.is_some().then_some(columns.quaternion[0]),
            position_std.is_some().then_some(columns.position_std[0]),
            orientation_std
                .is_some()
                .then_some(columns.orientation_std[0]),
        ];
        if let Some(column) = set.into_iter().flatten().flatten().next() {
            return Err(fields.bad(column, "set while the target's position is empty".into()));
        }
        return Ok(None);
    };
    if measured == Measured::Pose {
        let Some(q) = orientation else {
            let column = columns.quaternion[0].expect("pose targets have quaternion columns");
            return Err(fields.bad(column, "empty while the target's position is set".into()));
        };
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > UNIT_QUATERNION_TOLERANCE {
            let column = columns.quaternion[0].expect("pose targets have quaternion columns");
            return Err(fields.bad(column, format!("not a unit quaternion (norm {norm})")));
        }
    }
    for (values, group) in [
        (position_std, &columns.position_std),
        (orientation_std, &columns.orientation_std),
    ] {
        if let Some(i) = values.and_then(|v| v.iter().position(|&s| s < 0.0)) {
            let column = group[i].expect("present group");
            return Err(fields.bad(column, "a standard deviation cannot be negative".into()));
        }
    }
    Ok(Some(TargetMeasurement {
        position_mm,
        orientation,
        position_std_mm: position_std,
        orientation_std_rad: orientation_std,
    }))
}

/// Order indices increase strictly within each sequence.
fn check_order(row: &PoseRow, last_index: &mut HashMap<String, u64>) -> Result<(), Problem> {
    match last_index.get_mut(&row.sequence) {
        Some(previous) if row.index <= *previous => Err(Problem::BadField {
            column: INDEX.into(),
            reason: format!(
                "{} is not after {} of the previous pose of sequence {:?} (indices increase within a sequence)",
                row.index, previous, row.sequence
            ),
        }),
        Some(previous) => {
            *previous = row.index;
            Ok(())
        }
        None => {
            last_index.insert(row.sequence.clone(), row.index);
            Ok(())
        }
    }
}

/// Which optional groups the writer writes for one target.
struct WrittenGroups {
    position_std: bool,
    orientation_std: bool,
}

/// Writes `recording`'s rows to the new file `path`, after checking each as a reader would.
pub(crate) fn write(path: &Path, recording: &PosesRecording) -> Result<(), RecordingError> {
    let robot = &recording.robot;
    let groups: Vec<WrittenGroups> = (0..robot.targets.len())
        .map(|t| {
            let any = |f: fn(&TargetMeasurement) -> bool| {
                recording
                    .rows
                    .iter()
                    .any(|r| r.targets[t].as_ref().is_some_and(f))
            };
            WrittenGroups {
                position_std: any(|m| m.position_std_mm.is_some()),
                orientation_std: any(|m| m.orientation_std_rad.is_some()),
            }
        })
        .collect();
    let temperature = recording.rows.iter().any(|r| r.temperature_c.is_some());

    let mut names: Vec<String> = [SETUP, SEQUENCE, INDEX].map(str::to_owned).to_vec();
    names.extend(
        recording
            .joints
            .iter()
            .map(|j| format!("{JOINT_PREFIX}{j}")),
    );
    for (target, written) in robot.targets.iter().zip(&groups) {
        let mut add = |fields: &[&str]| {
            names.extend(fields.iter().map(|f| format!("{}.{f}", target.name)));
        };
        add(&POSITION);
        if target.measured == Measured::Pose {
            add(&QUATERNION);
        }
        if written.position_std {
            add(&POSITION_STD);
        }
        if written.orientation_std && target.measured == Measured::Pose {
            add(&ORIENTATION_STD);
        }
    }
    if temperature {
        names.push(TEMPERATURE.to_owned());
    }
    let refused = |line: u64, problem: Problem| RecordingError::Refused {
        path: path.to_path_buf(),
        line,
        problem,
    };
    let header = PosesHeader::parse(names.clone(), robot).map_err(|p| refused(1, p))?;

    let mut writer = csv::Writer::from_writer(Vec::new());
    let write_error = |e| RecordingError::csv(path.to_path_buf(), "write", e);
    writer.write_record(&names).map_err(write_error)?;
    let mut last_index = HashMap::new();
    let mut fields: Vec<String> = Vec::with_capacity(names.len());
    for (i, row) in recording.rows.iter().enumerate() {
        let line = i as u64 + 2;
        if row.joints.len() != recording.joints.len() || row.targets.len() != robot.targets.len() {
            return Err(refused(
                line,
                Problem::BadField {
                    column: JOINT_PREFIX.into(),
                    reason: format!(
                        "the row has {} joint values and {} targets, the recording {} and {}",
                        row.joints.len(),
                        row.targets.len(),
                        recording.joints.len(),
                        robot.targets.len()
                    ),
                },
            ));
        }
        fields.clear();
        fields.extend([
            row.setup.clone(),
            row.sequence.clone(),
            row.index.to_string(),
        ]);
        fields.extend(row.joints.iter().map(f64::to_string));
        for ((target, measurement), written) in robot.targets.iter().zip(&row.targets).zip(&groups)
        {
            let mut push = |values: Option<&[f64]>, count: usize| match values {
                Some(values) => fields.extend(values.iter().map(f64::to_string)),
                None => fields.extend(std::iter::repeat_n(String::new(), count)),
            };
            let m = measurement.as_ref();
            push(m.map(|m| &m.position_mm[..]), 3);
            if target.measured == Measured::Pose {
                push(m.and_then(|m| m.orientation.as_ref()).map(|q| &q[..]), 4);
            }
            if written.position_std {
                push(
                    m.and_then(|m| m.position_std_mm.as_ref()).map(|s| &s[..]),
                    3,
                );
            }
            if written.orientation_std && target.measured == Measured::Pose {
                push(
                    m.and_then(|m| m.orientation_std_rad.as_ref())
                        .map(|s| &s[..]),
                    3,
                );
            }
        }
        if temperature {
            fields.push(row.temperature_c.map(|t| t.to_string()).unwrap_or_default());
        }
        for (target, m) in robot.targets.iter().zip(&row.targets) {
            let oriented =
                m.is_some_and(|m| m.orientation.is_some() || m.orientation_std_rad.is_some());
            if target.measured == Measured::Point && oriented {
                return Err(refused(
                    line,
                    Problem::BadField {
                        column: format!("{}.x", target.name),
                        reason: "a point target has no orientation".into(),
                    },
                ));
            }
        }
        // The reader's checks, on exactly the fields about to be written.
        let record = StringRecord::from(fields.clone());
        let parsed = parse_row(&header, robot, &record, line).map_err(|p| refused(line, p))?;
        check_order(&parsed, &mut last_index).map_err(|p| refused(line, p))?;
        writer.write_record(&fields).map_err(write_error)?;
    }
    let bytes = writer.into_inner().map_err(|e| RecordingError::Io {
        path: path.to_path_buf(),
        action: "write",
        source: std::io::Error::other(e.to_string()),
    })?;
    super::write_new(path, &bytes)
}
