//! The calibration pipeline of the biopsy robot, the top of the engine: recording → time
//! sync → stepwise method → joint fit → residual loop → validation → report and calibrated
//! parameters. `sabr calibrate` and the live calibrator both call [`calibrate`].

use std::path::Path;
use std::time::Instant;

use sabr_model::RobotParams;
use sabr_recording::Recording;

use crate::data::frames::{measured_frames, FrameStats};
use crate::data::latency;
use crate::data::phases::{Phase, PhaseTable};
use crate::data::session::{joint_ranges, Observation, SessionData};
use crate::data::span::within_session;
use crate::discovery::discover;
use crate::error::CalibrationError;
use crate::fit::joint_fit::{joint_fit, JointFit};
use crate::fit::validation::{cross_validated, propagated_std};
use crate::math::stats::{median, ErrorSummary};
use crate::model::biopsy::noise::{from_static, vicra_default};
use crate::model::biopsy::params::{paper_layout, ParamId};
use crate::model::biopsy::predict::predict;
use crate::model::biopsy::stepwise::{stepwise, FitSets};
use crate::model::biopsy::validation::{
    marker_tip_errors, tip_sphere_error, validation_holds, Hold,
};
use crate::model::biopsy::{BiopsyModel, TIP};
use crate::report::discovery::BiopsyJudge;
use crate::report::output::{write_outputs as write_files, HoldPrediction, OutputError};
use crate::report::plots::{picture, Plots};
use crate::report::{
    model_residuals, parameter_table, DataReport, FinalReport, IdentifiabilityReport, NoiseReport,
    Report, TimeSyncReport, ValidationReport,
};

/// Label of the paper's model in the residual loop.
const PAPER_MODEL: &str = "paper model";

/// Knobs of the calibration, with sensible defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationOptions {
    /// Least range (rad) every joint must cover during the excitation.
    pub min_joint_range_rad: f64,
    /// Largest encoder gap (ms) to interpolate across.
    pub max_encoder_gap_ms: f64,
    /// Fewest tip-sphere readings in the tip phase.
    pub min_tip_readings: usize,
    /// Fewest static frames in the homing dwell.
    pub min_dwell_frames: usize,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        Self {
            min_joint_range_rad: 0.05,
            max_encoder_gap_ms: 5.0,
            min_tip_readings: 10,
            min_dwell_frames: 5,
        }
    }
}

/// Everything a calibration produced.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The calibrated model (joint fit), ready for `params.toml`.
    pub params: RobotParams,
    /// The report.
    pub report: Report,
    /// Nominal model with the homing offsets, at the model-free latency.
    pub nominal: BiopsyModel,
    /// Result of the stepwise method.
    pub stepwise: BiopsyModel,
    /// The joint fit (model, noise, fitted observations, Jacobian, identifiability).
    pub fit: JointFit<BiopsyModel>,
    /// The synchronised session (frames, clock, encoders, phases).
    pub session: SessionData,
    /// The calibrated model's predictions at the validation holds.
    pub predictions: Vec<HoldPrediction>,
}

/// Count rate (counts/s) below which a homing frame counts as at rest.
const DWELL_RATE: f64 = 5.0;

const REQUIRED_PHASES: [(Phase, &str, &str); 4] = [
    (
        Phase::Homing,
        "homing",
        "its dwell at the stops gives the joint offsets",
    ),
    (Phase::Excitation, "excitation", "it is the data of the fit"),
    (Phase::Tip, "tip", "the tip sphere gives the needle length"),
    (
        Phase::Validation,
        "validation",
        "it is held out to validate the model",
    ),
];

/// Refuses a session with fewer than `options.min_tip_readings` tip-sphere readings.
fn require_tip_readings(
    readings: usize,
    options: &CalibrationOptions,
) -> Result<(), CalibrationError> {
    if readings < options.min_tip_readings {
        return Err(CalibrationError::InsufficientData {
            phase: "tip",
            reason: format!(
                "{readings} tip-sphere readings, need at least {}: the needle length is not \
                 identifiable",
                options.min_tip_readings
            ),
        });
    }
    Ok(())
}

