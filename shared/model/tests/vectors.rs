//! The four forward-kinematics test vectors of docs/robot-model.md §3 and the IK of each.

use nalgebra::{Point3, Vector3};
use sabr_model::HOME_JOINTS;
use sabr_model::{forward, inverse, RobotParams};

/// θ1..θ5 (rad), tip (mm), z_N — copied from docs/robot-model.md §3.
const VECTORS: [([f64; 5], [f64; 3], [f64; 3]); 4] = [
    (
        [-2.368404, -0.777628, 0.0, -2.685073, -0.601543],
        [0.0, -90.0, 180.0],
        [0.0, 0.0, 1.0],
    ),
    (
        [-2.281138, -0.829988, 0.069813, -2.789793, -0.566636],
        [0.6994, -102.5676, 172.3905],
        [0.006198, -0.106914, 0.994249],
    ),
    (
        [-2.508031, -0.672909, -0.174533, -2.597807, -0.723716],
        [6.8652, -61.6116, 193.7630],
        [0.060675, 0.198498, 0.978221],
    ),
    (
        [-2.193871, -0.603095, 0.174533, -2.510540, -0.427010],
        [17.6674, -89.0828, 167.8082],
        [0.030056, -0.006635, 0.999526],
    ),
];

#[test]
fn forward_kinematics_reproduces_the_contract_vectors() {
    let geometry = RobotParams::nominal().geometry;
    for (q, tip, direction) in VECTORS {
        let pose = forward(&geometry, &q).unwrap();
        let tip_error = (pose.tip - Point3::from(tip)).norm();
        let direction_error = (pose.direction.into_inner() - Vector3::from(direction)).amax();
        println!(
            "{q:?}: tip {:?} error {tip_error:e}, direction error {direction_error:e}",
            pose.tip
        );
        assert!(tip_error < 1e-4, "tip of {q:?}: {} vs {tip:?}", pose.tip);
        assert!(
            direction_error < 1e-6,
            "direction of {q:?}: {:?}",
            pose.direction
        );
    }
}

#[test]
fn inverse_kinematics_returns_the_contract_joints() {
    let geometry = RobotParams::nominal().geometry;
    for (q, _, _) in VECTORS {
        let pose = forward(&geometry, &q).unwrap();
        let solved = inverse(&geometry, &pose.tip, &pose.direction, &HOME_JOINTS).unwrap();
        for (a, b) in solved.iter().zip(q) {
            assert!((a - b).abs() < 1e-9, "{solved:?} vs {q:?}");
        }
    }
}

#[test]
fn the_home_pose_has_the_contract_frames() {
    let params = RobotParams::nominal();
    let pose = forward(&params.geometry, &HOME_JOINTS).unwrap();
    let close = |a: Vector3<f64>, b: [f64; 3], tolerance: f64| {
        assert!((a - Vector3::from(b)).norm() < tolerance, "{a:?} vs {b:?}");
    };
    // Gimbal centres p_f = (0, −90, 100), p_b = (0, −70, 0) (rounded home joints: 1e-4 mm).
    close(
        pose.front_effector.translation.vector,
        [0.0, -90.0, 100.0],
        1e-4,
    );
    close(
        pose.back_effector.translation.vector,
        [0.0, -70.0, 0.0],
        1e-4,
    );
    // Needle frame: origin at the tip, z along the needle, y from p_r to p_b, x = y × z.
    close(pose.needle.translation.vector, [0.0, -90.0, 180.0], 1e-4);
    close(pose.needle.rotation * Vector3::z(), [0.0, 0.0, 1.0], 1e-6);
    close(pose.needle.rotation * Vector3::y(), [0.0, 1.0, 0.0], 1e-6);
    close(pose.needle.rotation * Vector3::x(), [1.0, 0.0, 0.0], 1e-6);
    // Effector orientations: Rz(θ2) for the front, Rx(θ3)·Rz(θ5) for the back.
    let front_x = pose.front_effector.rotation * Vector3::x();
    close(
        front_x,
        [HOME_JOINTS[1].cos(), HOME_JOINTS[1].sin(), 0.0],
        1e-12,
    );
    let back_x = pose.back_effector.rotation * Vector3::x();
    close(
        back_x,
        [HOME_JOINTS[4].cos(), HOME_JOINTS[4].sin(), 0.0],
        1e-12,
    );
    // Markers: T_M_Tf = T_M_Bb · T_Bb_Ef · T_Ef_Tf with the nominal mountings (z offsets).
    let markers = params.marker_poses(&pose);
    let front_z = pose.front_effector.rotation * Vector3::new(0.0, 0.0, 15.0);
    close(
        markers.front.translation.vector,
        [
            80.0 + front_z.x,
            -40.0 - 90.0 + front_z.y,
            50.0 + 100.0 + front_z.z,
        ],
        1e-4,
    );
    close(markers.tip.coords, [80.0, -130.0, 230.0], 1e-4);
}

#[test]
fn link_length_effects_change_the_geometry_used() {
    let mut params = RobotParams::nominal();
    params.effects = vec![
        sabr_model::Effect::LinkLength {
            link: sabr_model::Link::LF,
            delta: 0.5,
        },
        sabr_model::Effect::LinkLength {
            link: sabr_model::Link::DOffset,
            delta: -0.25,
        },
    ];
    let geometry = params.effective_geometry();
    assert_eq!(geometry.l_f, 50.5);
    assert_eq!(geometry.d_offset, 19.75);
    assert_eq!(geometry.l_b, 50.0);
    let moved = forward(&geometry, &HOME_JOINTS).unwrap();
    let nominal = forward(&params.geometry, &HOME_JOINTS).unwrap();
    assert!((moved.tip - nominal.tip).norm() > 0.1);
}
