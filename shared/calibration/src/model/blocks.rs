//! Measured quantities and the residual blocks a fit stacks into one vector.

use serde::Serialize;

use crate::model::RobotModel;

/// A kind of measured quantity of a model (its index in [`RobotModel::quantities`]), e.g. the
/// front marker pose of the biopsy robot or target 2 of a serial arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct QuantityKind(pub usize);

/// What a measured quantity is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    /// A 6-D pose: residual position (mm) then rotation vector (rad).
    Pose,
    /// A 3-D point: residual position (mm).
    Point,
}

impl Shape {
    /// Number of residual rows.
    pub fn dim(self) -> usize {
        match self {
            Shape::Pose => 6,
            Shape::Point => 3,
        }
    }
}

/// A kind of measured quantity: its name for reports and its shape.
#[derive(Debug, Clone, PartialEq)]
pub struct QuantityInfo {
    /// Name, e.g. `front`.
    pub name: String,
    /// Pose or point.
    pub shape: Shape,
}

/// One measured quantity of an observation, as its model lists it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Which kind.
    pub kind: QuantityKind,
    /// Its shape.
    pub shape: Shape,
    /// Its own standard deviations (position mm per axis, then rotation rad per axis),
    /// when the data give them; otherwise the noise model of its kind whitens it.
    pub sigma: Option<[f64; 6]>,
}

impl Measurement {
    /// A measurement whitened by the noise model of its kind.
    pub fn of(kind: QuantityKind, shape: Shape) -> Self {
        Self {
            kind,
            shape,
            sigma: None,
        }
    }
}

/// One block of the stacked residual vector: a measured quantity of an observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Block {
    /// Index of the observation in the fitted slice.
    pub obs: usize,
    /// Which kind of quantity.
    pub kind: QuantityKind,
    /// Number of residual rows (6 for a pose, 3 for a point).
    pub dim: usize,
    /// First row in the stacked vector.
    pub row: usize,
    /// Per-measurement standard deviations, if the data give them.
    pub sigma: Option<[f64; 6]>,
}

/// The blocks of `observations` (every measurement the model lists, in observation order)
/// and the number of rows they stack to.
pub fn blocks_of<M: RobotModel>(model: &M, observations: &[M::Observation]) -> (Vec<Block>, usize) {
    let mut blocks = Vec::new();
    let mut measurements = Vec::new();
    let mut row = 0;
    for (index, obs) in observations.iter().enumerate() {
        measurements.clear();
        model.measurements(obs, &mut measurements);
        for m in &measurements {
            let dim = m.shape.dim();
            blocks.push(Block {
                obs: index,
                kind: m.kind,
                dim,
                row,
                sigma: m.sigma,
            });
            row += dim;
        }
    }
    (blocks, row)
}

/// The blocks grouped by observation: `(index of the group's first block, the group)`.
pub fn groups(blocks: &[Block]) -> impl Iterator<Item = (usize, &[Block])> {
    let mut start = 0;
    blocks.chunk_by(|a, b| a.obs == b.obs).map(move |group| {
        let first = start;
        start += group.len();
        (first, group)
    })
}
