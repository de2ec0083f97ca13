//! The stacked, whitened, robustly weighted residual vector of a set of observations, its
//! Jacobian with respect to a [`ParamLayout`], and a Levenberg–Marquardt solve.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use sabr_model::Geometry;

use crate::layout::{CalibModel, Channel, ParamLayout};
use crate::observations::Observation;
use crate::residuals::{
    joint_angles, marker_poses, predict_at, raw_residual, Block, NoiseModel, Prediction, Quantity,
};
use crate::CalibrationError;

/// Whitened residual given to the rows of an observation whose kinematics fail (so that a
/// trial step into an unreachable region is rejected instead of aborting the fit).
const FAILED_PREDICTION_RESIDUAL: f64 = 1e3;
/// Largest residual rows of one observation (front + back + tip).
const MAX_ROWS_PER_OBSERVATION: usize = 15;
/// Step (rad) of the finite differences with respect to the joint angles.
const JOINT_STEP: f64 = 1e-7;

/// A weighted least-squares problem over observations.
#[derive(Debug, Clone, Copy)]
pub struct Problem<'a> {
    /// The parameters that move.
    pub layout: &'a ParamLayout,
    /// The fitted observations.
    pub observations: &'a [Observation],
    /// Residual blocks, grouped by observation in ascending order.
    pub blocks: &'a [Block],
    /// Total residual rows.
    pub rows: usize,
    /// Noise model that whitens each block.
    pub noise: &'a NoiseModel,
    /// Robust weight of each block (multiplies its squared residual).
    pub weights: &'a [f64],
}

