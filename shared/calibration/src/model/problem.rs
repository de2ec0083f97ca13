//! The weighted least-squares problem of a model over observations: the stacked, whitened,
//! robustly weighted residual vector and its Jacobian with respect to a [`ParamLayout`].

use nalgebra::{DMatrix, DVector};

use crate::model::blocks::{groups, Block};
use crate::model::layout::ParamLayout;
use crate::model::noise::NoiseModel;
use crate::model::RobotModel;

/// Whitened residual given to the rows of an observation the model cannot predict (so that
/// a trial step into an unreachable region is rejected instead of aborting the fit).
pub const FAILED_PREDICTION_RESIDUAL: f64 = 1e3;

/// A weighted least-squares problem of model `M` over observations.
#[derive(Debug)]
pub struct Problem<'a, M: RobotModel> {
    /// The parameters that move.
    pub layout: &'a ParamLayout<M::Param>,
    /// The fitted observations, in time order.
    pub observations: &'a [M::Observation],
    /// Residual blocks, grouped by observation in ascending order.
    pub blocks: &'a [Block],
    /// Total residual rows.
    pub rows: usize,
    /// Noise model that whitens each block.
    pub noise: &'a NoiseModel,
    /// Robust weight of each block (multiplies its squared residual).
    pub weights: &'a [f64],
}

impl<M: RobotModel> Clone for Problem<'_, M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M: RobotModel> Copy for Problem<'_, M> {}

impl<'a, M: RobotModel> Problem<'a, M> {
    /// The same problem over another layout.
    pub fn with_layout<'b>(&self, layout: &'b ParamLayout<M::Param>) -> Problem<'b, M>
    where
        'a: 'b,
    {
        Problem { layout, ..*self }
    }

    /// The blocks of each observation, with the index of the group's first block.
    pub fn groups(&self) -> impl Iterator<Item = (usize, &'a [Block])> {
        groups(self.blocks)
    }

    /// Raw residual of every block at `model` (`None` where it cannot predict).
    pub fn raw_residuals(&self, model: &M) -> Vec<Option<[f64; 6]>> {
        let mut out = Vec::with_capacity(self.blocks.len());
        model.residuals(self.observations, self.blocks, &mut out);
        out
    }

    /// Writes the whitened, weighted rows of block `index` (raw residual `raw`) through
    /// `write(row, value)`.
    pub fn write_block(&self, index: usize, raw: &[f64; 6], mut write: impl FnMut(usize, f64)) {
        let block = &self.blocks[index];
        let mut white = [0.0; 6];
        self.noise.whiten(block, raw, &mut white);
        let scale = self.weights[index].sqrt();
        for (d, value) in white[..block.dim].iter().enumerate() {
            write(block.row + d, scale * value);
        }
    }

    /// The stacked weighted residual vector of raw block residuals `raws`, and the number of
    /// observations that could not be predicted.
    pub fn stack(&self, raws: &[Option<[f64; 6]>]) -> (DVector<f64>, usize) {
        let mut r = DVector::zeros(self.rows);
        let mut failed = 0;
        for (first, group) in self.groups() {
            let mut group_failed = false;
            for (k, block) in group.iter().enumerate() {
                match &raws[first + k] {
                    Some(raw) => self.write_block(first + k, raw, |row, value| r[row] = value),
                    None => {
                        group_failed = true;
                        r.rows_mut(block.row, block.dim)
                            .fill(FAILED_PREDICTION_RESIDUAL);
                    }
                }
            }
            failed += usize::from(group_failed);
        }
        (r, failed)
    }

    /// The stacked weighted residual vector at `model`, and the number of observations it
    /// cannot predict.
    pub fn residuals(&self, model: &M) -> (DVector<f64>, usize) {
        self.stack(&self.raw_residuals(model))
    }

    /// Jacobian of [`Self::residuals`] at `model` (the model's own, see
    /// [`RobotModel::jacobian`]).
    pub fn jacobian(&self, model: &M) -> DMatrix<f64> {
        model.jacobian(self)
    }

    /// Forward-difference Jacobian of [`Self::residuals`]: each parameter moved by its step,
    /// the whole batch predicted again. Rows of blocks the model cannot predict at either
    /// point are left at zero.
    pub fn finite_difference_jacobian(&self, model: &M) -> DMatrix<f64> {
        let mut jacobian = DMatrix::zeros(self.rows, self.layout.len());
        let base = self.raw_residuals(model);
        let (r0, _) = self.stack(&base);
        for (col, &id) in self.layout.ids.iter().enumerate() {
            let step = model.describe(id).step;
            let mut shifted = model.clone();
            shifted.set(id, model.get(id) + step);
            let raws = self.raw_residuals(&shifted);
            for index in 0..self.blocks.len() {
                let (Some(_), Some(raw)) = (&base[index], &raws[index]) else {
                    continue;
                };
                self.write_block(index, raw, |row, value| {
                    jacobian[(row, col)] = (value - r0[row]) / step;
                });
            }
        }
        jacobian
    }
}
