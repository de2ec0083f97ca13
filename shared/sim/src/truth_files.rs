//! The truth on disk, `DIR/truth/`: `params.toml` (true model), `effects.toml` (effects,
//! tracker truth incl. latency and `T_S_M`, stops, power-up pose), `validation.csv` (true tip
//! at each validation hold) and `frames.csv` (exposure and arrival of every tracker frame).
//! Every file is created new: nothing is overwritten.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use sabr_model::RobotParams;
use sabr_recording::{write_all, Recording};
use serde::{Deserialize, Serialize};

use crate::effect_spec::SimEffect;
use crate::session::{FrameTruth, Truth, ValidationTruth};
use crate::tracker::TrackerTruth;
use crate::truth::{RobotTruth, ThermalDrift};
use crate::SimError;

/// Name of the truth directory inside a recording directory.
pub const TRUTH_DIR: &str = "truth";
const PARAMS_FILE: &str = "params.toml";
const EFFECTS_FILE: &str = "effects.toml";
const VALIDATION_FILE: &str = "validation.csv";
const FRAMES_FILE: &str = "frames.csv";
const VALIDATION_HEADER: &str = "t_start_ns,t_end_ns,x,y,z,ux,uy,uz,q1,q2,q3,q4,q5,c1,c2,c3,c4,c5";
const FRAMES_HEADER: &str = "frame,exposure_t_ns,arrival_t_ns";

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

fn join<T: ToString>(values: impl IntoIterator<Item = T>) -> String {
    values
        .into_iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(",")
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

        let mut csv = String::from(VALIDATION_HEADER);
        csv.push('\n');
        for v in &self.validation {
            let numbers = [v.tip.x, v.tip.y, v.tip.z]
                .into_iter()
                .chain(triple(&v.direction))
                .chain(v.joints);
            csv.push_str(&format!(
                "{},{},{},{}\n",
                v.t_start_ns,
                v.t_end_ns,
                join(numbers),
                join(v.counts)
            ));
        }
        create_new(&dir.join(VALIDATION_FILE), &csv)?;

        let mut csv = String::from(FRAMES_HEADER);
        csv.push('\n');
        for f in &self.frames {
            let arrival = f.arrival_ns.map_or(String::new(), |t| t.to_string());
            csv.push_str(&format!("{},{},{arrival}\n", f.frame, f.exposure_ns));
        }
        create_new(&dir.join(FRAMES_FILE), &csv)
    }

    /// Reads a truth directory written by [`Truth::write_dir`].
    pub fn read_dir(dir: &Path) -> Result<Truth, SimError> {
        let params_path = dir.join(PARAMS_FILE);
        let params =
            RobotParams::from_toml_str(&read(&params_path)?).map_err(|e| SimError::TruthFile {
                path: params_path.clone(),
                line: 0,
                reason: e.to_string(),
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
            },
            effects,
            tracker,
            host_start_ns: file.host_start_ns,
            validation: read_validation(&dir.join(VALIDATION_FILE))?,
            frames: read_frames(&dir.join(FRAMES_FILE))?,
        })
    }
}

fn read(path: &Path) -> Result<String, SimError> {
    fs::read_to_string(path).map_err(io_error(path, "read"))
}

/// The data lines of a CSV file with their 1-based line numbers, after checking the header.
fn csv_lines(path: &Path, header: &str) -> Result<Vec<(u64, Vec<String>)>, SimError> {
    let text = read(path)?;
    let mut lines = text.lines();
    if lines.next() != Some(header) {
        return Err(SimError::TruthFile {
            path: path.to_path_buf(),
            line: 1,
            reason: format!("expected the header `{header}`"),
        });
    }
    let width = header.split(',').count();
    lines
        .enumerate()
        .map(|(index, line)| {
            let number = index as u64 + 2;
            let fields: Vec<String> = line.split(',').map(str::to_string).collect();
            if fields.len() < width {
                return Err(SimError::TruthFile {
                    path: path.to_path_buf(),
                    line: number,
                    reason: format!("expected {width} fields, found {}", fields.len()),
                });
            }
            Ok((number, fields))
        })
        .collect()
}

fn field<T: std::str::FromStr>(
    path: &Path,
    line: u64,
    fields: &[String],
    index: usize,
    header: &str,
) -> Result<T, SimError> {
    fields[index].parse().map_err(|_| SimError::TruthFile {
        path: path.to_path_buf(),
        line,
        reason: format!(
            "field `{}` = `{}` is not a valid number",
            header.split(',').nth(index).unwrap_or("?"),
            fields[index]
        ),
    })
}

fn read_validation(path: &Path) -> Result<Vec<ValidationTruth>, SimError> {
    let get =
        |line, fields: &[String], index| field::<f64>(path, line, fields, index, VALIDATION_HEADER);
    csv_lines(path, VALIDATION_HEADER)?
        .into_iter()
        .map(|(line, fields)| {
            let int = |index| field::<i64>(path, line, &fields, index, VALIDATION_HEADER);
            let mut joints = [0.0; 5];
            let mut counts = [0; 5];
            for i in 0..5 {
                joints[i] = get(line, &fields, 8 + i)?;
                counts[i] = int(13 + i)?;
            }
            Ok(ValidationTruth {
                t_start_ns: int(0)?,
                t_end_ns: int(1)?,
                tip: Point3::new(
                    get(line, &fields, 2)?,
                    get(line, &fields, 3)?,
                    get(line, &fields, 4)?,
                ),
                direction: Vector3::new(
                    get(line, &fields, 5)?,
                    get(line, &fields, 6)?,
                    get(line, &fields, 7)?,
                ),
                joints,
                counts,
            })
        })
        .collect()
}

fn read_frames(path: &Path) -> Result<Vec<FrameTruth>, SimError> {
    csv_lines(path, FRAMES_HEADER)?
        .into_iter()
        .map(|(line, fields)| {
            Ok(FrameTruth {
                frame: field(path, line, &fields, 0, FRAMES_HEADER)?,
                exposure_ns: field(path, line, &fields, 1, FRAMES_HEADER)?,
                arrival_ns: if fields[2].is_empty() {
                    None
                } else {
                    Some(field(path, line, &fields, 2, FRAMES_HEADER)?)
                },
            })
        })
        .collect()
}

/// Writes a recording (format v1) to `dir` and its truth to `dir/truth/`. `dir` must not
/// already hold a recording or a truth: nothing is overwritten.
pub fn write_session(dir: &Path, recording: &Recording, truth: &Truth) -> Result<(), SimError> {
    write_all(recording, dir)?;
    truth.write_dir(&truth_dir(dir))
}

/// The truth directory of the recording directory `dir`.
pub fn truth_dir(dir: &Path) -> PathBuf {
    dir.join(TRUTH_DIR)
}
