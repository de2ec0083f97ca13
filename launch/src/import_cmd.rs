//! `sabr import ipa SERIES_DIR... --out REC`: converts series of the UR10 laser-tracker data
//! set (ipa-robot-accuracy) into one poses-v1 recording.
//!
//! - Each series directory holds one `measurements_*.csv` (`;` separators, `,` decimal
//!   marks), `Trafo_TM_F_init.txt` and, for some series, `calibration_handeye.csv`.
//! - Sequence = the series directory's name; order index = the row's position in its file.
//! - Set-up rule: one set-up per tracker placement. The authors measured a hand-eye set
//!   (`calibration_handeye.csv`) once per placement, so series whose hand-eye files are
//!   byte-identical share a set-up (in the published data: B and C), and a series without
//!   one has its own (A). `--setup SERIES=NAME` overrides the rule for a series.
//! - The target `tmac` (the T-Mac probe) is measured as a pose: position (mm) and
//!   orientation from `measurement_rx/ry/rz`, degrees, intrinsic X-Y-Z (`R = Rx·Ry·Rz`, as
//!   the authors' `dataset.py` reads them). Standard deviations when the file has them (A
//!   has none; the angular ones are converted from degrees to rad). Temperature from
//!   `measurement_temperature`.
//! - Nominal mounting of the probe on `tool0` (the flange): `Trafo_TM_F_init.txt` is
//!   `T_TM_F`, the flange in the probe's frame (mm; row-major, 3 or 4 rows), so the mounting
//!   `T_F_TM` is its inverse (the probe sits 109 mm out along the flange's z axis).
//! - The commanded `Goal` poses and the spreadsheet-mangled time stamps are not imported.

use sabr_node::{errln, outln};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use sabr_model::KinematicTree;
use sabr_recording::poses::{
    Measured, PoseRow, PosesRecording, PosesRobot, Target, TargetMeasurement,
};

use sabr_launcher::create_out_dir;

/// The UR10 description the importer copies into the recording unless `--urdf` is given.
const UR10_URDF: &str = include_str!("../../shared/model/robots/ur10.urdf");
/// File name of the URDF inside the recording.
const URDF_FILE: &str = "robot.urdf";
/// The measured target and the link it is mounted on.
const TARGET: &str = "tmac";
const TARGET_LINK: &str = "tool0";
/// The probe's initial mounting file and the hand-eye set of a series.
const MOUNTING_FILE: &str = "Trafo_TM_F_init.txt";
const HAND_EYE_FILE: &str = "calibration_handeye.csv";

/// Arguments of `sabr import`.
#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    #[command(subcommand)]
    source: ImportSource,
}

#[derive(Debug, clap::Subcommand)]
enum ImportSource {
    /// The UR10 laser-tracker data set (ipa-robot-accuracy): one or more series directories.
    Ipa(IpaArgs),
}

/// Arguments of `sabr import ipa`.
#[derive(Debug, clap::Args)]
struct IpaArgs {
    /// Series directories (e.g. `Series_A`), each with one `measurements_*.csv`.
    #[arg(required = true, value_name = "SERIES_DIR")]
    series: Vec<PathBuf>,
    /// Output recording directory (poses v1): must be absent or empty.
    #[arg(long, value_name = "REC")]
    out: PathBuf,
    /// Put series SERIES (its directory name) in set-up NAME, overriding the hand-eye rule
    /// (repeatable).
    #[arg(long = "setup", value_name = "SERIES=NAME", value_parser = parse_setup)]
    setups: Vec<(String, String)>,
    /// The robot's URDF (default: the UR10 description shipped with SABR); its joint
    /// variables must be columns of the measurement files.
    #[arg(long, value_name = "FILE")]
    urdf: Option<PathBuf>,
}

fn parse_setup(text: &str) -> Result<(String, String), String> {
    match text.split_once('=') {
        Some((series, setup)) if !series.is_empty() && !setup.is_empty() => {
            Ok((series.to_owned(), setup.to_owned()))
        }
        _ => Err(format!("{text:?} is not SERIES=NAME")),
    }
}

/// Runs `sabr import ...`.
pub fn run(args: &ImportArgs) -> anyhow::Result<ExitCode> {
    match &args.source {
        ImportSource::Ipa(ipa) => run_ipa(ipa),
    }
}

/// One series directory, read.
struct Series {
    name: String,
    dir: PathBuf,
    hand_eye: Option<Vec<u8>>,
    mounting: Isometry3<f64>,
}

