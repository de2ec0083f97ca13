//! Inverse kinematics: FK(IK(target)) = target, IK(FK(q)) = q, and refusals.

use nalgebra::{Point3, Rotation3, Vector3};
use proptest::prelude::*;
use sabr_model::HOME_JOINTS;
use sabr_model::{forward, inverse, Geometry, KinematicsError, RobotParams};

fn nominal() -> Geometry {
    RobotParams::nominal().geometry
}

/// A direction within `max_tilt` (rad) of +z: tilted by `tilt` towards the azimuth `azimuth`.
fn tilted(tilt: f64, azimuth: f64) -> Vector3<f64> {
    let (s, c) = tilt.sin_cos();
    Vector3::new(s * azimuth.cos(), s * azimuth.sin(), c)
}

/// A slightly miscalibrated geometry, to exercise the rotated front base.
fn perturbed() -> Geometry {
    let mut geometry = nominal();
    geometry.front_base = nalgebra::Isometry3::new(
        Vector3::new(0.4, -0.3, 100.5),
        Vector3::new(0.01, -0.015, 0.0),
    );
    geometry.l_n = 181.2;
    geometry.l_be += 0.2;
    geometry
}

/// Outer reach (mm) of a stage with proximal link `l` and effector extension `l_e`: the
/// proximal link plus the distal vector `l + l_e·e^{−iπ/4}`.
fn outer_reach(l: f64, l_e: f64) -> f64 {
    l + (l + l_e / 2f64.sqrt()).hypot(l_e / 2f64.sqrt())
}

/// A sufficient reachability test, independent of the IK under test: the needle line meets
/// the front stage plane inside the front stage's reach, and every point within `d_offset`
/// of `p_r` is inside the back stage's reach (both with a 0.5 mm margin). Near home the
/// gimbal-plane condition always has a root on the side FK uses, so these targets are
/// reachable. (Tips 15 mm off home with 12° of tilt can leave the front stage's reach, so the
/// ±15 mm / 12° box is not all reachable.)
fn certainly_reachable(geometry: &Geometry, tip: &Point3<f64>, direction: &Vector3<f64>) -> bool {
    let p_r = tip - geometry.l_n * direction;
    let to_front = geometry.front_base.inverse();
    let origin = to_front * p_r;
    let along = to_front.rotation * direction;
    let t = -origin.z / along.z;
    let front = (origin + t * along).coords.xy().norm();
    let back = p_r.coords.norm() + geometry.d_offset;
    front < outer_reach(geometry.l_f, geometry.l_fe) - 0.5
        && back < outer_reach(geometry.l_b, geometry.l_be) - 0.5
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 10_000,
        max_global_rejects: 100_000,
        ..ProptestConfig::default()
    })]

    /// FK(IK(target)) = target to 1e-6 mm for reachable tips within ±15 mm of home and
    /// directions within 12° of +z.
    #[test]
    fn forward_of_inverse_is_the_target(
        offset in prop::array::uniform3(-15.0f64..15.0),
        tilt in 0.0f64..12f64.to_radians(),
        azimuth in -std::f64::consts::PI..std::f64::consts::PI,
        perturb in any::<bool>(),
    ) {
        let geometry = if perturb { perturbed() } else { nominal() };
        let tip = Point3::new(offset[0], -90.0 + offset[1], 180.0 + offset[2]);
        let direction = tilted(tilt, azimuth);
        prop_assume!(certainly_reachable(&geometry, &tip, &direction));
        let q = inverse(&geometry, &tip, &direction, &HOME_JOINTS);
        prop_assert!(q.is_ok(), "{:?} {:?}: {:?}", tip, direction, q);
        let q = q.unwrap();
        let pose = forward(&geometry, &q).unwrap();
        prop_assert!((pose.tip - tip).norm() < 1e-6, "tip {} vs {}", pose.tip, tip);
        prop_assert!((pose.direction.into_inner() - direction).norm() < 1e-8);
        for (value, home) in q.iter().zip(HOME_JOINTS) {
            prop_assert!((value - home).abs() <= std::f64::consts::PI);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]

    /// IK(FK(q)) = q for joints within ±0.2 rad of home.
    #[test]
    fn inverse_of_forward_is_the_joints(delta in prop::array::uniform5(-0.2f64..0.2)) {
        let geometry = nominal();
        let q: [f64; 5] = std::array::from_fn(|i| HOME_JOINTS[i] + delta[i]);
        let pose = forward(&geometry, &q).unwrap();
        let solved = inverse(&geometry, &pose.tip, &pose.direction, &HOME_JOINTS).unwrap();
        for (a, b) in solved.iter().zip(q) {
            prop_assert!((a - b).abs() < 1e-8, "{:?} vs {:?}", solved, q);
        }
    }

    /// Unreachable targets (anywhere in a large box, any direction) are refused or solved
    /// exactly; the answer is never NaN and never a panic.
    #[test]
    fn every_target_is_solved_exactly_or_refused(
        tip in prop::array::uniform3(-400.0f64..400.0),
        direction in prop::array::uniform3(-1.0f64..1.0),
    ) {
        let geometry = nominal();
        let tip = Point3::from(tip);
        let direction = Vector3::from(direction);
        match inverse(&geometry, &tip, &direction, &HOME_JOINTS) {
            Ok(q) => {
                prop_assert!(q.iter().all(|v| v.is_finite()));
                let pose = forward(&geometry, &q).unwrap();
                prop_assert!((pose.tip - tip).norm() < 1e-6);
            }
            Err(error) => prop_assert!(matches!(error, KinematicsError::Unreachable(_))),
        }
    }
}

