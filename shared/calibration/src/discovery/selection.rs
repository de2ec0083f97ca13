//! The linearised problem around a fit, for scoring candidates: the Gram matrix of the
//! columns `[fitted parameters | candidate columns]` and their products with the residual,
//! in total and per cross-validation fold (time blocks).
//!
//! Adding columns `C` to the fitted set `S` and taking one Gauss–Newton step lowers the cost
//! by `Δχ² = SSE(S) − SSE(S ∪ C)` (the score statistic: under "no effect" it is χ² with
//! `dim C` degrees of freedom, the residual being whitened). Leaving a fold out, the same step
//! taken on the other folds predicts the left-out residual; its sum of squares is the
//! held-out error, and its reduction by `C` the held-out gain.

use nalgebra::{DMatrix, DVector};

use crate::fit::joint_fit::JointFit;
use crate::fit::ridge::{fold_grams, scaled_columns, Gram};
use crate::model::RobotModel;

/// Cross-validation folds.
pub const FOLDS: usize = 10;
/// Contiguous time blocks per fold (interleaved, so every fold spans the session).
const BLOCKS_PER_FOLD: usize = 4;
/// Ridge on the unit-normalised Gram diagonal (keeps near-collinear sets solvable).
const RIDGE: f64 = 1e-10;

impl Gram {
    /// Residual sum of squares after the step on `set` solved from `train` (`None` when the
    /// set is singular): `|r + Aδ|²` with `δ = −G⁻¹Aᵀr` of the training data.
    fn sse_with(&self, train: &Gram, set: &[usize]) -> Option<(f64, DVector<f64>)> {
        if set.is_empty() {
            return Some((self.rr, DVector::zeros(0)));
        }
        let mut g = train.gram.select_rows(set).select_columns(set);
        for k in 0..set.len() {
            g[(k, k)] += RIDGE;
        }
        let b = train.product.select_rows(set);
        let delta = -g.cholesky()?.solve(&b);
        let own_g = self.gram.select_rows(set).select_columns(set);
        let own_b = self.product.select_rows(set);
        let sse = self.rr + 2.0 * delta.dot(&own_b) + (delta.transpose() * own_g * &delta)[(0, 0)];
        Some((sse.max(0.0), delta))
    }
}

/// The linearised problem of a fit with extra candidate columns.
#[derive(Debug, Clone)]
pub struct Design {
    /// Columns of the fit's Jacobian (the fitted parameters), first in column order.
    pub fitted: usize,
    /// Norm of every column (columns are normalised to unit norm).
    scales: Vec<f64>,
    total: Gram,
    folds: Vec<(Gram, Gram)>,
    /// Residual rows.
    pub rows: usize,
}

/// How a set of columns does: in-sample and held-out sums of squares.
#[derive(Debug, Clone, PartialEq)]
pub struct SetFit {
    /// In-sample SSE after the step.
    pub sse: f64,
    /// Held-out SSE of each fold.
    pub fold_sse: Vec<f64>,
    /// The step, in the units of each column's parameter.
    pub step: Vec<f64>,
}

impl SetFit {
    /// Held-out SSE over all folds.
    pub fn held_out(&self) -> f64 {
        self.fold_sse.iter().sum()
    }
}

impl Design {
    /// Builds the design of `fit` (its weighted Jacobian and residual) with `extra` columns.
    pub fn new<M: RobotModel>(fit: &JointFit<M>, extra: &DMatrix<f64>) -> Self {
        Self::from_parts(&fit.jacobian, extra, &fit.residual, &fold_of_rows(fit))
    }

    /// Builds the design of a residual `residual` with fitted columns `jacobian`, `extra`
    /// columns, and the fold (< [`FOLDS`]) of every row.
    pub fn from_parts(
        jacobian: &DMatrix<f64>,
        extra: &DMatrix<f64>,
        residual: &DVector<f64>,
        fold_of_row: &[usize],
    ) -> Self {
        let fitted = jacobian.ncols();
        let rows = residual.len();
        let (columns, scales) = scaled_columns(jacobian, extra);
        let (total, folds) = fold_grams(&columns, residual, fold_of_row, FOLDS);
        Self {
            fitted,
            scales,
            total,
            folds,
            rows,
        }
    }

    /// Total residual sum of squares at the fit.
    pub fn rr(&self) -> f64 {
        self.total.rr
    }

    /// Index of the `k`-th extra column.
    pub fn extra(&self, k: usize) -> usize {
        self.fitted + k
    }

    /// Whether column `index` is identically zero (the signal never acts).
    pub fn is_empty_column(&self, index: usize) -> bool {
        self.total.gram[(index, index)] == 0.0
    }

    /// The Gram matrix of the (unit-normalised) columns `set` after projecting out the
    /// columns `base`: what `set` adds beyond `base`. Its diagonal is 1 for a column
    /// orthogonal to `base` and 0 for one inside its span; `None` when `base` is singular.
    pub fn conditional_gram(&self, base: &[usize], set: &[usize]) -> Option<DMatrix<f64>> {
        let gram = &self.total.gram;
        let own = gram.select_rows(set).select_columns(set);
        if base.is_empty() {
            return Some(own);
        }
        let mut g = gram.select_rows(base).select_columns(base);
        for k in 0..base.len() {
            g[(k, k)] += RIDGE;
        }
        let cross = gram.select_rows(base).select_columns(set);
        let solved = g.cholesky()?.solve(&cross);
        Some(own - cross.transpose() * solved)
    }

