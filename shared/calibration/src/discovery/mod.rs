//! Discovery layer, the residual loop: after the base-model fit, find the structure left in
//! the residual, name the effect behind it, add it to the model, refit everything, and
//! report the errors before and after — on data whose effects were not declared. It works
//! for any [`RobotModel`]: the model supplies the candidates and their columns, a [`Judge`]
//! the metrics of each step.
//!
//! 1. **Candidates** ([`RobotModel::candidates`]): the model's effect library at each of its
//!    joints and links, and probes outside it. Each is a few columns `∂r/∂(its parameters)`
//!    at zero.
//! 2. **Scores** ([`selection`]): for each candidate, the cost reduction of one joint
//!    Gauss–Newton step with all fitted parameters (the score test: the squared correlation
//!    of the whitened residual with the candidate's columns, after projecting out the fitted
//!    parameters), in-sample and held out over interleaved time blocks (10 folds).
//! 3. **Forward selection**: the significant candidate with the largest held-out gain wins.
//!    Significant means: in-sample gain above both the BIC penalty `k·ln m` and the χ²_k
//!    quantile of a family-wise level [`SELECTION_LEVEL`] over all candidates, positive
//!    held-out gain, and a lower held-out error in at least [`MIN_FOLDS_IMPROVED`] of the
//!    folds, and identifiable: at least [`MIN_IDENTIFIABLE`] of its columns outside the span
//!    of the fitted parameters. A library candidate within [`LIBRARY_PREFERENCE`] of the best
//!    held-out gain wins over a probe. A library winner is added to the model (its linearised coefficients start the
//!    fit), everything is refitted jointly ([`joint_fit`] on the extended layout) and kept
//!    only if the refit gains as much as the test demanded. A probe winner is structure the
//!    library does not explain: it is reported as a lead, never added, and the following
//!    tests are conditional on it (so that a library effect cannot be claimed for structure
//!    the probe explains better).
//! 4. **Outcome** ([`report`]): per effect, the fitted parameters with standard deviations,
//!    the evidence and the metrics before and after; the final fit, whether its residual is
//!    noise ([`significance`]), the leads and the strongest correlates.

pub mod families;
pub mod report;
mod round;
pub mod selection;
pub mod significance;

use crate::fit::joint_fit::{joint_fit, JointFit};
use crate::model::{Dataset, RobotModel};

pub use report::{Correlate, EffectReport, FittedValue, SelectionEvidence};
pub use round::chi2_threshold;

use round::{Evaluation, Round};
use selection::FOLDS;
use significance::chi2_tail;

/// Most effects the loop adds.
pub const MAX_EFFECTS: usize = 4;
/// Family-wise level of one selection step (Bonferroni over all candidates).
pub const SELECTION_LEVEL: f64 = 1e-3;
/// Folds (of [`FOLDS`]) in which a selected candidate must lower the held-out error.
pub const MIN_FOLDS_IMPROVED: usize = 7;
/// Smallest share of a candidate's columns that must lie outside the span of the fitted
/// parameters (smallest singular value of its unit columns after projecting them out) for
/// it to be selectable: below it the data cannot tell the candidate from what is fitted
/// (the relative singular-value floor of the identifiability pruning).
pub const MIN_IDENTIFIABLE: f64 = 1e-3;
/// Correlation beyond the fitted parameters at which two candidates are reported as
/// aliases of each other.
pub const ALIAS_CORRELATION: f64 = 0.9;
/// Share of the best probe's held-out gain at which a significant library candidate is
/// preferred to it.
pub const LIBRARY_PREFERENCE: f64 = 0.9;
/// Correlates listed in the outcome.
const CORRELATES_REPORTED: usize = 8;

/// What the loop measures about each model it considers (held-out errors, noise tests...).
pub trait Judge<M: RobotModel> {
    /// The metrics of one model.
    type Metrics: Clone;
    /// The metrics of `fit`, labelled `label`.
    fn metrics(&self, label: &str, fit: &JointFit<M>) -> Self::Metrics;
    /// Whether the residual of a model with these metrics is consistent with the
    /// measurement noise.
    fn residual_is_noise(&self, metrics: &Self::Metrics) -> bool;
}

