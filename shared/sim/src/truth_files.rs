//! The truth on disk, `DIR/truth/`: `params.toml` (true model), `effects.toml` (effects,
//! tracker truth incl. latency and `T_S_M`, stops, power-up pose), `validation.csv` (true tip
//! at each validation hold) and `frames.csv` (exposure and arrival of every tracker frame).
//! Every file is created new: nothing is overwritten. The CSV files are written and read
//! with `csv` + serde, one row struct per file.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use sabr_model::{read_params_file, ParamsFileError};
use sabr_recording::{write_all, Recording};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::effect_spec::SimEffect;
use crate::session::{FrameTruth, Truth, ValidationTruth};
use crate::tracker::TrackerTruth;
use crate::truth::{needle_sag_mm, LinkDrift, RobotTruth, ThermalDrift};
use crate::SimError;

/// Name of the truth directory inside a recording directory.
pub const TRUTH_DIR: &str = "truth";
const PARAMS_FILE: &str = "params.toml";
const EFFECTS_FILE: &str = "effects.toml";
const VALIDATION_FILE: &str = "validation.csv";
const FRAMES_FILE: &str = "frames.csv";

/// One row of `validation.csv`: a validation hold, its true tip (mm, `Bb`), needle direction,
/// joints (rad) and counts.
#[derive(Debug, Serialize, Deserialize)]
struct ValidationRow {
    t_start_ns: i64,
    t_end_ns: i64,
    x: f64,
    y: f64,
    z: f64,
    ux: f64,
    uy: f64,
    uz: f64,
    q1: f64,
    q2: f64,
    q3: f64,
    q4: f64,
    q5: f64,
    c1: i64,
    c2: i64,
    c3: i64,
    c4: i64,
    c5: i64,
}

/// The columns of `validation.csv`, in order.
const VALIDATION_COLUMNS: [&str; 18] = [
    "t_start_ns",
    "t_end_ns",
    "x",
    "y",
    "z",
    "ux",
    "uy",
    "uz",
    "q1",
    "q2",
    "q3",
    "q4",
    "q5",
    "c1",
    "c2",
    "c3",
    "c4",
    "c5",
];

impl From<&ValidationTruth> for ValidationRow {
    fn from(v: &ValidationTruth) -> Self {
        let [q1, q2, q3, q4, q5] = v.joints;
        let [c1, c2, c3, c4, c5] = v.counts;
        ValidationRow {
            t_start_ns: v.t_start_ns,
            t_end_ns: v.t_end_ns,
            x: v.tip.x,
            y: v.tip.y,
            z: v.tip.z,
            ux: v.direction.x,
            uy: v.direction.y,
            uz: v.direction.z,
            q1,
            q2,
            q3,
            q4,
            q5,
            c1,
            c2,
            c3,
            c4,
            c5,
        }
    }
}

impl From<ValidationRow> for ValidationTruth {
    fn from(r: ValidationRow) -> Self {
        ValidationTruth {
            t_start_ns: r.t_start_ns,
            t_end_ns: r.t_end_ns,
            tip: Point3::new(r.x, r.y, r.z),
            direction: Vector3::new(r.ux, r.uy, r.uz),
            joints: [r.q1, r.q2, r.q3, r.q4, r.q5],
            counts: [r.c1, r.c2, r.c3, r.c4, r.c5],
        }
    }
}

/// One row of `frames.csv`: a tracker frame's exposure and arrival (host ns; no arrival for
/// a dropped frame).
#[derive(Debug, Serialize, Deserialize)]
struct FrameRow {
    frame: u32,
    exposure_t_ns: i64,
    arrival_t_ns: Option<i64>,
}

/// The columns of `frames.csv`, in order.
const FRAMES_COLUMNS: [&str; 3] = ["frame", "exposure_t_ns", "arrival_t_ns"];

#[derive(Debug, Serialize, Deserialize)]
struct EffectsFile {
    /// Injected effects in the command-line syntax (joints 1..5).
    effects: Vec<String>,
    /// Host clock at power-up (ns).
    host_start_ns: i64,
    robot: RobotSection,
    tracker: TrackerSection,
}

#[derive(Debug, Serialize, Deserialize)]
struct RobotSection {
    true_stops: [f64; 5],
    stop_side: [f64; 5],
    power_up_joints: [f64; 5],
}

