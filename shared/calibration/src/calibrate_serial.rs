//! The serial-arm pipeline on a poses-v1 recording: set-up frames and target mountings on
//! the nominal geometry, then the minimal geometric error set, then the residual loop by
//! effect families (periodic joint errors, gravity compliance, thermal expansion, drift),
//! each step measured on the fitted poses and on poses held out at random. And the
//! evaluation of calibrated parameters on another recording (`sabr evaluate`).

use std::path::Path;
use std::time::Instant;

use sabr_recording::poses::PosesRecording;

use crate::discovery::families::select_families;
use crate::fit::joint_fit::{joint_fit, JointFit};
use crate::fit::pruning::minimal_layout;
use crate::model::serial::params_file::SerialParamsFile;
use crate::model::serial::{
    covered_ranges, ArmData, PoseObservation, PoseSet, SerialArm, SerialError,
};
use crate::model::{ParamLayout, RobotModel};
use crate::report::output::write_atomically;
use crate::report::serial::{
    html, ErrorStats, FamilyReport, JointScatter, SerialReport, StepReport,
};

/// Options of a serial-arm calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialOptions {
    /// Fraction of the poses held out at random (0 fits all).
    pub holdout: f64,
    /// Seed of the held-out draw and of the loop's folds.
    pub seed: u64,
    /// Whether pose targets are fitted with their orientation.
    pub use_orientation: bool,
}

impl Default for SerialOptions {
    fn default() -> Self {
        SerialOptions {
            holdout: 0.2,
            seed: 1,
            use_orientation: false,
        }
    }
}

/// A finished serial-arm calibration.
#[derive(Debug, Clone)]
pub struct SerialCalibration {
    /// The final arm.
    pub arm: SerialArm,
    /// The parameters after each step, labelled as the report's steps.
    pub step_params: Vec<(String, SerialParamsFile)>,
    /// The report.
    pub report: SerialReport,
    /// Residual scatters per joint (held-out poses, or fitted ones when none are held out).
    pub scatters: Vec<JointScatter>,
}

/// Whether pose `index` is held out: a hash of the index and seed below `fraction`.
fn held_out(index: usize, seed: u64, fraction: f64) -> bool {
    let mut z = (index as u64) ^ seed.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 33)).wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    z = (z ^ (z >> 33)).wrapping_mul(0xC4CE_B9FE_1A85_EC53);
    z ^= z >> 33;
    (z as f64 / u64::MAX as f64) < fraction
}

fn stats(arm: &SerialArm, observations: &[PoseObservation]) -> Option<ErrorStats> {
    (!observations.is_empty()).then(|| ErrorStats::of(&arm.position_errors(observations)))
}

/// Fits the set-up frames only (everything else as in `arm`) on `observations`.
pub fn fit_setups(
    arm: &SerialArm,
    observations: &[PoseObservation],
) -> Result<JointFit<SerialArm>, SerialError> {
    let start = arm.folded();
    let layout = ParamLayout::new(start.setup_layout());
    Ok(joint_fit(
        &PoseSet(observations.to_vec()),
        &start,
        &start.start_noise(),
        layout,
    )?)
}