/// Tracker frames with a tip-sphere reading whose clock-line time (no latency applied)
/// falls in the tip phase.
fn tip_readings_at_clock_line(session: &SessionData) -> usize {
    session
        .frames
        .iter()
        .enumerate()
        .filter(|(index, frame)| {
            frame.tip.is_some() && session.phases.at(session.exposure_ns(*index, 0.0)) == Phase::Tip
        })
        .count()
}

/// Calibrates the robot of `recording`.
pub fn calibrate(
    recording: &Recording,
    options: &CalibrationOptions,
) -> Result<Calibration, CalibrationError> {
    let started = Instant::now();
    // Only the session's own data (not a later test with the new parameters): see
    // `session_span`.
    let recording = &within_session(recording);
    let robot = recording.robot().map_err(CalibrationError::RobotToml)?;
    let phases = PhaseTable::new(&recording.phases);
    for (phase, name, why) in REQUIRED_PHASES {
        if !phases.contains(phase) {
            return Err(CalibrationError::MissingPhase { phase: name, why });
        }
    }
    check_motion(&robot, recording, &phases, options)?;
    let session = SessionData::synchronise(
        recording,
        &robot,
        phases,
        (options.max_encoder_gap_ms * 1e6) as i64,
    )?;
    tracing::debug!(elapsed_s = started.elapsed().as_secs_f64(), "synchronised");
    // A session without tip readings cannot give the needle length whatever its latency:
    // say so before the latency search, which a short or odd session can fail for its own
    // reasons. The tip phase is taken at the frames' clock line here (no latency yet); the
    // exact count at the estimated latency is checked again below.
    require_tip_readings(tip_readings_at_clock_line(&session), options)?;
    let model_free = latency::estimate(&session)?;
    tracing::debug!(
        elapsed_s = started.elapsed().as_secs_f64(),
        "model-free latency"
    );
    let matched = session.observations(model_free.latency_s);
    let by_phase = |phase: Phase| -> Vec<&Observation> {
        matched.items.iter().filter(|o| o.phase == phase).collect()
    };
    let dwell = homing_dwell(&by_phase(Phase::Homing));
    if dwell.len() < options.min_dwell_frames {
        return Err(CalibrationError::InsufficientData {
            phase: "homing",
            reason: format!(
                "{} tracker frames with the robot at rest, need at least {} (the dwell at the \
                 stops gives the joint offsets)",
                dwell.len(),
                options.min_dwell_frames
            ),
        });
    }
    let sets = FitSets {
        excitation: by_phase(Phase::Excitation)
            .into_iter()
            .filter(|o| o.front.is_some() && o.back.is_some())
            .collect(),
        dwell: dwell.clone(),
        tip: by_phase(Phase::Tip)
            .into_iter()
            .filter(|o| o.tip.is_some())
            .collect(),
    };
    require_tip_readings(sets.tip.len(), options)?;
    let dwell_noise = from_static(&dwell).unwrap_or_else(vicra_default);
    let nominal = nominal_model(&robot, &dwell, model_free.latency_s);
    let stepwise_model = stepwise(&nominal, &sets, &dwell_noise)?;
    tracing::debug!(
        elapsed_s = started.elapsed().as_secs_f64(),
        "stepwise method"
    );
    let layout = paper_layout();
    let paper_fit = joint_fit(&session, &stepwise_model, &dwell_noise, layout.clone())?;
    let judge = BiopsyJudge {
        session: &session,
        rest_noise: &dwell_noise,
        rest_frames: dwell.len(),
    };
    let discovery = discover(&session, paper_fit.clone(), &judge, PAPER_MODEL);
    let plots = Plots {
        before: Some(picture(PAPER_MODEL, &paper_fit, &dwell_noise)),
        after: (!discovery.effects.is_empty())
            .then(|| picture("final model", &discovery.fit, &dwell_noise)),
    };
    let final_report = FinalReport::new(&discovery, plots);
    let fit = discovery.fit;

    tracing::debug!(elapsed_s = started.elapsed().as_secs_f64(), "joint fit");
    let validation_frames: Vec<Observation> =
        by_phase(Phase::Validation).into_iter().cloned().collect();
    let holds = validation_holds(&validation_frames);
    let fitted_at_start: Vec<Observation> = matched
        .items
        .iter()
        .filter(|o| crate::model::biopsy::is_fitted(o))
        .cloned()
        .collect();
    let final_validation: Vec<Observation> = session
        .observations(fit.model.latency_s)
        .items
        .into_iter()
        .filter(|o| o.phase == Phase::Validation)
        .collect();
    let final_holds = validation_holds(&final_validation);
    let marker_tip =
        |model: &BiopsyModel, holds| ErrorSummary::of(&marker_tip_errors(model, holds, &fit.noise));
    let residual_rms = vec![
        model_residuals(
            "nominal",
            &nominal,
            &fitted_at_start,
            &validation_frames,
            marker_tip(&nominal, &holds),
        ),
        model_residuals(
            "stepwise",
            &stepwise_model,
            &fitted_at_start,
            &validation_frames,
            marker_tip(&stepwise_model, &holds),
        ),
        model_residuals(
            "joint",
            &fit.model,
            &fit.observations,
            &final_validation,
            marker_tip(&fit.model, &final_holds),
        ),
    ];
    let validation = validation_report(&fit, &final_holds);
    let predictions = final_holds
        .iter()
        .filter_map(|hold| {
            let pose = predict(&fit.model, &hold.observation).ok()?.pose;
            Some(HoldPrediction {
                counts: hold.observation.counts_at_latency(fit.model.latency_s),
                tip: pose.tip.coords.into(),
                direction: pose.direction.into_inner().into(),
            })
        })
        .collect();
    let latency_index = fit.layout.ids.iter().position(|id| *id == ParamId::Latency);
    let report = Report {
        recording: recording.dir.display().to_string(),
        latency_ms: fit.model.latency_s * 1e3,
        latency_std_ms: latency_index.map_or(f64::NAN, |k| fit.analysis.std_devs[k] * 1e3),
        time_sync: TimeSyncReport {
            tracker_tick_ms: session.clock.period_ns * 1e-6,
            arrival_jitter_ms: session.clock.jitter_ns * 1e-6,
            model_free_latency_ms: model_free.latency_s * 1e3,
            encoder_interval_ms: session.encoders.median_interval_ns() * 1e-6,
            frames: session_stats(recording, &robot)?,
            frames_rejected_encoder_gap: matched.rejected_encoder_gap,
        },
        data: DataReport {
            dwell_frames: dwell.len(),
            excitation_frames: sets.excitation.len(),
            tip_readings: sets.tip.len(),
            validation_frames: final_validation.len(),
            validation_holds: final_holds.len(),
            downweighted_measurements: fit.downweighted(),
        },
        noise: NoiseReport::new(&dwell_noise, &fit.noise),
        residual_rms,
        parameters: parameter_table(&layout, &nominal, &stepwise_model, &fit),
        identifiability: IdentifiabilityReport::new(&fit),
        validation,
        effects: discovery.effects,
        r#final: final_report,
        run_time_s: 0.0,
    };
    let mut params = fit.model.robot.clone();
    params.calibration = Some(sabr_model::params::CalibrationInfo {
        latency_ms: Some(report.latency_ms),
        source: Some(recording.dir.display().to_string()),
        ..Default::default()
    });
    let mut calibration = Calibration {
        params,
        report,
        nominal,
        stepwise: stepwise_model,
        fit,
        session,
        predictions,
    };
    calibration.report.run_time_s = started.elapsed().as_secs_f64();
    Ok(calibration)
}

