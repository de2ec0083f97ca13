//! The serial-arm calibration on simulated measurements: poses of a URDF arm computed by
//! the tree's forward kinematics with injected geometric errors (and a periodic joint
//! error), seen from an instrument placed far from the robot, with noise. The pipeline must
//! recover what was injected: held-out errors down to the noise, the periodic error named.

use std::path::Path;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sabr_calibration::calibrate_serial::{calibrate_serial, evaluate_serial, SerialOptions};
use sabr_calibration::model::serial::params_file::SerialParamsFile;
use sabr_model::KinematicTree;
use sabr_recording::poses::{
    Measured, PoseRow, PosesRecording, PosesRobot, Target, TargetMeasurement,
};

/// What is injected into a simulated arm.
struct Truth<'a> {
    errors: &'a [(&'a str, f64)],
    /// (joint variable, harmonic, sin amplitude rad).
    periodic: Option<(usize, f64, f64)>,
    setup: Isometry3<f64>,
    mounting: Vector3<f64>,
    noise_mm: f64,
}

fn robots_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../model/robots")
}

/// A poses-v1 recording of `poses` random poses of the URDF `urdf` with a point target on
/// `link`, measured under `truth`.
fn simulate(urdf: &str, link: &str, poses: usize, truth: &Truth, seed: u64) -> PosesRecording {
    let text = std::fs::read_to_string(robots_dir().join(urdf)).unwrap();
    let tree = KinematicTree::from_urdf_str(&text).unwrap();
    let mut errors = tree.nominal_errors();
    for (name, value) in truth.errors {
        let k = tree
            .error_parameters()
            .iter()
            .position(|p| p.name == *name)
            .unwrap();
        errors[k] = *value;
    }
    let link_id = tree.link_id(link).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, truth.noise_mm).unwrap();
    let mut rows = Vec::new();
    for index in 0..poses {
        let joints: Vec<f64> = tree
            .variables()
            .iter()
            .map(|v| match v.limits {
                Some(l) => {
                    let (lo, hi) = (l.lower.max(-3.0), l.upper.min(3.0));
                    rng.random_range(lo + 0.05 * (hi - lo)..hi - 0.05 * (hi - lo))
                }
                None => rng.random_range(-3.0..3.0),
            })
            .collect();
        let mut actual = joints.clone();
        if let Some((v, h, a)) = truth.periodic {
            actual[v] += a * (h * joints[v]).sin();
        }
        let state = tree.forward(&actual, &errors).unwrap();
        let p = truth.setup * (state.link_pose(link_id) * Point3::from(truth.mounting));
        rows.push(PoseRow {
            line: 0,
            setup: "placement".into(),
            sequence: "run".into(),
            index: index as u64,
            joints,
            targets: vec![Some(TargetMeasurement {
                position_mm: [
                    p.x + noise.sample(&mut rng),
                    p.y + noise.sample(&mut rng),
                    p.z + noise.sample(&mut rng),
                ],
                orientation: None,
                position_std_mm: None,
                orientation_std_rad: None,
            })],
            temperature_c: None,
        });
    }
    PosesRecording {
        dir: "simulated".into(),
        robot: PosesRobot::new(
            "robot.urdf",
            vec![Target {
                name: "prism".into(),
                link: link.into(),
                measured: Measured::Point,
                mounting_translation: Some([0.0, 0.0, 0.0]),
                mounting_rotation: None,
            }],
        ),
        urdf_text: text,
        joints: tree.variables().iter().map(|v| v.name.clone()).collect(),
        rows,
    }
}

fn far_setup() -> Isometry3<f64> {
    Isometry3::from_parts(
        nalgebra::Translation3::new(2400.0, -1300.0, 150.0),
        UnitQuaternion::from_euler_angles(0.02, -0.01, 2.3),
    )
}

#[test]
fn ur10_injected_geometric_and_periodic_errors_are_recovered() {
    let truth = Truth {
        errors: &[
            ("elbow_joint.ty", 0.6),
            ("shoulder_lift_joint.rx", 4e-4),
            ("wrist_1_joint.tz", -0.5),
            ("elbow_joint.rz", 3e-4),
        ],
        periodic: Some((2, 2.0, 3e-4)),
        setup: far_setup(),
        mounting: Vector3::new(5.0, -3.0, 110.0),
        noise_mm: 0.01,
    };
    let recording = simulate("ur10.urdf", "tool0", 1500, &truth, 7);
    let calibration = calibrate_serial(&recording, &SerialOptions::default()).unwrap();
    let steps = &calibration.report.steps;
    let held = |k: usize| steps[k].held_out.unwrap().rms_mm;
    assert_eq!(steps[0].model, "nominal");
    assert!(held(0) > 0.5, "nominal {}", held(0));
    assert!(
        held(1) < 0.5 * held(0),
        "geometric {} vs nominal {}",
        held(1),
        held(0)
    );
    let last = held(steps.len() - 1);
    assert!(
        last < 0.04,
        "final held-out RMS {last} mm, noise 0.01 mm per axis"
    );
    let periodic = calibration
        .report
        .effects
        .iter()
        .find(|e| e.label == "periodic elbow_joint")
        .unwrap_or_else(|| panic!("no periodic elbow effect: {:?}", calibration.report.effects));
    let sin2 = periodic
        .parameters
        .iter()
        .find(|(name, _, _)| name == "periodic elbow_joint ×2.sin")
        .unwrap();
    assert!((sin2.1 - 3e-4).abs() < 0.6e-4, "sin ×2 = {}", sin2.1);
    assert!(!calibration.report.dropped_parameters.is_empty());
}

#[test]
fn a_lift_arm_with_a_prismatic_joint_calibrates_from_points() {
    let truth = Truth {
        errors: &[
            ("lift_joint.tx", 1.5),
            ("shoulder_pitch_joint.tz", -0.5),
            ("elbow_joint.rx", 2e-3),
            ("lift_joint.ry", 5e-4),
        ],
        periodic: None,
        setup: far_setup(),
        mounting: Vector3::new(2.0, 1.0, -1.0),
        noise_mm: 0.01,
    };
    let recording = simulate("lift_arm.urdf", "probe_tip", 800, &truth, 11);
    let calibration = calibrate_serial(&recording, &SerialOptions::default()).unwrap();
    let steps = &calibration.report.steps;
    let nominal = steps[0].held_out.unwrap().rms_mm;
    let geometric = steps[1].held_out.unwrap().rms_mm;
    assert!(nominal > 0.3, "nominal {nominal}");
    assert!(
        geometric < 0.04,
        "geometric {geometric} mm, noise 0.01 mm per axis"
    );

    // The parameters evaluate on a fresh recording of the same arm, with the set-up
    // re-registered when the instrument moved.
    let file = SerialParamsFile::of(&calibration.arm);
    let path = Path::new("params.json");
    let again = simulate("lift_arm.urdf", "probe_tip", 200, &truth, 12);
    let same = evaluate_serial(&again, &file, path, false).unwrap();
    assert_eq!(same.count, 200);
    assert!(same.rms_mm < 0.04, "{same:?}");
    let moved = Truth {
        setup: Isometry3::translation(-500.0, 800.0, 30.0) * far_setup(),
        ..truth
    };
    let elsewhere = simulate("lift_arm.urdf", "probe_tip", 200, &moved, 13);
    let stale = evaluate_serial(&elsewhere, &file, path, false).unwrap();
    assert!(stale.rms_mm > 100.0, "{stale:?}");
    let refit = evaluate_serial(&elsewhere, &file, path, true).unwrap();
    assert!(refit.rms_mm < 0.04, "{refit:?}");
}
