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
use crate::CalibrationError;

pub use candidates::Candidate;
pub use effect_params::{EffectField, EffectParam};
pub use motion::MotionTrack;
pub use report::{summary_text, Correlate, EffectReport, FinalReport, StepMetrics};

use candidates::{candidate_columns, link_name, CandidateColumns};
use plots::{picture, Plots};
use report::{FittedValue, SelectionEvidence, StepSummary};
use selection::{Design, SetFit, FOLDS};
use significance::{chi2_quantile, chi2_tail, noise_tests};

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

/// A candidate's scores at one fit.
#[derive(Debug, Clone)]
struct Evaluation {
    candidate: Candidate,
    columns: Vec<usize>,
    chi2_gain: f64,
    threshold: f64,
    held_out_gain: f64,
    folds_improved: usize,
    held_out_rms: [f64; 2],
    coefficients: Vec<f64>,
    explained_share: f64,
}

impl Evaluation {
    fn significant(&self) -> bool {
        self.chi2_gain >= self.threshold
            && self.held_out_gain > 0.0
            && self.folds_improved >= MIN_FOLDS_IMPROVED
    }

    fn correlate(&self) -> Correlate {
        Correlate {
            label: self.candidate.label(),
            signal: self.candidate.signal().into(),
            in_library: self.candidate.in_library(),
            chi2_gain: self.chi2_gain,
            explained_share: self.explained_share,
            held_out_gain: self.held_out_gain,
            significant: self.significant(),
        }
    }
}

/// The threshold of the in-sample gain of a `k`-parameter candidate on `rows` residuals.
pub fn chi2_threshold(k: usize, rows: usize) -> f64 {
    let candidates = Candidate::all().len() as f64;
    (k as f64 * (rows.max(2) as f64).ln()).max(chi2_quantile(SELECTION_LEVEL / candidates, k))
}

/// The candidates' columns and the linearised problem at one fit.
struct Round {
    pool: Vec<Candidate>,
    columns: CandidateColumns,
    design: Design,
    ranges: Vec<Vec<usize>>,
}

impl Round {
    fn new(fit: &JointFit, pool: Vec<Candidate>) -> Self {
        let t = std::time::Instant::now();
        let columns = candidate_columns(fit, &pool);
        tracing::debug!(elapsed_s = t.elapsed().as_secs_f64(), "TMP columns");
        let design = Design::new(fit, &columns.columns);
        tracing::debug!(elapsed_s = t.elapsed().as_secs_f64(), "TMP design");
        let mut next = 0;
        let ranges = pool
            .iter()
            .map(|c| {
                let range: Vec<usize> = (next..next + c.dim()).map(|k| design.extra(k)).collect();
                next += c.dim();
                range
            })
            .collect();
        Self {
            pool,
            columns,
            design,
            ranges,
        }
    }

    /// Scores of the pool's candidates `which` on top of the columns `base`.
    fn evaluate(&self, base: &[usize], which: impl Iterator<Item = usize>) -> Vec<Evaluation> {
        let Some(without) = self.design.fit(base) else {
            return Vec::new();
        };
        which
            .filter_map(|k| self.evaluate_one(base, &without, k))
            .collect()
    }

