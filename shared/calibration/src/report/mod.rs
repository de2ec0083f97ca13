//! Report layer: the calibration report of the biopsy robot (`report.json`): latency,
//! residuals per tool for the nominal model, the stepwise method and the joint fit, the
//! parameter table with standard deviations, identifiability, held-out validation, the
//! residual loop and run time; its HTML rendering with plots, and the atomic writing of the
//! output files.

pub mod discovery;
pub mod discovery_html;
pub mod html;
pub mod hysteresis;
pub mod output;
pub mod plots;
pub mod serial;
mod svg;

use serde::Serialize;

use crate::data::frames::FrameStats;
use crate::data::session::Observation;
use crate::fit::identifiability::Analysis;
use crate::fit::joint_fit::{FixedParameter, JointFit};
use crate::math::stats::{self, ErrorSummary};
use crate::model::biopsy::params::ParamId;
use crate::model::biopsy::{BiopsyModel, BACK, FRONT, TIP};
use crate::model::{blocks_of, NoiseModel, ParamLayout, QuantityNoise, RobotModel};

pub use discovery::{summary_text, EffectEntry, FinalReport, StepMetrics};

/// The whole report.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The recording directory.
    pub recording: String,
    /// Tracker latency: exposure → availability at the tracker (the robust line through the
    /// frames' `t_ns` stamps; a format v1 recording's arrival stamps), ms.
    pub latency_ms: f64,
    /// Standard deviation of the latency (ms).
    pub latency_std_ms: f64,
    /// Time synchronisation details.
    pub time_sync: TimeSyncReport,
    /// How much data each phase contributed.
    pub data: DataReport,
    /// Tracker noise of each tool relative to the base marker.
    pub noise: NoiseReport,
    /// Residuals of each model (nominal, stepwise, joint) on the fitted and held-out data.
    pub residual_rms: Vec<ModelResiduals>,
    /// Parameter table.
    pub parameters: Vec<ParameterRow>,
    /// Identifiability at the joint solution.
    pub identifiability: IdentifiabilityReport,
    /// Held-out validation.
    pub validation: ValidationReport,
    /// Effects the residual loop added to the paper model, in order.
    pub effects: Vec<EffectEntry>,
    /// The model after the residual loop and what is left unexplained.
    pub r#final: FinalReport,
    /// Wall-clock time of the calibration (s).
    pub run_time_s: f64,
}

/// Time synchronisation details.
#[derive(Debug, Clone, Serialize)]
pub struct TimeSyncReport {
    /// Host time per tracker frame-counter tick (ms).
    pub tracker_tick_ms: f64,
    /// Robust standard deviation of the frames' `t_ns` stamps about the clock line (ms).
    pub arrival_jitter_ms: f64,
    /// The model-free latency estimate that started the fits (ms).
    pub model_free_latency_ms: f64,
    /// Median interval of the encoder samples (ms).
    pub encoder_interval_ms: f64,
    /// Tracker stream counts.
    pub frames: FrameStats,
    /// Frames whose exposure fell outside the encoder stream or into a gap.
    pub frames_rejected_encoder_gap: usize,
}

/// Data used per phase.
#[derive(Debug, Clone, Serialize)]
pub struct DataReport {
    /// Homing-dwell frames (static) used for the offsets and the noise.
    pub dwell_frames: usize,
    /// Excitation frames fitted.
    pub excitation_frames: usize,
    /// Tip-sphere readings fitted.
    pub tip_readings: usize,
    /// Validation frames (held out).
    pub validation_frames: usize,
    /// Static validation holds.
    pub validation_holds: usize,
    /// Measurement blocks the robust loss down-weighted in the joint fit.
    pub downweighted_measurements: usize,
}

/// Noise of one tool (relative to the base marker).
#[derive(Debug, Clone, Serialize)]
pub struct ToolNoiseReport {
    /// RMS position noise per axis (mm).
    pub position_mm: f64,
    /// Largest and smallest standard deviation along the covariance's principal axes (mm).
    pub position_principal_mm: [f64; 2],
    /// Rotation noise per axis (degrees).
    pub rotation_deg: f64,
}