impl Problem<'_> {
    /// The blocks of each observation, with the index of the first one.
    fn groups(&self) -> impl Iterator<Item = (usize, &[Block])> {
        let mut start = 0;
        self.blocks
            .chunk_by(|a, b| a.obs == b.obs)
            .map(move |group| {
                let first = start;
                start += group.len();
                (first, group)
            })
    }

    /// Writes the whitened (unweighted) residuals of one observation's blocks into `out`
    /// (consecutively, in block order); returns the rows written.
    fn observation_rows(&self, prediction: &Prediction, group: &[Block], out: &mut [f64]) -> usize {
        let mut k = 0;
        for block in group {
            let obs = &self.observations[block.obs];
            let dim = block.quantity.dim();
            let raw = raw_residual(prediction, obs, block.quantity).unwrap_or([0.0; 6]);
            self.noise
                .of(block.quantity)
                .whiten(&raw, dim, &mut out[k..k + dim]);
            k += dim;
        }
        k
    }

    /// The stacked weighted residual vector of `model`, and the number of observations
    /// whose kinematics failed.
    pub fn residuals(&self, model: &CalibModel) -> (DVector<f64>, usize) {
        let geometry = model.robot.effective_geometry();
        let mut r = DVector::zeros(self.rows);
        let mut failed = 0;
        let mut local = [0.0; MAX_ROWS_PER_OBSERVATION];
        for (first, group) in self.groups() {
            let obs = &self.observations[group[0].obs];
            let q = joint_angles(model, obs);
            match predict_at(&geometry, &model.robot.markers, q) {
                Ok(prediction) => {
                    self.observation_rows(&prediction, group, &mut local);
                    self.scatter(first, group, &local, |row, value| r[row] = value);
                }
                Err(_) => {
                    failed += 1;
                    for block in group {
                        for k in 0..block.quantity.dim() {
                            r[block.row + k] = FAILED_PREDICTION_RESIDUAL;
                        }
                    }
                }
            }
        }
        (r, failed)
    }

    /// Writes the rows of `local` (one observation, block order) to their stacked rows,
    /// scaled by the square root of each block's weight.
    fn scatter(
        &self,
        first: usize,
        group: &[Block],
        local: &[f64],
        mut write: impl FnMut(usize, f64),
    ) {
        let mut k = 0;
        for (i, block) in group.iter().enumerate() {
            let scale = self.weights[first + i].sqrt();
            for d in 0..block.quantity.dim() {
                write(block.row + d, scale * local[k]);
                k += 1;
            }
        }
    }

    /// Jacobian of [`Self::residuals`] with respect to the layout's parameters: the joint-map
    /// parameters by the chain rule through ∂r/∂q, mountings without forward kinematics,
    /// the geometry by forward differences of the kinematics.
    pub fn jacobian(&self, model: &CalibModel) -> DMatrix<f64> {
        let n = self.layout.len();
        let mut jacobian = DMatrix::zeros(self.rows, n);
        let geometry = model.robot.effective_geometry();
        let perturbed: Vec<Perturbed> = self
            .layout
            .ids
            .iter()
            .map(|id| {
                let step = id.step();
                let mut shifted = model.clone();
                id.set(&mut shifted, id.get(model) + step);
                let geometry = matches!(id.channel(), Channel::Geometry | Channel::FrontBase)
                    .then(|| shifted.robot.effective_geometry());
                Perturbed {
                    channel: id.channel(),
                    step,
                    model: shifted,
                    geometry,
                }
            })
            .collect();
        let needs_dq = perturbed.iter().any(|p| p.channel == Channel::JointMap);
        let mut r0 = [0.0; MAX_ROWS_PER_OBSERVATION];
        let mut r1 = [0.0; MAX_ROWS_PER_OBSERVATION];
        let mut dr_dq = [[0.0; MAX_ROWS_PER_OBSERVATION]; 5];
        let mut column = [0.0; MAX_ROWS_PER_OBSERVATION];
        for (first, group) in self.groups() {
            let obs = &self.observations[group[0].obs];
            let q0 = joint_angles(model, obs);
            let Ok(p0) = predict_at(&geometry, &model.robot.markers, q0) else {
                continue;
            };
            let rows = self.observation_rows(&p0, group, &mut r0);
            let sees_tip = group.iter().any(|b| b.quantity == Quantity::Tip);
            if needs_dq {
                for (j, derivative) in dr_dq.iter_mut().enumerate() {
                    let mut q = q0;
                    q[j] += JOINT_STEP;
                    if let Ok(p) = predict_at(&geometry, &model.robot.markers, q) {
                        self.observation_rows(&p, group, &mut r1);
                        for k in 0..rows {
                            derivative[k] = (r1[k] - r0[k]) / JOINT_STEP;
                        }
                    }
                }
            }
            for (col, p) in perturbed.iter().enumerate() {
                let ok = match p.channel {
                    Channel::JointMap => {
                        let q = joint_angles(&p.model, obs);
                        column[..rows].fill(0.0);
                        for j in 0..5 {
                            let dq = (q[j] - q0[j]) / p.step;
                            if dq != 0.0 {
                                for k in 0..rows {
                                    column[k] += dr_dq[j][k] * dq;
                                }
                            }
                        }
                        true
                    }
                    Channel::Mount => {
                        let (front_marker, back_marker) =
                            marker_poses(&p0.pose, &p.model.robot.markers);
                        let shifted = Prediction {
                            front_marker,
                            back_marker,
                            ..p0.clone()
                        };
                        self.finite_difference(&shifted, group, &r0, p.step, &mut column)
                    }
                    Channel::NeedleLength => {
                        let mut shifted = p0.clone();
                        shifted.pose.tip += shifted.pose.direction.into_inner() * p.step;
                        self.finite_difference(&shifted, group, &r0, p.step, &mut column)
                    }
                    Channel::FrontBase if !sees_tip => {
                        let motion = p.model.robot.geometry.front_base
                            * model.robot.geometry.front_base.inverse();
                        let shifted = Prediction {
                            front_marker: motion * p0.front_marker,
                            ..p0.clone()
                        };
                        self.finite_difference(&shifted, group, &r0, p.step, &mut column)
                    }
                    Channel::Geometry | Channel::FrontBase => {
                        let geometry = p.geometry.as_ref().unwrap_or(&geometry);
                        match predict_at(geometry, &p.model.robot.markers, q0) {
                            Ok(shifted) => {
                                self.finite_difference(&shifted, group, &r0, p.step, &mut column)
                            }
                            Err(_) => false,
                        }
                    }
                };
                if ok {
                    self.scatter(first, group, &column, |row, value| {
                        jacobian[(row, col)] = value
                    });
                }
            }
        }
        jacobian
    }

    fn finite_difference(
        &self,
        shifted: &Prediction,
        group: &[Block],
        r0: &[f64],
        step: f64,
        column: &mut [f64],
    ) -> bool {
        let rows = self.observation_rows(shifted, group, column);
        for k in 0..rows {
            column[k] = (column[k] - r0[k]) / step;
        }
        true
    }
}

