//! A Levenberg–Marquardt solve of a model's weighted least-squares problem.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

use crate::error::CalibrationError;
use crate::model::{Problem, RobotModel};

/// Result of a Levenberg–Marquardt solve.
#[derive(Debug, Clone)]
pub struct Solution<M> {
    /// The fitted model.
    pub model: M,
    /// Weighted cost `½ Σ r²` at the solution.
    pub cost: f64,
    /// Residual evaluations used.
    pub evaluations: usize,
}

struct LmAdapter<'a, M: RobotModel> {
    problem: Problem<'a, M>,
    template: M,
    x: DVector<f64>,
}

impl<M: RobotModel> LmAdapter<'_, M> {
    fn model(&self) -> M {
        let mut model = self.template.clone();
        self.problem.layout.apply(&mut model, &self.x);
        model
    }
}

impl<M: RobotModel> LeastSquaresProblem<f64, Dyn, Dyn> for LmAdapter<'_, M> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(self.problem.residuals(&self.model()).0)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        Some(self.problem.jacobian(&self.model()))
    }
}

/// Minimises the problem's cost with Levenberg–Marquardt from `start`. Errors (naming
/// `stage`) when the solver reports a numerical failure or the model cannot predict some
/// observations at the solution.
pub fn solve<M: RobotModel>(
    problem: Problem<'_, M>,
    start: &M,
    stage: &'static str,
) -> Result<Solution<M>, CalibrationError> {
    let adapter = LmAdapter {
        problem,
        template: start.clone(),
        x: problem.layout.values(start),
    };
    let (adapter, report) = LevenbergMarquardt::new()
        .with_ftol(1e-10)
        .with_xtol(1e-10)
        .with_gtol(1e-10)
        .with_stepbound(1.0)
        .with_patience(10)
        .minimize(adapter);
    let usable = report.termination.was_successful()
        || matches!(
            report.termination,
            levenberg_marquardt::TerminationReason::LostPatience
                | levenberg_marquardt::TerminationReason::NoImprovementPossible(_)
        );
    if !usable {
        return Err(CalibrationError::Fit {
            stage,
            reason: format!("Levenberg–Marquardt stopped: {:?}", report.termination),
        });
    }
    let model = adapter.model();
    let (_, failed) = problem.residuals(&model);
    if failed > 0 {
        return Err(CalibrationError::Fit {
            stage,
            reason: format!("the fitted model cannot reach {failed} of the measured poses"),
        });
    }
    Ok(Solution {
        model,
        cost: report.objective_function,
        evaluations: report.number_of_evaluations,
    })
}