/// What the loop found.
#[derive(Debug, Clone)]
pub struct Discovery<M: RobotModel, S> {
    /// The final fit (the base fit when nothing was added).
    pub fit: JointFit<M>,
    /// The effects added, in order.
    pub effects: Vec<EffectReport<S>>,
    /// Metrics of every step: the base model, then after each effect.
    pub steps: Vec<S>,
    /// Metrics of the final model.
    pub metrics: S,
    /// Whether the final residual is consistent with the measurement noise.
    pub residual_is_noise: bool,
    /// Whether structure is left that the library does not explain (a significant probe,
    /// or residual above the noise).
    pub structured_residual: bool,
    /// Significant signals outside the library found on the way (not claimed as effects)
    /// that the final model still leaves significant.
    pub leads: Vec<Correlate>,
    /// Signals outside the library that were significant on the way but that the effects
    /// added after them explain (no longer significant at the final fit): e.g. a wide
    /// backlash looks like a joint delay until its play is modelled.
    pub explained_leads: Vec<Correlate>,
    /// The strongest correlates of the final residual.
    pub strongest_correlates: Vec<Correlate>,
    /// Labels of the effects added.
    pub effects_added: Vec<String>,
    /// One-sentence conclusion.
    pub verdict: String,
}

/// An effect added and refitted.
struct Added<M: RobotModel> {
    fit: JointFit<M>,
    index: usize,
    parameters: Vec<(M::Param, &'static str)>,
    refit_gain: f64,
}

/// Adds the effect of `choice` (started at its linearised coefficients) and refits every
/// parameter jointly; `None` when the coefficients contradict the effect, the refit fails
/// or the fitted model is invalid.
fn add_effect<M: RobotModel>(
    data: &impl Dataset<M>,
    fit: &JointFit<M>,
    choice: &Evaluation<M>,
) -> Option<Added<M>> {
    let mut start = fit.model.clone();
    let added = start.add_effect(choice.candidate, &choice.coefficients)?;
    let mut layout = fit.layout.clone();
    layout
        .ids
        .extend(added.parameters.iter().map(|(id, _)| *id));
    let refit = match joint_fit(data, &start, &fit.noise, layout) {
        Ok(refit) => refit,
        Err(error) => {
            tracing::debug!(%error, candidate = choice.info.label, "refit with the effect failed");
            return None;
        }
    };
    refit.model.validate().ok()?;
    let before = fit.residual.norm_squared();
    let after = fit.problem().residuals(&refit.model).0.norm_squared();
    Some(Added {
        fit: refit,
        index: added.index,
        parameters: added.parameters,
        refit_gain: before - after,
    })
}

/// The report entry of an added effect.
fn effect_report<M: RobotModel, S>(
    choice: &Evaluation<M>,
    added: &Added<M>,
    before: S,
    after: S,
) -> EffectReport<S> {
    let fit = &added.fit;
    let parameters = added
        .parameters
        .iter()
        .map(|&(id, name)| FittedValue {
            name: name.into(),
            value: fit.model.get(id),
            std_dev: fit.layout.position(id).map(|k| fit.analysis.std_devs[k]),
            unit: fit.model.describe(id).unit.into(),
        })
        .collect();
    let info = &choice.info;
    EffectReport {
        name: info.class.into(),
        label: info.label.clone(),
        joint: info.joint,
        link: info.link.clone(),
        harmonic: info.harmonic,
        index: added.index,
        parameters,
        evidence: SelectionEvidence {
            parameters: info.dim,
            chi2_gain: choice.chi2_gain,
            chi2_threshold: choice.threshold,
            p_value: chi2_tail(choice.chi2_gain, info.dim),
            held_out_gain: choice.held_out_gain,
            folds_improved: choice.folds_improved,
            folds: FOLDS,
            held_out_whitened_rms: choice.held_out_rms,
            refit_chi2_gain: added.refit_gain,
            identifiable: choice.identifiable,
            aliases: choice.aliases.clone(),
        },
        before,
        after,
    }
}

/// The state of the forward selection.
struct Search<'a, M: RobotModel, D, J: Judge<M>> {
    data: &'a D,
    judge: &'a J,
    fit: JointFit<M>,
    current: J::Metrics,
    steps: Vec<J::Metrics>,
    effects: Vec<EffectReport<J::Metrics>>,
    /// The parameters of each added effect, in the order of its report's `parameters`.
    effect_params: Vec<Vec<M::Param>>,
    leads: Vec<Correlate>,
    nuisance: Vec<M::Candidate>,
    rejected: Vec<M::Candidate>,
}

