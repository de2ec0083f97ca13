//! A serial or branched arm described by URDF ([`sabr_model::KinematicTree`]), measured at
//! static poses by an external instrument (a laser tracker): the second implementation of
//! [`RobotModel`], with nothing specific to one robot.
//!
//! Parameters: per set-up the instrument ← root frame (6), per target its mounting on its
//! link (6; the rotation is unidentifiable for a point target or when orientations are not
//! used, and identifiability analysis drops it), the tree's per-joint geometric errors (6 per
//! moving joint, pruned to a minimal set by the identifiability analysis, see
//! [`SerialArm::geometric_layout`]), and the coefficients of the effects it carries
//! ([`candidates`]).
//!
//! Observations ([`observation`]) measure one block per target: a pose (position mm,
//! rotation vector rad) or, for a point target or when [`SerialArm::use_orientation`] is
//! off, a point.

pub mod candidates;
pub mod error;
pub mod frame;
pub mod observation;
pub mod params_file;
mod predict;

use std::sync::Arc;

use nalgebra::{DMatrix, Point3};
use sabr_model::KinematicTree;
use sabr_recording::poses::Measured;

use crate::math::registration::register;
use crate::math::se3::rotation_log;
use crate::model::blocks::groups;
use crate::model::{
    AddedEffect, Block, CandidateInfo, Dataset, Measurement, NoiseModel, ParamInfo, Problem,
    QuantityInfo, QuantityKind, QuantityNoise, RobotModel, Shape,
};

pub use candidates::{SerialEffect, MAX_HARMONIC};
pub use error::SerialError;
pub use frame::Frame;
pub use observation::{ArmData, MeasuredTarget, PoseObservation, TargetSpec};

/// One scalar parameter of a [`SerialArm`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SerialParam {
    /// Component (tx, ty, tz mm; rx, ry, rz rad) of set-up `setup`'s instrument ← root frame.
    Setup {
        /// Set-up index.
        setup: u16,
        /// 0..6.
        component: u8,
    },
    /// Component of target `target`'s mounting on its link.
    Mounting {
        /// Target index.
        target: u16,
        /// 0..6.
        component: u8,
    },
    /// Geometric error parameter (index into the tree's error parameters).
    Error(u16),
    /// Coefficient `k` of carried effect `effect`.
    Effect {
        /// Index in [`SerialArm::effects`].
        effect: u16,
        /// Coefficient index.
        k: u8,
    },
}

/// A measured serial or branched arm.
#[derive(Debug, Clone)]
pub struct SerialArm {
    /// The kinematic tree (nominal geometry from the URDF).
    pub tree: Arc<KinematicTree>,
    /// The measured targets.
    pub targets: Vec<TargetSpec>,
    /// Set-up ids.
    pub setups: Vec<String>,
    /// Per set-up: instrument ← root frame.
    pub setup_frames: Vec<Frame>,
    /// Per target: `T_link_target`.
    pub mountings: Vec<Frame>,
    /// Geometric errors, in the tree's error-parameter order.
    pub errors: Vec<f64>,
    /// The effects carried, with their coefficients.
    pub effects: Vec<(SerialEffect, Vec<f64>)>,
    /// Whether pose targets are fitted with their orientation (else as points).
    pub use_orientation: bool,
    /// Temperature the thermal expansion is referred to (°C).
    pub reference_temperature_c: f64,
    /// Whether any pose has a temperature (the thermal effect is offered only then).
    pub has_temperature: bool,
    /// Per joint variable: the range the calibration poses covered (rad or mm); periodic
    /// effects hold their value outside it.
    pub covered: Vec<[f64; 2]>,
}

/// Poses per set-up needed to register it.
const MIN_SETUP_POSES: usize = 3;

impl SerialArm {
    /// The nominal arm of `data`: the URDF geometry, the nominal mountings, and every set-up
    /// frame registered (rigidly, on the first measured target's positions) to the nominal
    /// predictions.
    pub fn nominal(data: &ArmData, use_orientation: bool) -> Result<Self, SerialError> {
        let temperatures: Vec<f64> = data
            .observations
            .iter()
            .filter_map(|o| o.temperature_c)
            .collect();
        let mut arm = SerialArm {
            tree: data.tree.clone(),
            targets: data.targets.clone(),
            setups: data.setups.clone(),
            setup_frames: vec![Frame::at(nalgebra::Isometry3::identity()); data.setups.len()],
            mountings: data.targets.iter().map(|t| Frame::at(t.nominal)).collect(),
            errors: data.tree.nominal_errors(),
            effects: Vec::new(),
            use_orientation,
            reference_temperature_c: if temperatures.is_empty() {
                0.0
            } else {
                temperatures.iter().sum::<f64>() / temperatures.len() as f64
            },
            has_temperature: !temperatures.is_empty(),
            covered: covered_ranges(data.tree.variables().len(), &data.observations),
        };
        for setup in 0..data.setups.len() {
            arm.register_setup(data, setup)?;
        }
        Ok(arm)
    }