#[derive(Debug, Serialize, Deserialize)]
struct TrackerSection {
    /// Total mean latency exposure→arrival (ms) = base + extra.
    latency_ms: f64,
    base_latency_ms: f64,
    extra_latency_ms: f64,
    period_ns: f64,
    first_exposure_after_power_up_ns: i64,
    first_frame: u32,
    frame_increment: u32,
    fit_rms_mm: [f64; 3],
    /// `T_S_M` translation (mm) and rotation vector (rad).
    tracker_to_base_translation: [f64; 3],
    tracker_to_base_rotation: [f64; 3],
}

fn io_error(path: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> SimError {
    let path = path.to_path_buf();
    move |source| SimError::Io {
        path,
        action,
        source,
    }
}

fn create_new(path: &Path, text: &str) -> Result<(), SimError> {
    let file = File::create_new(path).map_err(io_error(path, "create"))?;
    let mut writer = BufWriter::new(file);
    writer
        .write_all(text.as_bytes())
        .and_then(|()| writer.flush())
        .map_err(io_error(path, "write"))
}

fn triple(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

impl Truth {
    /// Writes the truth into `dir` (made if absent); refuses to overwrite existing files.
    pub fn write_dir(&self, dir: &Path) -> Result<(), SimError> {
        fs::create_dir_all(dir).map_err(io_error(dir, "create the directory"))?;
        create_new(&dir.join(PARAMS_FILE), &self.robot.params.to_toml_string())?;

        let tracker = &self.tracker;
        let pose = &tracker.tracker_from_base;
        let file = EffectsFile {
            effects: self.effects.iter().map(ToString::to_string).collect(),
            host_start_ns: self.host_start_ns,
            robot: RobotSection {
                true_stops: self.robot.stops,
                stop_side: self.robot.stop_side,
                power_up_joints: self.robot.power_up_joints,
            },
            tracker: TrackerSection {
                latency_ms: tracker.latency_ms(),
                base_latency_ms: tracker.base_latency_ms,
                extra_latency_ms: tracker.extra_latency_ms,
                period_ns: tracker.period_ns,
                first_exposure_after_power_up_ns: tracker.first_exposure_ns,
                first_frame: tracker.first_frame,
                frame_increment: tracker.frame_increment,
                fit_rms_mm: tracker.fit_rms_mm,
                tracker_to_base_translation: triple(&pose.translation.vector),
                tracker_to_base_rotation: triple(&pose.rotation.scaled_axis()),
            },
        };
        let text = toml::to_string(&file)
            .map_err(|e| SimError::Config(format!("cannot serialise the truth: {e}")))?;
        create_new(&dir.join(EFFECTS_FILE), &text)?;

        write_csv(
            &dir.join(VALIDATION_FILE),
            self.validation.iter().map(ValidationRow::from),
        )?;
        write_csv(
            &dir.join(FRAMES_FILE),
            self.frames.iter().map(|f| FrameRow {
                frame: f.frame,
                exposure_t_ns: f.exposure_ns,
                arrival_t_ns: f.arrival_ns,
            }),
        )
    }

    /// Reads a truth directory written by [`Truth::write_dir`].
    pub fn read_dir(dir: &Path) -> Result<Truth, SimError> {
        let params_path = dir.join(PARAMS_FILE);
        let params = read_params_file(&params_path).map_err(|error| match error {
            ParamsFileError::Read { path, source } => SimError::Io {
                path,
                action: "read",
                source,
            },
            ParamsFileError::Invalid { path, line, source } => SimError::TruthFile {
                path,
                line: line.map_or(0, |l| l as u64),
                reason: source.to_string(),
            },
        })?;
        let effects_path = dir.join(EFFECTS_FILE);
        let file: EffectsFile =
            toml::from_str(&read(&effects_path)?).map_err(|e| SimError::TruthFile {
                path: effects_path.clone(),
                line: 0,
                reason: e.to_string(),
            })?;
        let effects = file
            .effects
            .iter()
            .map(|spec| spec.parse::<SimEffect>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| SimError::TruthFile {
                path: effects_path.clone(),
                line: 0,
                reason: e.to_string(),
            })?;
        let thermal = ThermalDrift::all_in(&effects);
        let t = &file.tracker;
        let tracker = TrackerTruth {
            tracker_from_base: Isometry3::from_parts(
                Translation3::from(Vector3::from(t.tracker_to_base_translation)),
                UnitQuaternion::from_scaled_axis(Vector3::from(t.tracker_to_base_rotation)),
            ),
            base_latency_ms: t.base_latency_ms,
            extra_latency_ms: t.extra_latency_ms,
            period_ns: t.period_ns,
            first_exposure_ns: t.first_exposure_after_power_up_ns,
            first_frame: t.first_frame,
            frame_increment: t.frame_increment,
            fit_rms_mm: t.fit_rms_mm,
        };
        Ok(Truth {
            robot: RobotTruth {
                params,
                stops: file.robot.true_stops,
                stop_side: file.robot.stop_side,
                power_up_joints: file.robot.power_up_joints,
                thermal,
                link_drift: LinkDrift::all_in(&effects),
                needle_sag_mm: needle_sag_mm(&effects),
            },
            effects,
            tracker,
            host_start_ns: file.host_start_ns,
            validation: read_csv::<ValidationRow>(&dir.join(VALIDATION_FILE), &VALIDATION_COLUMNS)?
                .into_iter()
                .map(ValidationTruth::from)
                .collect(),
            frames: read_csv::<FrameRow>(&dir.join(FRAMES_FILE), &FRAMES_COLUMNS)?
                .into_iter()
                .map(|r| FrameTruth {
                    frame: r.frame,
                    exposure_ns: r.exposure_t_ns,
                    arrival_ns: r.arrival_t_ns,
                })
                .collect(),
        })
    }
}

fn read(path: &Path) -> Result<String, SimError> {
    fs::read_to_string(path).map_err(io_error(path, "read"))
}

/// Writes `rows` as a new CSV file at `path`, with the header of the row struct.
fn write_csv<T: Serialize>(path: &Path, rows: impl IntoIterator<Item = T>) -> Result<(), SimError> {
    let file = File::create_new(path).map_err(io_error(path, "create"))?;
    let mut writer = csv::Writer::from_writer(BufWriter::new(file));
    for row in rows {
        writer.serialize(row).map_err(|e| csv_error(path, &[], e))?;
    }
    writer.flush().map_err(io_error(path, "write"))
}

/// Every row of the CSV file at `path`, after checking its header is `columns`.
fn read_csv<T: DeserializeOwned>(path: &Path, columns: &[&str]) -> Result<Vec<T>, SimError> {
    let file = File::open(path).map_err(io_error(path, "read"))?;
    let mut reader = csv::Reader::from_reader(std::io::BufReader::new(file));
    let header = reader.headers().map_err(|e| csv_error(path, columns, e))?;
    if !header.iter().eq(columns.iter().copied()) {
        return Err(SimError::TruthFile {
            path: path.to_path_buf(),
            line: 1,
            reason: format!("expected the header `{}`", columns.join(",")),
        });
    }
    reader
        .deserialize()
        .map(|row| row.map_err(|e| csv_error(path, columns, e)))
        .collect()
}

/// A CSV error as a [`SimError`] naming the file, the line and the column.
fn csv_error(path: &Path, columns: &[&str], error: csv::Error) -> SimError {
    let line = error.position().map_or(0, csv::Position::line);
    let message = error.to_string();
    let reason = match error.into_kind() {
        csv::ErrorKind::Io(source) => {
            return SimError::Io {
                path: path.to_path_buf(),
                action: "read or write",
                source,
            }
        }
        csv::ErrorKind::Deserialize { err, .. } => {
            let column = err
                .field()
                .and_then(|index| columns.get(index as usize))
                .map_or(String::new(), |name| format!("field `{name}`: "));
            format!("{column}{}", err.kind())
        }
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("expected {expected_len} fields, found {len}"),
        _ => message,
    };
    SimError::TruthFile {
        path: path.to_path_buf(),
        line,
        reason,
    }
}

/// Writes a recording (format v2) to `dir` and its truth to `dir/truth/`. `dir` must not
/// already hold a recording or a truth: nothing is overwritten.
pub fn write_session(dir: &Path, recording: &Recording, truth: &Truth) -> Result<(), SimError> {
    write_all(recording, dir)?;
    truth.write_dir(&truth_dir(dir))
}

/// The truth directory of the recording directory `dir`.
pub fn truth_dir(dir: &Path) -> PathBuf {
    dir.join(TRUTH_DIR)
}
