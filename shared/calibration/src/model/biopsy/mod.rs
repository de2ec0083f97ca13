//! The biopsy robot's closed-chain model, the first [`RobotModel`]: the robot parameters of
//! `sabr_model` (gear ratios, joint offsets, `T_Bb_Bf`, needle length, marker mountings,
//! effects) plus the tracker latency, predicting the front and back marker poses and the tip
//! sphere of every tracker frame.
//!
//! - [`params`]: the parameter ids and the paper's layout;
//! - [`predict`]: joint angles from the counts, FK, marker poses, raw residuals;
//! - [`jacobian`]: its fast channel Jacobian (the model's override of the default);
//! - [`noise`]: the tracker noise at rest and the Vicra default;
//! - [`candidates`]: the effects it can carry and the probes of the residual loop;
//! - [`marker_ik`], [`stepwise`]: the paper's stepwise method (the start of the joint fit);
//! - [`validation`]: its held-out checks (validation holds, marker-derived tip error).

pub mod candidates;
pub mod jacobian;
pub mod marker_ik;
pub mod noise;
pub mod params;
pub mod predict;
pub mod stepwise;
pub mod validation;

use nalgebra::DMatrix;
use sabr_model::{EffectSlot, RobotParams};

use crate::data::phases::Phase;
use crate::data::session::{Observation, SessionData};
use crate::model::biopsy::candidates::Candidate;
use crate::model::biopsy::params::{EffectParam, ParamId};
use crate::model::biopsy::predict::{joint_angles, predict_at, raw_residual};
use crate::model::blocks::groups;
use crate::model::{
    AddedEffect, Block, CandidateInfo, Dataset, Measurement, ParamInfo, Problem, QuantityInfo,
    QuantityKind, RobotModel, Shape,
};

/// The front marker pose `T_Bb_Tf`.
pub const FRONT: QuantityKind = QuantityKind(0);
/// The back marker pose `T_Bb_Tb`.
pub const BACK: QuantityKind = QuantityKind(1);
/// The tip sphere centre in `Bb`.
pub const TIP: QuantityKind = QuantityKind(2);

/// Re-match the observations to the encoders when the latency moved more than this (s).
const LATENCY_REMATCH_S: f64 = 2e-4;

/// The model being calibrated: the robot parameters plus the tracker latency.
#[derive(Debug, Clone, PartialEq)]
pub struct BiopsyModel {
    /// Robot parameters (joint offsets always defined).
    pub robot: RobotParams,
    /// Tracker latency from exposure to the clock line (s); see `data::clock`.
    pub latency_s: f64,
}

impl RobotModel for BiopsyModel {
    type Observation = Observation;
    type Param = ParamId;
    type Candidate = Candidate;

    fn describe(&self, param: ParamId) -> ParamInfo {
        ParamInfo {
            name: param.name(),
            unit: param.unit(),
            step: param.step(),
        }
    }

    fn get(&self, param: ParamId) -> f64 {
        param.get(self)
    }

    fn set(&mut self, param: ParamId, value: f64) {
        param.set(self, value);
    }

    fn quantities(&self) -> Vec<QuantityInfo> {
        [
            ("front", Shape::Pose),
            ("back", Shape::Pose),
            ("tip", Shape::Point),
        ]
        .into_iter()
        .map(|(name, shape)| QuantityInfo {
            name: name.into(),
            shape,
        })
        .collect()
    }

    /// Front and back marker poses wherever seen; the tip sphere wherever seen in the tip
    /// phase (only then is it attached by plan).
    fn measurements(&self, obs: &Observation, out: &mut Vec<Measurement>) {
        if obs.front.is_some() {
            out.push(Measurement::of(FRONT, Shape::Pose));
        }
        if obs.back.is_some() {
            out.push(Measurement::of(BACK, Shape::Pose));
        }
        if obs.tip.is_some() && obs.phase == Phase::Tip {
            out.push(Measurement::of(TIP, Shape::Point));
        }
    }

    fn residuals(
        &self,
        observations: &[Observation],
        blocks: &[Block],
        out: &mut Vec<Option<[f64; 6]>>,
    ) {
        let geometry = self.robot.effective_geometry();
        for (_, group) in groups(blocks) {
            let obs = &observations[group[0].obs];
            let prediction =
                predict_at(&geometry, &self.robot.markers, joint_angles(self, obs)).ok();
            for block in group {
                out.push(
                    prediction
                        .as_ref()
                        .and_then(|p| raw_residual(p, obs, block.kind)),
                );
            }
        }
    }

    fn jacobian(&self, problem: &Problem<'_, Self>) -> DMatrix<f64> {
        jacobian::channel_jacobian(self, problem)
    }

    fn validate(&self) -> Result<(), String> {
        self.robot.validate().map_err(|e| e.to_string())
    }

    fn candidates(&self) -> Vec<Candidate> {
        Candidate::all()
    }

    fn candidate_info(&self, candidate: Candidate) -> CandidateInfo {
        candidate.info()
    }

    fn carried(&self) -> Vec<Candidate> {
        self.robot
            .effects
            .iter()
            .map(|e| Candidate::Library(EffectSlot::of(e)))
            .collect()
    }

    fn candidate_columns(
        &self,
        problem: &Problem<'_, Self>,
        candidates: &[Candidate],
    ) -> DMatrix<f64> {
        candidates::candidate_columns(self, problem, candidates)
    }

    fn add_effect(
        &mut self,
        candidate: Candidate,
        coefficients: &[f64],
    ) -> Option<AddedEffect<ParamId>> {
        let effect = candidate.effect(coefficients)?;
        let index = self.robot.effects.len();
        let parameters = effect
            .fields()
            .iter()
            .map(|&field| (ParamId::Effect(EffectParam { index, field }), field.name()))
            .collect();
        self.robot.effects.push(effect);
        Some(AddedEffect { index, parameters })
    }
}

/// Whether an observation is part of the fit: excitation and tip phases.
pub fn is_fitted(obs: &Observation) -> bool {
    matches!(obs.phase, Phase::Excitation | Phase::Tip)
}

/// The fitted observations of a session are its excitation and tip frames, matched to the
/// encoders at the model's latency (and matched again when the latency moves).
impl Dataset<BiopsyModel> for SessionData {
    fn fit_set(&self, model: &BiopsyModel) -> Vec<Observation> {
        self.observations(model.latency_s)
            .items
            .into_iter()
            .filter(is_fitted)
            .collect()
    }

    fn needs_rematch(&self, matched: &BiopsyModel, model: &BiopsyModel) -> bool {
        (model.latency_s - matched.latency_s).abs() > LATENCY_REMATCH_S
    }
}
