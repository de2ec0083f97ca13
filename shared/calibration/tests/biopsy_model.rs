//! The biopsy model through the boundary: Levenberg–Marquardt recovers every paper parameter
//! from exact synthetic data, and its channel Jacobian (the model's override) matches both
//! central differences of the residuals and the boundary's default forward differences.

use nalgebra::Vector3;
use sabr_calibration::data::phases::Phase;
use sabr_calibration::data::session::Observation;
use sabr_calibration::fit::identifiability::analyse;
use sabr_calibration::fit::solve::solve;
use sabr_calibration::math::se3;
use sabr_calibration::model::biopsy::noise::vicra_default;
use sabr_calibration::model::biopsy::params::{paper_layout, EffectParam, ParamId};
use sabr_calibration::model::biopsy::predict::predict;
use sabr_calibration::model::biopsy::BiopsyModel;
use sabr_calibration::model::{blocks_of, Problem};
use sabr_model::{JointMotion, RobotParams};

/// Joints of the home pose of docs/robot-model.md §3 (rad).
const HOME: [f64; 5] = [-2.368404, -0.777628, 0.0, -2.685073, -0.601543];

/// A perturbed "true" model and noise-free observations of it along a multi-sine
/// trajectory about the home pose; every third observation sees the tip (tip phase).
fn synthetic(count: usize) -> (BiopsyModel, BiopsyModel, Vec<Observation>) {
    let mut nominal = RobotParams::nominal();
    nominal.joints.offset = Some(HOME);
    let start = BiopsyModel {
        robot: nominal,
        latency_s: 0.0,
    };
    let mut truth = start.clone();
    let robot = &mut truth.robot;
    robot.joints.gear_ratio = [0.101, 0.0985, 0.0504, 0.1012, 0.0991];
    robot.joints.offset = Some([
        HOME[0] + 0.01,
        HOME[1] - 0.02,
        0.015,
        HOME[3] + 0.012,
        HOME[4] - 0.008,
    ]);
    robot.geometry.front_base = se3::isometry(
        Vector3::new(0.8, -0.5, 100.9),
        Vector3::new(0.006, -0.004, 0.0),
    );
    robot.geometry.l_n = 181.7;
    robot.markers.front_mount = se3::isometry(
        Vector3::new(0.6, -0.4, 15.8),
        Vector3::new(0.02, -0.01, 0.03),
    );
    robot.markers.back_mount = se3::isometry(
        Vector3::new(-0.7, 0.3, -14.4),
        Vector3::new(-0.015, 0.02, -0.01),
    );
    let offset = truth.robot.joints.offset.unwrap();
    let observations = (0..count)
        .map(|k| {
            let t = k as f64 * 0.37;
            let q: [f64; 5] = std::array::from_fn(|j| {
                HOME[j]
                    + 0.12 * (t * (1.0 + 0.31 * j as f64)).sin() * if j == 2 { 0.8 } else { 1.0 }
            });
            let motor: [f64; 5] =
                std::array::from_fn(|j| (q[j] - offset[j]) / truth.robot.joints.gear_ratio[j]);
            let counts = truth.robot.counts_from_motor_angles(&motor);
            let mut obs = Observation {
                frame: k as u32,
                exposure_ns: k as f64 * 5e7,
                latency_s: 0.0,
                phase: if k % 3 == 0 {
                    Phase::Tip
                } else {
                    Phase::Excitation
                },
                counts,
                count_rates: [0.0; 5],
                motion: JointMotion::default(),
                front: None,
                back: None,
                tip: None,
            };
            let p = predict(&truth, &obs).unwrap();
            obs.front = Some(p.front_marker);
            obs.back = Some(p.back_marker);
            obs.tip = (k % 3 == 0).then_some(p.pose.tip);
            obs
        })
        .collect();
    (truth, start, observations)
}

