//! The residual loop in the report: the metrics of each model the loop considered (the
//! judge of the biopsy model), the `final` block of `report.json`, and the short summary
//! `sabr calibrate` prints.

use serde::Serialize;

use crate::data::phases::Phase;
use crate::data::session::{Observation, SessionData};
use crate::discovery::significance::{noise_tests, NoiseTest};
use crate::discovery::{Correlate, Discovery, EffectReport, Judge};
use crate::fit::joint_fit::JointFit;
use crate::fit::validation::cross_validated;
use crate::math::stats::ErrorSummary;
use crate::model::biopsy::validation::{marker_tip_errors, validation_holds};
use crate::model::biopsy::{BiopsyModel, BACK, FRONT, TIP};
use crate::model::NoiseModel;
use crate::report::hysteresis::HysteresisDiagnostic;
use crate::report::plots::Plots;
use crate::report::{model_residuals, ModelResiduals, Report};

/// An effect the loop added to the biopsy model, as `report.json` lists it.
pub type EffectEntry = EffectReport<StepMetrics>;

/// The errors of one model of the loop (the paper model, then after each effect).
#[derive(Debug, Clone, Serialize)]
pub struct StepMetrics {
    /// `paper model`, or `+ <effect label>`.
    pub label: String,
    /// Residual RMS per tool on the fitted phases and on the held-out validation phase,
    /// and the held-out marker-derived tip error.
    pub residual_rms: ModelResiduals,
    /// Cross-validated tip error over the tip phase (mm).
    pub cross_validated_tip: Option<ErrorSummary>,
    /// The residual against the tracker noise at rest, per tool.
    pub noise_test: Vec<NoiseTest>,
}

impl StepMetrics {
    /// Held-out error (mm): RMS of the marker-derived tip error at the validation holds.
    pub fn held_out_tip_mm(&self) -> Option<f64> {
        self.residual_rms.validation_marker_tip.map(|e| e.rms_mm)
    }
}

/// The metrics of the biopsy model's steps: errors on the fitted data, at the held-out
/// validation holds and over the tip phase, and the residual against the tracker noise at
/// rest (the homing dwell).
pub struct BiopsyJudge<'a> {
    /// The synchronised session (its validation phase is held out).
    pub session: &'a SessionData,
    /// Tracker noise measured at rest.
    pub rest_noise: &'a NoiseModel,
    /// Frames it was measured on.
    pub rest_frames: usize,
}

impl Judge<BiopsyModel> for BiopsyJudge<'_> {
    type Metrics = StepMetrics;

    fn metrics(&self, label: &str, fit: &JointFit<BiopsyModel>) -> StepMetrics {
        let validation: Vec<Observation> = self
            .session
            .observations(fit.model.latency_s)
            .items
            .into_iter()
            .filter(|o| o.phase == Phase::Validation)
            .collect();
        let holds = validation_holds(&validation);
        let marker_tip = ErrorSummary::of(&marker_tip_errors(&fit.model, &holds, &fit.noise));
        StepMetrics {
            label: label.into(),
            residual_rms: model_residuals(
                label,
                &fit.model,
                &fit.observations,
                &validation,
                marker_tip,
            ),
            cross_validated_tip: cross_validated(fit, TIP),
            noise_test: noise_tests(fit, self.rest_noise, self.rest_frames, &[FRONT, BACK]),
        }
    }

    fn residual_is_noise(&self, metrics: &StepMetrics) -> bool {
        metrics.noise_test.iter().all(|t| t.is_noise)
    }
}

/// One row of the held-out error per step.
#[derive(Debug, Clone, Serialize)]
pub struct StepSummary {
    /// Model label.
    pub label: String,
    /// Held-out marker-derived tip error RMS (mm).
    pub held_out_tip_mm: Option<f64>,
    /// Cross-validated tip error RMS over the tip phase (mm).
    pub cross_validated_tip_mm: Option<f64>,
    /// Front and back marker position residual RMS on the fitted phases (mm).
    pub fitted_marker_mm: [f64; 2],
}

