//! Ridge-regularised Gauss–Newton steps on the linearised problem around a fit, with
//! cross-validated errors: the Gram matrices of the columns `[fitted parameters | extra
//! columns]` and their products with the residual, in total and per fold.
//!
//! A step on a column set `S` solves `(A_Sᵀ A_S + Λ) δ = −A_Sᵀ r`, where `Λ` is a ridge on
//! chosen columns, relative to the column's squared norm (columns are normalised, so a
//! relative ridge of 0.1 shrinks a column that explains as much as it weighs by about 10 %).
//! Effects with many parameters (harmonics of a joint angle) stay bounded outside the range
//! the data cover this way. Leaving a fold out, the step solved on the other folds predicts
//! the fold's residual; the sum of squares over all folds is the held-out error.
//!
//! The residual may be moved to `r + A_S δ_S` (the residual after a step on a set already
//! chosen) without touching the rows: only the products change.

use nalgebra::{DMatrix, DVector};

/// Gram matrix, product with the residual and residual sum of squares of some rows.
#[derive(Debug, Clone)]
pub(crate) struct Gram {
    /// `AᵀA` of the rows.
    pub(crate) gram: DMatrix<f64>,
    /// `Aᵀr` of the rows.
    pub(crate) product: DVector<f64>,
    /// `rᵀr` of the rows.
    pub(crate) rr: f64,
}

impl Gram {
    fn of(columns: &DMatrix<f64>, residual: &DVector<f64>, rows: &[usize]) -> Self {
        let a = columns.select_rows(rows);
        let r = residual.select_rows(rows);
        let a_t = a.transpose();
        Gram {
            gram: &a_t * &a,
            product: &a_t * &r,
            rr: r.norm_squared(),
        }
    }

    fn minus(&self, other: &Gram) -> Gram {
        Gram {
            gram: &self.gram - &other.gram,
            product: &self.product - &other.product,
            rr: self.rr - other.rr,
        }
    }

    /// The same rows with the residual moved by the step `delta` on `set`.
    fn shifted(&self, set: &[usize], delta: &DVector<f64>) -> Gram {
        if set.is_empty() {
            return self.clone();
        }
        let g_set = self.gram.select_columns(set);
        let moved = &g_set * delta;
        let own = self.product.select_rows(set);
        Gram {
            gram: self.gram.clone(),
            rr: (self.rr + 2.0 * delta.dot(&own) + delta.dot(&moved.select_rows(set))).max(0.0),
            product: &self.product + moved,
        }
    }

    /// The step on `set` with relative ridges `ridge` (`None` when singular).
    fn step(&self, set: &[usize], ridge: &[f64]) -> Option<DVector<f64>> {
        let mut g = self.gram.select_rows(set).select_columns(set);
        for (k, lambda) in ridge.iter().enumerate() {
            g[(k, k)] += lambda * g[(k, k)].max(f64::MIN_POSITIVE) + 1e-12;
        }
        let b = self.product.select_rows(set);
        Some(-g.cholesky()?.solve(&b))
    }

    /// Sum of squares of these rows after the step `delta` on `set`.
    fn sse_after(&self, set: &[usize], delta: &DVector<f64>) -> f64 {
        let g = self.gram.select_rows(set).select_columns(set);
        let b = self.product.select_rows(set);
        (self.rr + 2.0 * delta.dot(&b) + (delta.transpose() * g * delta)[(0, 0)]).max(0.0)
    }
}

/// The linearised problem of a fit with extra columns, split in folds.
#[derive(Debug, Clone)]
pub struct RidgeDesign {
    /// Columns of the fit's Jacobian (the fitted parameters), first in column order.
    pub fitted: usize,
    scales: Vec<f64>,
    total: Gram,
    folds: Vec<(Gram, Gram)>,
}

/// How a column set does after a ridge step.
#[derive(Debug, Clone, PartialEq)]
pub struct RidgeFit {
    /// In-sample sum of squares.
    pub sse: f64,
    /// Held-out sum of squares over all folds.
    pub held_out: f64,
    /// The step on all rows, in each column's parameter units.
    pub step: Vec<f64>,
}

impl RidgeDesign {
    /// The design of residual `residual` with fitted columns `jacobian` and `extra` columns;
    /// `fold_of_row` gives each row's fold (< `folds`).
    pub fn new(
        jacobian: &DMatrix<f64>,
        extra: &DMatrix<f64>,
        residual: &DVector<f64>,
        fold_of_row: &[usize],
        folds: usize,
    ) -> Self {
        let fitted = jacobian.ncols();
        let (columns, scales) = scaled_columns(jacobian, extra);
        let (total, folds) = fold_grams(&columns, residual, fold_of_row, folds);
        Self {
            fitted,
            scales,
            total,
            folds,
        }
    }

    /// Index of the `k`-th extra column.
    pub fn extra(&self, k: usize) -> usize {
        self.fitted + k
    }

    /// Whether column `index` never acts.
    pub fn is_empty_column(&self, index: usize) -> bool {
        self.total.gram[(index, index)] == 0.0
    }

    /// The design with the residual moved by the (normalised) step `delta` on `set`.
    fn shifted(&self, set: &[usize], delta: &DVector<f64>) -> Self {
        Self {
            fitted: self.fitted,
            scales: self.scales.clone(),
            total: self.total.shifted(set, delta),
            folds: self
                .folds
                .iter()
                .map(|(own, train)| (own.shifted(set, delta), train.shifted(set, delta)))
                .collect(),
        }
    }

