//! Shared helpers of the residual-loop tests (`effects_*.rs`): simulated sessions with
//! injected effects the calibrator is not told about, and tip errors against the
//! simulator's truth.

// Each test crate uses a subset of these helpers.
#![allow(dead_code)]

use sabr_calibration::data::motion::MotionTrack;
use sabr_calibration::fit::joint_fit::joint_fit;
use sabr_calibration::model::biopsy::params::paper_layout;
use sabr_calibration::report::EffectEntry;
use sabr_calibration::{calibrate, Calibration, CalibrationOptions};
use sabr_model::DIRECTION_DEAD_BAND_COUNTS;
use sabr_model::{forward, RobotParams};
use sabr_recording::Recording;
use sabr_sim::{record_session, SimConfig, Truth};

/// A session for `seed` at `scale` with the effects `specs` (the simulator's syntax), with
/// enough validation poses for a truth comparison.
pub fn config(seed: u64, scale: f64, specs: &[&str]) -> SimConfig {
    let mut config = SimConfig::new(seed);
    config.duration_scale = scale;
    config.durations.validation_poses = 60;
    config.effects = specs
        .iter()
        .map(|s| s.parse().expect("effect spec"))
        .collect();
    config
}

/// A calibrated session.
pub struct Run {
    /// The recording.
    pub recording: Recording,
    /// The simulator's truth.
    pub truth: Truth,
    /// The calibration.
    pub calibration: Calibration,
}

/// Records and calibrates a session.
pub fn run(config: &SimConfig) -> Run {
    let (recording, truth) = record_session(config).expect("simulated session");
    let calibration = calibrate(&recording, &CalibrationOptions::default()).expect("calibration");
    Run {
        recording,
        truth,
        calibration,
    }
}

/// RMS tip error (mm) of `params` against the true tip at every validation hold, with the
/// direction of motion the encoder history gives at the hold.
pub fn truth_tip_rms(params: &RobotParams, run: &Run) -> f64 {
    let rows = &run.recording.encoders;
    let times: Vec<i64> = rows.iter().map(|r| r.t_ns).collect();
    let counts: Vec<[i64; 5]> = rows.iter().map(|r| r.counts).collect();
    let motion = MotionTrack::new(&times, &counts, DIRECTION_DEAD_BAND_COUNTS);
    let geometry = params.effective_geometry();
    let holds = &run.truth.validation;
    let sum: f64 = holds
        .iter()
        .map(|hold| {
            let middle = 0.5 * (hold.t_start_ns + hold.t_end_ns) as f64;
            let q = params
                .joints_from_counts(&hold.counts, &motion.at(middle))
                .expect("offsets");
            (forward(&geometry, &q).expect("reachable").tip - hold.tip).norm_squared()
        })
        .sum();
    (sum / holds.len() as f64).sqrt()
}

/// The paper model fitted to the same data without the residual loop (the joint fit of the
/// paper's parameters from the stepwise result).
pub fn paper_model(run: &Run) -> RobotParams {
    let calibration = &run.calibration;
    let fit = joint_fit(
        &calibration.session,
        &calibration.stepwise,
        &calibration.fit.noise,
        paper_layout(),
    )
    .expect("paper fit");
    fit.model.robot
}

/// What a test expects to be found: class, joint (1..5) or link name.
#[derive(Debug, Clone, PartialEq)]
pub struct Named {
    /// Effect class, e.g. `backlash`.
    pub class: String,
    /// Joint 1..5.
    pub joint: Option<usize>,
    /// Link name.
    pub link: Option<String>,
}

impl Named {
    /// An effect of joint `joint` (1..5).
    pub fn joint(class: &str, joint: usize) -> Self {
        Self {
            class: class.into(),
            joint: Some(joint),
            link: None,
        }
    }

    /// A link-length error of `link`.
    pub fn link(link: &str) -> Self {
        Self {
            class: "link_length".into(),
            joint: None,
            link: Some(link.into()),
        }
    }

    fn of(report: &EffectEntry) -> Self {
        Self {
            class: report.name.clone(),
            joint: report.joint,
            link: report.link.clone(),
        }
    }
}

/// Errors (mm, truth) of one seed with and without the injected effects.
#[derive(Debug, Clone, Copy)]
pub struct Figures {
    /// The calibrated model (with the effects found) on the recording with effects.
    pub with_loop: f64,
    /// The paper model alone on the recording with effects.
    pub paper_only: f64,
    /// The calibrated model on the same seed without effects.
    pub clean: f64,
}

