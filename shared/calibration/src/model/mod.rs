//! Model layer: the boundary through which the engine fits any robot.
//!
//! A robot plugs in by implementing [`RobotModel`]:
//!
//! - **parameters**: opaque ids ([`RobotModel::Param`]) the model names, with a unit and a
//!   finite-difference scale ([`ParamInfo`]); a [`ParamLayout`] is the ordered subset the
//!   optimiser moves;
//! - **measurements**: each observation carries measured quantities of known kinds
//!   ([`QuantityKind`], a 6-D pose or a 3-D point, optionally with its own standard
//!   deviations); the engine stacks them as residual [`Block`]s;
//! - **predictions**: [`RobotModel::residuals`] gives measured − predicted for a whole
//!   time-ordered batch of observations at once, so that a model with history-dependent
//!   effects (a play operator, hysteresis) runs its state through the samples;
//! - **Jacobian**: forward differences of the batch by default; a model may override
//!   [`RobotModel::jacobian`] with a faster one (the biopsy robot's channel Jacobian);
//! - **effects**: the candidate explanations of a residual the model can carry, attached to
//!   one of its joints or links, with their linearised columns and how to add them.
//!
//! A [`Dataset`] gives the observations to fit at a model (and says when they must be
//! re-derived, e.g. when the latency they were matched at moved). The fit, identifiability
//! and discovery layers above use only this module's generic items; [`biopsy`] is the
//! biopsy robot's closed-chain model, the first implementation.

pub mod biopsy;
pub mod blocks;
pub mod layout;
pub mod noise;
pub mod problem;
pub mod serial;

use std::fmt::Debug;
use std::hash::Hash;

use nalgebra::DMatrix;

pub use blocks::{blocks_of, Block, Measurement, QuantityInfo, QuantityKind, Shape};
pub use layout::{ParamInfo, ParamLayout};
pub use noise::{NoiseModel, QuantityNoise};
pub use problem::Problem;

/// A robot model the engine can fit: parameters, predictions of the measured quantities of
/// its observations, their Jacobian, and the effects it can carry.
pub trait RobotModel: Clone + Debug + Send + Sync + Sized {
    /// One observation: what the model needs to predict (joint readings, time, temperature,
    /// set-up...) and what was measured there.
    type Observation: Clone + Debug + Send + Sync;
    /// Names one scalar parameter of the model.
    type Param: Copy + Eq + Hash + Debug + Send + Sync;
    /// A candidate explanation of a residual: an effect the model can carry, or a probe
    /// that only points at structure outside its library.
    type Candidate: Copy + Eq + Debug + Send + Sync;

    /// Name, unit and finite-difference step of a parameter.
    fn describe(&self, param: Self::Param) -> ParamInfo;
    /// The parameter's value (in its unit).
    fn get(&self, param: Self::Param) -> f64;
    /// Sets the parameter's value (in its unit).
    fn set(&mut self, param: Self::Param, value: f64);

    /// The kinds of quantity the model's observations measure, indexed by [`QuantityKind`].
    fn quantities(&self) -> Vec<QuantityInfo>;
    /// The measured quantities of `observation` that the fit uses, in block order.
    fn measurements(&self, observation: &Self::Observation, out: &mut Vec<Measurement>);
    /// Raw residuals (measured − predicted) of `blocks` (grouped by observation in ascending
    /// order, indexing `observations`), one entry per block pushed onto `out`: position (mm)
    /// then rotation vector (rad) for a pose, position only (first 3) for a point, `None`
    /// where the model cannot predict the observation. `observations` is the whole
    /// time-ordered set, even when `blocks` covers only part of it.
    fn residuals(
        &self,
        observations: &[Self::Observation],
        blocks: &[Block],
        out: &mut Vec<Option<[f64; 6]>>,
    );
    /// The whitened, weighted Jacobian of `problem`'s stacked residual at this model (rows as
    /// the problem's, one column per layout parameter). Default: forward differences of
    /// [`RobotModel::residuals`] over the whole batch.
    fn jacobian(&self, problem: &Problem<'_, Self>) -> DMatrix<f64> {
        problem.finite_difference_jacobian(self)
    }
    /// Checks the model is physically valid (after a fit moved it).
    fn validate(&self) -> Result<(), String>;

    /// Every candidate the residual loop may try, the model's effect library first.
    fn candidates(&self) -> Vec<Self::Candidate>;
    /// What a candidate is, for the loop's decisions and reports.
    fn candidate_info(&self, candidate: Self::Candidate) -> CandidateInfo;
    /// The effects the model carries, as candidates (so they are not proposed again).
    fn carried(&self) -> Vec<Self::Candidate>;
    /// The candidates' columns at this model: for each candidate, its
    /// [`CandidateInfo::dim`] consecutive columns, the derivative of `problem`'s whitened,
    /// weighted residual with respect to its parameters at zero.
    fn candidate_columns(
        &self,
        problem: &Problem<'_, Self>,
        candidates: &[Self::Candidate],
    ) -> DMatrix<f64>;
    /// Adds the library effect of `candidate`, started at its linearised `coefficients`
    /// (one per column, parameter units). `None` for a probe or when the coefficients
    /// contradict the effect (e.g. a negative backlash width).
    fn add_effect(
        &mut self,
        candidate: Self::Candidate,
        coefficients: &[f64],
    ) -> Option<AddedEffect<Self::Param>>;
}

/// What a candidate explanation is.
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateInfo {
    /// Class, e.g. `backlash` (effects) or `drift_in_time` (probes).
    pub class: &'static str,
    /// Human-readable label naming where it attaches, e.g. `backlash θ4`.
    pub label: String,
    /// What its signal is, for reports.
    pub signal: &'static str,
    /// Number of columns (parameters of the linearised candidate).
    pub dim: usize,
    /// Whether it is an effect the model can carry (else a probe).
    pub in_library: bool,
    /// The joint it attaches to, numbered as the model numbers its joints.
    pub joint: Option<usize>,
    /// The link it attaches to, named as the model names its links.
    pub link: Option<String>,
    /// Harmonic of its periodic signal, for periodic effects.
    pub harmonic: Option<f64>,
}

/// An effect added to a model.
#[derive(Debug, Clone, PartialEq)]
pub struct AddedEffect<P> {
    /// Index of the effect among the model's effects (as in its parameter file).
    pub index: usize,
    /// Its free parameters, with their field names (e.g. `amplitude`).
    pub parameters: Vec<(P, &'static str)>,
}

/// Where a fit's observations come from.
pub trait Dataset<M: RobotModel> {
    /// The observations to fit with `model`, in time order.
    fn fit_set(&self, model: &M) -> Vec<M::Observation>;
    /// Whether observations derived at `matched` must be derived again for `model` (for
    /// example because a latency they were matched at has moved). Default: never.
    fn needs_rematch(&self, matched: &M, model: &M) -> bool {
        let _ = (matched, model);
        false
    }
}
