//! The parameter vector of a fit: which of a model's scalars each entry of the optimiser's
//! vector is.

use nalgebra::DVector;

use crate::model::RobotModel;

/// What a parameter is.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamInfo {
    /// Name as in reports, e.g. `gear_ratio[3]`.
    pub name: String,
    /// Unit of its value, e.g. `mm`, `rad`, `s`, `1`.
    pub unit: &'static str,
    /// Its scale: the forward-difference step of the Jacobian, in its unit.
    pub step: f64,
}

/// An ordered list of the model scalars the optimiser moves.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamLayout<P> {
    /// The parameters, in vector order.
    pub ids: Vec<P>,
}

impl<P: Copy + PartialEq> ParamLayout<P> {
    /// A layout of `ids`.
    pub fn new(ids: Vec<P>) -> Self {
        Self { ids }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether the layout is empty.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Position of `id` in the layout.
    pub fn position(&self, id: P) -> Option<usize> {
        self.ids.iter().position(|i| *i == id)
    }

    /// The layout without `id`.
    pub fn without(&self, id: P) -> Self {
        Self {
            ids: self.ids.iter().copied().filter(|i| *i != id).collect(),
        }
    }

    /// The parameter vector of `model`.
    pub fn values<M: RobotModel<Param = P>>(&self, model: &M) -> DVector<f64> {
        DVector::from_iterator(self.ids.len(), self.ids.iter().map(|id| model.get(*id)))
    }

    /// Writes the vector `x` into `model`.
    pub fn apply<M: RobotModel<Param = P>>(&self, model: &mut M, x: &DVector<f64>) {
        for (id, value) in self.ids.iter().zip(x.iter()) {
            model.set(*id, *value);
        }
    }

    /// The names of the parameters (layout order).
    pub fn names<M: RobotModel<Param = P>>(&self, model: &M) -> Vec<String> {
        self.ids.iter().map(|id| model.describe(*id).name).collect()
    }
}
