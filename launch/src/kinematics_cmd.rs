//! `sabr fk` and `sabr ik`: forward and inverse kinematics over CSV files
//! (docs/robot-model.md §3–§4). Output goes to standard output as CSV with a header line, one row
//! per input row; a row that has no solution becomes `error,<reason>` and makes the command
//! exit with a failure status after all rows are written.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::ArgGroup;
use glam::DVec3;
use sabr_model::realtime::RealtimeGeometry;
use sabr_model::{
    forward, DirectionTracker, Geometry, JointMotion, Joints, RobotParams,
    DIRECTION_DEAD_BAND_COUNTS, HOME_JOINTS,
};
use sabr_node::{console, errln};

/// Arguments of `sabr fk`.
#[derive(Debug, clap::Args)]
#[command(group(ArgGroup::new("input").required(true).args(["counts", "joints"])))]
pub struct FkArgs {
    /// Robot parameters: a calibrated params.toml, or a robot.toml (then only --joints).
    #[arg(long, value_name = "FILE")]
    params: PathBuf,
    /// CSV of encoder counts with header c1,c2,c3,c4,c5 (extra columns are ignored;
    /// fractional counts are accepted). Needs the joint offsets of a calibrated params.toml.
    /// Rows are read as a time-ordered count history: a calibrated backlash uses each
    /// joint's direction of its last move of at least 2 counts (none before its first).
    #[arg(long, value_name = "CSV")]
    counts: Option<PathBuf>,
    /// CSV of joint angles (rad) with header q1,q2,q3,q4,q5 (extra columns are ignored).
    #[arg(long, value_name = "CSV")]
    joints: Option<PathBuf>,
}

/// Arguments of `sabr ik`.
#[derive(Debug, clap::Args)]
pub struct IkArgs {
    /// Robot parameters: a calibrated params.toml (joints and counts are printed) or a
    /// robot.toml (joints only).
    #[arg(long, value_name = "FILE")]
    params: PathBuf,
    /// CSV of targets with header x,y,z,ux,uy,uz: tip (mm) and needle direction (any length
    /// but zero) in the robot base frame Bb. Of several solutions the one nearest the home
    /// joints of docs/robot-model.md §3 is printed.
    #[arg(long, value_name = "CSV")]
    targets: PathBuf,
}

const JOINT_COLUMNS: [&str; 5] = ["q1", "q2", "q3", "q4", "q5"];
const COUNT_COLUMNS: [&str; 5] = ["c1", "c2", "c3", "c4", "c5"];
const POSE_COLUMNS: [&str; 6] = ["x", "y", "z", "ux", "uy", "uz"];

/// Runs `sabr fk`: prints `x,y,z,ux,uy,uz` (tip in mm and needle direction, in `Bb`) per row.
pub fn run_fk(args: &FkArgs) -> anyhow::Result<ExitCode> {
    let params = load_params(&args.params)?;
    let geometry = params.effective_geometry();
    let (path, columns) = match (&args.counts, &args.joints) {
        (Some(counts), _) => {
            if params.joints.offset.is_none() {
                bail!(
                    "--counts needs the joint offsets of a calibrated parameter file, and {} \
                     defines none (joints.joint_offset; a robot.toml never does): calibrate \
                     first or use --joints",
                    args.params.display()
                );
            }
            (counts, COUNT_COLUMNS)
        }
        (None, Some(joints)) => (joints, JOINT_COLUMNS),
        (None, None) => bail!("give --counts or --joints"),
    };
    let from_counts = args.counts.is_some();
    let mut reader = ColumnReader::open(path, &columns)?;
    let mut out = output();
    out.write_record(POSE_COLUMNS)?;
    let mut failures = 0;
    let mut directions = DirectionTracker::new(DIRECTION_DEAD_BAND_COUNTS as f64);
    while let Some(values) = reader.next_row()? {
        if console::silenced() {
            break;
        }
        let values: [f64; 5] = std::array::from_fn(|i| values[i]);
        let q = if from_counts {
            let motion = directions.update(&values);
            params
                .joints_from_fractional_counts(&values, &motion)
                .map_err(|error| error.to_string())
        } else {
            Ok(values)
        };
        match q.and_then(|q| pose_row(&geometry, &q)) {
            Ok(row) => out.write_record(&row)?,
            Err(reason) => {
                failures += 1;
                out.write_record(["error", reason.as_str()])?;
            }
        }
    }
    finish(out, failures, reader.rows, "joint vectors")
}