impl<M: RobotModel, D: Dataset<M>, J: Judge<M>> Search<'_, M, D, J> {
    /// The candidates at the current fit: the probes conditioned on first, then every
    /// candidate neither in the model, nor conditioned on, nor rejected.
    fn round(&self) -> Round<M> {
        let model = &self.fit.model;
        let present = model.carried();
        let open = model.candidates().into_iter().filter(|c| {
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
    fn select(&mut self, round: &Round<M>) -> Option<Evaluation<M>> {
        let mut conditioned: Vec<usize> = (0..self.nuisance.len()).collect();
        let mut base: Vec<usize> = (0..round.design.fitted).collect();
        for &k in &conditioned {
            base.extend(&round.ranges[k]);
        }
        loop {
            let open = (0..round.pool.len()).filter(|k| !conditioned.contains(k));
            let significant: Vec<Evaluation<M>> = round
                .evaluate(&base, open)
                .into_iter()
                .filter(Evaluation::significant)
                .collect();
            let best = significant
                .iter()
                .max_by(|a, b| a.held_out_gain.total_cmp(&b.held_out_gain))?;
            // A library effect that does nearly as well as a probe is the more specific
            // explanation (e.g. a ripple of a motor turning less than a revolution looks like
            // a smooth function of the joint angle): it is added, and the probe is re-checked
            // at the final fit.
            let library = significant
                .iter()
                .filter(|e| e.info.in_library)
                .max_by(|a, b| a.held_out_gain.total_cmp(&b.held_out_gain))
                .filter(|e| e.held_out_gain >= LIBRARY_PREFERENCE * best.held_out_gain);
            let best = library.unwrap_or(best).clone();
            if best.info.in_library {
                return Some(round.with_aliases(&base, best));
            }
            tracing::debug!(probe = best.info.label, "structure outside the library");
            conditioned.push(best.index);
            base.extend(&best.columns);
            self.nuisance.push(best.candidate);
            self.leads.push(best.correlate());
        }
    }

    /// Adds the chosen effect and refits; keeps it if the refit gains as much as the
    /// selection test demanded, otherwise rejects the candidate. When the data can hardly
    /// tell the choice from some other library candidates (its aliases), each of them is
    /// refitted in its place and the best refit is kept, named with the others as aliases.
    fn try_add(&mut self, choice: &Evaluation<M>) {
        tracing::debug!(
            candidate = choice.info.label,
            gain = choice.chi2_gain,
            "adding an effect"
        );
        let refits = std::iter::once(choice)
            .chain(&choice.alternatives)
            .filter_map(|candidate| {
                let added = add_effect(self.data, &self.fit, candidate)?;
                (added.refit_gain >= candidate.threshold).then_some((candidate, added))
            });
        let best = refits.max_by(|a, b| a.1.refit_gain.total_cmp(&b.1.refit_gain));
        let best = best.map(|(winner, added)| {
            let mut winner = winner.clone();
            winner.aliases = std::iter::once(&choice.info.label)
                .chain(&choice.aliases)
                .filter(|label| **label != winner.info.label)
                .cloned()
                .collect();
            (winner, added)
        });
        match best {
            Some((choice, added)) => {
                let choice = &choice;
                let after = self
                    .judge
                    .metrics(&format!("+ {}", choice.info.label), &added.fit);
                self.steps.push(after.clone());
                let before = std::mem::replace(&mut self.current, after.clone());
                self.effect_params
                    .push(added.parameters.iter().map(|(id, _)| *id).collect());
                self.effects
                    .push(effect_report(choice, &added, before, after));
                self.fit = added.fit;
            }
            None => self.rejected.push(choice.candidate),
        }
    }

    /// The outcome, from the last round (at the final fit). Every effect's parameters are
    /// reported as the final fit has them (an effect added later refits the earlier ones).
    fn finish(mut self, last: &Round<M>, base_label: &str) -> Discovery<M, J::Metrics> {
        for (effect, ids) in self.effects.iter_mut().zip(&self.effect_params) {
            for (value, &id) in effect.parameters.iter_mut().zip(ids) {
                value.value = self.fit.model.get(id);
                value.std_dev = self
                    .fit
                    .layout
                    .position(id)
                    .map(|k| self.fit.analysis.std_devs[k]);
            }
        }
        let fitted: Vec<usize> = (0..last.design.fitted).collect();
        let mut correlates: Vec<Correlate> = last
            .evaluate(&fitted, 0..last.pool.len())
            .iter()
            .map(Evaluation::correlate)
            .collect();
        let (leads, explained_leads): (Vec<Correlate>, Vec<Correlate>) =
            self.leads.into_iter().partition(|lead| {
                correlates
                    .iter()
                    .any(|c| c.label == lead.label && c.significant)
            });
        correlates.sort_by(|a, b| b.chi2_gain.total_cmp(&a.chi2_gain));
        correlates.truncate(CORRELATES_REPORTED);
        let residual_is_noise = self.judge.residual_is_noise(&self.current);
        let effects_added: Vec<String> = self.effects.iter().map(|e| e.label.clone()).collect();
        Discovery {
            verdict: verdict(
                base_label,
                &effects_added,
                &leads,
                &correlates,
                residual_is_noise,
            ),
            effects_added,
            fit: self.fit,
            effects: self.effects,
            steps: self.steps,
            metrics: self.current,
            residual_is_noise,
            structured_residual: !leads.is_empty() || !residual_is_noise,
            leads,
            explained_leads,
            strongest_correlates: correlates,
        }
    }
}

/// Runs the loop on the base fit `base` (labelled `base_label`, e.g. `paper model`), with
/// `data` for the refits and `judge` for the metrics of every step. Returns the final fit
/// (the base fit when nothing was added) and what was found. A candidate whose refit fails
/// is rejected, never an error: the base fit always stands.
pub fn discover<M: RobotModel, D: Dataset<M>, J: Judge<M>>(
    data: &D,
    base: JointFit<M>,
    judge: &J,
    base_label: &str,
) -> Discovery<M, J::Metrics> {
    let started = std::time::Instant::now();
    let current = judge.metrics(base_label, &base);
    let mut search = Search {
        data,
        judge,
        steps: vec![current.clone()],
        current,
        fit: base,
        effects: Vec::new(),
        effect_params: Vec::new(),
        leads: Vec::new(),
        nuisance: Vec::new(),
        rejected: Vec::new(),
    };
    let last = loop {
        let round = search.round();
        if search.effects.len() == MAX_EFFECTS {
            break round;
        }
        match search.select(&round) {
            Some(choice) => search.try_add(&choice),
            None => break round,
        }
    };
    let outcome = search.finish(&last, base_label);
    tracing::debug!(elapsed_s = started.elapsed().as_secs_f64(), "residual loop");
    outcome
}

fn verdict(
    base_label: &str,
    effects: &[String],
    leads: &[Correlate],
    correlates: &[Correlate],
    is_noise: bool,
) -> String {
    let mut text = if effects.is_empty() {
        format!("No effect beyond the {base_label} is supported by the data.")
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