    /// Registers set-up `setup`'s frame rigidly on its poses at the current model (the
    /// start of a set-up fit).
    pub fn register_setup(&mut self, data: &ArmData, setup: usize) -> Result<(), SerialError> {
        let (mut from, mut to) = (Vec::new(), Vec::new());
        for obs in data.observations.iter().filter(|o| o.setup == setup) {
            let Some(state) = self.state(obs) else {
                continue;
            };
            for m in &obs.measured {
                let target = &self.targets[m.target];
                let root = state.link_pose(target.link) * self.mountings[m.target].pose();
                from.push(Point3::from(root.translation.vector));
                to.push(Point3::from(m.position));
            }
        }
        let name = &self.setups[setup];
        let fail = |reason: String| SerialError::Setup {
            path: data.source.clone(),
            setup: name.clone(),
            reason,
        };
        if from.len() < MIN_SETUP_POSES {
            return Err(fail(format!(
                "{} measured positions; at least {MIN_SETUP_POSES} are needed to place the \
                 instrument",
                from.len()
            )));
        }
        let frame = register(&from, &to)
            .ok_or_else(|| fail("the measured positions lie on a line".into()))?;
        self.setup_frames[setup] = Frame::at(frame);
        Ok(())
    }

    /// The set-up frame parameters.
    pub fn setup_layout(&self) -> Vec<SerialParam> {
        (0..self.setups.len() as u16)
            .flat_map(|setup| (0..6).map(move |component| SerialParam::Setup { setup, component }))
            .collect()
    }

    /// The mounting parameters (translation only for point targets and when orientations
    /// are not used).
    pub fn mounting_layout(&self) -> Vec<SerialParam> {
        self.targets
            .iter()
            .enumerate()
            .flat_map(|(t, spec)| {
                let n = if self.shape(spec) == Shape::Pose {
                    6
                } else {
                    3
                };
                (0..n).map(move |component| SerialParam::Mounting {
                    target: t as u16,
                    component,
                })
            })
            .collect()
    }

    /// Every geometric error parameter (complete and redundant; see
    /// [`sabr_model::tree::geometric`]).
    pub fn error_layout(&self) -> Vec<SerialParam> {
        (0..self.errors.len() as u16)
            .map(SerialParam::Error)
            .collect()
    }

    /// The coefficients of every carried effect.
    pub fn effect_layout(&self) -> Vec<SerialParam> {
        self.effects
            .iter()
            .enumerate()
            .flat_map(|(e, (effect, _))| {
                (0..effect.dim() as u8).map(move |k| SerialParam::Effect {
                    effect: e as u16,
                    k,
                })
            })
            .collect()
    }

    /// The shape a target is fitted as.
    pub fn shape(&self, target: &TargetSpec) -> Shape {
        if target.measured == Measured::Pose && self.use_orientation {
            Shape::Pose
        } else {
            Shape::Point
        }
    }

    /// A noise model to start fits with: 0.1 mm and 0.1 mrad per target.
    pub fn start_noise(&self) -> NoiseModel {
        NoiseModel {
            kinds: self
                .targets
                .iter()
                .map(|_| QuantityNoise::isotropic(0.1, 1e-4))
                .collect(),
        }
    }

    /// The same arm with every frame correction folded into its start (so that the
    /// corrections of the next fit start at zero).
    pub fn folded(&self) -> Self {
        let mut arm = self.clone();
        for frame in arm.setup_frames.iter_mut().chain(arm.mountings.iter_mut()) {
            *frame = frame.folded();
        }
        arm
    }

    fn variable_name(&self, variable: usize) -> String {
        self.tree.variables()[variable].name.clone()
    }
}