fn run_ipa(args: &IpaArgs) -> anyhow::Result<ExitCode> {
    let urdf_text = match &args.urdf {
        Some(path) => std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the URDF", path.display()))?,
        None => UR10_URDF.to_owned(),
    };
    let tree = KinematicTree::from_urdf_str(&urdf_text).context("the robot description")?;
    tree.link_id(TARGET_LINK).context("the probe's link")?;
    let joints: Vec<String> = tree.variables().iter().map(|v| v.name.clone()).collect();

    let series = args
        .series
        .iter()
        .map(|dir| read_series(dir))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let setups = assign_setups(&series, &args.setups)?;
    let mounting = series[0].mounting;
    for other in &series[1..] {
        let apart = (other.mounting.inverse() * mounting)
            .translation
            .vector
            .norm();
        if apart > 1e-6 || other.mounting.rotation.angle_to(&mounting.rotation) > 1e-9 {
            bail!(
                "{} differs from {}: the recording has one probe mounting, import these series separately",
                other.dir.join(MOUNTING_FILE).display(),
                series[0].dir.join(MOUNTING_FILE).display()
            );
        }
    }

    let mut rows = Vec::new();
    for (one, setup) in series.iter().zip(&setups) {
        let path = measurement_file(&one.dir)?;
        let before = rows.len();
        read_measurements(&path, &joints, setup, &one.name, &mut rows)?;
        errln!(
            "{}: {} poses, set-up {setup}",
            path.display(),
            rows.len() - before
        );
    }

    let target = Target {
        name: TARGET.into(),
        link: TARGET_LINK.into(),
        measured: Measured::Pose,
        mounting_translation: Some(mounting.translation.vector.into()),
        mounting_rotation: Some(mounting.rotation.scaled_axis().into()),
    };
    let recording = PosesRecording {
        dir: args.out.clone(),
        robot: PosesRobot::new(URDF_FILE, vec![target]),
        urdf_text,
        joints,
        rows,
    };
    let out = create_out_dir(Some(args.out.clone()), "import")?;
    recording.write(&out)?;
    outln!("{}: {} poses", out.display(), recording.rows.len());
    Ok(ExitCode::SUCCESS)
}

fn read_series(dir: &Path) -> anyhow::Result<Series> {
    let name = dir
        .canonicalize()
        .with_context(|| format!("{}: cannot open the series directory", dir.display()))?
        .file_name()
        .and_then(|n| n.to_str())
        .map(str::to_owned)
        .with_context(|| format!("{}: the series directory needs a name", dir.display()))?;
    let hand_eye_path = dir.join(HAND_EYE_FILE);
    let hand_eye = match std::fs::read(&hand_eye_path) {
        Ok(bytes) => Some(bytes),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => {
            return Err(e).with_context(|| format!("{}: cannot read", hand_eye_path.display()))
        }
    };
    let mounting = read_mounting(&dir.join(MOUNTING_FILE))?;
    Ok(Series {
        name,
        dir: dir.to_path_buf(),
        hand_eye,
        mounting,
    })
}

/// The set-up of each series: `--setup` first, else shared by identical hand-eye files.
fn assign_setups(series: &[Series], overrides: &[(String, String)]) -> anyhow::Result<Vec<String>> {
    for (name, _) in overrides {
        if !series.iter().any(|s| &s.name == name) {
            bail!("--setup {name}=…: no series directory is named {name}");
        }
    }
    let mut groups: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (i, one) in series.iter().enumerate() {
        let first = match &one.hand_eye {
            Some(bytes) => series
                .iter()
                .position(|other| other.hand_eye.as_ref() == Some(bytes))
                .expect("the series itself matches"),
            None => i,
        };
        groups.entry(first).or_default().push(i);
    }
    let mut setups = vec![String::new(); series.len()];
    for members in groups.values() {
        let joined = members
            .iter()
            .map(|&i| series[i].name.as_str())
            .collect::<Vec<_>>()
            .join("+");
        for &i in members {
            let reason = if members.len() > 1 {
                "identical hand-eye sets: one tracker placement"
            } else if series[i].hand_eye.is_some() {
                "its own hand-eye set"
            } else {
                "no hand-eye set: its own placement"
            };
            setups[i] = match overrides
                .iter()
                .rev()
                .find(|(name, _)| name == &series[i].name)
            {
                Some((_, setup)) => {
                    errln!("{}: set-up {setup} (--setup)", series[i].name);
                    setup.clone()
                }
                None => {
                    errln!("{}: set-up {joined} ({reason})", series[i].name);
                    joined.clone()
                }
            };
        }
    }
    Ok(setups)
}

/// The series' one `measurements_*.csv`.
fn measurement_file(dir: &Path) -> anyhow::Result<PathBuf> {
    let mut found = Vec::new();
    for entry in
        std::fs::read_dir(dir).with_context(|| format!("{}: cannot list", dir.display()))?
    {
        let path = entry
            .with_context(|| format!("{}: cannot list", dir.display()))?
            .path();
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        if name.starts_with("measurements_") && name.ends_with(".csv") {
            found.push(path);
        }
    }
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => bail!(
            "{}: no measurements_*.csv in the series directory",
            dir.display()
        ),
        _ => bail!(
            "{}: more than one measurements_*.csv: {found:?}",
            dir.display()
        ),
    }
}