/// Errors unless every joint covers `min_joint_range_rad` during the excitation.
fn check_motion(
    robot: &RobotParams,
    recording: &Recording,
    phases: &PhaseTable,
    options: &CalibrationOptions,
) -> Result<(), CalibrationError> {
    let ranges = joint_ranges(robot, &recording.encoders, phases, Phase::Excitation);
    match ranges.iter().position(|r| *r < options.min_joint_range_rad) {
        Some(j) => Err(CalibrationError::TooLittleMotion {
            joint: j + 1,
            range_rad: ranges[j],
            needed_rad: options.min_joint_range_rad,
        }),
        None => Ok(()),
    }
}

fn session_stats(
    recording: &Recording,
    robot: &RobotParams,
) -> Result<FrameStats, CalibrationError> {
    Ok(measured_frames(&recording.tracker, &robot.markers.base_to_robot)?.1)
}

/// The longest run of consecutive homing frames at rest (same counts).
fn homing_dwell<'a>(homing: &[&'a Observation]) -> Vec<&'a Observation> {
    let mut best: Vec<&Observation> = Vec::new();
    let mut run: Vec<&Observation> = Vec::new();
    for obs in homing {
        let at_rest = obs.count_rates.iter().all(|r| r.abs() < DWELL_RATE);
        let same = run.first().is_none_or(|first| {
            first
                .counts
                .iter()
                .zip(&obs.counts)
                .all(|(a, b)| (a - b).abs() < 1.0)
        });
        if !(at_rest && same) {
            if run.len() >= best.len() {
                best = std::mem::take(&mut run);
            }
            run.clear();
        }
        if at_rest {
            run.push(obs);
        }
    }
    if run.len() >= best.len() {
        best = run;
    }
    best
}

