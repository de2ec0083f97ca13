//! Parameter files (`robot.toml` or a calibrated `params.toml`) as the IK server and the
//! motion executor load them.

use sabr_model::{Geometry, RobotParams};
use std::path::{Path, PathBuf};

/// Why a parameter file could not be used; names the file and the reason.
#[derive(Debug, thiserror::Error)]
pub enum ParamsFileError {
    /// The file could not be read.
    #[error("cannot read parameter file {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a valid parameter file (syntax with line and column, or the field).
    #[error("invalid parameter file {}: {source}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The parser's or validator's error.
        source: sabr_model::ParamsError,
    },
}

/// Reads and validates a `robot.toml` or `params.toml`.
pub fn load_params(path: &Path) -> Result<RobotParams, ParamsFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| ParamsFileError::Read {
        path: path.to_owned(),
        source,
    })?;
    RobotParams::from_toml_str(&text).map_err(|source| ParamsFileError::Invalid {
        path: path.to_owned(),
        source,
    })
}

/// A loaded parameter set: the parameters, the geometry FK/IK use (link-length effects
/// applied), its version and where it came from.
#[derive(Debug, Clone)]
pub struct ParameterSet {
    /// The robot parameters.
    pub params: RobotParams,
    /// `params.effective_geometry()`, computed once.
    pub geometry: Geometry,
    /// Version: 0 for a file given on the command line, else the calibrator's announced
    /// `ParameterSetAnnouncement::version`.
    pub version: u64,
    /// The file it was read from.
    pub path: PathBuf,
}

impl ParameterSet {
    /// Wraps loaded parameters with their version and source.
    pub fn new(params: RobotParams, version: u64, path: &Path) -> Self {
        Self {
            geometry: params.effective_geometry(),
            params,
            version,
            path: path.to_owned(),
        }
    }

    /// Loads `path` as version `version`.
    pub fn load(path: &Path, version: u64) -> Result<Self, ParamsFileError> {
        Ok(Self::new(load_params(path)?, version, path))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_file_and_the_reason() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.toml");
        let error = load_params(&missing).unwrap_err();
        assert!(matches!(error, ParamsFileError::Read { .. }));
        assert!(error.to_string().contains("missing.toml"), "{error}");

        let corrupt = dir.path().join("params.toml");
        std::fs::write(&corrupt, "format = 1\n[geometry\nl_f = 50.0\n").unwrap();
        let error = load_params(&corrupt).unwrap_err();
        assert!(matches!(error, ParamsFileError::Invalid { .. }));
        let text = error.to_string();
        assert!(
            text.contains("params.toml") && text.contains("line 2"),
            "{text}"
        );

        let good = dir.path().join("robot.toml");
        std::fs::write(&good, RobotParams::nominal().to_toml_string()).unwrap();
        let set = ParameterSet::load(&good, 4).unwrap();
        assert_eq!(set.version, 4);
        assert_eq!(set.geometry, RobotParams::nominal().effective_geometry());
    }
}
