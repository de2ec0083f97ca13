//! Held-out checks that work for any model: the cross-validated error of one quantity kind
//! over contiguous folds of its blocks, and the standard deviation of a predicted position
//! propagated from the fit's parameter covariance.
//!
//! Cross-validation: each fold's blocks are left out in turn, the joint solution is updated
//! without them (one Gauss–Newton step from the full solution, exact to first order) and the
//! left-out measurements are predicted.

use nalgebra::{DMatrix, DVector, Vector3};

use crate::fit::joint_fit::JointFit;
use crate::math::stats::ErrorSummary;
use crate::model::{Block, QuantityKind, RobotModel};

/// Folds of the cross-validation.
pub const CROSS_VALIDATION_FOLDS: usize = 5;

/// Cross-validated position error (mm) of the blocks of `kind` over contiguous folds (see
/// the module docs); `None` without at least one block of the kind per fold.
pub fn cross_validated<M: RobotModel>(
    fit: &JointFit<M>,
    kind: QuantityKind,
) -> Option<ErrorSummary> {
    let kind_blocks: Vec<usize> = (0..fit.blocks.len())
        .filter(|&i| fit.blocks[i].kind == kind && fit.weights[i] > 0.0)
        .collect();
    if kind_blocks.len() < CROSS_VALIDATION_FOLDS {
        return None;
    }
    let j = &fit.jacobian;
    let r = &fit.residual;
    let normal = j.transpose() * j;
    let x = fit.layout.values(&fit.model);
    let fold_len = kind_blocks.len().div_ceil(CROSS_VALIDATION_FOLDS);
    let mut errors = Vec::with_capacity(kind_blocks.len());
    let mut raws = Vec::new();
    for fold in kind_blocks.chunks(fold_len) {
        let rows: Vec<usize> = fold
            .iter()
            .flat_map(|&b| {
                let block = &fit.blocks[b];
                (0..block.dim).map(move |k| block.row + k)
            })
            .collect();
        let j_fold = DMatrix::from_fn(rows.len(), j.ncols(), |a, c| j[(rows[a], c)]);
        let r_fold = DVector::from_fn(rows.len(), |a, _| r[rows[a]]);
        let reduced = &normal - j_fold.transpose() * &j_fold;
        let step = reduced.cholesky()?.solve(&(j_fold.transpose() * r_fold));
        let mut model = fit.model.clone();
        fit.layout.apply(&mut model, &(&x + step));
        let blocks: Vec<Block> = fold.iter().map(|&b| fit.blocks[b]).collect();
        raws.clear();
        model.residuals(&fit.observations, &blocks, &mut raws);
        for raw in raws.iter().flatten() {
            errors.push((raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2]).sqrt());
        }
    }
    ErrorSummary::of(&errors)
}

/// Standard deviation (of the 3-D error, mm) of the position `predict` gives at the fitted
/// model, from the fit's parameter covariance (forward differences of `predict` over the
/// fitted parameters); `None` when a parameter is undetermined or `predict` fails.
pub fn propagated_std<M: RobotModel>(
    fit: &JointFit<M>,
    predict: impl Fn(&M) -> Option<Vector3<f64>>,
) -> Option<f64> {
    let ids = &fit.layout.ids;
    let n = ids.len();
    let sigma = &fit.analysis.std_devs;
    if sigma.iter().any(|s| !s.is_finite()) {
        return None;
    }
    let covariance = DMatrix::from_fn(n, n, |a, b| {
        fit.analysis.correlation[(a, b)] * sigma[a] * sigma[b]
    });
    let base = predict(&fit.model)?;
    let mut jacobian = DMatrix::<f64>::zeros(3, n);
    for (k, &id) in ids.iter().enumerate() {
        let step = fit.model.describe(id).step;
        let mut shifted = fit.model.clone();
        shifted.set(id, fit.model.get(id) + step);
        let d = (predict(&shifted)? - base) / step;
        jacobian.set_column(k, &d);
    }
    Some(
        (&jacobian * &covariance * jacobian.transpose())
            .trace()
            .max(0.0)
            .sqrt(),
    )
}
