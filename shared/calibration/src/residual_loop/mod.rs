//! The residual loop (issue 5): after the paper-model fit, find the structure left in the
//! residual, name the effect behind it, add it to the model, refit everything, and report
//! the errors before and after — on data whose effects were not declared.
//!
//! 1. **Candidates** ([`candidates`]): the effect library of `sabr_model::Effect`
//!    (transmission ripple per joint and motor-angle harmonic 1..3, backlash, joint
//!    compliance, link-length error; the tracker latency is part of every fit already) and
//!    probes outside it (joint-angle harmonics, joint velocity, drift in time, needle
//!    elevation). Each is a few columns `∂r/∂(its parameters)` at zero.
//! 2. **Scores** ([`selection`]): for each candidate, the cost reduction of one joint
//!    Gauss–Newton step with all fitted parameters (the score test: the squared correlation
//!    of the whitened residual with the candidate's columns, after projecting out the fitted
//!    parameters), in-sample and held out over interleaved time blocks (10 folds).
//! 3. **Forward selection**: the significant candidate with the largest held-out gain wins.
//!    Significant means: in-sample gain above both the BIC penalty `k·ln m` and the χ²_k
//!    quantile of a family-wise level [`SELECTION_LEVEL`] over all candidates, positive
//!    held-out gain, and a lower held-out error in at least [`MIN_FOLDS_IMPROVED`] of the
//!    folds. A library winner is added to the model (its linearised coefficients start the
//!    fit), everything is refitted jointly ([`crate::joint_fit::joint_fit`] on the extended
//!    layout) and kept only if the refit gains as much as the test demanded. A probe
//!    winner is structure the library does not explain: it is reported as a lead, never
//!    added, and the following tests are conditional on it (so that a library effect cannot
//!    be claimed for structure the probe explains better).
//! 4. **Report** ([`report`], [`html`]): per effect, the fitted parameters with standard
//!    deviations and the errors before and after; the final model, the test of its residual
//!    against the tracker noise at rest ([`significance`]) and its strongest correlates.

pub mod candidates;
pub mod effect_params;
pub mod html;
pub mod motion;
pub mod plots;
pub mod report;
mod round;
pub mod selection;
pub mod significance;
mod svg;

use sabr_model::Effect;

use crate::joint_fit::{joint_fit, JointFit};
use crate::layout::ParamId;
use crate::noise::NoiseModel;
use crate::observations::{Observation, Phase, SessionData};
use crate::report::model_residuals;
use crate::validation::{cross_validated_tip, marker_tip_errors, validation_holds, TipError};

pub use candidates::Candidate;
pub use effect_params::{EffectField, EffectParam};
pub use motion::MotionTrack;
pub use report::{summary_text, Correlate, EffectReport, FinalReport, StepMetrics};
pub use round::chi2_threshold;

use candidates::link_name;
use plots::{picture, Plots};
use report::{FittedValue, SelectionEvidence, StepSummary};
use round::{Evaluation, Round};
use selection::FOLDS;
use significance::{chi2_tail, noise_tests};

/// Most effects the loop adds.
pub const MAX_EFFECTS: usize = 4;
/// Family-wise level of one selection step (Bonferroni over all candidates).
pub const SELECTION_LEVEL: f64 = 1e-3;
/// Folds (of [`FOLDS`]) in which a selected candidate must lower the held-out error.
pub const MIN_FOLDS_IMPROVED: usize = 7;
/// Correlates listed in the final block.
const CORRELATES_REPORTED: usize = 8;

/// What the loop found, for the report.
#[derive(Debug, Clone)]
pub struct Discovery {
    /// The effects added, in order.
    pub effects: Vec<EffectReport>,
    /// The final block.
    pub final_report: FinalReport,
}

/// Errors of `fit` on its fitted data, at the held-out validation holds and over the tip
/// phase, and its residual against the tracker noise at rest.
fn step_metrics(
    label: &str,
    fit: &JointFit,
    session: &SessionData,
    rest_noise: &NoiseModel,
    rest_frames: usize,
) -> StepMetrics {
    let validation: Vec<Observation> = session
        .observations(fit.model.latency_s)
        .items
        .into_iter()
        .filter(|o| o.phase == Phase::Validation)
        .collect();
    let holds = validation_holds(&validation);
    let marker_tip = TipError::of(&marker_tip_errors(&fit.model, &holds, &fit.noise));
    StepMetrics {
        label: label.into(),
        residual_rms: model_residuals(
            label,
            &fit.model,
            &fit.observations,
            &validation,
            marker_tip,
        ),
        cross_validated_tip: cross_validated_tip(fit),
        noise_test: noise_tests(fit, rest_noise, rest_frames),
    }
}

/// An effect added and refitted.
struct Added {
    fit: JointFit,
    index: usize,
    refit_gain: f64,
}

