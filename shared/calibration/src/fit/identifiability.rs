//! Identifiability of the fitted parameters from the weighted Jacobian at the solution:
//! numerical rank and condition number (of the column-scaled Jacobian, so units do not
//! matter), the standard deviation of every parameter from `σ̂²·(JᵀJ)⁻¹`, and the near-null
//! directions with the parameters they involve.

use nalgebra::{DMatrix, DVector};

/// Singular values below this fraction of the largest count as rank-deficient.
pub const RANK_TOLERANCE: f64 = 1e-9;
/// Singular values below this fraction of the largest mark a direction that must be fixed.
pub const NEAR_NULL_TOLERANCE: f64 = 1e-6;
/// A parameter is named in a near-null direction if its component exceeds this.
const INVOLVED_COMPONENT: f64 = 0.2;

/// A direction of parameter space the data do not determine.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct NearNullDirection {
    /// Singular value relative to the largest.
    pub relative_singular_value: f64,
    /// Parameters involved, with their (column-scaled) components, largest first.
    pub parameters: Vec<(String, f64)>,
    /// Index (in the analysed layout) of the parameter with the largest component.
    #[serde(skip)]
    pub dominant: usize,
}

/// Result of the analysis.
#[derive(Debug, Clone, PartialEq)]
pub struct Analysis {
    /// Numerical rank of the column-scaled Jacobian.
    pub rank: usize,
    /// Condition number of the column-scaled Jacobian.
    pub condition_number: f64,
    /// Singular values of the column-scaled Jacobian, largest first.
    pub singular_values: Vec<f64>,
    /// Standard deviation of each parameter (layout order, parameter units); infinite for
    /// parameters in a near-null direction.
    pub std_devs: Vec<f64>,
    /// Correlation matrix of the parameters (layout order).
    pub correlation: DMatrix<f64>,
    /// Reduced χ² (`Σr²/(m−n)`) that scales the covariance.
    pub reduced_chi_squared: f64,
    /// Directions below [`NEAR_NULL_TOLERANCE`].
    pub near_null: Vec<NearNullDirection>,
}

/// Analyses the weighted Jacobian `jacobian` and residual `residual` at a solution; `names`
/// are the parameters' names (column order).
pub fn analyse(names: &[String], jacobian: &DMatrix<f64>, residual: &DVector<f64>) -> Analysis {
    let (m, n) = jacobian.shape();
    let scales: Vec<f64> = jacobian
        .column_iter()
        .map(|c| {
            let norm = c.norm();
            if norm > 0.0 {
                norm
            } else {
                1.0
            }
        })
        .collect();
    let mut scaled = jacobian.clone();
    for (j, mut column) in scaled.column_iter_mut().enumerate() {
        column /= scales[j];
    }
    // R of the QR factorisation has the singular values and right vectors of the tall J.
    let r = scaled.qr().r();
    let svd = r.svd(false, true);
    let v_t = svd.v_t.unwrap_or_else(|| DMatrix::identity(n, n));
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|a, b| svd.singular_values[*b].total_cmp(&svd.singular_values[*a]));
    let singular_values: Vec<f64> = order.iter().map(|&i| svd.singular_values[i]).collect();
    let largest = singular_values.first().copied().unwrap_or(0.0);
    let smallest = singular_values.last().copied().unwrap_or(0.0);
    let rank = singular_values
        .iter()
        .filter(|s| **s > RANK_TOLERANCE * largest)
        .count();
    let reduced_chi_squared = if m > n {
        residual.norm_squared() / (m - n) as f64
    } else {
        f64::NAN
    };
    let mut covariance = DMatrix::<f64>::zeros(n, n);
    let mut near_null = Vec::new();
    for &i in &order {
        let s = svd.singular_values[i];
        let v = v_t.row(i).transpose();
        if s > NEAR_NULL_TOLERANCE * largest {
            covariance += &v * v.transpose() / (s * s);
        } else {
            near_null.push(direction(names, &v, s / largest.max(f64::MIN_POSITIVE)));
        }
    }
    let mut std_devs = Vec::with_capacity(n);
    for j in 0..n {
        let in_null = near_null
            .iter()
            .any(|d| d.parameters.iter().any(|(name, _)| *name == names[j]));
        std_devs.push(if in_null {
            f64::INFINITY
        } else {
            (covariance[(j, j)] * reduced_chi_squared).sqrt() / scales[j]
        });
    }
    let correlation = DMatrix::from_fn(n, n, |a, b| {
        let d = (covariance[(a, a)] * covariance[(b, b)]).sqrt();
        if d > 0.0 {
            covariance[(a, b)] / d
        } else {
            0.0
        }
    });
    Analysis {
        rank,
        condition_number: if smallest > 0.0 {
            largest / smallest
        } else {
            f64::INFINITY
        },
        singular_values,
        std_devs,
        correlation,
        reduced_chi_squared,
        near_null,
    }
}

