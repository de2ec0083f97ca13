//! What the residual loop reports: the `effects` list and the `final` block of
//! `report.json`, per-step metrics, and the short summary `sabr calibrate` prints.

use serde::Serialize;

use crate::report::{ModelResiduals, Report};
use crate::residual_loop::plots::Plots;
use crate::residual_loop::significance::NoiseTest;
use crate::validation::TipError;

/// The errors of one model of the loop (the paper model, then after each effect).
#[derive(Debug, Clone, Serialize)]
pub struct StepMetrics {
    /// `paper model`, or `+ <effect label>`.
    pub label: String,
    /// Residual RMS per tool on the fitted phases and on the held-out validation phase,
    /// and the held-out marker-derived tip error.
    pub residual_rms: ModelResiduals,
    /// Cross-validated tip error over the tip phase (mm).
    pub cross_validated_tip: Option<TipError>,
    /// The residual against the tracker noise at rest, per tool.
    pub noise_test: Vec<NoiseTest>,
}

impl StepMetrics {
    /// Held-out error (mm): RMS of the marker-derived tip error at the validation holds.
    pub fn held_out_tip_mm(&self) -> Option<f64> {
        self.residual_rms.validation_marker_tip.map(|e| e.rms_mm)
    }
}

/// A fitted parameter of an effect.
#[derive(Debug, Clone, Serialize)]
pub struct FittedValue {
    /// Field name as in `params.toml` (`amplitude`, `phase`, `width`, `delta`, `gain`).
    pub name: String,
    /// Value.
    pub value: f64,
    /// Standard deviation from the joint fit's covariance (`None` if it had to be fixed).
    pub std_dev: Option<f64>,
    /// Unit.
    pub unit: String,
}

/// The evidence for adding a candidate: the linearised gain at the model before it.
#[derive(Debug, Clone, Serialize)]
pub struct SelectionEvidence {
    /// Parameters of the candidate.
    pub parameters: usize,
    /// In-sample cost reduction of one Gauss–Newton step (score statistic, χ² units).
    pub chi2_gain: f64,
    /// The threshold it had to pass: the larger of the BIC penalty and the Bonferroni χ²
    /// quantile over all candidates.
    pub chi2_threshold: f64,
    /// Probability of a gain this large from noise alone (χ² tail, one candidate).
    pub p_value: f64,
    /// Held-out (cross-validated over time blocks) cost reduction, χ² units.
    pub held_out_gain: f64,
    /// Folds in which the held-out error fell.
    pub folds_improved: usize,
    /// Folds.
    pub folds: usize,
    /// Held-out RMS of the whitened residual without and with the candidate.
    pub held_out_whitened_rms: [f64; 2],
    /// Cost reduction of the actual joint refit, measured on the fit before it (χ² units).
    pub refit_chi2_gain: f64,
}

/// One effect the loop added.
#[derive(Debug, Clone, Serialize)]
pub struct EffectReport {
    /// Class: `transmission_ripple`, `backlash`, `joint_compliance` or `link_length`.
    pub name: String,
    /// Human-readable label, e.g. `transmission_ripple θ2 h1`.
    pub label: String,
    /// Joint 1..5 (θ1..θ5), for joint-side effects. (The `joint` of the effect in
    /// `params.toml` is the model's 0-based index.)
    pub joint: Option<usize>,
    /// Link name (`l_f`, `l_fe`, `l_b`, `l_be`, `d_offset`), for link-length errors.
    pub link: Option<String>,
    /// Harmonic of the motor angle, for ripple.
    pub harmonic: Option<f64>,
    /// Index of the effect in `params.toml`'s `[[effects]]`.
    pub index: usize,
    /// Fitted parameters with standard deviations.
    pub parameters: Vec<FittedValue>,
    /// Why it was added.
    pub evidence: SelectionEvidence,
    /// The model before adding it.
    pub before: StepMetrics,
    /// The model after adding it and refitting everything.
    pub after: StepMetrics,
}

/// A signal the residual correlates with.
#[derive(Debug, Clone, Serialize)]
pub struct Correlate {
    /// Candidate label, e.g. `drift_in_time θ3`.
    pub label: String,
    /// What the signal is.
    pub signal: String,
    /// Whether the effect library has a model for it.
    pub in_library: bool,
    /// Cost reduction if it were added (score statistic, χ² units).
    pub chi2_gain: f64,
    /// Share of the residual sum of squares it explains (squared partial correlation).
    pub explained_share: f64,
    /// Held-out cost reduction (χ² units).
    pub held_out_gain: f64,
    /// Whether it passes the selection test on its own.
    pub significant: bool,
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
    /// Significant signals outside the library found on the way (not claimed as effects).
    pub leads: Vec<Correlate>,
    /// The strongest correlates of the final residual.
    pub strongest_correlates: Vec<Correlate>,
    /// One-sentence conclusion.
    pub verdict: String,
    /// Data of the report's plots (not written to `report.json`).
    #[serde(skip)]
    pub plots: Plots,
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
