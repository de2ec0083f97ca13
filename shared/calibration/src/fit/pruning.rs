//! A minimal parameter set: the engine's identifiability analysis drops, one near-null
//! direction at a time, the parameter that dominates it, until the rest are all
//! determined by the data. Complete but redundant error sets (a serial arm's per-joint
//! error transforms) become minimal this way before they are fitted.

use nalgebra::DVector;

use crate::fit::identifiability::analyse;
use crate::model::{blocks_of, NoiseModel, ParamLayout, Problem, RobotModel};

/// The parameters of `layout` that `observations` determine at `model` (noise `noise`),
/// and the names of those dropped, in the order they were dropped.
pub fn minimal_layout<M: RobotModel>(
    model: &M,
    observations: &[M::Observation],
    noise: &NoiseModel,
    layout: &ParamLayout<M::Param>,
) -> (ParamLayout<M::Param>, Vec<String>) {
    let (blocks, rows) = blocks_of(model, observations);
    let weights = vec![1.0; blocks.len()];
    let problem = Problem {
        layout,
        observations,
        blocks: &blocks,
        rows,
        noise,
        weights: &weights,
    };
    // JᵀJ = RᵀR: the n×n factor R carries everything the analysis needs of the tall J.
    let r = problem.jacobian(model).qr().r();
    let residual = DVector::zeros(r.nrows());
    let mut kept = layout.clone();
    let mut dropped = Vec::new();
    loop {
        let columns: Vec<usize> = kept
            .ids
            .iter()
            .filter_map(|id| layout.position(*id))
            .collect();
        let analysis = analyse(&kept.names(model), &r.select_columns(&columns), &residual);
        let Some(direction) = analysis.near_null.iter().min_by(|a, b| {
            a.relative_singular_value
                .total_cmp(&b.relative_singular_value)
        }) else {
            return (kept, dropped);
        };
        let id = kept.ids[direction.dominant];
        dropped.push(model.describe(id).name);
        kept = kept.without(id);
    }
}