/// Per joint variable, the smallest and largest value in `observations`.
pub fn covered_ranges(variables: usize, observations: &[PoseObservation]) -> Vec<[f64; 2]> {
    let mut ranges = vec![[f64::INFINITY, f64::NEG_INFINITY]; variables];
    for obs in observations {
        for (range, q) in ranges.iter_mut().zip(&obs.joints) {
            range[0] = range[0].min(*q);
            range[1] = range[1].max(*q);
        }
    }
    ranges
}

/// A fixed set of observations to fit.
#[derive(Debug, Clone)]
pub struct PoseSet(pub Vec<PoseObservation>);

impl Dataset<SerialArm> for PoseSet {
    fn fit_set(&self, _model: &SerialArm) -> Vec<PoseObservation> {
        self.0.clone()
    }
}

impl RobotModel for SerialArm {
    type Observation = PoseObservation;
    type Param = SerialParam;
    type Candidate = SerialEffect;

    fn describe(&self, param: SerialParam) -> ParamInfo {
        const SUFFIX: [&str; 6] = ["tx", "ty", "tz", "rx", "ry", "rz"];
        let frame_info = |owner: String, component: u8| ParamInfo {
            name: format!("{owner}.{}", SUFFIX[usize::from(component)]),
            unit: if component < 3 { "mm" } else { "rad" },
            step: if component < 3 { 1e-3 } else { 1e-6 },
        };
        match param {
            SerialParam::Setup { setup, component } => frame_info(
                format!("setup[{}]", self.setups[usize::from(setup)]),
                component,
            ),
            SerialParam::Mounting { target, component } => frame_info(
                format!("target[{}]", self.targets[usize::from(target)].name),
                component,
            ),
            SerialParam::Error(index) => {
                let p = &self.tree.error_parameters()[usize::from(index)];
                ParamInfo {
                    name: p.name.clone(),
                    unit: p.unit.symbol(),
                    step: p.scale * 1e-3,
                }
            }
            SerialParam::Effect { effect, k } => {
                let (candidate, _) = self.effects[usize::from(effect)];
                let info = self.candidate_info(candidate);
                let kind = info
                    .joint
                    .map_or(sabr_model::tree::JointType::Revolute, |j| {
                        self.tree.variables()[j].kind
                    });
                ParamInfo {
                    name: format!("{}.{}", info.label, candidate.fields()[usize::from(k)]),
                    unit: candidate.unit(kind, usize::from(k)),
                    step: 1e-6,
                }
            }
        }
    }

    fn get(&self, param: SerialParam) -> f64 {
        match param {
            SerialParam::Setup { setup, component } => {
                self.setup_frames[usize::from(setup)].delta[usize::from(component)]
            }
            SerialParam::Mounting { target, component } => {
                self.mountings[usize::from(target)].delta[usize::from(component)]
            }
            SerialParam::Error(index) => self.errors[usize::from(index)],
            SerialParam::Effect { effect, k } => {
                self.effects[usize::from(effect)].1[usize::from(k)]
            }
        }
    }

    fn set(&mut self, param: SerialParam, value: f64) {
        match param {
            SerialParam::Setup { setup, component } => {
                self.setup_frames[usize::from(setup)].delta[usize::from(component)] = value
            }
            SerialParam::Mounting { target, component } => {
                self.mountings[usize::from(target)].delta[usize::from(component)] = value
            }
            SerialParam::Error(index) => self.errors[usize::from(index)] = value,
            SerialParam::Effect { effect, k } => {
                self.effects[usize::from(effect)].1[usize::from(k)] = value
            }
        }
    }

    fn quantities(&self) -> Vec<QuantityInfo> {
        self.targets
            .iter()
            .map(|t| QuantityInfo {
                name: t.name.clone(),
                shape: self.shape(t),
            })
            .collect()
    }

    fn measurements(&self, observation: &PoseObservation, out: &mut Vec<Measurement>) {
        for m in &observation.measured {
            let shape = self.shape(&self.targets[m.target]);
            out.push(Measurement::of(QuantityKind(m.target), shape));
        }
    }

