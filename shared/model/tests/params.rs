//! Parameter files: robot.toml parsing, params.toml round trip, malformed files.

use nalgebra::{Isometry3, Vector3};
use proptest::prelude::*;
use sabr_model::effects::Link;
use sabr_model::params::CalibrationInfo;
use sabr_model::{Effect, ParamsError, RobotParams};

/// The `robot.toml` example of docs/robot-model.md §7, verbatim.
const ROBOT_TOML: &str = r#"format = 1
[geometry]          # mm
l_f = 50.0
l_fe = 20.0
l_b = 50.0
l_be = 20.0
d_offset = 20.0
l_n = 180.0
front_base_translation = [0.0, 0.0, 100.0]   # T_Bb_Bf
front_base_rotation = [0.0, 0.0, 0.0]        # rotation vector, rad
[joints]
counts_per_rev = [2000, 2000, 4000, 2000, 2000]
gear_ratio = [0.1, 0.1, 0.05, 0.1, 0.1]
home_stops = [-2.2, -0.9, -0.2, -2.55, -0.75]  # rad, nominal joint angles at the stops
[markers]            # rotation vectors (rad) and translations (mm)
base_to_robot_translation = [80.0, -40.0, 50.0]   # T_M_Bb
base_to_robot_rotation = [0.0, 0.0, 0.0]
front_mount_translation = [0.0, 0.0, 15.0]        # nominal T_Ef_Tf
front_mount_rotation = [0.0, 0.0, 0.0]
back_mount_translation = [0.0, 0.0, -15.0]        # nominal T_Eb_Tb
back_mount_rotation = [0.0, 0.0, 0.0]
[tracker]
rate_hz = 20.0
"#;

#[test]
fn the_contract_robot_toml_is_the_nominal_model() {
    assert_eq!(
        RobotParams::from_toml_str(ROBOT_TOML).unwrap(),
        RobotParams::nominal()
    );
}

fn calibrated() -> RobotParams {
    let mut params = RobotParams::nominal();
    params.geometry.front_base = Isometry3::new(
        Vector3::new(0.31, -0.27, 100.43),
        Vector3::new(0.0123456789, -0.00987654321, 0.0),
    );
    params.geometry.l_n = 180.123456789;
    params.joints.gear_ratio[2] = 0.0501234567891;
    params.joints.offset = Some([-2.2345, -0.91234, -0.2001, -2.5512345678, -0.751]);
    params.markers.front_mount = Isometry3::new(
        Vector3::new(1.5, -2.25, 15.125),
        Vector3::new(0.03, 0.02, -0.05),
    );
    params.markers.back_mount = Isometry3::new(
        Vector3::new(-0.5, 0.75, -14.5),
        Vector3::new(-0.041, 0.013, 0.029),
    );
    params.effects = vec![
        Effect::TransmissionRipple {
            joint: 2,
            harmonic: 1.0,
            amplitude: 0.0007,
            phase: 0.3,
        },
        Effect::Backlash {
            joint: 0,
            width: 0.002,
        },
        Effect::LinkLength {
            link: Link::LBe,
            delta: 0.15,
        },
        Effect::JointCompliance {
            joint: 3,
            gain: -0.001,
        },
    ];
    let mut extra = std::collections::BTreeMap::new();
    extra.insert("rms_mm".to_owned(), toml::Value::Float(0.2345));
    params.calibration = Some(CalibrationInfo {
        latency_ms: Some(37.5),
        source: Some("recordings/2024-05-01".into()),
        extra,
    });
    params
}

#[test]
fn a_calibrated_model_round_trips_through_toml() {
    let params = calibrated();
    let text = params.to_toml_string();
    println!("{text}");
    let read = RobotParams::from_toml_str(&text).unwrap();
    assert_eq!(read, params);
    assert_eq!(read.to_toml_string(), text);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// A pose built from a rotation vector with components within ±1 rad (as files and
    /// calibrators build them: mountings are off by a few degrees) round-trips bit for bit.
    #[test]
    fn poses_from_rotation_vectors_round_trip_exactly(
        v in prop::array::uniform3(-1.0f64..1.0),
        t in prop::array::uniform3(-500.0f64..500.0),
    ) {

        let mut params = RobotParams::nominal();
        params.geometry.front_base = Isometry3::new(Vector3::from(t), Vector3::from(v));
        let read = RobotParams::from_toml_str(&params.to_toml_string()).unwrap();
        prop_assert_eq!(read, params);
    }

    /// Any other unit quaternion comes back within 1 ulp (the rotation-vector form cannot
    /// hold every quaternion), and from then on round-trips exactly.
    #[test]
    fn any_rotation_round_trips_to_within_an_ulp(w in prop::array::uniform4(-1.0f64..1.0)) {
        let quaternion = nalgebra::Quaternion::new(w[0], w[1], w[2], w[3]);
        prop_assume!(quaternion.norm() > 0.1);
        let mut params = RobotParams::nominal();
        params.markers.back_mount.rotation = nalgebra::UnitQuaternion::from_quaternion(quaternion);
        let once = RobotParams::from_toml_str(&params.to_toml_string()).unwrap();
        let angle = once.markers.back_mount.rotation.angle_to(&params.markers.back_mount.rotation);
        prop_assert!(angle < 1e-7, "rotation changed by {} rad", angle);
        let twice = RobotParams::from_toml_str(&once.to_toml_string()).unwrap();
        prop_assert_eq!(twice, once);
    }
}

