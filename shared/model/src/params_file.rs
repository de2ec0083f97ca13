//! The one reader of parameter files (`robot.toml` of the biopsy robot, a calibrated
//! `params.toml`): the IK solver, the synchroniser, the recorder, the calibrator and the
//! command line all read them here, so a bad file is reported the same way everywhere —
//! the file, the line, the field and the reason.

use crate::params::{ParamsError, RobotParams};
use std::path::{Path, PathBuf};

/// Why a parameter file could not be used; names the file, the line (when known) and the
/// reason.
#[derive(Debug, thiserror::Error)]
pub enum ParamsFileError {
    /// The file could not be read.
    #[error("{}: cannot read parameter file: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a valid parameter file.
    #[error("{}{}: {source}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line of the offending text, when the file shows it.
        line: Option<usize>,
        /// The parser's or validator's error (with the field for a value error).
        source: ParamsError,
    },
}

impl ParamsFileError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            ParamsFileError::Read { path, .. } | ParamsFileError::Invalid { path, .. } => path,
        }
    }
}

/// Reads and validates the parameter file at `path`.
pub fn read_params_file(path: &Path) -> Result<RobotParams, ParamsFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| ParamsFileError::Read {
        path: path.to_owned(),
        source,
    })?;
    parse_params_file(path, &text)
}

/// Parses and validates `text`, the contents of the parameter file at `path` (already read,
/// e.g. the `robot.toml` of a recording held in memory).
pub fn parse_params_file(path: &Path, text: &str) -> Result<RobotParams, ParamsFileError> {
    RobotParams::from_toml_str(text).map_err(|source| ParamsFileError::Invalid {
        path: path.to_owned(),
        line: source.line_in(text),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn invalid(text: &str) -> (Option<usize>, String) {
        let error = parse_params_file(Path::new("dir/params.toml"), text).unwrap_err();
        let ParamsFileError::Invalid { line, .. } = &error else {
            panic!("{error}")
        };
        (*line, error.to_string())
    }

    #[test]
    fn a_syntax_error_names_the_file_and_the_parsers_line() {
        let text = RobotParams::nominal().to_toml_string();
        let broken = text.replacen("l_b = ", "l_b = = ", 1);
        let expected = broken.lines().position(|l| l.contains("l_b")).unwrap() + 1;
        let (line, message) = invalid(&broken);
        assert_eq!(line, Some(expected), "{message}");
        assert!(
            message.starts_with(&format!("dir/params.toml:{expected}: ")),
            "{message}"
        );
    }

    #[test]
    fn a_value_error_names_the_file_the_line_of_the_field_and_the_field() {
        let text = RobotParams::nominal().to_toml_string();
        let line_of = |needle: &str| text.lines().position(|l| l.contains(needle)).unwrap() + 1;
        let broken = text.replacen("l_fe = 20.0", "l_fe = -20.0", 1);
        let (line, message) = invalid(&broken);
        assert_eq!(line, Some(line_of("l_fe =")), "{message}");
        assert!(message.contains("field `geometry.l_fe`"), "{message}");
        assert!(message.contains("positive"), "{message}");

        let mut params = RobotParams::nominal();
        params.calibration = Some(crate::CalibrationInfo {
            latency_ms: Some(-3.0),
            ..Default::default()
        });
        let text = params.to_toml_string();
        let (line, message) = invalid(&text);
        let expected = text
            .lines()
            .position(|l| l.starts_with("latency_ms"))
            .unwrap()
            + 1;
        assert_eq!(line, Some(expected), "{message}");
        assert!(message.contains("calibration.latency_ms"), "{message}");
    }

    #[test]
    fn an_unreadable_file_is_named() {
        let error = read_params_file(Path::new("/nonexistent/robot.toml")).unwrap_err();
        assert!(matches!(error, ParamsFileError::Read { .. }));
        assert_eq!(error.path(), Path::new("/nonexistent/robot.toml"));
        assert!(error
            .to_string()
            .contains("/nonexistent/robot.toml: cannot read parameter file"));
    }
}