impl StepSummary {
    /// The summary of a step.
    pub fn of(step: &StepMetrics) -> Self {
        Self {
            label: step.label.clone(),
            held_out_tip_mm: step.held_out_tip_mm(),
            cross_validated_tip_mm: step.cross_validated_tip.map(|e| e.rms_mm),
            fitted_marker_mm: [step.residual_rms.front_mm, step.residual_rms.back_mm],
        }
    }
}

/// The `final` block: the model after the loop and what is left unexplained.
#[derive(Debug, Clone, Serialize)]
pub struct FinalReport {
    /// Effects added to the paper model.
    pub effects_added: Vec<String>,
    /// The final model's errors.
    pub metrics: StepMetrics,
    /// Tracker latency of the final model (ms): the library's latency effect, estimated by
    /// the time synchronisation and refined by every joint fit.
    pub latency_ms: f64,
    /// Held-out error per step (paper model, then after each effect).
    pub steps: Vec<StepSummary>,
    /// Whether every tool's residual is consistent with the tracker noise at rest.
    pub residual_is_noise: bool,
    /// Whether structure is left that the library does not explain (a significant probe
    /// outside the library, or residual above the tracker noise).
    pub structured_residual: bool,
    /// Significant signals outside the library found on the way (not claimed as effects)
    /// and still significant at the final fit.
    pub leads: Vec<Correlate>,
    /// Signals outside the library significant on the way but explained by the effects
    /// added after them.
    pub explained_leads: Vec<Correlate>,
    /// The strongest correlates of the final residual.
    pub strongest_correlates: Vec<Correlate>,
    /// One-sentence conclusion.
    pub verdict: String,
    /// Hysteresis diagnostics of the final model's residual, per joint.
    pub hysteresis: Vec<HysteresisDiagnostic>,
    /// Data of the report's plots (not written to `report.json`).
    #[serde(skip)]
    pub plots: Plots,
}

impl FinalReport {
    /// The block of a loop's outcome, with the plots of the report.
    pub fn new(discovery: &Discovery<BiopsyModel, StepMetrics>, plots: Plots) -> Self {
        Self {
            effects_added: discovery.effects_added.clone(),
            metrics: discovery.metrics.clone(),
            latency_ms: discovery.fit.model.latency_s * 1e3,
            steps: discovery.steps.iter().map(StepSummary::of).collect(),
            residual_is_noise: discovery.residual_is_noise,
            structured_residual: discovery.structured_residual,
            leads: discovery.leads.clone(),
            explained_leads: discovery.explained_leads.clone(),
            strongest_correlates: discovery.strongest_correlates.clone(),
            verdict: discovery.verdict.clone(),
            hysteresis: plots
                .after
                .as_ref()
                .or(plots.before.as_ref())
                .map(|p| p.hysteresis.to_vec())
                .unwrap_or_default(),
            plots,
        }
    }
}

/// The summary `sabr calibrate` prints: held-out tip error of the nominal model, the paper
/// model and after each effect added, then the verdict.
pub fn summary_text(report: &Report) -> String {
    let nominal = report
        .residual_rms
        .first()
        .and_then(|r| r.validation_marker_tip)
        .map(|e| e.rms_mm);
    let mm = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
    let mut text = String::from(
        "model                                  held-out tip RMS mm  cross-validated tip mm\n",
    );
    text.push_str(&format!(
        "{:<38} {:>19}  {:>22}\n",
        "nominal",
        mm(nominal),
        "–"
    ));
    for step in &report.r#final.steps {
        text.push_str(&format!(
            "{:<38} {:>19}  {:>22}\n",
            step.label,
            mm(step.held_out_tip_mm),
            mm(step.cross_validated_tip_mm)
        ));
    }
    for effect in &report.effects {
        let values: Vec<String> = effect
            .parameters
            .iter()
            .map(|p| {
                let std = p.std_dev.map_or("fixed".into(), |s| format!("{s:.2e}"));
                format!("{} = {:.4e} ± {std} {}", p.name, p.value, p.unit)
            })
            .collect();
        text.push_str(&format!("  {}: {}\n", effect.label, values.join(", ")));
    }
    text.push_str(&report.r#final.verdict);
    text.push('\n');
    text
}