/// A model with one parameter shifted by its finite-difference step.
struct Perturbed {
    channel: Channel,
    step: f64,
    model: CalibModel,
    geometry: Option<Geometry>,
}

/// Result of a Levenberg–Marquardt solve.
#[derive(Debug, Clone)]
pub struct Solution {
    /// The fitted model.
    pub model: CalibModel,
    /// Weighted cost `½ Σ r²` at the solution.
    pub cost: f64,
    /// Residual evaluations used.
    pub evaluations: usize,
}

struct LmAdapter<'a> {
    problem: Problem<'a>,
    template: CalibModel,
    x: DVector<f64>,
}

impl LmAdapter<'_> {
    fn model(&self) -> CalibModel {
        let mut model = self.template.clone();
        self.problem.layout.apply(&mut model, &self.x);
        model
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for LmAdapter<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(self.problem.residuals(&self.model()).0)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        Some(self.problem.jacobian(&self.model()))
    }
}

/// Minimises the problem's cost with Levenberg–Marquardt from `start`. Errors when the
/// solver reports a numerical failure or the kinematics fail at the solution.
pub fn solve(
    problem: Problem<'_>,
    start: &CalibModel,
    stage: &'static str,
) -> Result<Solution, CalibrationError> {
    let adapter = LmAdapter {
        problem,
        template: start.clone(),
        x: problem.layout.values(start),
    };
    let (adapter, report) = LevenbergMarquardt::new()
        .with_ftol(1e-10)
        .with_xtol(1e-10)
        .with_gtol(1e-10)
        .with_stepbound(1.0)
        .with_patience(10)
        .minimize(adapter);
    let usable = report.termination.was_successful()
        || matches!(
            report.termination,
            levenberg_marquardt::TerminationReason::LostPatience
                | levenberg_marquardt::TerminationReason::NoImprovementPossible(_)
        );
    if !usable {
        return Err(CalibrationError::Fit {
            stage,
            reason: format!("Levenberg–Marquardt stopped: {:?}", report.termination),
        });
    }
    let model = adapter.model();
    let (_, failed) = problem.residuals(&model);
    if failed > 0 {
        return Err(CalibrationError::Fit {
            stage,
            reason: format!("the fitted model cannot reach {failed} of the measured poses"),
        });
    }
    Ok(Solution {
        model,
        cost: report.objective_function,
        evaluations: report.number_of_evaluations,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use nalgebra::Vector3;
    use sabr_model::{JointMotion, RobotParams};

    use super::*;
    use crate::identifiability::analyse;
    use crate::layout::ParamId;
    use crate::observations::Phase;
    use crate::residuals::{blocks_of, predict};
    use crate::se3;

    /// Joints of the home pose of docs/robot-model.md §3 (rad).
    const HOME: [f64; 5] = [-2.368404, -0.777628, 0.0, -2.685073, -0.601543];

    /// A perturbed "true" model and noise-free observations of it along a multi-sine
    /// trajectory about the home pose; every third observation sees the tip (tip phase).
    pub(crate) fn synthetic(count: usize) -> (CalibModel, CalibModel, Vec<Observation>) {
        let mut nominal = RobotParams::nominal();
        nominal.joints.offset = Some(HOME);
        let start = CalibModel {
            robot: nominal,
            latency_s: 0.0,
        };
        let mut truth = start.clone();
        let robot = &mut truth.robot;
        robot.joints.gear_ratio = [0.101, 0.0985, 0.0504, 0.1012, 0.0991];
        robot.joints.offset = Some([
            HOME[0] + 0.01,
            HOME[1] - 0.02,
            0.015,
            HOME[3] + 0.012,
            HOME[4] - 0.008,
        ]);
        robot.geometry.front_base = se3::isometry(
            Vector3::new(0.8, -0.5, 100.9),
            Vector3::new(0.006, -0.004, 0.0),
        );
        robot.geometry.l_n = 181.7;
        robot.markers.front_mount = se3::isometry(
            Vector3::new(0.6, -0.4, 15.8),
            Vector3::new(0.02, -0.01, 0.03),
        );
        robot.markers.back_mount = se3::isometry(
            Vector3::new(-0.7, 0.3, -14.4),
            Vector3::new(-0.015, 0.02, -0.01),
        );
        let offset = truth.robot.joints.offset.unwrap();
        let observations = (0..count)
            .map(|k| {
                let t = k as f64 * 0.37;
                let q: [f64; 5] = std::array::from_fn(|j| {
                    HOME[j]
                        + 0.12
                            * (t * (1.0 + 0.31 * j as f64)).sin()
                            * if j == 2 { 0.8 } else { 1.0 }
                });
                let motor: [f64; 5] =
                    std::array::from_fn(|j| (q[j] - offset[j]) / truth.robot.joints.gear_ratio[j]);
                let counts = truth.robot.counts_from_motor_angles(&motor);
                let mut obs = Observation {
                    frame: k as u32,
                    exposure_ns: k as f64 * 5e7,
                    latency_s: 0.0,
                    phase: if k % 3 == 0 {
                        Phase::Tip
                    } else {
                        Phase::Excitation
                    },
                    counts,
                    count_rates: [0.0; 5],
                    motion: JointMotion::default(),
                    front: None,
                    back: None,
                    tip: None,
                };
                let p = predict(&truth, &obs).unwrap();
                obs.front = Some(p.front_marker);
                obs.back = Some(p.back_marker);
                obs.tip = (k % 3 == 0).then_some(p.pose.tip);
                obs
            })
            .collect();
        (truth, start, observations)
    }

    #[test]
    fn levenberg_marquardt_recovers_every_paper_parameter_from_exact_data() {
        let (truth, start, observations) = synthetic(90);
        let layout = ParamLayout::paper().without(ParamId::Latency);
        let (blocks, rows) = blocks_of(&observations, |o| o.phase == Phase::Tip);
        let noise = NoiseModel::vicra_default();
        let weights = vec![1.0; blocks.len()];
        let problem = Problem {
            layout: &layout,
            observations: &observations,
            blocks: &blocks,
            rows,
            noise: &noise,
            weights: &weights,
        };
        let solution = solve(problem, &start, "test").unwrap();
        let found = layout.values(&solution.model);
        let expected = layout.values(&truth);
        for (k, id) in layout.ids.iter().enumerate() {
            assert!(
                (found[k] - expected[k]).abs() < 1e-6,
                "{}: {} vs {}",
                id.name(),
                found[k],
                expected[k]
            );
        }
        let analysis = analyse(
            &layout,
            &problem.jacobian(&solution.model),
            &problem.residuals(&solution.model).0,
        );
        assert_eq!(analysis.rank, layout.len());
        assert!(analysis.near_null.is_empty());
    }

    #[test]
    fn jacobian_matches_central_differences_of_the_residuals() {
        let (_, start, observations) = synthetic(12);
        let layout = ParamLayout::paper();
        let (blocks, rows) = blocks_of(&observations, |o| o.phase == Phase::Tip);
        let noise = NoiseModel::vicra_default();
        let weights: Vec<f64> = (0..blocks.len())
            .map(|i| 0.5 + (i % 2) as f64 * 0.5)
            .collect();
        let mut observations = observations;
        for (k, obs) in observations.iter_mut().enumerate() {
            obs.count_rates = [300.0 * (k as f64).cos(), 200.0, -150.0, 90.0, -40.0];
        }
        let problem = Problem {
            layout: &layout,
            observations: &observations,
            blocks: &blocks,
            rows,
            noise: &noise,
            weights: &weights,
        };
        let jacobian = problem.jacobian(&start);
        let x = layout.values(&start);
        for (col, id) in layout.ids.iter().enumerate() {
            let h = id.step() * 10.0;
            let at = |delta: f64| {
                let mut model = start.clone();
                let mut shifted = x.clone();
                shifted[col] += delta;
                layout.apply(&mut model, &shifted);
                problem.residuals(&model).0
            };
            let numeric = (at(h) - at(-h)) / (2.0 * h);
            let error = (&numeric - jacobian.column(col)).amax();
            let scale = numeric.amax().max(1.0);
            assert!(
                error < 1e-3 * scale,
                "{}: error {error} of {scale}",
                id.name()
            );
        }
        let latency = analyse(&layout, &jacobian, &problem.residuals(&start).0);
        assert!(
            latency.near_null.is_empty(),
            "moving joints make the latency identifiable"
        );
    }
}
