//! The calibration report (`report.json`): latency, residuals per tool for the nominal
//! model, the stepwise method and the joint fit, the parameter table with standard
//! deviations, identifiability, held-out validation and run time.

use serde::Serialize;

use crate::frames::FrameStats;
use crate::identifiability::Analysis;
use crate::joint_fit::{FixedParameter, JointFit};
use crate::layout::{CalibModel, ParamLayout};
use crate::noise::{NoiseModel, ToolNoise};
use crate::observations::{Observation, Phase};
use crate::residuals::{blocks_of, raw_block_residuals, Quantity};
use crate::stats;
use crate::validation::TipError;

/// The whole report.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The recording directory.
    pub recording: String,
    /// Tracker latency: exposure → arrival (the robust line through the arrival stamps), ms.
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
    pub effects: Vec<crate::residual_loop::EffectReport>,
    /// The model after the residual loop and what is left unexplained.
    pub r#final: crate::residual_loop::FinalReport,
    /// Wall-clock time of the calibration (s).
    pub run_time_s: f64,
}

/// Time synchronisation details.
#[derive(Debug, Clone, Serialize)]
pub struct TimeSyncReport {
    /// Host time per tracker frame-counter tick (ms).
    pub tracker_tick_ms: f64,
    /// Robust standard deviation of the arrival stamps about the clock line (ms).
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
    fn of(noise: &ToolNoise) -> Self {
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
            dwell: [
                ToolNoiseReport::of(&dwell.front),
                ToolNoiseReport::of(&dwell.back),
            ],
            fitted: [
                ToolNoiseReport::of(&fitted.front),
                ToolNoiseReport::of(&fitted.back),
                ToolNoiseReport::of(&fitted.tip),
            ],
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
    pub validation_marker_tip: Option<TipError>,
}

/// RMS residuals of `model` on `fitted` (excitation and tip) and `validation` frames.
pub fn model_residuals(
    name: &str,
    model: &CalibModel,
    fitted: &[Observation],
    validation: &[Observation],
    marker_tip: Option<TipError>,
) -> ModelResiduals {
    let summary = |observations: &[Observation]| {
        let (blocks, _) = blocks_of(observations, |o| o.phase == Phase::Tip);
        let raws = raw_block_residuals(model, observations, &blocks);
        let mut position: [Vec<f64>; 3] = Default::default();
        let mut angle: [Vec<f64>; 3] = Default::default();
        for (block, raw) in blocks.iter().zip(raws) {
            let raw = raw.unwrap_or([f64::NAN; 6]);
            let q = block.quantity as usize;
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
        front_mm: position[Quantity::Front as usize],
        front_deg: angle[Quantity::Front as usize],
        back_mm: position[Quantity::Back as usize],
        back_deg: angle[Quantity::Back as usize],
        tip_mm: position[Quantity::Tip as usize],
        validation_front_mm: held_out[Quantity::Front as usize],
        validation_back_mm: held_out[Quantity::Back as usize],
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
    layout: &ParamLayout,
    nominal: &CalibModel,
    stepwise: &CalibModel,
    fit: &JointFit,
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
    pub fn new(fit: &JointFit) -> Self {
        let analysis: &Analysis = &fit.analysis;
        let n = fit.layout.len();
        let mut strong = Vec::new();
        for a in 0..n {
            for b in a + 1..n {
                let rho = analysis.correlation[(a, b)];
                if rho.abs() > 0.9 {
                    strong.push((fit.layout.ids[a].name(), fit.layout.ids[b].name(), rho));
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
    pub tip_error: Option<TipError>,
    /// Cross-validated tip error over the tip phase (vs. the noisy tip readings), mm.
    pub cross_validated_tip: Option<TipError>,
    /// 3-D RMS noise of a tip-sphere reading (mm), from the joint fit's residuals.
    pub tip_reading_noise_mm: f64,
    /// What the cross-validated error adds to the reading noise:
    /// `√max(0, rms² − noise²)` (mm), an estimate of the tip error itself.
    pub cross_validated_excess_mm: Option<f64>,
    /// Standard deviation of the predicted tip at the validation holds, from the parameter
    /// covariance (RMS and max over the holds, mm).
    pub predicted_tip_std: Option<TipError>,
    /// Static validation holds.
    pub holds: usize,
    /// How the held-out numbers are obtained.
    pub method: String,
}
