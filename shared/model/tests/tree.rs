//! Kinematic trees from URDF: forward kinematics against hand-computed poses and against the
//! UR10 data set's commanded poses, mimic, prismatic and branched trees, joint values by
//! name, limits, malformed descriptions, the Jacobian against finite differences, and
//! gravity torques against the derivative of the potential energy.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3, Vector6};
use proptest::prelude::*;
use sabr_model::tree::{Payload, STANDARD_GRAVITY};
use sabr_model::{KinematicTree, TreeError};

const UR10: &str = include_str!("../robots/ur10.urdf");
const LIFT_ARM: &str = include_str!("../robots/lift_arm.urdf");
const DUAL_ARM: &str = include_str!("../robots/dual_arm_torso.urdf");

/// Two revolute joints about z, links of 100 mm and 50 mm along x.
const PLANAR: &str = r#"<robot name="planar">
  <link name="base"/><link name="upper"/><link name="lower"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="continuous"><parent link="upper"/><child link="lower"/>
    <origin xyz="0.1 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="lower"/><child link="tip"/>
    <origin xyz="0.05 0 0"/></joint>
</robot>"#;

fn tree(text: &str) -> KinematicTree {
    KinematicTree::from_urdf_str(text).unwrap()
}

fn assert_close(a: &Vector3<f64>, b: &Vector3<f64>, tolerance: f64) {
    assert!((a - b).norm() <= tolerance, "{a:?} is not {b:?}");
}

#[test]
fn planar_forward_kinematics_matches_the_hand_computed_pose() {
    let tree = tree(PLANAR);
    let tip = tree.link_id("tip").unwrap();
    let state = tree
        .forward(&[FRAC_PI_2, -FRAC_PI_2], &tree.nominal_errors())
        .unwrap();
    let pose = state.link_pose(tip);
    // The upper link points along +y (100 mm), the lower link along +x again (50 mm).
    assert_close(
        &pose.translation.vector,
        &Vector3::new(50.0, 100.0, 0.0),
        1e-12,
    );
    assert!(pose.rotation.angle() < 1e-12);
    let state = tree.forward(&[0.3, 0.4], &tree.nominal_errors()).unwrap();
    let expected = Vector3::new(
        100.0 * 0.3f64.cos() + 50.0 * 0.7f64.cos(),
        100.0 * 0.3f64.sin() + 50.0 * 0.7f64.sin(),
        0.0,
    );
    assert_close(&state.link_pose(tip).translation.vector, &expected, 1e-12);
    assert!((state.link_pose(tip).rotation.angle() - 0.7).abs() < 1e-12);
}

#[test]
fn an_error_translation_moves_the_joint_origin_in_the_joint_frame() {
    let tree = tree(PLANAR);
    let tip = tree.link_id("tip").unwrap();
    let mut errors = tree.nominal_errors();
    let ty = tree
        .error_parameters()
        .iter()
        .position(|p| p.name == "j2.ty")
        .unwrap();
    errors[ty] = 2.0;
    // j1 at π/2 turns j2's frame so its y axis is the root's −x.
    let state = tree.forward(&[FRAC_PI_2, 0.0], &errors).unwrap();
    assert_close(
        &state.link_pose(tip).translation.vector,
        &Vector3::new(-2.0, 150.0, 0.0),
        1e-12,
    );
    let rz = tree
        .error_parameters()
        .iter()
        .position(|p| p.name == "j2.rz")
        .unwrap();
    // A rotation error about a revolute joint's own axis is its zero offset.
    let mut offset = tree.nominal_errors();
    offset[rz] = 0.25;
    let with_error = tree.forward(&[0.1, 0.2], &offset).unwrap();
    let shifted = tree.forward(&[0.1, 0.45], &tree.nominal_errors()).unwrap();
    assert_close(
        &with_error.link_pose(tip).translation.vector,
        &shifted.link_pose(tip).translation.vector,
        1e-12,
    );
}

