//! What the residual loop reports of each effect it added (its parameters, the evidence, the
//! metrics before and after) and of the signals the residual correlates with.

use serde::Serialize;

/// A fitted parameter of an effect.
#[derive(Debug, Clone, Serialize)]
pub struct FittedValue {
    /// Field name as the model names it (e.g. `amplitude`).
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
    /// How much of the candidate the fitted parameters did not already explain: the
    /// smallest singular value of its unit columns after projecting them out (1 = new).
    pub identifiable: f64,
    /// Other candidates the data can hardly tell from this one (their columns correlate at
    /// least 0.9 with its own beyond the fitted parameters): the effect may sit on any of
    /// them.
    pub aliases: Vec<String>,
}

/// One effect the loop added, with the metrics `S` of the models before and after.
#[derive(Debug, Clone, Serialize)]
pub struct EffectReport<S> {
    /// Class, e.g. `backlash`.
    pub name: String,
    /// Human-readable label, e.g. `backlash θ4`.
    pub label: String,
    /// The joint it attaches to, numbered as the model numbers its joints (the biopsy
    /// robot: 1..5; the `joint` of the effect in its `params.toml` is the 0-based index).
    pub joint: Option<usize>,
    /// The link it attaches to, named as the model names it.
    pub link: Option<String>,
    /// Harmonic of its periodic signal, for periodic effects.
    pub harmonic: Option<f64>,
    /// Index of the effect among the model's effects (its parameter file's order).
    pub index: usize,
    /// Fitted parameters with standard deviations.
    pub parameters: Vec<FittedValue>,
    /// Why it was added.
    pub evidence: SelectionEvidence,
    /// The model before adding it.
    pub before: S,
    /// The model after adding it and refitting everything.
    pub after: S,
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
    /// Smallest singular value of its unit columns beyond the fitted parameters (1 = new
    /// information, below 1e-3 = not identifiable, never selected).
    pub identifiable: f64,
    /// Whether it passes the selection test on its own.
    pub significant: bool,
}