/// Calibrates the arm of `recording`.
pub fn calibrate_serial(
    recording: &PosesRecording,
    options: &SerialOptions,
) -> Result<SerialCalibration, SerialError> {
    let started = Instant::now();
    let data = ArmData::from_recording(recording)?;
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for (k, obs) in data.observations.iter().enumerate() {
        if held_out(k, options.seed, options.holdout) {
            test.push(obs.clone());
        } else {
            train.push(obs.clone());
        }
    }
    let mut nominal = SerialArm::nominal(&data, options.use_orientation)?;
    nominal.covered = covered_ranges(nominal.tree.variables().len(), &train);
    let noise = nominal.start_noise();
    let set = PoseSet(train.clone());
    let mut frames = nominal.setup_layout();
    frames.extend(nominal.mounting_layout());
    let nominal_fit = joint_fit(&set, &nominal, &noise, ParamLayout::new(frames))?;

    let start = nominal_fit.model.folded();
    let mut full = start.setup_layout();
    full.extend(start.mounting_layout());
    full.extend(start.error_layout());
    let (layout, dropped) =
        minimal_layout(&start, &train, &nominal_fit.noise, &ParamLayout::new(full));
    let geometric = joint_fit(&set, &start, &nominal_fit.noise, layout)?;
    let selection = select_families(&geometric, options.seed);

    let step = |label: &str, arm: &SerialArm, parameters: usize| StepReport {
        model: label.to_string(),
        fit: ErrorStats::of(&arm.position_errors(&train)),
        held_out: stats(arm, &test),
        parameters,
    };
    let mut steps = vec![
        step("nominal", &nominal_fit.model, nominal_fit.layout.len()),
        step("geometric", &geometric.model, geometric.layout.len()),
    ];
    let mut step_params = vec![
        (
            "nominal".to_string(),
            SerialParamsFile::of(&nominal_fit.model),
        ),
        (
            "geometric".to_string(),
            SerialParamsFile::of(&geometric.model),
        ),
    ];
    let mut effects = Vec::new();
    let mut parameters = geometric.layout.len();
    for family in &selection.steps {
        let label = format!("+ {}", family.label);
        let before = steps.last().and_then(|s| s.held_out).map(|s| s.rms_mm);
        parameters += family
            .candidates
            .iter()
            .map(|(c, _)| c.dim())
            .sum::<usize>();
        let report = step(&label, &family.model, parameters);
        let after = report.held_out.map(|s| s.rms_mm);
        let kind = family
            .joint
            .map_or(sabr_model::tree::JointType::Revolute, |j| {
                family.model.tree.variables()[j].kind
            });
        effects.push(FamilyReport {
            label: family.label.clone(),
            class: family.class.to_string(),
            ridge: family.ridge,
            cross_validated: family.held_out,
            parameters: family
                .candidates
                .iter()
                .flat_map(|(c, values)| {
                    let name = family.model.candidate_info(*c).label;
                    c.fields()
                        .iter()
                        .enumerate()
                        .map(|(k, f)| {
                            (
                                format!("{name}.{f}"),
                                values[k],
                                c.unit(kind, k).to_string(),
                            )
                        })
                        .collect::<Vec<_>>()
                })
                .collect(),
            held_out_rms_mm: before.zip(after).map(|(a, b)| [a, b]),
        });
        steps.push(report);
        step_params.push((label, SerialParamsFile::of(&family.model)));
    }
    let arm = selection
        .steps
        .last()
        .map_or_else(|| geometric.model.clone(), |s| s.model.clone());
    let shown = if test.is_empty() { &train } else { &test };
    let scatters = arm
        .tree
        .variables()
        .iter()
        .enumerate()
        .map(|(v, variable)| JointScatter {
            joint: variable.name.clone(),
            series: [("geometric", &geometric.model), ("final", &arm)]
                .iter()
                .map(|(label, model)| {
                    let errors = model.position_errors(shown);
                    let mut k = 0;
                    let mut points = Vec::new();
                    for obs in shown {
                        for _ in &obs.measured {
                            points.push((obs.joints[v], errors[k]));
                            k += 1;
                        }
                    }
                    (label.to_string(), points)
                })
                .collect(),
        })
        .collect();
    let report = SerialReport {
        recording: recording.dir.display().to_string(),
        robot: arm.tree.name().to_string(),
        poses: [train.len(), test.len()],
        use_orientation: options.use_orientation,
        steps,
        effects,
        rejected: selection.rejected.clone(),
        dropped_parameters: dropped,
        fixed_parameters: geometric.fixed.iter().map(|f| f.name.clone()).collect(),
        condition_number: geometric.analysis.condition_number,
        periodograms_before: selection.periodograms_before.clone(),
        periodograms_after: selection.periodograms_after.clone(),
        run_time_s: started.elapsed().as_secs_f64(),
    };
    Ok(SerialCalibration {
        arm,
        step_params,
        report,
        scatters,
    })
}

/// Writes `params.json` (the final parameters), `params-<k>.json` for every step,
/// `report.json` and `report.html` to `dir` (created if needed).
pub fn write_serial_outputs(
    calibration: &SerialCalibration,
    dir: &Path,
) -> Result<Vec<String>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: cannot create: {e}", dir.display()))?;
    let mut written = Vec::new();
    let mut write = |name: String, text: String| -> Result<(), String> {
        write_atomically(&dir.join(&name), text.as_bytes()).map_err(|e| e.to_string())?;
        written.push(name);
        Ok(())
    };
    write(
        "params.json".into(),
        SerialParamsFile::of(&calibration.arm).to_json(),
    )?;
    for (k, (_, params)) in calibration.step_params.iter().enumerate() {
        write(format!("params-{k}.json"), params.to_json())?;
    }
    write(
        "report.json".into(),
        serde_json::to_string_pretty(&calibration.report).map_err(|e| e.to_string())?,
    )?;
    write(
        "report.html".into(),
        html(&calibration.report, &calibration.scatters)?,
    )?;
    Ok(written)
}

/// The position errors of the parameters `params` (read from `path`) on `recording`;
/// with `refit_setup`, the set-up frames are registered and fitted again first.
pub fn evaluate_serial(
    recording: &PosesRecording,
    params: &SerialParamsFile,
    path: &Path,
    refit_setup: bool,
) -> Result<ErrorStats, SerialError> {
    let data = ArmData::from_recording(recording)?;
    let mut arm = SerialArm::nominal(&data, params.use_orientation)?;
    params.apply(path, &mut arm, refit_setup)?;
    if refit_setup {
        for setup in 0..arm.setups.len() {
            arm.register_setup(&data, setup)?;
        }
        arm = fit_setups(&arm, &data.observations)?.model;
    }
    Ok(ErrorStats::of(&arm.position_errors(&data.observations)))
}