    fn residuals(
        &self,
        observations: &[PoseObservation],
        blocks: &[Block],
        out: &mut Vec<Option<[f64; 6]>>,
    ) {
        let chunks = chunks(blocks);
        let parts: Vec<Vec<Option<[f64; 6]>>> = std::thread::scope(|scope| {
            let handles: Vec<_> = chunks
                .iter()
                .map(|range| {
                    let part = &blocks[range.clone()];
                    scope.spawn(move || {
                        let mut raws = Vec::with_capacity(part.len());
                        self.residuals_of(observations, part, &mut raws);
                        raws
                    })
                })
                .collect();
            handles
                .into_iter()
                .zip(&chunks)
                .map(|(h, range)| h.join().unwrap_or_else(|_| vec![None; range.len()]))
                .collect()
        });
        for part in parts {
            out.extend(part);
        }
    }

    fn jacobian(&self, problem: &Problem<'_, Self>) -> DMatrix<f64> {
        let ids = &problem.layout.ids;
        self.columns(problem, ids.len(), |arm, obs, m, lin, out| {
            for (column, id) in out.iter_mut().zip(ids) {
                *column = arm.derivative(obs, m, lin, *id);
            }
        })
    }

    fn validate(&self) -> Result<(), String> {
        let values = self
            .errors
            .iter()
            .chain(self.effects.iter().flat_map(|(_, c)| c))
            .chain(
                self.setup_frames
                    .iter()
                    .chain(&self.mountings)
                    .flat_map(|f| &f.delta),
            );
        match values.into_iter().find(|v| !v.is_finite()) {
            Some(v) => Err(format!("a fitted parameter is {v}")),
            None => Ok(()),
        }
    }

    fn candidates(&self) -> Vec<SerialEffect> {
        let mut out = Vec::new();
        for (v, variable) in self.tree.variables().iter().enumerate() {
            let variable_index = v as u16;
            if variable.kind == sabr_model::tree::JointType::Revolute {
                out.extend((1..=MAX_HARMONIC).map(|harmonic| SerialEffect::Periodic {
                    variable: variable_index,
                    harmonic,
                }));
            }
            out.push(SerialEffect::Compliance {
                variable: variable_index,
            });
        }
        if self.has_temperature {
            out.push(SerialEffect::Thermal);
        }
        out.extend((0..self.setups.len() as u16).map(|setup| SerialEffect::Drift { setup }));
        out
    }

    fn candidate_info(&self, candidate: SerialEffect) -> CandidateInfo {
        candidate.info(|v| self.variable_name(v), |s| self.setups[s].clone())
    }

    fn carried(&self) -> Vec<SerialEffect> {
        self.effects.iter().map(|(e, _)| *e).collect()
    }

    fn candidate_columns(
        &self,
        problem: &Problem<'_, Self>,
        candidates: &[SerialEffect],
    ) -> DMatrix<f64> {
        let mut offsets = Vec::with_capacity(candidates.len());
        let mut total = 0;
        for c in candidates {
            offsets.push(total);
            total += c.dim();
        }
        self.columns(problem, total, |arm, obs, _, lin, out| {
            for (candidate, offset) in candidates.iter().zip(&offsets) {
                for (k, column) in arm
                    .effect_derivative(obs, lin, *candidate)
                    .into_iter()
                    .enumerate()
                {
                    out[offset + k] = column;
                }
            }
        })
    }

    fn add_effect(
        &mut self,
        candidate: SerialEffect,
        coefficients: &[f64],
    ) -> Option<AddedEffect<SerialParam>> {
        if coefficients.len() != candidate.dim() || self.carried().contains(&candidate) {
            return None;
        }
        let index = self.effects.len();
        self.effects.push((candidate, coefficients.to_vec()));
        Some(AddedEffect {
            index,
            parameters: candidate
                .fields()
                .iter()
                .enumerate()
                .map(|(k, name)| {
                    (
                        SerialParam::Effect {
                            effect: index as u16,
                            k: k as u8,
                        },
                        *name,
                    )
                })
                .collect(),
        })
    }
}

impl SerialArm {
    /// Raw residuals of `blocks` (see [`RobotModel::residuals`]), on this thread.
    fn residuals_of(
        &self,
        observations: &[PoseObservation],
        blocks: &[Block],
        out: &mut Vec<Option<[f64; 6]>>,
    ) {
        for (_, group) in groups(blocks) {
            let obs = &observations[group[0].obs];
            let state = self.state(obs);
            for block in group {
                let raw = state.as_ref().and_then(|state| {
                    let m = obs.measured.iter().find(|m| m.target == block.kind.0)?;
                    let predicted = self.predict(obs, state, m).pose;
                    let dp = m.position - predicted.translation.vector;
                    let dr = match (block.dim, m.orientation) {
                        (6, Some(q)) => rotation_log(&(q * predicted.rotation.inverse())),
                        _ => nalgebra::Vector3::zeros(),
                    };
                    Some([dp.x, dp.y, dp.z, dr.x, dr.y, dr.z])
                });
                out.push(raw);
            }
        }
    }