/// `T_F_TM` (mm) from the file of `T_TM_F`: a 3×4 or 4×4 row-major matrix.
fn read_mounting(path: &Path) -> anyhow::Result<Isometry3<f64>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let mut rows = Vec::new();
    for (i, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let values = line
            .split_whitespace()
            .map(|v| v.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<Vec<_>>>();
        match values {
            Some(values) if values.len() == 4 => rows.push(values),
            _ => bail!(
                "{} line {}: expected four numbers, found {line:?}",
                path.display(),
                i + 1
            ),
        }
    }
    if !(rows.len() == 3 || (rows.len() == 4 && rows[3] == [0.0, 0.0, 0.0, 1.0])) {
        bail!(
            "{}: expected 3 rows, or 4 ending in `0 0 0 1`",
            path.display()
        );
    }
    let matrix = Matrix3::from_fn(|r, c| rows[r][c]);
    let orthonormal = (matrix.transpose() * matrix - Matrix3::identity()).norm() < 1e-4;
    if !orthonormal || matrix.determinant() < 0.0 {
        bail!("{}: the 3×3 part is not a rotation", path.display());
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&matrix));
    let translation = Translation3::new(rows[0][3], rows[1][3], rows[2][3]);
    Ok(Isometry3::from_parts(translation, rotation).inverse())
}

/// The columns of a measurement file that the importer reads.
struct Columns {
    joints: Vec<usize>,
    position: [usize; 3],
    angles: [usize; 3],
    position_std: Option<[usize; 3]>,
    angle_std: Option<[usize; 3]>,
    temperature: Option<usize>,
}

impl Columns {
    fn find(names: &[&str], joints: &[String]) -> Result<Columns, String> {
        let find = |name: &str| names.iter().position(|&n| n == name);
        let require = |name: &str| find(name).ok_or_else(|| format!("missing column `{name}`"));
        let three = |names: [&str; 3]| -> Result<[usize; 3], String> {
            Ok([require(names[0])?, require(names[1])?, require(names[2])?])
        };
        let optional_three = |names: [&str; 3]| -> Result<Option<[usize; 3]>, String> {
            if names.iter().all(|n| find(n).is_none()) {
                Ok(None)
            } else {
                three(names).map(Some)
            }
        };
        Ok(Columns {
            joints: joints
                .iter()
                .map(|j| require(j))
                .collect::<Result<_, _>>()?,
            position: three(["measurement_x", "measurement_y", "measurement_z"])?,
            angles: three(["measurement_rx", "measurement_ry", "measurement_rz"])?,
            position_std: optional_three([
                "measurement_std_x",
                "measurement_std_y",
                "measurement_std_z",
            ])?,
            angle_std: optional_three([
                "measurement_std_rx",
                "measurement_std_ry",
                "measurement_std_rz",
            ])?,
            temperature: find("measurement_temperature"),
        })
    }
}

/// Reads one series' measurement file into rows of set-up `setup` and sequence `sequence`.
fn read_measurements(
    path: &Path,
    joints: &[String],
    setup: &str,
    sequence: &str,
    rows: &mut Vec<PoseRow>,
) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .with_context(|| format!("{} line 1: empty file", path.display()))?
        .split(';')
        .map(str::trim)
        .collect();
    let columns = Columns::find(&header, joints)
        .map_err(|e| anyhow::anyhow!("{} line 1: {e}", path.display()))?;
    for (i, line) in lines.enumerate() {
        let line_number = i + 2;
        let fields: Vec<&str> = line.split(';').collect();
        let number = |column: usize| -> anyhow::Result<f64> {
            let name = header[column];
            let Some(text) = fields.get(column) else {
                bail!(
                    "{} line {line_number}: field `{name}`: missing (the row has {} fields)",
                    path.display(),
                    fields.len()
                );
            };
            match text.trim().replace(',', ".").parse::<f64>() {
                Ok(value) if value.is_finite() => Ok(value),
                _ => bail!(
                    "{} line {line_number}: field `{name}`: {text:?} is not a number",
                    path.display()
                ),
            }
        };
        let triple = |columns: [usize; 3]| -> anyhow::Result<[f64; 3]> {
            Ok([
                number(columns[0])?,
                number(columns[1])?,
                number(columns[2])?,
            ])
        };
        let angles = triple(columns.angles)?.map(f64::to_radians);
        // Intrinsic X-Y-Z: R = Rx(a) · Ry(b) · Rz(c).
        let rotation = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), angles[0])
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), angles[1])
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angles[2]);
        let q = rotation.into_inner();
        let measurement = TargetMeasurement {
            position_mm: triple(columns.position)?,
            orientation: Some([q.w, q.i, q.j, q.k]),
            position_std_mm: columns.position_std.map(triple).transpose()?,
            orientation_std_rad: columns
                .angle_std
                .map(|c| triple(c).map(|s| s.map(f64::to_radians)))
                .transpose()?,
        };
        rows.push(PoseRow {
            line: 0,
            setup: setup.to_owned(),
            sequence: sequence.to_owned(),
            index: i as u64,
            joints: columns
                .joints
                .iter()
                .map(|&c| number(c))
                .collect::<anyhow::Result<_>>()?,
            targets: vec![Some(measurement)],
            temperature_c: columns.temperature.map(number).transpose()?,
        });
    }
    Ok(())
}