impl ToolNoiseReport {
    fn of(noise: &QuantityNoise) -> Self {
        let eigen = noise.position_covariance.symmetric_eigenvalues();
        Self {
            position_mm: noise.position_sigma(),
            position_principal_mm: [eigen.max().sqrt(), eigen.min().max(0.0).sqrt()],
            rotation_deg: noise.rotation_sigma.to_degrees(),
        }
    }
}

/// Noise of the three tools.
#[derive(Debug, Clone, Serialize)]
pub struct NoiseReport {
    /// Measured in the static homing dwell.
    pub dwell: [ToolNoiseReport; 2],
    /// Re-estimated from the joint fit's residuals: front, back, tip.
    pub fitted: [ToolNoiseReport; 3],
}

impl NoiseReport {
    /// Report of the dwell noise and the fitted noise.
    pub fn new(dwell: &NoiseModel, fitted: &NoiseModel) -> Self {
        Self {
            dwell: [FRONT, BACK].map(|kind| ToolNoiseReport::of(dwell.of(kind))),
            fitted: [FRONT, BACK, TIP].map(|kind| ToolNoiseReport::of(fitted.of(kind))),
        }
    }
}

/// RMS residuals of one model.
#[derive(Debug, Clone, Serialize)]
pub struct ModelResiduals {
    /// `nominal`, `stepwise` or `joint`.
    pub model: String,
    /// Front marker position (RMS of the 3-D error, mm), fitted phases.
    pub front_mm: f64,
    /// Front marker orientation (RMS angle, degrees), fitted phases.
    pub front_deg: f64,
    /// Back marker position (mm), fitted phases.
    pub back_mm: f64,
    /// Back marker orientation (degrees), fitted phases.
    pub back_deg: f64,
    /// Tip sphere (RMS 3-D, mm), tip phase.
    pub tip_mm: f64,
    /// Front marker position on the held-out validation frames (mm).
    pub validation_front_mm: f64,
    /// Back marker position on the held-out validation frames (mm).
    pub validation_back_mm: f64,
    /// Marker-derived tip error on the held-out validation holds (mm).
    pub validation_marker_tip: Option<ErrorSummary>,
}

/// RMS residuals of `model` on `fitted` (excitation and tip) and `validation` frames.
pub fn model_residuals(
    name: &str,
    model: &BiopsyModel,
    fitted: &[Observation],
    validation: &[Observation],
    marker_tip: Option<ErrorSummary>,
) -> ModelResiduals {
    let summary = |observations: &[Observation]| {
        let (blocks, _) = blocks_of(model, observations);
        let mut raws = Vec::with_capacity(blocks.len());
        model.residuals(observations, &blocks, &mut raws);
        let mut position: [Vec<f64>; 3] = Default::default();
        let mut angle: [Vec<f64>; 3] = Default::default();
        for (block, raw) in blocks.iter().zip(raws) {
            let raw = raw.unwrap_or([f64::NAN; 6]);
            let q = block.kind.0;
            position[q].push((raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2]).sqrt());
            angle[q].push(
                (raw[3] * raw[3] + raw[4] * raw[4] + raw[5] * raw[5])
                    .sqrt()
                    .to_degrees(),
            );
        }
        let rms = |v: &Vec<f64>| stats::rms(v.iter().copied());
        (position.map(|v| rms(&v)), angle.map(|v| rms(&v)))
    };
    let (position, angle) = summary(fitted);
    let (held_out, _) = summary(validation);
    ModelResiduals {
        model: name.into(),
        front_mm: position[FRONT.0],
        front_deg: angle[FRONT.0],
        back_mm: position[BACK.0],
        back_deg: angle[BACK.0],
        tip_mm: position[TIP.0],
        validation_front_mm: held_out[FRONT.0],
        validation_back_mm: held_out[BACK.0],
        validation_marker_tip: marker_tip,
    }
}