    /// The whitened, weighted columns `∂r/∂·` of `problem`'s rows: `fill(arm, obs, target,
    /// linearisation, columns)` writes the prediction's derivative for every column. The
    /// blocks are shared out over threads.
    fn columns<F>(&self, problem: &Problem<'_, Self>, count: usize, fill: F) -> DMatrix<f64>
    where
        F: Fn(&Self, &PoseObservation, &MeasuredTarget, &predict::Linearised, &mut [[f64; 6]])
            + Sync,
    {
        let mut out = DMatrix::zeros(problem.rows, count);
        let chunks = chunks(problem.blocks);
        let parts: Vec<Option<(usize, DMatrix<f64>)>> = std::thread::scope(|scope| {
            let handles: Vec<_> = chunks
                .iter()
                .map(|range| {
                    let fill = &fill;
                    let range = range.clone();
                    scope.spawn(move || self.columns_of(problem, range, count, fill))
                })
                .collect();
            handles.into_iter().map(|h| h.join().ok()).collect()
        });
        for (first_row, part) in parts.into_iter().flatten() {
            out.rows_mut(first_row, part.nrows()).copy_from(&part);
        }
        out
    }

    /// The columns of the rows of blocks `range`: their first row and the rows.
    fn columns_of<F>(
        &self,
        problem: &Problem<'_, Self>,
        range: std::ops::Range<usize>,
        count: usize,
        fill: &F,
    ) -> (usize, DMatrix<f64>)
    where
        F: Fn(&Self, &PoseObservation, &MeasuredTarget, &predict::Linearised, &mut [[f64; 6]]),
    {
        let blocks = &problem.blocks[range.clone()];
        let first_row = blocks.first().map_or(0, |b| b.row);
        let rows = blocks.last().map_or(0, |b| b.row + b.dim - first_row);
        let mut out = DMatrix::zeros(rows, count);
        let mut buffer = vec![[0.0; 6]; count];
        for (first, group) in groups(blocks) {
            let obs = &problem.observations[group[0].obs];
            let Some(state) = self.state(obs) else {
                continue;
            };
            for (k, block) in group.iter().enumerate() {
                let Some(m) = obs.measured.iter().find(|m| m.target == block.kind.0) else {
                    continue;
                };
                let lin = self.linearise(obs, &state, m);
                fill(self, obs, m, &lin, &mut buffer);
                for (col, d) in buffer.iter().enumerate() {
                    let negated = d.map(|v| -v);
                    problem.write_block(range.start + first + k, &negated, |row, value| {
                        out[(row - first_row, col)] = value
                    });
                }
            }
        }
        (first_row, out)
    }
}

/// Blocks per thread below which one thread does it all.
const MIN_BLOCKS_PER_THREAD: usize = 1000;

/// `blocks` cut at observation boundaries into one range per available core (at most 4).
fn chunks(blocks: &[Block]) -> Vec<std::ops::Range<usize>> {
    let threads = std::thread::available_parallelism()
        .map_or(1, usize::from)
        .clamp(1, 4)
        .min(blocks.len() / MIN_BLOCKS_PER_THREAD)
        .max(1);
    let mut ranges = Vec::with_capacity(threads);
    let mut start = 0;
    for t in 1..=threads {
        let mut end = blocks.len() * t / threads;
        while end > start && end < blocks.len() && blocks[end].obs == blocks[end - 1].obs {
            end += 1;
        }
        if end > start {
            ranges.push(start..end);
        }
        start = end;
    }
    ranges
}

impl SerialArm {
    /// The position error (mm, |measured − predicted|) of every measured target of
    /// `observations`, in order; infinite where the kinematics refuse a pose.
    pub fn position_errors(&self, observations: &[PoseObservation]) -> Vec<f64> {
        let mut out = Vec::new();
        for obs in observations {
            let state = self.state(obs);
            for m in &obs.measured {
                out.push(match &state {
                    Some(state) => {
                        (m.position - self.predict(obs, state, m).pose.translation.vector).norm()
                    }
                    None => f64::INFINITY,
                });
            }
        }
        out
    }
}