#[test]
fn far_targets_are_unreachable() {
    let geometry = nominal();
    for tip in [
        [0.0, -90.0, 600.0],
        [300.0, -90.0, 180.0],
        [0.0, 200.0, 180.0],
    ] {
        let result = inverse(&geometry, &Point3::from(tip), &Vector3::z(), &HOME_JOINTS);
        println!("{tip:?}: {result:?}");
        assert!(
            matches!(result, Err(KinematicsError::Unreachable(_))),
            "{tip:?}: {result:?}"
        );
    }
}

#[test]
fn a_direction_89_degrees_off_is_unreachable() {
    let geometry = nominal();
    let home_tip = Point3::new(0.0, -90.0, 180.0);
    for azimuth in [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0] {
        let direction = Rotation3::from_axis_angle(&Vector3::z_axis(), azimuth)
            * tilted(89f64.to_radians(), 0.0);
        let result = inverse(&geometry, &home_tip, &direction, &HOME_JOINTS);
        println!("{azimuth}: {result:?}");
        assert!(
            matches!(result, Err(KinematicsError::Unreachable(_))),
            "{result:?}"
        );
    }
}

#[test]
fn non_finite_inputs_are_refused() {
    let geometry = nominal();
    let tip = Point3::new(0.0, -90.0, 180.0);
    let bad = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
    for value in bad {
        let bad_tip = Point3::new(0.0, value, 180.0);
        let bad_direction = Vector3::new(value, 0.0, 1.0);
        let mut bad_near = HOME_JOINTS;
        bad_near[2] = value;
        assert_eq!(
            inverse(&geometry, &bad_tip, &Vector3::z(), &HOME_JOINTS),
            Err(KinematicsError::NotFinite("tip"))
        );
        assert!(matches!(
            inverse(&geometry, &tip, &bad_direction, &HOME_JOINTS),
            Err(KinematicsError::NotFinite(_))
        ));
        assert!(matches!(
            inverse(&geometry, &tip, &Vector3::z(), &bad_near),
            Err(KinematicsError::NotFinite(_))
        ));
        let mut bad_q = HOME_JOINTS;
        bad_q[4] = value;
        assert!(matches!(
            forward(&geometry, &bad_q),
            Err(KinematicsError::NotFinite(_))
        ));
    }
    assert!(matches!(
        inverse(&geometry, &tip, &Vector3::zeros(), &HOME_JOINTS),
        Err(KinematicsError::Unreachable(_))
    ));
}

#[test]
fn the_solution_nearest_near_is_chosen_and_wrapped() {
    let geometry = nominal();
    let tip = Point3::new(3.0, -85.0, 175.0);
    let direction = tilted(0.1, 0.7);
    let home = inverse(&geometry, &tip, &direction, &HOME_JOINTS).unwrap();
    // Shifting `near` by whole turns shifts the answer by the same turns.
    let mut turned = HOME_JOINTS;
    turned[0] += std::f64::consts::TAU;
    turned[3] -= 2.0 * std::f64::consts::TAU;
    let shifted = inverse(&geometry, &tip, &direction, &turned).unwrap();
    assert!((shifted[0] - home[0] - std::f64::consts::TAU).abs() < 1e-9);
    assert!((shifted[3] - home[3] + 2.0 * std::f64::consts::TAU).abs() < 1e-9);
    // Another assembly (elbow) branch is another valid solution: asking near it returns it.
    let front_branch = [home[1] + 0.0, home[0], home[2], home[3], home[4]];
    let other = inverse(&geometry, &tip, &direction, &front_branch).unwrap();
    assert!((other[0] - home[0]).abs() > 0.1, "{other:?} vs {home:?}");
    let pose = forward(&geometry, &other).unwrap();
    assert!((pose.tip - tip).norm() < 1e-6);
}