/// Parses `text` and returns the error message; panics if it parses.
fn error_of(text: &str) -> (ParamsError, String) {
    let error = RobotParams::from_toml_str(text).expect_err("the file should be rejected");
    let message = error.to_string();
    (error, message)
}

#[test]
fn bad_syntax_is_reported_with_its_line() {
    let text = ROBOT_TOML.replace("l_b = 50.0", "l_b = 50.0.0");
    let (error, message) = error_of(&text);
    println!("{message}");
    assert!(matches!(error, ParamsError::Syntax { .. }));
    assert!(message.contains("line 5"), "{message}");
}

#[test]
fn a_missing_field_is_named() {
    let text = ROBOT_TOML.replace("l_n = 180.0\n", "");
    let (error, message) = error_of(&text);
    println!("{message}");
    assert!(matches!(error, ParamsError::Syntax { .. }));
    assert!(message.contains("missing field `l_n`"), "{message}");
}

#[test]
fn a_wrong_array_length_is_reported_with_its_line() {
    let text = ROBOT_TOML.replace("[0.1, 0.1, 0.05, 0.1, 0.1]", "[0.1, 0.1, 0.05, 0.1]");
    let (_, message) = error_of(&text);
    println!("{message}");
    assert!(message.contains("line 13"), "{message}");
    assert!(message.contains("length"), "{message}");
}

#[test]
fn an_unknown_field_is_named() {
    let text = ROBOT_TOML.replace("gear_ratio =", "gear_ratios =");
    let (_, message) = error_of(&text);
    println!("{message}");
    assert!(message.contains("gear_ratios"), "{message}");
}

#[test]
fn a_negative_length_is_rejected_by_name() {
    let text = ROBOT_TOML.replace("l_fe = 20.0", "l_fe = -20.0");
    let (error, message) = error_of(&text);
    println!("{message}");
    assert!(
        matches!(&error, ParamsError::Field { field, .. } if field == "geometry.l_fe"),
        "{message}"
    );
    assert!(message.contains("positive"), "{message}");
}

#[test]
fn invalid_values_are_rejected_by_name() {
    let cases = [
        ("format = 1", "format = 2", "format"),
        ("rate_hz = 20.0", "rate_hz = nan", "tracker.rate_hz"),
        (
            "[0.1, 0.1, 0.05, 0.1, 0.1]",
            "[0.1, 0.0, 0.05, 0.1, 0.1]",
            "joints.gear_ratio[1]",
        ),
        (
            "[2000, 2000, 4000, 2000, 2000]",
            "[2000, 2000, 0, 2000, 2000]",
            "joints.counts_per_rev[2]",
        ),
        ("-0.2, -2.55", "-0.2, inf", "joints.home_stops[3]"),
        (
            "[0.0, 0.0, 15.0]",
            "[0.0, nan, 15.0]",
            "markers.front_mount_translation[1]",
        ),
    ];
    for (from, to, field_name) in cases {
        let (error, message) = error_of(&ROBOT_TOML.replacen(from, to, 1));
        println!("{message}");
        assert!(
            matches!(&error, ParamsError::Field { field, .. } if field == field_name),
            "{to}: {message}"
        );
    }
}

#[test]
fn invalid_effects_are_rejected() {
    let cases = [
        (
            "kind = \"backlash\"\njoint = 5\nwidth = 0.01",
            "joint index 5",
        ),
        ("kind = \"backlash\"\njoint = 1\nwidth = -0.01", "negative"),
        ("kind = \"joint_compliance\"\njoint = 1\ngain = nan", "gain"),
        (
            "kind = \"link_length\"\nlink = \"l_fe\"\ndelta = -25.0",
            "l_fe",
        ),
        ("kind = \"wobble\"\njoint = 1", "wobble"),
        (
            "kind = \"backlash\"\njoint = 1\nwidth = 0.01\nspeed = 2.0",
            "speed",
        ),
    ];
    for (effect, expected) in cases {
        let text = format!("{ROBOT_TOML}\n[[effects]]\n{effect}\n");
        let (_, message) = error_of(&text);
        println!("{message}");
        assert!(message.contains(expected), "{effect}: {message}");
    }
}

#[test]
fn offsets_are_required_for_counts() {
    let params = RobotParams::nominal();
    let motion = sabr_model::JointMotion::default();
    let error = params.joints_from_counts(&[0; 5], &motion).unwrap_err();
    assert!(error.to_string().contains("joint_offset"), "{error}");
    assert!(params.counts_from_joints(&[0.0; 5], &motion).is_err());
}

#[test]
fn counts_and_joints_invert_each_other_with_effects() {
    let params = calibrated();
    let motion = sabr_model::JointMotion {
        direction: [1.0, -1.0, 0.0, 1.0, -1.0],
        ..sabr_model::JointMotion::default()
    };
    let q = [-2.3, -0.8, 0.05, -2.7, -0.6];
    let counts = params.counts_from_joints(&q, &motion).unwrap();
    let back = params
        .joints_from_fractional_counts(&counts, &motion)
        .unwrap();
    for (a, b) in back.iter().zip(q) {
        assert!((a - b).abs() < 1e-12, "{back:?} vs {q:?}");
    }
    let integer_counts = counts.map(|c| c.round() as i64);
    let from_integers = params.joints_from_counts(&integer_counts, &motion).unwrap();
    let expected = params
        .joints_from_fractional_counts(&integer_counts.map(|c| c as f64), &motion)
        .unwrap();
    assert_eq!(from_integers, expected);
}