/// The nominal model with the offsets homing gives: `θ_off = home_stops − GR·θ_enc(dwell)`.
fn nominal_model(robot: &RobotParams, dwell: &[&Observation], latency_s: f64) -> BiopsyModel {
    let motor: Vec<[f64; 5]> = dwell
        .iter()
        .map(|o| robot.motor_angles_fractional(&o.counts))
        .collect();
    let offsets = std::array::from_fn(|j| {
        let mut m: Vec<f64> = motor.iter().map(|v| v[j]).collect();
        robot.joints.home_stops[j] - robot.joints.gear_ratio[j] * median(&mut m)
    });
    let mut robot = robot.clone();
    robot.joints.offset = Some(offsets);
    robot.calibration = None;
    BiopsyModel { robot, latency_s }
}

fn validation_report(fit: &JointFit<BiopsyModel>, holds: &[Hold]) -> ValidationReport {
    let sphere = tip_sphere_error(&fit.model, holds);
    let cross = cross_validated(fit, TIP);
    let predicted: Vec<f64> = holds
        .iter()
        .filter_map(|h| {
            propagated_std(fit, |model| {
                Some(predict(model, &h.observation).ok()?.pose.tip.coords)
            })
        })
        .collect();
    let std = ErrorSummary::of(&predicted);
    let (source, tip_error) = match sphere {
        Some(error) => ("validation_tip_sphere", Some(error)),
        None => ("cross_validated_tip_phase", cross),
    };
    let tip_reading_noise_mm = fit.noise.of(TIP).position_covariance.trace().sqrt();
    ValidationReport {
        tip_error_source: source.into(),
        tip_error,
        cross_validated_tip: cross,
        tip_reading_noise_mm,
        cross_validated_excess_mm: cross.map(|c| {
            (c.rms_mm.powi(2) - tip_reading_noise_mm.powi(2))
                .max(0.0)
                .sqrt()
        }),
        predicted_tip_std: std,
        holds: holds.len(),
        method: format!(
            "The validation phase is never fitted. tip_error: {}. Per model, \
             validation_marker_tip compares the tip computed from each validation hold's mean \
             marker poses (IK with the calibrated mountings) with the tip predicted from its \
             encoder counts; it checks everything but the needle length. predicted_tip_std \
             propagates the parameter covariance to the tip at the holds.",
            if sphere.is_some() {
                "the tip sphere at the validation holds against the predicted tip"
            } else {
                "the recording has no tip data in its validation phase, so this is a \
                 cross-validated estimate: contiguous folds of the tip phase are left out in \
                 turn, the joint solution is updated without them (one Gauss-Newton step) and \
                 their tip readings predicted; it includes the tracker noise of the readings"
            }
        ),
    }
}

/// Writes the outputs of `calibration` into `dir` (created if needed): `params.toml`,
/// `report.json`, `report.html` and `validation_predictions.csv`, each atomically.
pub fn write_outputs(calibration: &Calibration, dir: &Path) -> Result<(), OutputError> {
    write_files(
        &calibration.params.to_toml_string(),
        &calibration.report,
        &calibration.predictions,
        dir,
    )
}
