//! The IK answer to one request, with the parameter set in service.

use crate::parameter_set::ParameterSet;
use glam::DVec3;
use sabr_model::ParamsFileError;
use sabr_model::{JointMotion, KinematicsError};
use sabr_msgs::{FixedString, IkRequest, IkResponse, IkStatus, ParameterSetAnnouncement};
use std::path::Path;

/// Shortest usable needle direction (its length is otherwise free).
const MIN_DIRECTION_NORM: f64 = 1e-12;

/// Turns IK requests into responses with the parameter set in service.
#[derive(Debug, Clone, Default)]
pub struct IkSolver {
    set: Option<ParameterSet>,
}

/// What a parameter announcement did to the solver.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReloadOutcome {
    /// The announced set is now in service.
    Loaded {
        /// Its version.
        version: u64,
    },
    /// The announcement is not newer than the set in service; nothing changed.
    Ignored {
        /// The announced version.
        announced: u64,
        /// The version in service.
        current: u64,
    },
}

impl IkSolver {
    /// A solver without parameters: every request is answered [`IkStatus::NoParameters`].
    pub fn new() -> Self {
        Self::default()
    }

    /// A solver serving `set`.
    pub fn with_parameters(set: ParameterSet) -> Self {
        Self { set: Some(set) }
    }

    /// The parameter set in service.
    pub fn parameters(&self) -> Option<&ParameterSet> {
        self.set.as_ref()
    }

    /// Loads the file named by a calibrator announcement if it is newer than the set in
    /// service. A file that cannot be read or is invalid is an error and the previous set
    /// stays in service.
    pub fn reload(
        &mut self,
        announcement: &ParameterSetAnnouncement,
    ) -> Result<ReloadOutcome, ParamsFileError> {
        let current = self.set.as_ref().map(|set| set.version);
        if let Some(current) = current.filter(|&current| announcement.version <= current) {
            return Ok(ReloadOutcome::Ignored {
                announced: announcement.version,
                current,
            });
        }
        let set = ParameterSet::load(Path::new(announcement.path.as_str()), announcement.version)?;
        self.set = Some(set);
        Ok(ReloadOutcome::Loaded {
            version: announcement.version,
        })
    }

    /// The answer to `request`: joints nearest `request.near_joints_rad` and their motor
    /// counts at rest, exactly what `sabr ik` computes for the same target and near joints.
    pub fn solve(&self, request: &IkRequest) -> IkResponse {
        let mut response = IkResponse {
            id: request.id,
            parameter_version: self.set.as_ref().map_or(0, |set| set.version),
            ..IkResponse::default()
        };
        match self.try_solve(request) {
            Ok((joints, counts)) => {
                response.status = IkStatus::Ok;
                response.joints_rad = joints;
                response.counts = counts;
            }
            Err((status, reason)) => {
                response.status = status;
                response.error = FixedString::truncated(&reason);
            }
        }
        response
    }