/// Adds the effect of `choice` (started at its linearised coefficients) and refits every
/// parameter jointly; `None` when the coefficients contradict the effect, the refit fails
/// or the fitted model is invalid.
fn add_effect(session: &SessionData, fit: &JointFit, choice: &Evaluation) -> Option<Added> {
    let effect = choice.candidate.effect(&choice.coefficients)?;
    let mut start = fit.model.clone();
    start.robot.effects.push(effect.clone());
    let index = start.robot.effects.len() - 1;
    let mut layout = fit.layout.clone();
    layout.ids.extend(
        EffectField::of(&effect)
            .iter()
            .map(|&field| ParamId::Effect(EffectParam { index, field })),
    );
    let refit = match joint_fit(session, &start, &fit.noise, layout) {
        Ok(refit) => refit,
        Err(error) => {
            tracing::debug!(%error, candidate = choice.candidate.label(), "refit with the effect failed");
            return None;
        }
    };
    refit.model.robot.validate().ok()?;
    let before = fit.residual.norm_squared();
    let after = fit.problem().residuals(&refit.model).0.norm_squared();
    Some(Added {
        fit: refit,
        index,
        refit_gain: before - after,
    })
}

/// The report entry of an effect added at `index` of the model of `after_fit`.
fn effect_report(
    choice: &Evaluation,
    added: &Added,
    before: StepMetrics,
    after: StepMetrics,
) -> EffectReport {
    let fit = &added.fit;
    let effect = &fit.model.robot.effects[added.index];
    let parameters = EffectField::of(effect)
        .iter()
        .map(|&field| {
            let param = EffectParam {
                index: added.index,
                field,
            };
            let position = fit
                .layout
                .ids
                .iter()
                .position(|id| *id == ParamId::Effect(param));
            FittedValue {
                name: field.name().into(),
                value: param.get(&fit.model.robot.effects),
                std_dev: position.map(|k| fit.analysis.std_devs[k]),
                unit: param.unit().into(),
            }
        })
        .collect();
    let candidate = choice.candidate;
    EffectReport {
        name: candidate.class().into(),
        label: candidate.label(),
        joint: candidate.joint().map(|j| j + 1),
        link: match effect {
            Effect::LinkLength { link, .. } => Some(link_name(*link).into()),
            _ => None,
        },
        harmonic: match effect {
            Effect::TransmissionRipple { harmonic, .. } => Some(*harmonic),
            _ => None,
        },
        index: added.index,
        parameters,
        evidence: SelectionEvidence {
            parameters: candidate.dim(),
            chi2_gain: choice.chi2_gain,
            chi2_threshold: choice.threshold,
            p_value: chi2_tail(choice.chi2_gain, candidate.dim()),
            held_out_gain: choice.held_out_gain,
            folds_improved: choice.folds_improved,
            folds: FOLDS,
            held_out_whitened_rms: choice.held_out_rms,
            refit_chi2_gain: added.refit_gain,
        },
        before,
        after,
    }
}

/// The state of the forward selection.
struct Search<'a> {
    session: &'a SessionData,
    rest_noise: &'a NoiseModel,
    rest_frames: usize,
    fit: JointFit,
    current: StepMetrics,
    steps: Vec<StepSummary>,
    effects: Vec<EffectReport>,
    leads: Vec<Correlate>,
    nuisance: Vec<Candidate>,
    rejected: Vec<Candidate>,
    plots: Plots,
}