/// The direction of parameter space the weighted Jacobian `jacobian` determines least (of
/// the column-scaled Jacobian, so units do not matter), with its relative singular value;
/// `None` for an empty layout.
pub fn weakest_direction(names: &[String], jacobian: &DMatrix<f64>) -> Option<NearNullDirection> {
    let n = jacobian.ncols();
    if n == 0 {
        return None;
    }
    let mut scaled = jacobian.clone();
    for mut column in scaled.column_iter_mut() {
        let norm = column.norm();
        if norm > 0.0 {
            column /= norm;
        }
    }
    let r = scaled.qr().r();
    let svd = r.svd(false, true);
    let v_t = svd.v_t?;
    let (weakest, smallest) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let largest = svd.singular_values.max();
    let v = v_t.row(weakest).transpose();
    Some(direction(
        names,
        &v,
        smallest / largest.max(f64::MIN_POSITIVE),
    ))
}

fn direction(names: &[String], v: &DVector<f64>, relative: f64) -> NearNullDirection {
    let mut involved: Vec<(usize, f64)> = v
        .iter()
        .enumerate()
        .filter(|(_, c)| c.abs() > INVOLVED_COMPONENT)
        .map(|(j, c)| (j, *c))
        .collect();
    involved.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    let dominant = v.iamax();
    NearNullDirection {
        relative_singular_value: relative,
        parameters: involved
            .iter()
            .map(|(j, c)| (names[*j].clone(), *c))
            .collect(),
        dominant,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_duplicated_column_is_named_as_a_near_null_direction() {
        let names: Vec<String> = ["gain", "offset", "length"].map(String::from).to_vec();
        let jacobian = DMatrix::from_fn(50, 3, |i, j| {
            let t = i as f64 / 10.0;
            match j {
                0 => t.sin(),
                1 => 2.0 * t.sin(),
                _ => t.cos() + 0.3,
            }
        });
        let residual = DVector::from_fn(50, |i, _| ((i * 7) % 5) as f64 - 2.0);
        let analysis = analyse(&names, &jacobian, &residual);
        assert_eq!(analysis.rank, 2);
        assert_eq!(analysis.near_null.len(), 1);
        let names: Vec<&str> = analysis.near_null[0]
            .parameters
            .iter()
            .map(|(n, _)| n.as_str())
            .collect();
        assert!(
            names.contains(&"gain") && names.contains(&"offset"),
            "{names:?}"
        );
        assert!(analysis.std_devs[2].is_finite() && analysis.std_devs[0].is_infinite());
    }

    #[test]
    fn std_dev_of_a_mean_matches_sigma_over_sqrt_n() {
        let names = vec!["length".to_string()];
        let jacobian = DMatrix::from_element(100, 1, 1.0);
        let residual = DVector::from_fn(100, |i, _| if i % 2 == 0 { 1.0 } else { -1.0 });
        let analysis = analyse(&names, &jacobian, &residual);
        assert!((analysis.std_devs[0] - (100.0f64 / 99.0).sqrt() / 10.0).abs() < 1e-12);
        assert_eq!(analysis.condition_number, 1.0);
    }
}
