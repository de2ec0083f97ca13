//! The parameter set the IK server and the motion executor serve: a parameter file read by
//! the one reader (`sabr_model::read_params_file`), its FK/IK geometry, version and source.

use sabr_model::realtime::RealtimeGeometry;
use sabr_model::{read_params_file, Geometry, ParamsFileError, RobotParams};
use std::path::{Path, PathBuf};

/// A loaded parameter set: the parameters, the geometry FK/IK use (link-length effects
/// applied), its version and where it came from.
#[derive(Debug, Clone)]
pub struct ParameterSet {
    /// The robot parameters.
    pub params: RobotParams,
    /// `params.effective_geometry()`, computed once.
    pub geometry: Geometry,
    /// That geometry prepared for the real-time (glam) kinematics, computed once.
    pub realtime: RealtimeGeometry,
    /// Version: 0 for a file given on the command line, else the calibrator's announced
    /// `ParameterSetAnnouncement::version`.
    pub version: u64,
    /// The file it was read from.
    pub path: PathBuf,
}

impl ParameterSet {
    /// Wraps loaded parameters with their version and source.
    pub fn new(params: RobotParams, version: u64, path: &Path) -> Self {
        let geometry = params.effective_geometry();
        Self {
            realtime: RealtimeGeometry::from(&geometry),
            geometry,
            params,
            version,
            path: path.to_owned(),
        }
    }

    /// Loads the `robot.toml` or `params.toml` at `path` as version `version`.
    pub fn load(path: &Path, version: u64) -> Result<Self, ParamsFileError> {
        Ok(Self::new(read_params_file(path)?, version, path))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_file_and_the_reason() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.toml");
        let error = ParameterSet::load(&missing, 1).unwrap_err();
        assert!(matches!(error, ParamsFileError::Read { .. }));
        assert!(error.to_string().contains("missing.toml"), "{error}");

        let corrupt = dir.path().join("params.toml");
        std::fs::write(&corrupt, "format = 1\n[geometry\nl_f = 50.0\n").unwrap();
        let error = ParameterSet::load(&corrupt, 1).unwrap_err();
        assert!(matches!(error, ParamsFileError::Invalid { .. }));
        let text = error.to_string();
        assert!(
            text.contains("params.toml:2:") && text.contains("line 2"),
            "{text}"
        );

        let good = dir.path().join("robot.toml");
        std::fs::write(&good, RobotParams::nominal().to_toml_string()).unwrap();
        let set = ParameterSet::load(&good, 4).unwrap();
        assert_eq!(set.version, 4);
        assert_eq!(set.geometry, RobotParams::nominal().effective_geometry());
    }
}