    fn try_solve(&self, request: &IkRequest) -> Result<([f64; 5], [f64; 5]), (IkStatus, String)> {
        let Some(set) = &self.set else {
            return Err((
                IkStatus::NoParameters,
                "no parameter set loaded (start with --params or wait for the calibrator)".into(),
            ));
        };
        if set.params.joints.offset.is_none() {
            return Err((
                IkStatus::NoParameters,
                format!(
                    "parameter set v{} ({}) has no joint offsets: counts need a calibrated set",
                    set.version,
                    set.path.display()
                ),
            ));
        }
        let invalid = |what: &str| (IkStatus::InvalidInput, format!("{what} is NaN or infinite"));
        if !request.tip_mm.iter().all(|v| v.is_finite()) {
            return Err(invalid("the tip"));
        }
        if !request.direction.iter().all(|v| v.is_finite()) {
            return Err(invalid("the needle direction"));
        }
        if !request.near_joints_rad.iter().all(|v| v.is_finite()) {
            return Err(invalid("the near joints"));
        }
        let direction = DVec3::from_array(request.direction);
        if direction.length() <= MIN_DIRECTION_NORM {
            return Err((
                IkStatus::InvalidInput,
                "the needle direction has zero length".into(),
            ));
        }
        let tip = DVec3::from_array(request.tip_mm);
        let joints = set
            .realtime
            .inverse(tip, direction, &request.near_joints_rad)
            .map_err(|error| match error {
                KinematicsError::NotFinite(_) => (IkStatus::InvalidInput, error.to_string()),
                KinematicsError::Unreachable(_) => (IkStatus::Unreachable, error.to_string()),
            })?;
        let counts = set
            .params
            .counts_from_joints(&joints, &JointMotion::default())
            .map_err(|error| (IkStatus::Unreachable, format!("no motor counts: {error}")))?;
        Ok((joints, counts))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_model::realtime::RealtimeGeometry;
    use sabr_model::{forward, inverse, RobotParams, HOME_JOINTS};

    fn calibrated() -> RobotParams {
        let mut params = RobotParams::nominal();
        params.joints.offset = Some([-2.3, -0.7, 0.05, -2.6, -0.55]);
        params.joints.gear_ratio[2] = 0.051;
        params.geometry.l_n = 181.5;
        params
    }

    fn solver(params: RobotParams) -> IkSolver {
        IkSolver::with_parameters(ParameterSet::new(params, 3, Path::new("params.toml")))
    }

    fn request(tip: [f64; 3], direction: [f64; 3]) -> IkRequest {
        IkRequest {
            id: 17,
            tip_mm: tip,
            direction,
            near_joints_rad: HOME_JOINTS,
        }
    }

    #[test]
    fn reachable_targets_match_the_model_library_exactly() {
        let params = calibrated();
        let geometry = params.effective_geometry();
        let realtime = RealtimeGeometry::from(&geometry);
        let solver = solver(params.clone());
        for q in [
            HOME_JOINTS,
            [-2.281138, -0.829988, 0.069813, -2.789793, -0.566636],
            [-2.508031, -0.672909, -0.174533, -2.597807, -0.723716],
        ] {
            let pose = forward(&geometry, &q).unwrap();
            let req = request(pose.tip.coords.into(), pose.direction.into_inner().into());
            let response = solver.solve(&req);
            assert_eq!(response.status, IkStatus::Ok, "{}", response.error);
            assert_eq!(response.id, 17);
            assert_eq!(response.parameter_version, 3);
            let tip = DVec3::from_array(pose.tip.coords.into());
            let direction = DVec3::from_array(pose.direction.into_inner().into());
            let expected = realtime.inverse(tip, direction, &HOME_JOINTS).unwrap();
            assert_eq!(response.joints_rad, expected);
            let nalgebra = inverse(&geometry, &pose.tip, &pose.direction, &HOME_JOINTS).unwrap();
            for (a, b) in expected.iter().zip(&nalgebra) {
                assert!((a - b).abs() < 1e-9, "glam {a} vs nalgebra {b}");
            }
            let counts = params
                .counts_from_joints(&expected, &JointMotion::default())
                .unwrap();
            assert_eq!(response.counts, counts);
            for (a, b) in response.joints_rad.iter().zip(&q) {
                assert!((a - b).abs() < 1e-9, "{a} vs {b}");
            }
            assert!(response.error.is_empty());
        }
    }

    #[test]
    fn invalid_and_unreachable_targets_get_errors_with_reasons() {
        let solver = solver(calibrated());
        let cases = [
            (
                request([f64::NAN, -90.0, 180.0], [0.0, 0.0, 1.0]),
                IkStatus::InvalidInput,
                "tip",
            ),
            (
                request([0.0, f64::INFINITY, 180.0], [0.0, 0.0, 1.0]),
                IkStatus::InvalidInput,
                "tip",
            ),
            (
                request([0.0, -90.0, 180.0], [0.0, f64::NAN, 1.0]),
                IkStatus::InvalidInput,
                "direction",
            ),
            (
                request([0.0, -90.0, 180.0], [0.0, 0.0, 0.0]),
                IkStatus::InvalidInput,
                "zero length",
            ),
            (
                request([0.0, -90.0, 900.0], [0.0, 0.0, 1.0]),
                IkStatus::Unreachable,
                "unreachable",
            ),
            (
                request([0.0, -90.0, 180.0], [1.0, 0.0, 0.0]),
                IkStatus::Unreachable,
                "unreachable",
            ),
        ];
        for (req, status, reason) in cases {
            let response = solver.solve(&req);
            assert_eq!(response.status, status, "{req:?}: {}", response.error);
            assert!(
                response.error.as_str().contains(reason),
                "{}",
                response.error
            );
            assert_eq!(response.joints_rad, [0.0; 5]);
            assert_eq!(response.counts, [0.0; 5]);
        }
        let mut near_nan = request([0.0, -90.0, 180.0], [0.0, 0.0, 1.0]);
        near_nan.near_joints_rad[2] = f64::NEG_INFINITY;
        assert_eq!(solver.solve(&near_nan).status, IkStatus::InvalidInput);
    }

    #[test]
    fn without_parameters_or_offsets_there_is_no_answer() {
        let home = request([0.0, -90.0, 180.0], [0.0, 0.0, 1.0]);
        let response = IkSolver::new().solve(&home);
        assert_eq!(response.status, IkStatus::NoParameters);
        let response = solver(RobotParams::nominal()).solve(&home);
        assert_eq!(response.status, IkStatus::NoParameters);
        assert!(
            response.error.as_str().contains("offsets"),
            "{}",
            response.error
        );
    }

    #[test]
    fn reload_takes_newer_valid_sets_and_keeps_the_old_one_otherwise() {
        let dir = tempfile::tempdir().unwrap();
        let mut solver = solver(calibrated());
        let announce = |version: u64, path: &Path| ParameterSetAnnouncement {
            version,
            t_ns: 0,
            path: FixedString::new(path.to_str().unwrap()).unwrap(),
        };
        let corrupt = dir.path().join("corrupt.toml");
        std::fs::write(&corrupt, "format = 1\n[geometry]\nl_f = \"long\"\n").unwrap();
        assert!(solver.reload(&announce(4, &corrupt)).is_err());
        assert_eq!(solver.parameters().unwrap().version, 3);

        let mut newer = calibrated();
        newer.geometry.l_n = 179.0;
        let good = dir.path().join("params.toml");
        std::fs::write(&good, newer.to_toml_string()).unwrap();
        assert_eq!(
            solver.reload(&announce(2, &good)).unwrap(),
            ReloadOutcome::Ignored {
                announced: 2,
                current: 3
            }
        );
        assert_eq!(solver.parameters().unwrap().params.geometry.l_n, 181.5);
        assert_eq!(
            solver.reload(&announce(5, &good)).unwrap(),
            ReloadOutcome::Loaded { version: 5 }
        );
        let set = solver.parameters().unwrap();
        assert_eq!((set.version, set.params.geometry.l_n), (5, 179.0));
        let response = solver.solve(&request([0.0, -90.0, 180.0], [0.0, 0.0, 1.0]));
        assert_eq!(response.parameter_version, 5);
    }
}