impl Figures {
    /// Asserts that the paper model alone misses the 1.5× goal (so the effect matters and
    /// the test is not passed by the paper model).
    pub fn assert_paper_model_alone_fails(&self) {
        assert!(
            self.paper_only > 1.5 * self.clean,
            "the effect does not matter: {self:?}"
        );
    }
}

/// Calibrates seed `seed` at `scale` with the effects `specs`, checks that exactly the
/// effects `expected` are named, no other structure is reported, and the held-out tip error
/// is at most 1.5× the error on the same seed without the effects. Returns the run and the
/// figures.
pub fn assert_discovers(
    seed: u64,
    scale: f64,
    specs: &[&str],
    expected: &[Named],
) -> (Run, Figures) {
    let with = run(&config(seed, scale, specs));
    let report = &with.calibration.report;
    let mut named: Vec<Named> = report.effects.iter().map(Named::of).collect();
    let mut wanted = expected.to_vec();
    let key = |n: &Named| format!("{n:?}");
    named.sort_by_key(key);
    wanted.sort_by_key(key);
    assert_eq!(
        named, wanted,
        "seed {seed} {specs:?}: {}",
        report.r#final.verdict
    );
    assert!(
        report.r#final.leads.is_empty(),
        "seed {seed}: leads {:?}",
        report.r#final.leads
    );

    let clean = run(&config(seed, scale, &[]));
    assert!(
        clean.calibration.report.effects.is_empty(),
        "seed {seed}: effects found on clean data"
    );
    let figures = Figures {
        with_loop: truth_tip_rms(&with.calibration.params, &with),
        paper_only: truth_tip_rms(&paper_model(&with), &with),
        clean: truth_tip_rms(&clean.calibration.params, &clean),
    };
    eprintln!("seed {seed} {specs:?}: {figures:?}");
    assert!(
        figures.with_loop <= 1.5 * figures.clean,
        "seed {seed} {specs:?}: held-out tip error {:.4} mm vs {:.4} mm without the effect",
        figures.with_loop,
        figures.clean
    );
    (with, figures)
}

/// The fitted value and standard deviation of parameter `name` of the effect at `index`.
pub fn fitted_with_std(run: &Run, index: usize, name: &str) -> (f64, f64) {
    let parameter = run.calibration.report.effects[index]
        .parameters
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("no parameter {name}"));
    (
        parameter.value,
        parameter.std_dev.expect("a standard deviation"),
    )
}

/// Asserts that parameter `name` of the effect at `index` matches the injected `expected`
/// within 4 of its standard deviations (or 5 %), and within 25 % in any case.
pub fn assert_parameter(run: &Run, index: usize, name: &str, expected: f64) {
    let (value, std) = fitted_with_std(run, index, name);
    let error = (value - expected).abs();
    assert!(
        error <= (4.0 * std).max(0.05 * expected.abs()) && error <= 0.25 * expected.abs(),
        "{name}: fitted {value} ± {std}, injected {expected}"
    );
}

/// Asserts that each of `specs`, injected alone into seed `seed`, is absorbed: no effect is
/// claimed, no lead reported, the tracker latency is still measured within 2 ms, and the
/// held-out tip error stays within 1.5× the clean session's.
pub fn assert_absorbed(seed: u64, specs: &[&str]) {
    let clean = run(&config(seed, 0.25, &[]));
    let reference = truth_tip_rms(&clean.calibration.params, &clean);
    for spec in specs {
        let with = run(&config(seed, 0.25, &[spec]));
        let report = &with.calibration.report;
        assert!(
            report.effects.is_empty(),
            "{spec}: {}",
            report.r#final.verdict
        );
        assert!(report.r#final.leads.is_empty(), "{spec}");
        let tip = truth_tip_rms(&with.calibration.params, &with);
        eprintln!("{spec}: tip {tip:.4} mm, clean {reference:.4} mm");
        assert!(
            tip <= 1.5 * reference,
            "{spec}: {tip:.4} mm vs {reference:.4} mm"
        );
        let latency_error = report.r#final.latency_ms - with.truth.tracker.latency_ms();
        assert!(
            latency_error.abs() <= 2.0,
            "{spec}: latency off by {latency_error:.3} ms"
        );
    }
}
