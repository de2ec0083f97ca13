//! Writing the calibration outputs atomically: each file is written to a temporary file in
//! the output directory, synced, then renamed over the target.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::report::html;
use crate::report::Report;

/// Why the outputs could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot {action}: {source}", path.display())]
pub struct OutputError {
    /// The file or directory.
    pub path: PathBuf,
    /// What was being done.
    pub action: &'static str,
    /// The cause.
    pub source: std::io::Error,
}

/// Writes `contents` to `path` atomically (temporary file + rename in the same directory).
pub fn write_atomically(path: &Path, contents: &[u8]) -> Result<(), OutputError> {
    let error = |action| {
        move |source| OutputError {
            path: path.to_path_buf(),
            action,
            source,
        }
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let temporary = path.with_file_name(format!(".{name}.tmp{}", std::process::id()));
    let mut file =
        std::fs::File::create(&temporary).map_err(error("create a temporary file for"))?;
    file.write_all(contents).map_err(error("write"))?;
    file.sync_all().map_err(error("sync"))?;
    drop(file);
    std::fs::rename(&temporary, path).map_err(error("rename the temporary file onto"))
}

/// The calibrated model's prediction at one validation hold (in `Bb`).
#[derive(Debug, Clone, PartialEq)]
pub struct HoldPrediction {
    /// Mean encoder counts of the hold.
    pub counts: [f64; 5],
    /// Predicted tip (mm).
    pub tip: [f64; 3],
    /// Predicted needle direction `z_N` (unit).
    pub direction: [f64; 3],
}

/// The validation predictions as CSV: `c1..c5` (mean counts of each hold) then the predicted
/// tip `x,y,z` (mm) and direction `ux,uy,uz`, in the input/output format of `sabr fk`.
pub fn predictions_csv(predictions: &[HoldPrediction]) -> String {
    let mut text = String::from("c1,c2,c3,c4,c5,x,y,z,ux,uy,uz\n");
    for p in predictions {
        let fields: Vec<String> = p
            .counts
            .iter()
            .chain(&p.tip)
            .chain(&p.direction)
            .map(|v| v.to_string())
            .collect();
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    text
}

/// Writes `params.toml` (the text `params_toml`), `report.json`, `report.html` and
/// `validation_predictions.csv` into `dir` (created if needed).
pub fn write_outputs(
    params_toml: &str,
    report: &Report,
    predictions: &[HoldPrediction],
    dir: &Path,
) -> Result<(), OutputError> {
    std::fs::create_dir_all(dir).map_err(|source| OutputError {
        path: dir.to_path_buf(),
        action: "create the output directory",
        source,
    })?;
    write_atomically(&dir.join("params.toml"), params_toml.as_bytes())?;
    let json = serde_json::to_string_pretty(report).map_err(|e| OutputError {
        path: dir.join("report.json"),
        action: "serialise",
        source: std::io::Error::other(e),
    })?;
    write_atomically(&dir.join("report.json"), json.as_bytes())?;
    write_atomically(&dir.join("report.html"), html::render(report).as_bytes())?;
    write_atomically(
        &dir.join("validation_predictions.csv"),
        predictions_csv(predictions).as_bytes(),
    )
}