    fn evaluate_one(&self, base: &[usize], without: &SetFit, k: usize) -> Option<Evaluation> {
        let columns = &self.ranges[k];
        if columns.iter().any(|&c| self.design.is_empty_column(c)) {
            return None;
        }
        let set: Vec<usize> = base.iter().chain(columns).copied().collect();
        let with = self.design.fit(&set)?;
        let gains: Vec<f64> = without
            .fold_sse
            .iter()
            .zip(&with.fold_sse)
            .map(|(a, b)| a - b)
            .collect();
        let rows = self.design.rows.max(1) as f64;
        let candidate = self.pool[k];
        Some(Evaluation {
            candidate,
            columns: columns.clone(),
            chi2_gain: without.sse - with.sse,
            threshold: chi2_threshold(candidate.dim(), self.design.rows),
            held_out_gain: gains.iter().sum(),
            folds_improved: gains.iter().filter(|g| **g > 0.0).count(),
            held_out_rms: [
                (without.held_out() / rows).sqrt(),
                (with.held_out() / rows).sqrt(),
            ],
            coefficients: with.step[base.len()..].to_vec(),
            explained_share: (without.sse - with.sse) / without.sse.max(f64::MIN_POSITIVE),
        })
    }
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

/// Runs the loop on the paper-model fit `paper`. `rest_noise` is the tracker noise measured
/// on `rest_frames` static frames (the homing dwell). Returns the final fit (the paper fit
/// when nothing was added) and what was found.
pub fn discover(
    session: &SessionData,
    paper: JointFit,
    rest_noise: &NoiseModel,
    rest_frames: usize,
) -> Result<(JointFit, Discovery), CalibrationError> {
    let started = std::time::Instant::now();
    let mut fit = paper;
    let mut current = step_metrics("paper model", &fit, session, rest_noise, rest_frames);
    let mut steps = vec![StepSummary::of(&current)];
    let mut effects: Vec<EffectReport> = Vec::new();
    let mut leads: Vec<Correlate> = Vec::new();
    let mut nuisance: Vec<Candidate> = Vec::new();
    let mut rejected: Vec<Candidate> = Vec::new();
    let mut plots = Plots::default();
    let last_round = loop {
        let present: Vec<Candidate> = fit
            .model
            .robot
            .effects
            .iter()
            .map(Candidate::of_effect)
            .collect();
        let pool: Vec<Candidate> =
            nuisance
                .iter()
                .copied()
                .chain(Candidate::all().into_iter().filter(|c| {
                    !present.contains(c) && !nuisance.contains(c) && !rejected.contains(c)
                }))
                .collect();
        let round = Round::new(&fit, pool);
        tracing::debug!(elapsed_s = started.elapsed().as_secs_f64(), "candidates scored");
        if plots.before.is_none() {
            plots.before = Some(picture(
                "paper model",
                &fit,
                &round.columns.joint_derivatives,
                rest_noise,
            ));
        }
        if effects.len() == MAX_EFFECTS {
            break round;
        }
        let mut base: Vec<usize> = (0..round.design.fitted).collect();
        let mut conditioned: Vec<usize> = (0..nuisance.len()).collect();
        for &k in &conditioned {
            base.extend(&round.ranges[k]);
        }
        let choice = loop {
            let open = (0..round.pool.len()).filter(|k| !conditioned.contains(k));
            let best = round
                .evaluate(&base, open)
                .into_iter()
                .filter(Evaluation::significant)
                .max_by(|a, b| a.held_out_gain.total_cmp(&b.held_out_gain));
            match best {
                Some(probe) if !probe.candidate.in_library() => {
                    tracing::debug!(
                        probe = probe.candidate.label(),
                        gain = probe.chi2_gain,
                        "structure outside the library"
                    );
                    let k = round
                        .pool
                        .iter()
                        .position(|c| *c == probe.candidate)
                        .unwrap_or(0);
                    conditioned.push(k);
                    base.extend(&probe.columns);
                    nuisance.push(probe.candidate);
                    leads.push(probe.correlate());
                }
                other => break other,
            }
        };
        let Some(choice) = choice else {
            break round;
        };
        tracing::debug!(
            candidate = choice.candidate.label(),
            gain = choice.chi2_gain,
            "adding an effect"
        );
        match add_effect(session, &fit, &choice) {
            Some(added) if added.refit_gain >= choice.threshold => {
                let label = format!("+ {}", choice.candidate.label());
                let after = step_metrics(&label, &added.fit, session, rest_noise, rest_frames);
                steps.push(StepSummary::of(&after));
                let before = std::mem::replace(&mut current, after.clone());
                effects.push(effect_report(&choice, &added, before, after));
                fit = added.fit;
            }
            _ => rejected.push(choice.candidate),
        }
    };
    if !effects.is_empty() {
        plots.after = Some(picture(
            "final model",
            &fit,
            &last_round.columns.joint_derivatives,
            rest_noise,
        ));
    }
    let fitted: Vec<usize> = (0..last_round.design.fitted).collect();
    let mut correlates: Vec<Correlate> = last_round
        .evaluate(&fitted, 0..last_round.pool.len())
        .iter()
        .map(Evaluation::correlate)
        .collect();
    correlates.sort_by(|a, b| b.chi2_gain.total_cmp(&a.chi2_gain));
    correlates.truncate(CORRELATES_REPORTED);
    let metrics = current;
    let residual_is_noise = metrics.noise_test.iter().all(|t| t.is_noise);
    let structured_residual = !leads.is_empty() || !residual_is_noise;
    let effects_added: Vec<String> = effects.iter().map(|e| e.label.clone()).collect();
    let verdict = verdict(&effects_added, &leads, &correlates, residual_is_noise);
    let final_report = FinalReport {
        effects_added,
        latency_ms: fit.model.latency_s * 1e3,
        steps,
        metrics,
        residual_is_noise,
        structured_residual,
        leads,
        strongest_correlates: correlates,
        verdict,
        plots,
    };
    tracing::debug!(elapsed_s = started.elapsed().as_secs_f64(), "residual loop");
    Ok((
        fit,
        Discovery {
            effects,
            final_report,
        },
    ))
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
