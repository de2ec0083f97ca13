//! Which tracker latency the synchroniser subtracts: the configured one until a parameter set
//! with a calibrated latency (`[calibration] latency_ms` of a `params.toml`) is loaded.

use sabr_model::{read_params_file, ParamsFileError, RobotParams};
use std::path::{Path, PathBuf};

pub use sabr_model::MAX_LATENCY_MS;
pub use sabr_msgs::LatencySource;

/// The latency in use: ns, and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Latency {
    /// Frame clock line minus exposure time, ns.
    pub ns: i64,
    /// Configured or calibrated.
    pub source: LatencySource,
}

/// A parameter file that was read.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterSet {
    /// The file.
    pub path: PathBuf,
    /// The model it holds (counts per revolution for the encoder angles).
    pub params: RobotParams,
    /// Its calibrated latency, ns, if it has one.
    pub latency_ns: Option<i64>,
}

/// Reads a `robot.toml` or `params.toml` (the one parameter-file reader, which also checks
/// that a calibrated latency lies within 0..=[`MAX_LATENCY_MS`]), with its calibrated latency
/// if any.
pub fn read_parameter_set(path: &Path) -> Result<ParameterSet, ParamsFileError> {
    let params = read_params_file(path)?;
    let latency_ns = params
        .calibration
        .as_ref()
        .and_then(|c| c.latency_ms)
        .map(|ms| (ms * 1e6).round() as i64);
    Ok(ParameterSet {
        path: path.to_path_buf(),
        params,
        latency_ns,
    })
}

/// Checks a latency in ms (finite, 0 ≤ ms ≤ [`MAX_LATENCY_MS`]) and converts it to ns.
pub fn latency_ns(ms: f64) -> Result<i64, String> {
    if !ms.is_finite() || !(0.0..=MAX_LATENCY_MS).contains(&ms) {
        return Err(format!(
            "latency {ms} ms is outside 0..={MAX_LATENCY_MS} ms"
        ));
    }
    Ok((ms * 1e6).round() as i64)
}

/// The configured latency and, once known, the calibrated one (which wins).
#[derive(Debug, Clone, PartialEq)]
pub struct LatencySetting {
    configured_ns: Option<i64>,
    calibrated_ns: Option<i64>,
}

impl LatencySetting {
    /// From the command line's latency (ns), if given.
    pub fn new(configured_ns: Option<i64>) -> Self {
        Self {
            configured_ns,
            calibrated_ns: None,
        }
    }

    /// Takes the calibrated latency of `set`, if it has one; returns true if the latency in
    /// use changed.
    pub fn apply(&mut self, set: &ParameterSet) -> bool {
        let before = self.current();
        if set.latency_ns.is_some() {
            self.calibrated_ns = set.latency_ns;
        }
        self.current() != before
    }

    /// The latency to use: calibrated if known, else configured; `None` if neither.
    pub fn current(&self) -> Option<Latency> {
        match (self.calibrated_ns, self.configured_ns) {
            (Some(ns), _) => Some(Latency {
                ns,
                source: LatencySource::Calibrated,
            }),
            (None, Some(ns)) => Some(Latency {
                ns,
                source: LatencySource::Configured,
            }),
            (None, None) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params_file(dir: &Path, latency_ms: Option<f64>) -> PathBuf {
        let mut params = RobotParams::nominal();
        if let Some(ms) = latency_ms {
            params.calibration = Some(sabr_model::CalibrationInfo {
                latency_ms: Some(ms),
                ..Default::default()
            });
        }
        let path = dir.join(format!("params-{latency_ms:?}.toml"));
        std::fs::write(&path, params.to_toml_string()).unwrap();
        path
    }

    #[test]
    fn a_calibrated_latency_replaces_the_configured_one() {
        let dir = tempfile::tempdir().unwrap();
        let mut setting = LatencySetting::new(Some(30_000_000));
        assert_eq!(
            setting.current(),
            Some(Latency {
                ns: 30_000_000,
                source: LatencySource::Configured
            })
        );
        let without = read_parameter_set(&params_file(dir.path(), None)).unwrap();
        assert_eq!(without.latency_ns, None);
        assert!(!setting.apply(&without), "no latency: nothing changes");
        let with = read_parameter_set(&params_file(dir.path(), Some(41.25))).unwrap();
        assert!(setting.apply(&with));
        assert_eq!(
            setting.current(),
            Some(Latency {
                ns: 41_250_000,
                source: LatencySource::Calibrated
            })
        );
        assert!(
            !setting.apply(&without),
            "a later set without latency keeps it"
        );
        assert_eq!(LatencySetting::new(None).current(), None);
    }

    #[test]
    fn bad_files_and_latencies_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nope.toml");
        let error = read_parameter_set(&missing).unwrap_err();
        assert!(error.to_string().contains("nope.toml"), "{error}");
        let bad = dir.path().join("bad.toml");
        std::fs::write(&bad, "format = 1\n[geometry]\nl_f = \"long\"\n").unwrap();
        let error = read_parameter_set(&bad).unwrap_err().to_string();
        assert!(error.contains("bad.toml"), "{error}");
        let negative = params_file(dir.path(), Some(-3.0));
        let error = read_parameter_set(&negative).unwrap_err().to_string();
        assert!(error.contains("calibration.latency_ms"), "{error}");
        assert!(latency_ns(f64::NAN).is_err());
        assert_eq!(latency_ns(12.5), Ok(12_500_000));
    }
}