#[test]
fn levenberg_marquardt_recovers_every_paper_parameter_from_exact_data() {
    let (truth, start, observations) = synthetic(90);
    let layout = paper_layout().without(ParamId::Latency);
    let (blocks, rows) = blocks_of(&start, &observations);
    let noise = vicra_default();
    let weights = vec![1.0; blocks.len()];
    let problem = Problem {
        layout: &layout,
        observations: &observations,
        blocks: &blocks,
        rows,
        noise: &noise,
        weights: &weights,
    };
    let solution = solve(problem, &start, "test").unwrap();
    let found = layout.values(&solution.model);
    let expected = layout.values(&truth);
    for (k, id) in layout.ids.iter().enumerate() {
        assert!(
            (found[k] - expected[k]).abs() < 1e-6,
            "{}: {} vs {}",
            id.name(),
            found[k],
            expected[k]
        );
    }
    let analysis = analyse(
        &layout.names(&start),
        &problem.jacobian(&solution.model),
        &problem.residuals(&solution.model).0,
    );
    assert_eq!(analysis.rank, layout.len());
    assert!(analysis.near_null.is_empty());
}

#[test]
fn jacobian_matches_central_differences_of_the_residuals() {
    let (_, start, observations) = synthetic(12);
    let layout = paper_layout();
    let (blocks, rows) = blocks_of(&start, &observations);
    let noise = vicra_default();
    let weights: Vec<f64> = (0..blocks.len())
        .map(|i| 0.5 + (i % 2) as f64 * 0.5)
        .collect();
    let mut observations = observations;
    for (k, obs) in observations.iter_mut().enumerate() {
        obs.count_rates = [300.0 * (k as f64).cos(), 200.0, -150.0, 90.0, -40.0];
    }
    let problem = Problem {
        layout: &layout,
        observations: &observations,
        blocks: &blocks,
        rows,
        noise: &noise,
        weights: &weights,
    };
    let jacobian = problem.jacobian(&start);
    let x = layout.values(&start);
    for (col, id) in layout.ids.iter().enumerate() {
        let h = id.step() * 10.0;
        let at = |delta: f64| {
            let mut model = start.clone();
            let mut shifted = x.clone();
            shifted[col] += delta;
            layout.apply(&mut model, &shifted);
            problem.residuals(&model).0
        };
        let numeric = (at(h) - at(-h)) / (2.0 * h);
        let error = (&numeric - jacobian.column(col)).amax();
        let scale = numeric.amax().max(1.0);
        assert!(
            error < 1e-3 * scale,
            "{}: error {error} of {scale}",
            id.name()
        );
    }
    let latency = analyse(
        &layout.names(&start),
        &jacobian,
        &problem.residuals(&start).0,
    );
    assert!(
        latency.near_null.is_empty(),
        "moving joints make the latency identifiable"
    );
}

/// The biopsy model's channel Jacobian (its override) agrees with the boundary's default
/// forward differences of the batch residuals.
#[test]
fn the_channel_jacobian_agrees_with_the_default_finite_differences() {
    let (_, mut start, mut observations) = synthetic(12);
    start.robot.effects.push(sabr_model::Effect::LinkLength {
        link: sabr_model::Link::LB,
        delta: 0.3,
    });
    for (k, obs) in observations.iter_mut().enumerate() {
        obs.count_rates = [300.0 * (k as f64).cos(), 200.0, -150.0, 90.0, -40.0];
    }
    let mut layout = paper_layout();
    layout.ids.push(ParamId::Effect(EffectParam {
        index: 0,
        field: sabr_model::EffectField::Delta,
    }));
    let (blocks, rows) = blocks_of(&start, &observations);
    let noise = vicra_default();
    let weights = vec![0.7; blocks.len()];
    let problem = Problem {
        layout: &layout,
        observations: &observations,
        blocks: &blocks,
        rows,
        noise: &noise,
        weights: &weights,
    };
    let channel = problem.jacobian(&start);
    let default = problem.finite_difference_jacobian(&start);
    for (col, id) in layout.ids.iter().enumerate() {
        let error = (channel.column(col) - default.column(col)).amax();
        let scale = default.column(col).amax().max(1.0);
        assert!(
            error < 1e-3 * scale,
            "{}: error {error} of {scale}",
            id.name()
        );
    }
}