/// Runs `sabr ik`: prints `q1..q5` (rad) and, when the parameters define joint offsets,
/// `c1..c5` (fractional counts for a robot at rest) per target row. It solves with the
/// real-time kinematics, as the IK server does, so both give the same joints.
pub fn run_ik(args: &IkArgs) -> anyhow::Result<ExitCode> {
    let params = load_params(&args.params)?;
    let geometry = RealtimeGeometry::from(&params.effective_geometry());
    let with_counts = params.joints.offset.is_some();
    let mut reader = ColumnReader::open(&args.targets, &POSE_COLUMNS)?;
    let mut out = output();
    let mut header: Vec<&str> = JOINT_COLUMNS.to_vec();
    if with_counts {
        header.extend(COUNT_COLUMNS);
    }
    out.write_record(&header)?;
    let mut failures = 0;
    while let Some(v) = reader.next_row()? {
        if console::silenced() {
            break;
        }
        let tip = DVec3::new(v[0], v[1], v[2]);
        let direction = DVec3::new(v[3], v[4], v[5]);
        let row = geometry
            .inverse(tip, direction, &HOME_JOINTS)
            .map_err(|error| error.to_string())
            .and_then(|q| joints_row(&params, &q, with_counts));
        match row {
            Ok(row) => out.write_record(&row)?,
            Err(reason) => {
                failures += 1;
                out.write_record(["error", reason.as_str()])?;
            }
        }
    }
    finish(out, failures, reader.rows, "targets")
}

/// Tip and direction of FK, formatted.
fn pose_row(geometry: &Geometry, q: &Joints) -> Result<Vec<String>, String> {
    let pose = forward(geometry, q).map_err(|error| error.to_string())?;
    Ok(pose
        .tip
        .iter()
        .chain(pose.direction.iter())
        .map(f64::to_string)
        .collect())
}

/// Joints and, if asked, the counts that produce them, formatted.
fn joints_row(params: &RobotParams, q: &Joints, with_counts: bool) -> Result<Vec<String>, String> {
    let mut row: Vec<String> = q.iter().map(f64::to_string).collect();
    if with_counts {
        let counts = params
            .counts_from_joints(q, &JointMotion::default())
            .map_err(|error| error.to_string())?;
        row.extend(counts.iter().map(f64::to_string));
    }
    Ok(row)
}

/// Reads a `robot.toml` or `params.toml` with the one parameter-file reader; errors name
/// the file, the line and the field.
fn load_params(path: &Path) -> anyhow::Result<RobotParams> {
    Ok(sabr_model::read_params_file(path)?)
}

/// CSV writer on standard output (rows may be shorter than the header: error rows), through
/// [`console`]: once it is silenced (the reader left, or a write failed) the command stops
/// reading rows.
fn output() -> csv::Writer<console::Stdout> {
    csv::WriterBuilder::new()
        .flexible(true)
        .from_writer(console::Stdout)
}

/// Flushes the output and turns the failure count into the exit status.
fn finish(
    mut out: csv::Writer<impl Write>,
    failures: usize,
    rows: usize,
    what: &str,
) -> anyhow::Result<ExitCode> {
    out.flush().context("cannot write to standard output")?;
    if failures > 0 {
        errln!("sabr: {failures} of {rows} {what} have no solution (see the error rows)");
        Ok(ExitCode::FAILURE)
    } else {
        Ok(ExitCode::SUCCESS)
    }
}

/// Reads the named numeric columns of a CSV file with a header line, row by row; errors name
/// the file, line, column and reason.
struct ColumnReader {
    path: PathBuf,
    reader: csv::Reader<File>,
    names: Vec<String>,
    indices: Vec<usize>,
    record: csv::StringRecord,
    /// Rows read so far.
    rows: usize,
}

impl ColumnReader {
    fn open(path: &Path, names: &[&str]) -> anyhow::Result<Self> {
        let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
        let mut reader = csv::ReaderBuilder::new().flexible(true).from_reader(file);
        let header = reader
            .headers()
            .with_context(|| format!("{}: line 1: cannot read the header", path.display()))?
            .clone();
        let mut indices = Vec::with_capacity(names.len());
        for name in names {
            let Some(index) = header.iter().position(|column| column.trim() == *name) else {
                bail!(
                    "{}: line 1: the header has no column `{name}` (it needs {}; found {})",
                    path.display(),
                    names.join(","),
                    header.iter().collect::<Vec<_>>().join(",")
                );
            };
            indices.push(index);
        }
        Ok(Self {
            path: path.to_owned(),
            reader,
            names: names.iter().map(|name| name.to_string()).collect(),
            indices,
            record: csv::StringRecord::new(),
            rows: 0,
        })
    }

    /// The next row's values in the order of the requested names, `None` at the end.
    fn next_row(&mut self) -> anyhow::Result<Option<Vec<f64>>> {
        let more = self
            .reader
            .read_record(&mut self.record)
            .with_context(|| format!("{}: malformed CSV", self.path.display()))?;
        if !more {
            return Ok(None);
        }
        self.rows += 1;
        let line = self.record.position().map_or(0, |position| position.line());
        let mut values = Vec::with_capacity(self.indices.len());
        for (name, &index) in self.names.iter().zip(&self.indices) {
            let Some(field) = self.record.get(index) else {
                bail!(
                    "{}: line {line}: column `{name}` is missing (the row has {} fields)",
                    self.path.display(),
                    self.record.len()
                );
            };
            let value = field.trim().parse::<f64>().with_context(|| {
                format!(
                    "{}: line {line}: column `{name}`: `{field}` is not a number",
                    self.path.display()
                )
            })?;
            values.push(value);
        }
        Ok(Some(values))
    }
}
