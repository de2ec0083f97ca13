//! A minimal parameter set: the engine's identifiability analysis drops, one weak direction
//! at a time, the parameter that dominates it, until the rest are all well determined by
//! the data. Complete but redundant error sets (a serial arm's per-joint error transforms)
//! become minimal this way before they are fitted.
//!
//! Well determined means a relative singular value (of the column-scaled Jacobian) of at
//! least [`PRUNE_TOLERANCE`]. Exact redundancies sit far below it; directions just above
//! exact redundancy (a tool point a fraction of a millimetre off the last joint's axis makes
//! that axis's tilt and offset almost the same error) are dropped too: the data determine
//! them only through a tiny lever, so they fit noise and move by amounts at which the
//! linearisation fails.

use crate::fit::identifiability::weakest_direction;

/// Smallest relative singular value a kept parameter set may have.
pub const PRUNE_TOLERANCE: f64 = 1e-3;
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
    let mut kept = layout.clone();
    let mut dropped = Vec::new();
    loop {
        let columns: Vec<usize> = kept
            .ids
            .iter()
            .filter_map(|id| layout.position(*id))
            .collect();
        let weakest = weakest_direction(&kept.names(model), &r.select_columns(&columns));
        let Some(direction) = weakest.filter(|d| d.relative_singular_value < PRUNE_TOLERANCE)
        else {
            return (kept, dropped);
        };
        let id = kept.ids[direction.dominant];
        dropped.push(model.describe(id).name);
        kept = kept.without(id);
    }
}
