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

use crate::joint_fit::JointFit;

/// Cross-validation folds.
pub const FOLDS: usize = 10;
/// Contiguous time blocks per fold (interleaved, so every fold spans the session).
const BLOCKS_PER_FOLD: usize = 4;
/// Ridge on the unit-normalised Gram diagonal (keeps near-collinear sets solvable).
const RIDGE: f64 = 1e-10;

#[derive(Debug, Clone)]
struct Gram {
    gram: DMatrix<f64>,
    product: DVector<f64>,
    rr: f64,
}

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
    pub fn new(fit: &JointFit, extra: &DMatrix<f64>) -> Self {
        let fitted = fit.jacobian.ncols();
        let mut columns = DMatrix::zeros(fit.rows, fitted + extra.ncols());
        columns.columns_mut(0, fitted).copy_from(&fit.jacobian);
        columns.columns_mut(fitted, extra.ncols()).copy_from(extra);
        let scales: Vec<f64> = columns
            .column_iter()
            .map(|c| c.norm())
            .map(|n| if n > 0.0 { n } else { 1.0 })
            .collect();
        for (k, mut column) in columns.column_iter_mut().enumerate() {
            column /= scales[k];
        }
        let fold_of_row = fold_of_rows(fit);
        let grams: Vec<Gram> = (0..FOLDS)
            .map(|f| {
                let rows: Vec<usize> = (0..fit.rows).filter(|&r| fold_of_row[r] == f).collect();
                let a = columns.select_rows(&rows);
                let a_t = a.transpose();
                let r = fit.residual.select_rows(&rows);
                Gram {
                    rr: r.norm_squared(),
                    gram: &a_t * &a,
                    product: &a_t * r,
                }
            })
            .collect();
        let total = Gram {
            gram: grams
                .iter()
                .fold(DMatrix::zeros(columns.ncols(), columns.ncols()), |s, g| {
                    s + &g.gram
                }),
            product: grams
                .iter()
                .fold(DVector::zeros(columns.ncols()), |s, g| s + &g.product),
            rr: grams.iter().map(|g| g.rr).sum(),
        };
        let folds = grams
            .into_iter()
            .map(|own| {
                let train = Gram {
                    gram: &total.gram - &own.gram,
                    product: &total.product - &own.product,
                    rr: total.rr - own.rr,
                };
                (own, train)
            })
            .collect();
        Self {
            fitted,
            scales,
            total,
            folds,
            rows: fit.rows,
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
fn fold_of_rows(fit: &JointFit) -> Vec<usize> {
    let n = fit.observations.len().max(1);
    let blocks = FOLDS * BLOCKS_PER_FOLD;
    let mut folds = vec![0; fit.rows];
    for block in &fit.blocks {
        let fold = (block.obs * blocks / n) % FOLDS;
        for row in block.row..block.row + block.quantity.dim() {
            folds[row] = fold;
        }
    }
    folds
}
