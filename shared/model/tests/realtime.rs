//! The glam kinematics (`sabr_model::realtime`) against the nalgebra one: equal poses and
//! joints to 1e-9, the same refusals.

use glam::{DAffine3, DVec3};
use nalgebra::{Isometry3, Point3, Vector3};
use proptest::prelude::*;
use sabr_model::realtime::RealtimeGeometry;
use sabr_model::{forward, inverse, Geometry, KinematicsError, RobotParams, HOME_JOINTS};

/// Largest difference allowed between the two paths (mm, rad, unit vectors).
const TOLERANCE: f64 = 1e-9;

/// The nominal geometry with its front base moved and turned, link lengths changed, and each
/// joint axis tilted by `tilts` (rad).
fn geometry(tilts: [[f64; 2]; 5]) -> Geometry {
    let mut geometry = RobotParams::nominal().geometry;
    geometry.front_base = Isometry3::new(
        Vector3::new(0.4, -0.3, 100.5),
        Vector3::new(0.01, -0.015, 0.0),
    );
    geometry.l_n = 181.2;
    geometry.l_be += 0.2;
    geometry.axis_tilt = tilts;
    geometry
}

fn tilts(max_rad: f64) -> impl Strategy<Value = [[f64; 2]; 5]> {
    prop::array::uniform5(prop::array::uniform2(-max_rad..max_rad))
}

fn vector(v: DVec3) -> Vector3<f64> {
    Vector3::from(v.to_array())
}

/// Largest difference between the rotation matrices and translations of two poses.
fn pose_difference(glam: &DAffine3, nalgebra: &Isometry3<f64>) -> f64 {
    let rotation = nalgebra.rotation.to_rotation_matrix();
    let glam_rotation = nalgebra::Matrix3::from_column_slice(&glam.matrix3.to_cols_array());
    let translation = vector(glam.translation) - nalgebra.translation.vector;
    (glam_rotation - rotation.matrix())
        .amax()
        .max(translation.amax())
}

fn assert_same_forward(geometry: &Geometry, q: &[f64; 5]) -> Result<(), TestCaseError> {
    let fast = RealtimeGeometry::from(geometry).forward(q);
    let reference = forward(geometry, q);
    match (fast, reference) {
        (Ok(fast), Ok(reference)) => {
            prop_assert!((vector(fast.tip) - reference.tip.coords).amax() < TOLERANCE);
            prop_assert!(
                (vector(fast.direction) - reference.direction.into_inner()).amax() < TOLERANCE
            );
            prop_assert!(pose_difference(&fast.needle, &reference.needle) < TOLERANCE);
            prop_assert!(
                pose_difference(&fast.front_effector, &reference.front_effector) < TOLERANCE
            );
            prop_assert!(
                pose_difference(&fast.back_effector, &reference.back_effector) < TOLERANCE
            );
            let converted = fast.to_nalgebra();
            prop_assert!(
                (converted
                    .front_effector
                    .rotation
                    .angle_to(&reference.front_effector.rotation))
                    < TOLERANCE
            );
            prop_assert!(
                (converted
                    .back_effector
                    .rotation
                    .angle_to(&reference.back_effector.rotation))
                    < TOLERANCE
            );
            prop_assert!(
                (converted
                    .needle
                    .rotation
                    .angle_to(&reference.needle.rotation))
                    < TOLERANCE
            );
            prop_assert!((converted.tip - reference.tip).amax() < TOLERANCE);
        }
        (fast, reference) => prop_assert_eq!(fast.err(), reference.err()),
    }
    Ok(())
}

fn assert_same_inverse(
    geometry: &Geometry,
    tip: &Point3<f64>,
    direction: &Vector3<f64>,
) -> Result<(), TestCaseError> {
    let fast = RealtimeGeometry::from(geometry).inverse(
        DVec3::from_array(tip.coords.into()),
        DVec3::from_array((*direction).into()),
        &HOME_JOINTS,
    );
    let reference = inverse(geometry, tip, direction, &HOME_JOINTS);
    match (fast, reference) {
        (Ok(fast), Ok(reference)) => {
            for (a, b) in fast.iter().zip(&reference) {
                prop_assert!((a - b).abs() < TOLERANCE, "{:?} vs {:?}", fast, reference);
            }
        }
        (Err(fast), Err(reference)) => prop_assert_eq!(fast, reference),
        (fast, reference) => prop_assert!(false, "{:?} vs {:?}", fast, reference),
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]

    /// Tip, direction and the three poses agree for joints within ±0.2 rad of home, joint
    /// axes tilted by up to 1°.
    #[test]
    fn forward_matches_the_nalgebra_kinematics(
        delta in prop::array::uniform5(-0.2f64..0.2),
        tilts in tilts(1f64.to_radians()),
        tilted in any::<bool>(),
    ) {
        let geometry = geometry(if tilted { tilts } else { [[0.0; 2]; 5] });
        let q: [f64; 5] = std::array::from_fn(|i| HOME_JOINTS[i] + delta[i]);
        assert_same_forward(&geometry, &q)?;
    }

    /// The joints of reachable targets (FK of joints near home) agree, untilted and with
    /// joint axes tilted by up to 1° (the Newton refinement).
    #[test]
    fn inverse_matches_the_nalgebra_kinematics(
        delta in prop::array::uniform5(-0.2f64..0.2),
        tilts in tilts(1f64.to_radians()),
        tilted in any::<bool>(),
    ) {
        let geometry = geometry(if tilted { tilts } else { [[0.0; 2]; 5] });
        let q: [f64; 5] = std::array::from_fn(|i| HOME_JOINTS[i] + delta[i]);
        let pose = forward(&geometry, &q).unwrap();
        let fast = RealtimeGeometry::from(&geometry).inverse(
            DVec3::from_array(pose.tip.coords.into()),
            DVec3::from_array(pose.direction.into_inner().into()),
            &HOME_JOINTS,
        );
        prop_assert!(fast.is_ok(), "{:?}", fast);
        assert_same_inverse(&geometry, &pose.tip, &pose.direction)?;
    }

    /// Targets anywhere in a large box, any direction: both solve (to the same joints) or
    /// both refuse with the same error.
    #[test]
    fn both_refuse_the_same_targets(
        tip in prop::array::uniform3(-400.0f64..400.0),
        direction in prop::array::uniform3(-1.0f64..1.0),
        tilts in tilts(1f64.to_radians()),
        tilted in any::<bool>(),
    ) {
        let geometry = geometry(if tilted { tilts } else { [[0.0; 2]; 5] });
        assert_same_inverse(&geometry, &Point3::from(tip), &Vector3::from(direction))?;
    }
}

#[test]
fn an_unreachable_target_is_refused() {
    let realtime = RealtimeGeometry::from(&RobotParams::nominal().geometry);
    for tip in [
        DVec3::new(0.0, -90.0, 600.0),
        DVec3::new(300.0, -90.0, 180.0),
    ] {
        let result = realtime.inverse(tip, DVec3::Z, &HOME_JOINTS);
        assert!(
            matches!(result, Err(KinematicsError::Unreachable(_))),
            "{tip}: {result:?}"
        );
    }
    assert_eq!(
        realtime.inverse(DVec3::new(0.0, f64::NAN, 180.0), DVec3::Z, &HOME_JOINTS),
        Err(KinematicsError::NotFinite("tip"))
    );
}