/// One row of the parameter table.
#[derive(Debug, Clone, Serialize)]
pub struct ParameterRow {
    /// Parameter name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Nominal value (with the homing offsets).
    pub nominal: f64,
    /// Stepwise-method value.
    pub stepwise: f64,
    /// Joint-fit value.
    pub joint: f64,
    /// Standard deviation of the joint-fit value; `None` if the parameter was fixed.
    pub std_dev: Option<f64>,
}

/// The parameter table over the full layout (fixed parameters have no standard deviation).
pub fn parameter_table(
    layout: &ParamLayout<ParamId>,
    nominal: &BiopsyModel,
    stepwise: &BiopsyModel,
    fit: &JointFit<BiopsyModel>,
) -> Vec<ParameterRow> {
    layout
        .ids
        .iter()
        .map(|id| {
            let std_dev = fit
                .layout
                .ids
                .iter()
                .position(|f| f == id)
                .map(|k| fit.analysis.std_devs[k]);
            ParameterRow {
                name: id.name(),
                unit: id.unit().into(),
                nominal: id.get(nominal),
                stepwise: id.get(stepwise),
                joint: id.get(&fit.model),
                std_dev,
            }
        })
        .collect()
}

/// Identifiability block.
#[derive(Debug, Clone, Serialize)]
pub struct IdentifiabilityReport {
    /// Numerical rank of the column-scaled weighted Jacobian.
    pub rank: usize,
    /// Number of fitted parameters.
    pub parameters: usize,
    /// Condition number of the column-scaled weighted Jacobian.
    pub condition_number: f64,
    /// Its singular values, largest first.
    pub singular_values: Vec<f64>,
    /// Reduced χ² of the whitened residuals (≈ 1 when the noise model fits).
    pub reduced_chi_squared: f64,
    /// Parameters held fixed because the data do not determine them.
    pub fixed: Vec<FixedParameter>,
    /// Parameter pairs correlated by more than 0.9 in absolute value.
    pub strong_correlations: Vec<(String, String, f64)>,
}

impl IdentifiabilityReport {
    /// The block for a joint fit.
    pub fn new(fit: &JointFit<BiopsyModel>) -> Self {
        let analysis: &Analysis = &fit.analysis;
        let n = fit.layout.len();
        let names = fit.layout.names(&fit.model);
        let mut strong = Vec::new();
        for a in 0..n {
            for b in a + 1..n {
                let rho = analysis.correlation[(a, b)];
                if rho.abs() > 0.9 {
                    strong.push((names[a].clone(), names[b].clone(), rho));
                }
            }
        }
        Self {
            rank: analysis.rank,
            parameters: n,
            condition_number: analysis.condition_number,
            singular_values: analysis.singular_values.clone(),
            reduced_chi_squared: analysis.reduced_chi_squared,
            fixed: fit.fixed.clone(),
            strong_correlations: strong,
        }
    }
}

/// Held-out validation block.
#[derive(Debug, Clone, Serialize)]
pub struct ValidationReport {
    /// What `tip_error` is: `validation_tip_sphere` (held-out tip readings) or
    /// `cross_validated_tip_phase` (the recording has no tip data in its validation phase).
    pub tip_error_source: String,
    /// The tip error of the joint fit (mm).
    pub tip_error: Option<ErrorSummary>,
    /// Cross-validated tip error over the tip phase (vs. the noisy tip readings), mm.
    pub cross_validated_tip: Option<ErrorSummary>,
    /// 3-D RMS noise of a tip-sphere reading (mm), from the joint fit's residuals.
    pub tip_reading_noise_mm: f64,
    /// What the cross-validated error adds to the reading noise:
    /// `√max(0, rms² − noise²)` (mm), an estimate of the tip error itself.
    pub cross_validated_excess_mm: Option<f64>,
    /// Standard deviation of the predicted tip at the validation holds, from the parameter
    /// covariance (RMS and max over the holds, mm).
    pub predicted_tip_std: Option<ErrorSummary>,
    /// Static validation holds.
    pub holds: usize,
    /// How the held-out numbers are obtained.
    pub method: String,
}