#[test]
fn the_ur10_has_six_variables_and_36_error_parameters_in_mm_and_rad() {
    let tree = tree(UR10);
    let names: Vec<_> = tree.variables().iter().map(|v| v.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint"
        ]
    );
    let errors = tree.error_parameters();
    assert_eq!(errors.len(), 36);
    assert_eq!(errors[0].name, "shoulder_pan_joint.tx");
    assert_eq!(errors[0].unit.symbol(), "mm");
    assert_eq!(errors[5].name, "shoulder_pan_joint.rz");
    assert_eq!(errors[5].unit.symbol(), "rad");
    assert_eq!(errors[5].scale, 1e-3);
    let limits = tree.variables()[2].limits.unwrap();
    assert_eq!((limits.lower, limits.upper), (-2.0 * PI, 2.0 * PI));
}

/// Every `step`-th row of the fixture's series `file`: joint angles (rad) and the commanded
/// T-Mac pose (`Goal`, m and extrinsic roll-pitch-yaw) in base_link.
fn goal_rows(file: &str) -> Vec<([f64; 6], Isometry3<f64>)> {
    let path = format!(
        "{}/../recording/tests/fixtures/ipa-robot-accuracy/{file}",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap();
    text.lines()
        .skip(1)
        .map(|line| {
            let fields: Vec<f64> = line
                .trim_end()
                .split(';')
                .skip(1)
                .take(12)
                .map(|field| field.replace(',', ".").parse().unwrap())
                .collect();
            let goal = Isometry3::from_parts(
                Translation3::new(fields[0] * 1e3, fields[1] * 1e3, fields[2] * 1e3),
                UnitQuaternion::from_euler_angles(fields[3], fields[4], fields[5]),
            );
            (std::array::from_fn(|i| fields[6 + i]), goal)
        })
        .collect()
}

/// `T_TM_F` of the data set (flange in the T-Mac frame, mm), rows of the matrix.
fn tmac_to_flange() -> Isometry3<f64> {
    let path = format!(
        "{}/../recording/tests/fixtures/ipa-robot-accuracy/Series_A/Trafo_TM_F_init.txt",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(path).unwrap();
    let m: Vec<f64> = text
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    let matrix = nalgebra::Matrix4::from_row_slice(&m);
    let rotation = nalgebra::Rotation3::from_matrix(&matrix.fixed_view::<3, 3>(0, 0).into());
    Isometry3::from_parts(
        Translation3::new(m[3], m[7], m[11]),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

#[test]
fn ur10_forward_kinematics_reproduces_the_data_sets_commanded_poses() {
    let tree = tree(UR10);
    let tool0 = tree.link_id("tool0").unwrap();
    let flange_to_tmac = tmac_to_flange().inverse();
    assert!((flange_to_tmac.translation.vector.z - 109.0).abs() < 0.01);
    for file in [
        "Series_A/measurements_grid.csv",
        "Series_B/measurements_joint_configurations.csv",
        "Series_C/measurements_random_poses.csv",
    ] {
        let rows = goal_rows(file);
        assert!(rows.len() > 250, "{file}: {} rows", rows.len());
        let (mut position, mut rotation) = (Vec::new(), Vec::new());
        for (joints, goal) in rows {
            let state = tree.forward(&joints, &tree.nominal_errors()).unwrap();
            let tmac = state.link_pose(tool0) * flange_to_tmac;
            position.push((tmac.translation.vector - goal.translation.vector).norm());
            rotation.push(tmac.rotation.angle_to(&goal.rotation));
        }
        let (position, rotation) = (median(position), median(rotation));
        assert!(
            position < 0.15,
            "{file}: median position error {position} mm"
        );
        assert!(
            rotation < 2e-3,
            "{file}: median rotation error {rotation} rad"
        );
    }
}

#[test]
fn a_prismatic_joint_translates_everything_after_it() {
    let tree = tree(LIFT_ARM);
    let tip = tree.link_id("probe_tip").unwrap();
    assert_eq!(tree.variables()[0].name, "lift_joint");
    assert_eq!(tree.variables()[0].kind.unit(), "mm");
    let limits = tree.variables()[0].limits.unwrap();
    assert_eq!((limits.lower, limits.upper), (0.0, 800.0));
    let low = tree
        .forward(&[100.0, 0.4, -0.3, 0.8, 0.2], &tree.nominal_errors())
        .unwrap();
    let high = tree
        .forward(&[350.0, 0.4, -0.3, 0.8, 0.2], &tree.nominal_errors())
        .unwrap();
    let lift = high.link_pose(tip).translation.vector - low.link_pose(tip).translation.vector;
    assert_close(&lift, &Vector3::new(0.0, 0.0, 250.0), 1e-9);
    // Stretched out along x at the lowest position: 300 + 100 + 80 mm up, 50 + 350 + 300 +
    // 120 mm out, 20 mm above the wrist axis.
    let home = tree.forward(&[0.0; 5], &tree.nominal_errors()).unwrap();
    assert_close(
        &home.link_pose(tip).translation.vector,
        &Vector3::new(820.0, 0.0, 500.0),
        1e-9,
    );
}

#[test]
fn a_mimic_joint_follows_its_driver_and_takes_no_value() {
    let tree = tree(DUAL_ARM);
    let names: Vec<_> = tree.variables().iter().map(|v| v.name.as_str()).collect();
    assert!(names.contains(&"left_finger_a_joint"));
    assert!(!names.contains(&"left_finger_b_joint"));
    let mut values = vec![("left_finger_a_joint", 15.0)];
    values.extend(
        names
            .iter()
            .filter(|&&n| n != "left_finger_a_joint")
            .map(|&n| (n, 0.0)),
    );
    let joints = tree.joint_vector(values.iter().copied()).unwrap();
    let state = tree.forward(&joints, &tree.nominal_errors()).unwrap();
    let hand = state.link_pose(tree.link_id("left_hand").unwrap());
    let a = hand.inverse() * state.link_pose(tree.link_id("left_finger_a").unwrap());
    let b = hand.inverse() * state.link_pose(tree.link_id("left_finger_b").unwrap());
    assert_close(&a.translation.vector, &Vector3::new(80.0, 15.0, 0.0), 1e-9);
    assert_close(&b.translation.vector, &Vector3::new(80.0, -15.0, 0.0), 1e-9);
    // The mimic joint has its own limits: −15 mm is inside [−40, 0].
    tree.check_limits(&joints).unwrap();

    let error = tree
        .joint_vector([("left_finger_b_joint", 1.0)])
        .unwrap_err();
    assert_eq!(
        error,
        TreeError::NotAVariable {
            name: "left_finger_b_joint".into(),
            reason: "a mimic of `left_finger_a_joint`".into()
        }
    );
    // The driver's Jacobian column moves finger b the opposite way.
    let finger_a = tree.variable_index("left_finger_a_joint").unwrap();
    let link_b = tree.link_id("left_finger_b").unwrap();
    let jacobian = tree.point_jacobian(&state, link_b, &Point3::origin());
    let column: Vector3<f64> = jacobian.joints.fixed_view::<3, 1>(0, finger_a).into();
    let hand_y = hand.rotation * Vector3::y();
    assert_close(&column, &(-hand_y), 1e-12);
}

#[test]
fn branches_move_independently_and_the_waist_moves_both() {
    let tree = tree(DUAL_ARM);
    let left = tree.link_id("left_hand").unwrap();
    let right = tree.link_id("right_hand").unwrap();
    let zero = vec![0.0; tree.variables().len()];
    let home = tree.forward(&zero, &tree.nominal_errors()).unwrap();
    // Torso at 500 mm, shoulders 400 mm up and ±200 mm aside, upper arms ±300 mm along y,
    // forearms 250 mm along x.
    assert_close(
        &home.link_pose(left).translation.vector,
        &Vector3::new(250.0, 500.0, 900.0),
        1e-9,
    );
    assert_close(
        &home.link_pose(right).translation.vector,
        &Vector3::new(250.0, -500.0, 900.0),
        1e-9,
    );
    let mut joints = zero.clone();
    joints[tree.variable_index("left_elbow_joint").unwrap()] = 0.7;
    let moved = tree.forward(&joints, &tree.nominal_errors()).unwrap();
    assert_eq!(moved.link_pose(right), home.link_pose(right));
    assert_ne!(moved.link_pose(left), home.link_pose(left));
    let jacobian = tree.point_jacobian(&moved, right, &Point3::origin());
    let left_elbow = tree.variable_index("left_elbow_joint").unwrap();
    assert_eq!(jacobian.joints.column(left_elbow).norm(), 0.0);

    let mut turned = zero;
    turned[tree.variable_index("waist_joint").unwrap()] = FRAC_PI_2;
    let turned = tree.forward(&turned, &tree.nominal_errors()).unwrap();
    assert_close(
        &turned.link_pose(left).translation.vector,
        &Vector3::new(-500.0, 250.0, 900.0),
        1e-9,
    );
    assert_close(
        &turned.link_pose(right).translation.vector,
        &Vector3::new(500.0, 250.0, 900.0),
        1e-9,
    );
}

#[test]
fn joint_values_by_name_name_the_unknown_missing_or_fixed_joint() {
    let tree = tree(PLANAR);
    assert_eq!(
        tree.joint_vector([("j2", 0.5), ("j1", 0.25)]).unwrap(),
        vec![0.25, 0.5]
    );
    let unknown = tree.joint_vector([("j1", 0.0), ("j3", 0.0)]).unwrap_err();
    assert_eq!(
        unknown.to_string(),
        "unknown joint `j3` (joint variables: j1, j2)"
    );
    let missing = tree.joint_vector([("j1", 0.0)]).unwrap_err();
    assert_eq!(missing, TreeError::MissingValue("j2".into()));
    let fixed = tree.joint_vector([("tip_joint", 0.0)]).unwrap_err();
    assert_eq!(
        fixed.to_string(),
        "joint `tip_joint` is fixed: it takes no value"
    );
    let twice = tree.joint_vector([("j1", 0.0), ("j1", 1.0)]).unwrap_err();
    assert_eq!(twice, TreeError::DuplicateValue("j1".into()));
    let nan = tree
        .joint_vector([("j1", f64::NAN), ("j2", 0.0)])
        .unwrap_err();
    assert!(
        matches!(nan, TreeError::NotFinite { ref name, .. } if name == "j1"),
        "{nan}"
    );
    let short = tree.forward(&[0.0], &tree.nominal_errors()).unwrap_err();
    assert_eq!(
        short,
        TreeError::WrongLength {
            what: "joint vector",
            expected: 2,
            found: 1
        }
    );
    let unknown_link = tree.link_id("hand").unwrap_err();
    assert_eq!(
        unknown_link.to_string(),
        "unknown link `hand` (links: base, upper, lower, tip)"
    );
}

#[test]
fn limits_are_checked_and_continuous_joints_have_none() {
    let tree = tree(PLANAR);
    tree.check_limits(&[2.9, 100.0]).unwrap();
    let error = tree.check_limits(&[3.5, 0.0]).unwrap_err();
    assert_eq!(
        error.to_string(),
        "joint `j1`: 3.5 rad is outside its limits [-3, 3]"
    );
    assert!(tree.variables()[1].limits.is_none());
}

#[test]
fn malformed_descriptions_are_refused_with_the_reason() {
    let cases = [
        ("<robot", "not a valid URDF"),
        (
            r#"<robot name="r"><link name="a"/><link name="b"/>
              <joint name="j" type="floating"><parent link="a"/><child link="b"/></joint></robot>"#,
            "joint `j`: type floating is not supported",
        ),
        (
            r#"<robot name="r"><link name="a"/><link name="b"/></robot>"#,
            "exactly one root link",
        ),
        (
            r#"<robot name="r"><link name="a"/>
              <joint name="j" type="fixed"><parent link="a"/><child link="c"/></joint></robot>"#,
            "joint `j`: unknown child link `c`",
        ),
        (
            r#"<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
              <joint name="j1" type="fixed"><parent link="a"/><child link="b"/></joint>
              <joint name="j2" type="fixed"><parent link="c"/><child link="b"/></joint></robot>"#,
            "link `b` is the child of two joints",
        ),
        (
            r#"<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
              <joint name="j1" type="fixed"><parent link="b"/><child link="c"/></joint>
              <joint name="j2" type="fixed"><parent link="c"/><child link="b"/></joint></robot>"#,
            "link `b` is not connected to the root",
        ),
        (
            r#"<robot name="r"><link name="a"/><link name="b"/>
              <joint name="j" type="revolute"><parent link="a"/><child link="b"/>
              <axis xyz="0 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"#,
            "joint `j`: the axis must be a finite, non-zero vector",
        ),
        (
            r#"<robot name="r"><link name="a"/><link name="b"/>
              <joint name="j" type="revolute"><parent link="a"/><child link="b"/>
              <axis xyz="0 0 1"/></joint></robot>"#,
            "joint `j`: the limits [0, 0] rad are empty",
        ),
        (
            r#"<robot name="r"><link name="a"/><link name="b"/>
              <joint name="j" type="continuous"><parent link="a"/><child link="b"/>
              <mimic joint="k"/></joint></robot>"#,
            "joint `j`: cannot mimic `k`: no such joint",
        ),
        (
            r#"<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
              <joint name="j" type="continuous"><parent link="a"/><child link="b"/>
              <mimic joint="k"/></joint>
              <joint name="k" type="continuous"><parent link="b"/><child link="c"/>
              <mimic joint="j"/></joint></robot>"#,
            "the mimic references form a loop",
        ),
        (
            r#"<robot name="r"><link name="a"><inertial><mass value="-1"/>
              <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link></robot>"#,
            "link `a`: the mass must be finite and not negative",
        ),
    ];
    for (text, expected) in cases {
        let error = KinematicTree::from_urdf_str(text).unwrap_err().to_string();
        assert!(error.contains(expected), "{error:?} lacks {expected:?}");
    }
}

/// Pose difference `b ⊖ a` as (position, rotation vector) in the root frame.
fn pose_difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> Vector6<f64> {
    let position = b.translation.vector - a.translation.vector;
    let rotation = (b.rotation * a.rotation.inverse()).scaled_axis();
    Vector6::new(
        position.x, position.y, position.z, rotation.x, rotation.y, rotation.z,
    )
}

/// Checks the analytic Jacobian of a target on `link` against central differences.
fn check_jacobian(tree: &KinematicTree, link: &str, joints: &[f64], errors: &[f64]) {
    let link = tree.link_id(link).unwrap();
    let mounting = Isometry3::new(
        Vector3::new(12.0, -30.0, 45.0),
        Vector3::new(0.2, -0.1, 0.3),
    );
    let state = tree.forward(joints, errors).unwrap();
    let jacobian = tree.pose_jacobian(&state, link, &mounting);
    assert_eq!(jacobian.pose, state.link_pose(link) * mounting);
    let pose_at = |joints: &[f64], errors: &[f64]| {
        tree.forward(joints, errors).unwrap().link_pose(link) * mounting
    };
    for (i, parameter) in tree.error_parameters().iter().enumerate() {
        let h = 1e-4 * parameter.scale;
        let (mut plus, mut minus) = (errors.to_vec(), errors.to_vec());
        plus[i] += h;
        minus[i] -= h;
        let numeric =
            pose_difference(&pose_at(joints, &minus), &pose_at(joints, &plus)) / (2.0 * h);
        let analytic = jacobian.errors.column(i);
        let scale = 1.0 + numeric.norm();
        assert!(
            (numeric - analytic).norm() < 1e-5 * scale,
            "{}: numeric {numeric:?}, analytic {analytic:?}",
            parameter.name
        );
    }
    for (i, variable) in tree.variables().iter().enumerate() {
        let h = 1e-6;
        let (mut plus, mut minus) = (joints.to_vec(), joints.to_vec());
        plus[i] += h;
        minus[i] -= h;
        let numeric =
            pose_difference(&pose_at(&minus, errors), &pose_at(&plus, errors)) / (2.0 * h);
        let analytic = jacobian.joints.column(i);
        let scale = 1.0 + numeric.norm();
        assert!(
            (numeric - analytic).norm() < 1e-5 * scale,
            "{}: numeric {numeric:?}, analytic {analytic:?}",
            variable.name
        );
    }
}

/// A joint vector and an error vector (errors up to 2 mm and 20 mrad) from unit samples.
fn configuration(tree: &KinematicTree, unit: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let joints = tree
        .variables()
        .iter()
        .enumerate()
        .map(|(i, variable)| {
            let (lower, upper) = variable
                .limits
                .map(|l| (l.lower.max(-3.0 * 1e3), l.upper.min(3.0 * 1e3)))
                .unwrap_or((-PI, PI));
            lower + (upper - lower) * unit[i % unit.len()]
        })
        .collect();
    let errors = tree
        .error_parameters()
        .iter()
        .enumerate()
        .map(|(i, p)| 20.0 * p.scale * (unit[(i * 7 + 3) % unit.len()] - 0.5) * 2.0 * 0.1)
        .collect();
    (joints, errors)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn the_jacobian_matches_finite_differences(
        unit in proptest::collection::vec(0.0..1.0f64, 17),
    ) {
        for (text, link) in [(UR10, "tool0"), (LIFT_ARM, "probe_tip"), (DUAL_ARM, "left_finger_b")] {
            let tree = tree(text);
            let (joints, errors) = configuration(&tree, &unit);
            check_jacobian(&tree, link, &joints, &errors);
        }
    }

    #[test]
    fn gravity_torques_are_the_derivative_of_the_potential_energy(
        unit in proptest::collection::vec(0.0..1.0f64, 17),
    ) {
        for text in [UR10, LIFT_ARM, DUAL_ARM] {
            let tree = tree(text);
            let (joints, errors) = configuration(&tree, &unit);
            let payload = Payload {
                link: tree.link_id(if text == UR10 { "tool0" } else { tree.links().last().unwrap().name.as_str() }).unwrap(),
                mass_kg: 1.3,
                centre_of_mass_mm: Point3::new(5.0, -8.0, 109.0),
            };
            // −V = Σ m g·p (J, with p in m); τ = ∂(−V)/∂q.
            let negative_potential = |joints: &[f64]| {
                let state = tree.forward(joints, &errors).unwrap();
                let links = tree.links().iter().enumerate().filter_map(|(i, link)| {
                    let inertial = link.inertial?;
                    let pose = state.link_poses()[i];
                    Some((inertial.mass_kg, pose * Point3::from(inertial.centre_of_mass_mm)))
                });
                let carried = (payload.mass_kg, state.link_pose(payload.link) * payload.centre_of_mass_mm);
                links.chain([carried]).map(|(m, p)| m * STANDARD_GRAVITY.dot(&p.coords) * 1e-3).sum::<f64>()
            };
            let state = tree.forward(&joints, &errors).unwrap();
            let torques = tree.gravity_torques(&state, &STANDARD_GRAVITY, &[payload]);
            for (i, variable) in tree.variables().iter().enumerate() {
                let h = 1e-6;
                let (mut plus, mut minus) = (joints.clone(), joints.clone());
                plus[i] += h;
                minus[i] -= h;
                // J per rad is N·m; J per mm is 10⁻³ N.
                let per_unit = if variable.kind.unit() == "mm" { 1e3 } else { 1.0 };
                let numeric =
                    per_unit * (negative_potential(&plus) - negative_potential(&minus)) / (2.0 * h);
                prop_assert!(
                    (numeric - torques[i]).abs() < 1e-5 * (1.0 + numeric.abs()),
                    "{}: numeric {numeric}, analytic {}", variable.name, torques[i]
                );
            }
        }
    }
}

#[test]
fn ur10_gravity_torque_is_zero_upright_and_largest_on_the_shoulder_stretched_out() {
    let tree = tree(UR10);
    let upright = tree
        .forward(
            &[0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0, 0.0],
            &tree.nominal_errors(),
        )
        .unwrap();
    let torques = tree.gravity_torques(&upright, &STANDARD_GRAVITY, &[]);
    assert!(torques.iter().all(|t| t.abs() < 1.0), "{torques:?}");
    let stretched = tree
        .forward(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], &tree.nominal_errors())
        .unwrap();
    let torques = tree.gravity_torques(&stretched, &STANDARD_GRAVITY, &[]);
    // Horizontal levers about the shoulder axis: upper arm 12.7 kg at 0.612 − 0.38 m,
    // forearm 4.27 kg at 0.612 + 0.5723 − 0.24 m, the wrists' 4.365 kg at about
    // 0.612 + 0.5723 m: about 119 N·m.
    let expected = 9.80665 * (12.7 * 0.232 + 4.27 * 0.9443 + 4.365 * 1.1843);
    assert!(
        (torques[1].abs() - expected).abs() < 0.05 * expected,
        "{torques:?} vs {expected}"
    );
    assert!(torques[0].abs() < 1e-9);
}
