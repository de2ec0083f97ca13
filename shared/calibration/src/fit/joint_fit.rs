//! The joint nonlinear least-squares fit of all parameters of a layout together:
//! Levenberg–Marquardt on the whitened residuals of every measured quantity, inside an
//! iteratively reweighted loop (Huber loss per measurement, noise re-estimated from the
//! residuals, observations derived again when the dataset asks for it), then the
//! identifiability analysis; directions the data do not determine are fixed at their start
//! values and reported.

use nalgebra::{DMatrix, DVector};

use crate::error::CalibrationError;
use crate::fit::identifiability::{analyse, Analysis, NearNullDirection};
use crate::fit::solve::solve;
use crate::math::stats::huber_weight;
use crate::model::{blocks_of, Block, Dataset, NoiseModel, ParamLayout, Problem, RobotModel};

const STAGE: &str = "joint fit";
/// Reweighting iterations (each a full LM solve, warm-started).
const MIN_OUTER: usize = 2;
const MAX_OUTER: usize = 6;
/// Stop reweighting when no block weight changes more than this.
const WEIGHT_TOLERANCE: f64 = 0.02;
/// Huber thresholds on the whitened block norm (√ of the χ² 99.9 % quantile).
const HUBER_POSE: f64 = 4.74;
const HUBER_POINT: f64 = 4.03;
/// Rounds of fixing near-null directions.
const MAX_FIX_ROUNDS: usize = 3;

/// A parameter held at its start value because the data do not determine it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FixedParameter {
    /// Parameter name.
    pub name: String,
    /// The value it was held at.
    pub value: f64,
    /// The near-null direction that required it.
    pub direction: NearNullDirection,
}

/// The fitted set and everything needed to reuse it (residual diagnostics, effects).
#[derive(Debug, Clone)]
pub struct JointFit<M: RobotModel> {
    /// The fitted model.
    pub model: M,
    /// The parameters that were fitted (the start layout minus the fixed ones).
    pub layout: ParamLayout<M::Param>,
    /// Parameters that had to be fixed.
    pub fixed: Vec<FixedParameter>,
    /// Noise re-estimated from the residuals.
    pub noise: NoiseModel,
    /// The fitted observations (derived at the final model).
    pub observations: Vec<M::Observation>,
    /// Their residual blocks.
    pub blocks: Vec<Block>,
    /// Total residual rows.
    pub rows: usize,
    /// Final robust weight of each block.
    pub weights: Vec<f64>,
    /// Weighted Jacobian at the solution.
    pub jacobian: DMatrix<f64>,
    /// Weighted residual at the solution.
    pub residual: DVector<f64>,
    /// Identifiability at the solution.
    pub analysis: Analysis,
    /// Reweighting iterations used.
    pub outer_iterations: usize,
}

impl<M: RobotModel> JointFit<M> {
    /// The problem at the solution (for Jacobians or residuals of the same set).
    pub fn problem(&self) -> Problem<'_, M> {
        Problem {
            layout: &self.layout,
            observations: &self.observations,
            blocks: &self.blocks,
            rows: self.rows,
            noise: &self.noise,
            weights: &self.weights,
        }
    }

    /// Blocks whose robust weight is below 1 (treated as partial outliers).
    pub fn downweighted(&self) -> usize {
        self.weights.iter().filter(|w| **w < 1.0).count()
    }
}

/// Huber weights of blocks from their raw residuals under `noise`.
pub fn robust_weights(blocks: &[Block], raws: &[Option<[f64; 6]>], noise: &NoiseModel) -> Vec<f64> {
    blocks
        .iter()
        .zip(raws)
        .map(|(block, raw)| {
            let Some(raw) = raw else { return 0.0 };
            let mut white = [0.0; 6];
            noise.whiten(block, raw, &mut white);
            let norm = white[..block.dim].iter().map(|v| v * v).sum::<f64>().sqrt();
            let k = if block.dim == 3 {
                HUBER_POINT
            } else {
                HUBER_POSE
            };
            huber_weight(norm, k)
        })
        .collect()
}

/// Runs the joint fit of `layout` from `start` on the observations of `data`.
pub fn joint_fit<M: RobotModel>(
    data: &impl Dataset<M>,
    start: &M,
    noise: &NoiseModel,
    layout: ParamLayout<M::Param>,
) -> Result<JointFit<M>, CalibrationError> {
    let mut layout = layout;
    let mut model = start.clone();
    let mut noise = noise.clone();
    let mut matched = model.clone();
    let mut observations = data.fit_set(&matched);
    let (mut blocks, mut rows) = blocks_of(&model, &observations);
    let mut weights = vec![1.0; blocks.len()];
    let mut outer_iterations = 0;
    for outer in 0..MAX_OUTER {
        outer_iterations = outer + 1;
        let problem = Problem {
            layout: &layout,
            observations: &observations,
            blocks: &blocks,
            rows,
            noise: &noise,
            weights: &weights,
        };
        let solution = solve(problem, &model, STAGE)?;
        tracing::debug!(
            outer,
            evaluations = solution.evaluations,
            cost = solution.cost,
            "joint fit pass"
        );
        model = solution.model;
        let rematched = data.needs_rematch(&matched, &model);
        if rematched {
            matched = model.clone();
            observations = data.fit_set(&matched);
            (blocks, rows) = blocks_of(&model, &observations);
            weights = vec![1.0; blocks.len()];
        }
        let mut raws = Vec::with_capacity(blocks.len());
        model.residuals(&observations, &blocks, &mut raws);
        noise = noise.from_residuals(
            blocks
                .iter()
                .zip(&raws)
                .zip(&weights)
                .filter_map(|((b, r), w)| Some((b, r.as_ref()?, *w))),
        );
        let new_weights = robust_weights(&blocks, &raws, &noise);
        let change = new_weights
            .iter()
            .zip(&weights)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        weights = new_weights;
        if outer + 1 >= MIN_OUTER && !rematched && change < WEIGHT_TOLERANCE {
            break;
        }
    }
    let mut fixed = Vec::new();
    let mut round = 0;
    loop {
        let problem = Problem {
            layout: &layout,
            observations: &observations,
            blocks: &blocks,
            rows,
            noise: &noise,
            weights: &weights,
        };
        let jacobian = problem.jacobian(&model);
        let (residual, _) = problem.residuals(&model);
        let analysis = analyse(&layout.names(&model), &jacobian, &residual);
        if analysis.near_null.is_empty() || round == MAX_FIX_ROUNDS {
            return Ok(JointFit {
                model,
                layout,
                fixed,
                noise,
                observations,
                blocks,
                rows,
                weights,
                jacobian,
                residual,
                analysis,
                outer_iterations,
            });
        }
        round += 1;
        let to_fix: Vec<(M::Param, NearNullDirection)> = analysis
            .near_null
            .iter()
            .map(|d| (layout.ids[d.dominant], d.clone()))
            .collect();
        for (id, direction) in to_fix {
            let value = start.get(id);
            model.set(id, value);
            layout = layout.without(id);
            fixed.push(FixedParameter {
                name: start.describe(id).name,
                value,
                direction,
            });
        }
        let problem = Problem {
            layout: &layout,
            observations: &observations,
            blocks: &blocks,
            rows,
            noise: &noise,
            weights: &weights,
        };
        model = solve(problem, &model, STAGE)?.model;
    }
}