impl Search<'_> {
    fn metrics(&self, label: &str, fit: &JointFit) -> StepMetrics {
        step_metrics(label, fit, self.session, self.rest_noise, self.rest_frames)
    }

    /// The candidates at the current fit: the probes conditioned on first, then every
    /// candidate neither in the model, nor conditioned on, nor rejected.
    fn round(&self) -> Round {
        let present: Vec<Candidate> = self
            .fit
            .model
            .robot
            .effects
            .iter()
            .map(Candidate::of_effect)
            .collect();
        let open = Candidate::all().into_iter().filter(|c| {
            !present.contains(c) && !self.nuisance.contains(c) && !self.rejected.contains(c)
        });
        Round::new(
            &self.fit,
            self.nuisance.iter().copied().chain(open).collect(),
        )
    }

    /// The significant candidate with the largest held-out gain, conditioned on the
    /// probes found so far; probes that win are recorded as leads and conditioned on in
    /// turn, until a library candidate wins or nothing is significant.
    fn select(&mut self, round: &Round) -> Option<Evaluation> {
        let mut conditioned: Vec<usize> = (0..self.nuisance.len()).collect();
        let mut base: Vec<usize> = (0..round.design.fitted).collect();
        for &k in &conditioned {
            base.extend(&round.ranges[k]);
        }
        loop {
            let open = (0..round.pool.len()).filter(|k| !conditioned.contains(k));
            let best = round
                .evaluate(&base, open)
                .into_iter()
                .filter(Evaluation::significant)
                .max_by(|a, b| a.held_out_gain.total_cmp(&b.held_out_gain))?;
            if best.candidate.in_library() {
                return Some(best);
            }
            tracing::debug!(
                probe = best.candidate.label(),
                "structure outside the library"
            );
            conditioned.push(best.index);
            base.extend(&best.columns);
            self.nuisance.push(best.candidate);
            self.leads.push(best.correlate());
        }
    }

    /// Adds the chosen effect and refits; keeps it if the refit gains as much as the
    /// selection test demanded, otherwise rejects the candidate.
    fn try_add(&mut self, choice: &Evaluation) {
        tracing::debug!(
            candidate = choice.candidate.label(),
            gain = choice.chi2_gain,
            "adding an effect"
        );
        match add_effect(self.session, &self.fit, choice) {
            Some(added) if added.refit_gain >= choice.threshold => {
                let after = self.metrics(&format!("+ {}", choice.candidate.label()), &added.fit);
                self.steps.push(StepSummary::of(&after));
                let before = std::mem::replace(&mut self.current, after.clone());
                self.effects
                    .push(effect_report(choice, &added, before, after));
                self.fit = added.fit;
            }
            _ => self.rejected.push(choice.candidate),
        }
    }

    /// The final fit and the report, from the last round (at the final fit).
    fn finish(mut self, last: &Round) -> (JointFit, Discovery) {
        let derivatives = &last.joint_derivatives;
        if !self.effects.is_empty() {
            self.plots.after = Some(picture(
                "final model",
                &self.fit,
                derivatives,
                self.rest_noise,
            ));
        }
        let fitted: Vec<usize> = (0..last.design.fitted).collect();
        let mut correlates: Vec<Correlate> = last
            .evaluate(&fitted, 0..last.pool.len())
            .iter()
            .map(Evaluation::correlate)
            .collect();
        correlates.sort_by(|a, b| b.chi2_gain.total_cmp(&a.chi2_gain));
        correlates.truncate(CORRELATES_REPORTED);
        let residual_is_noise = self.current.noise_test.iter().all(|t| t.is_noise);
        let effects_added: Vec<String> = self.effects.iter().map(|e| e.label.clone()).collect();
        let final_report = FinalReport {
            verdict: verdict(&effects_added, &self.leads, &correlates, residual_is_noise),
            effects_added,
            latency_ms: self.fit.model.latency_s * 1e3,
            steps: self.steps,
            metrics: self.current,
            residual_is_noise,
            structured_residual: !self.leads.is_empty() || !residual_is_noise,
            leads: self.leads,
            strongest_correlates: correlates,
            plots: self.plots,
        };
        (
            self.fit,
            Discovery {
                effects: self.effects,
                final_report,
            },
        )
    }
}

/// Runs the loop on the paper-model fit `paper`. `rest_noise` is the tracker noise measured
/// on `rest_frames` static frames (the homing dwell). Returns the final fit (the paper fit
/// when nothing was added) and what was found. A candidate whose refit fails is rejected,
/// never an error: the paper fit always stands.
pub fn discover(
    session: &SessionData,
    paper: JointFit,
    rest_noise: &NoiseModel,
    rest_frames: usize,
) -> (JointFit, Discovery) {
    let started = std::time::Instant::now();
    let mut search = Search {
        session,
        rest_noise,
        rest_frames,
        current: step_metrics("paper model", &paper, session, rest_noise, rest_frames),
        fit: paper,
        steps: Vec::new(),
        effects: Vec::new(),
        leads: Vec::new(),
        nuisance: Vec::new(),
        rejected: Vec::new(),
        plots: Plots::default(),
    };
    search.steps.push(StepSummary::of(&search.current));
    let last = loop {
        let round = search.round();
        if search.plots.before.is_none() {
            let derivatives = &round.joint_derivatives;
            search.plots.before =
                Some(picture("paper model", &search.fit, derivatives, rest_noise));
        }
        if search.effects.len() == MAX_EFFECTS {
            break round;
        }
        match search.select(&round) {
            Some(choice) => search.try_add(&choice),
            None => break round,
        }
    };
    let result = search.finish(&last);
    tracing::debug!(elapsed_s = started.elapsed().as_secs_f64(), "residual loop");
    result
}

fn verdict(
    effects: &[String],
    leads: &[Correlate],
    correlates: &[Correlate],
    is_noise: bool,
) -> String {
    let mut text = if effects.is_empty() {
        "No effect beyond the paper model is supported by the data.".to_string()
    } else {
        format!("Added {} effect(s): {}.", effects.len(), effects.join(", "))
    };
    if !leads.is_empty() {
        let names: Vec<String> = leads
            .iter()
            .map(|l| format!("{} ({}; Δχ² {:.0})", l.label, l.signal, l.chi2_gain))
            .collect();
        text.push_str(&format!(
            " Structured residual outside the effect library, not claimed as an effect: it \
             correlates most with {}.",
            names.join(", ")
        ));
    } else if !is_noise {
        let strongest = correlates
            .first()
            .map_or("nothing".to_string(), |c| c.label.clone());
        text.push_str(&format!(
            " The residual exceeds the tracker noise at rest, but no candidate explains it \
             (strongest correlate: {strongest})."
        ));
    } else {
        text.push_str(" The remaining residual is consistent with the tracker noise.");
    }
    text
}