#[test]
fn extreme_finite_inputs_are_refused_not_nan() {
    let geometry = nominal();
    let huge = [1e300, -1e300, f64::MAX, f64::MIN_POSITIVE, 1e-300];
    for a in huge {
        for b in huge {
            let tip = Point3::new(a, -90.0, b);
            let direction = Vector3::new(b, a, 1.0);
            for (tip, direction) in [
                (tip, Vector3::z()),
                (Point3::new(0.0, -90.0, 180.0), direction),
            ] {
                match inverse(&geometry, &tip, &direction, &HOME_JOINTS) {
                    Ok(q) => {
                        let pose = forward(&geometry, &q).unwrap();
                        assert!((pose.tip - tip).norm() < 1e-6, "{tip:?} {direction:?}");
                    }
                    Err(error) => assert!(
                        matches!(error, KinematicsError::Unreachable(_)),
                        "{tip:?} {direction:?}: {error}"
                    ),
                }
            }
        }
    }
}

/// The nominal geometry with every joint axis tilted (rad).
fn with_axis_tilts(tilt: [[f64; 2]; 5]) -> Geometry {
    let mut geometry = nominal();
    geometry.axis_tilt = tilt;
    geometry
}

proptest::proptest! {
    /// With tilted joint axes (up to 1°), inverse kinematics reproduces forward kinematics.
    #[test]
    fn inverse_undoes_forward_with_tilted_axes(
        dq in proptest::array::uniform5(-0.15f64..0.15),
        tilt in proptest::array::uniform10(-0.0175f64..0.0175),
    ) {
        let geometry = with_axis_tilts(std::array::from_fn(|j| [tilt[2 * j], tilt[2 * j + 1]]));
        let q: [f64; 5] = std::array::from_fn(|i| HOME_JOINTS[i] + dq[i]);
        let pose = forward(&geometry, &q).unwrap();
        let solved = inverse(&geometry, &pose.tip, &pose.direction, &HOME_JOINTS).unwrap();
        let again = forward(&geometry, &solved).unwrap();
        proptest::prop_assert!((again.tip - pose.tip).norm() < 1e-6);
        proptest::prop_assert!((again.direction.into_inner() - pose.direction.into_inner()).norm() < 1e-8);
        for i in 0..5 {
            proptest::prop_assert!((solved[i] - q[i]).abs() < 1e-6, "joint {}: {} vs {}", i + 1, solved[i], q[i]);
        }
    }
}

/// A small tilt of θ1 lifts the front effector out of the plane of `Bf` to first order and
/// moves the tip; a target out of reach is still refused with tilted axes.
#[test]
fn tilts_act_to_first_order_and_unreachable_targets_stay_refused() {
    let q = HOME_JOINTS;
    let plain = forward(&nominal(), &q).unwrap();
    for tilt in [1e-4, 2e-4, 4e-4] {
        let mut t = [[0.0; 2]; 5];
        t[0][0] = tilt;
        let moved = forward(&with_axis_tilts(t), &q).unwrap();
        let shift = (moved.tip - plain.tip).norm();
        assert!(shift > 0.0, "a tilt of θ1 moves the tip");
        // The front effector leaves the plane of Bf by ≈ l_f·sinθ1·tilt (about x).
        let out_of_plane = (nominal().front_base.inverse()
            * Point3::from(moved.front_effector.translation.vector))
        .z;
        let expected = 50.0 * q[0].sin() * tilt;
        assert!(
            (out_of_plane - expected).abs() < 1e-3 * tilt.abs() * 50.0,
            "{out_of_plane} vs {expected}"
        );
    }
    let mut t = [[0.0; 2]; 5];
    t[2] = [0.01, -0.01];
    let far = nalgebra::Point3::new(0.0, -90.0, 400.0);
    assert!(inverse(
        &with_axis_tilts(t),
        &far,
        &nalgebra::Vector3::z(),
        &HOME_JOINTS
    )
    .is_err());
}