    /// The design of the residual left by the ridge step on `set` over all rows.
    pub fn after(&self, set: &[usize], ridge: &[f64]) -> Option<Self> {
        let delta = self.total.step(set, ridge)?;
        Some(self.shifted(set, &delta))
    }

    /// In-sample and held-out sums of squares of the ridge step on `set` (relative ridge
    /// per column of `set`); `None` when singular.
    pub fn fit(&self, set: &[usize], ridge: &[f64]) -> Option<RidgeFit> {
        if set.is_empty() {
            return Some(RidgeFit {
                sse: self.total.rr,
                held_out: self.total.rr,
                step: Vec::new(),
            });
        }
        let delta = self.total.step(set, ridge)?;
        let sse = self.total.sse_after(set, &delta);
        let mut held_out = 0.0;
        for (own, train) in &self.folds {
            held_out += own.sse_after(set, &train.step(set, ridge)?);
        }
        Some(RidgeFit {
            sse,
            held_out,
            step: set
                .iter()
                .zip(delta.iter())
                .map(|(&k, d)| d / self.scales[k])
                .collect(),
        })
    }

    /// In-sample power of the columns `set` alone on the residual (the cost reduction of a
    /// step on them, ignoring every other column): a periodogram ordinate for a sine and
    /// cosine pair.
    pub fn power(&self, set: &[usize]) -> f64 {
        match self.total.step(set, &vec![0.0; set.len()]) {
            Some(delta) => self.total.rr - self.total.sse_after(set, &delta),
            None => 0.0,
        }
    }

    /// Total residual sum of squares.
    pub fn rr(&self) -> f64 {
        self.total.rr
    }
}

/// The Gram of all rows and, per fold (`fold_of_row[r] < folds`), the fold's own Gram and that
/// of the other folds (its training rows).
pub(crate) fn fold_grams(
    columns: &DMatrix<f64>,
    residual: &DVector<f64>,
    fold_of_row: &[usize],
    folds: usize,
) -> (Gram, Vec<(Gram, Gram)>) {
    let rows = residual.len();
    let owns: Vec<Gram> = (0..folds)
        .map(|f| {
            let selected: Vec<usize> = (0..rows).filter(|&r| fold_of_row[r] == f).collect();
            Gram::of(columns, residual, &selected)
        })
        .collect();
    let mut total = owns[0].clone();
    for own in &owns[1..] {
        total.gram += &own.gram;
        total.product += &own.product;
        total.rr += own.rr;
    }
    let folds = owns
        .into_iter()
        .map(|own| {
            let train = total.minus(&own);
            (own, train)
        })
        .collect();
    (total, folds)
}

/// The columns of `jacobian` followed by those of `extra`, each scaled to unit norm (a zero
/// column keeps scale 1), and the scales: the common form of every design the ridge and the
/// selection solve, so their penalties act on comparable columns.
pub fn scaled_columns(jacobian: &DMatrix<f64>, extra: &DMatrix<f64>) -> (DMatrix<f64>, Vec<f64>) {
    let fitted = jacobian.ncols();
    let mut columns = DMatrix::zeros(jacobian.nrows(), fitted + extra.ncols());
    columns.columns_mut(0, fitted).copy_from(jacobian);
    columns.columns_mut(fitted, extra.ncols()).copy_from(extra);
    let scales: Vec<f64> = columns
        .column_iter()
        .map(|c| c.norm())
        .map(|n| if n > 0.0 { n } else { 1.0 })
        .collect();
    for (k, mut column) in columns.column_iter_mut().enumerate() {
        column /= scales[k];
    }
    (columns, scales)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ridge_step_matches_explicit_regularised_least_squares() {
        let m = 300;
        let t = |i: usize| i as f64 / m as f64;
        let jacobian = DMatrix::from_fn(m, 1, |_, _| 1.0);
        let extra = DMatrix::from_fn(m, 2, |i, j| {
            if j == 0 {
                (9.0 * t(i)).sin()
            } else {
                (9.0 * t(i)).cos()
            }
        });
        let residual = DVector::from_fn(m, |i, _| {
            0.4 - 0.7 * (9.0 * t(i)).sin() + 0.01 * ((i * 37 % 11) as f64 - 5.0)
        });
        let folds: Vec<usize> = (0..m).map(|i| i % 5).collect();
        let design = RidgeDesign::new(&jacobian, &extra, &residual, &folds, 5);
        let set = [0, design.extra(0), design.extra(1)];
        let plain = design.fit(&set, &[0.0; 3]).unwrap();
        // The step cancels the residual: δ ≈ −(0.4, −0.7, 0).
        assert!((plain.step[0] + 0.4).abs() < 0.01, "{:?}", plain.step);
        assert!((plain.step[1] - 0.7).abs() < 0.01, "{:?}", plain.step);
        assert!(plain.sse < 0.01 * design.rr() && plain.held_out < 0.02 * design.rr());
        let shrunk = design.fit(&set, &[0.0, 1.0, 1.0]).unwrap();
        assert!(
            shrunk.step[1].abs() < plain.step[1].abs() * 0.8,
            "{:?}",
            shrunk.step
        );
        assert!(shrunk.sse > plain.sse);
        // Moving the residual by the plain step leaves nothing for the same columns.
        let after = design.after(&set, &[0.0; 3]).unwrap();
        assert!((after.rr() - plain.sse).abs() < 1e-9 * design.rr());
        assert!(after.power(&[design.extra(0), design.extra(1)]) < 1e-6 * design.rr());
        assert!(design.power(&[design.extra(0), design.extra(1)]) > 0.5 * design.rr());
    }
}