    /// In-sample and held-out fit of the column set `set`; `None` when it is singular.
    pub fn fit(&self, set: &[usize]) -> Option<SetFit> {
        let (sse, delta) = self.total.sse_with(&self.total, set)?;
        let fold_sse = self
            .folds
            .iter()
            .map(|(own, train)| own.sse_with(train, set).map(|(s, _)| s))
            .collect::<Option<Vec<f64>>>()?;
        let step = set
            .iter()
            .zip(delta.iter())
            .map(|(&k, d)| d / self.scales[k])
            .collect();
        Some(SetFit {
            sse,
            fold_sse,
            step,
        })
    }
}

/// The fold of every residual row: observations are cut into `FOLDS·BLOCKS_PER_FOLD`
/// contiguous blocks in time order, block `b` going to fold `b mod FOLDS`.
fn fold_of_rows<M: RobotModel>(fit: &JointFit<M>) -> Vec<usize> {
    let n = fit.observations.len().max(1);
    let blocks = FOLDS * BLOCKS_PER_FOLD;
    let mut folds = vec![0; fit.rows];
    for block in &fit.blocks {
        let fold = (block.obs * blocks / n) % FOLDS;
        folds[block.row..block.row + block.dim].fill(fold);
    }
    folds
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Least-squares residual sum of squares of `y` on the columns `x`.
    fn least_squares_sse(x: &DMatrix<f64>, y: &DVector<f64>) -> (f64, DVector<f64>) {
        let beta = (x.transpose() * x)
            .cholesky()
            .unwrap()
            .solve(&(x.transpose() * y));
        ((y - x * &beta).norm_squared(), beta)
    }

    #[test]
    fn gains_match_explicit_least_squares_in_sample_and_held_out() {
        let m = 400;
        let t = |i: usize| i as f64 / m as f64;
        // Fitted columns: constant and slope; extra: a sine that is in the data, and noise.
        let jacobian = DMatrix::from_fn(m, 2, |i, j| if j == 0 { 1.0 } else { t(i) });
        let extra = DMatrix::from_fn(m, 2, |i, j| {
            if j == 0 {
                (17.0 * t(i)).sin()
            } else {
                ((i * 7919) % 13) as f64 - 6.0
            }
        });
        let noise = |i: usize| (((i * 104_729) % 97) as f64 / 97.0 - 0.5) * 0.2;
        let data = DVector::from_fn(m, |i, _| {
            0.3 + 0.5 * t(i) + 0.8 * (17.0 * t(i)).sin() + noise(i)
        });
        // The residual at the fit of the fitted columns (what a converged fit leaves).
        let (_, beta) = least_squares_sse(&jacobian, &data);
        let residual = &data - &jacobian * beta;
        let folds: Vec<usize> = (0..m).map(|i| (i * FOLDS * 4 / m) % FOLDS).collect();
        let design = Design::from_parts(&jacobian, &extra, &residual, &folds);

        let base = design.fit(&[0, 1]).unwrap();
        let with = design.fit(&[0, 1, design.extra(0)]).unwrap();
        let mut x = jacobian.clone().insert_column(2, 0.0);
        x.set_column(2, &extra.column(0));
        let (sse_base, _) = least_squares_sse(&jacobian, &data);
        let (sse_with, beta_with) = least_squares_sse(&x, &data);
        assert!(
            (base.sse - sse_base).abs() < 1e-9 * sse_base,
            "{} {sse_base}",
            base.sse
        );
        assert!(
            (with.sse - sse_with).abs() < 1e-9 * sse_with,
            "{} {sse_with}",
            with.sse
        );
        // The columns act as ∂r/∂p = X here, so the step on the sine's parameter is minus
        // its regression coefficient, in the column's own units.
        assert!(
            (with.step[2] + beta_with[2]).abs() < 1e-9,
            "{:?}",
            with.step
        );
        assert!((with.step[2] + 0.8).abs() < 0.02);

        // Held out: fit on the other folds, predict the fold.
        for f in [0, 3, 9] {
            let train: Vec<usize> = (0..m).filter(|&i| folds[i] != f).collect();
            let test: Vec<usize> = (0..m).filter(|&i| folds[i] == f).collect();
            let (_, b) = least_squares_sse(&x.select_rows(&train), &data.select_rows(&train));
            let expected = (data.select_rows(&test) - x.select_rows(&test) * b).norm_squared();
            assert!(
                (with.fold_sse[f] - expected).abs() < 1e-8 * expected.max(1.0),
                "fold {f}"
            );
        }
        assert!(with.held_out() < base.held_out());
        // The sine is nearly orthogonal to constant and slope; a copy of the slope is not.
        let sine = design
            .conditional_gram(&[0, 1], &[design.extra(0)])
            .unwrap();
        assert!(sine[(0, 0)] > 0.9, "{sine}");
        let slope_again = Design::from_parts(
            &jacobian.columns(0, 1).into_owned(),
            &jacobian.columns(1, 1).into_owned(),
            &residual,
            &folds,
        );
        let inside = slope_again.conditional_gram(&[0], &[1]).unwrap();
        assert!(inside[(0, 0)] < 0.3, "{inside}");
        assert!(inside[(0, 0)] > 0.0);
        // A column of noise gains little in sample and loses held out.
        let noisy = design.fit(&[0, 1, design.extra(1)]).unwrap();
        assert!(base.sse - noisy.sse < 0.01 * base.sse);
        assert!(
            noisy.held_out() > base.held_out(),
            "{} {}",
            noisy.held_out(),
            base.held_out()
        );
    }
}
