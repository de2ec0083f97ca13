//! The session plan and the true robot: the nominal model's error is the paper's, the
//! phases are there, the excitation covers the joints, validation poses spread out.

mod common;

use common::{nominal_validation_rms, phase, short_config};
use sabr_sim::{record_session, Session, SimConfig, SimError};

#[test]
fn nominal_model_with_homing_offsets_is_off_by_2_to_8_mm_over_seeds() {
    let mut errors = Vec::new();
    for seed in 0..6 {
        let config = short_config(seed, 0.05);
        let (recording, truth) = record_session(&config).unwrap();
        errors.push(nominal_validation_rms(&config, &recording, &truth));
    }
    assert!(
        errors.iter().all(|e| (2.0..=8.0).contains(e)),
        "validation tip RMS per seed (mm): {errors:?}"
    );
}

#[test]
fn true_robot_differs_from_nominal_within_the_stated_amounts() {
    for seed in 0..10 {
        let config = short_config(seed, 0.05);
        let session = Session::new(&config).unwrap();
        let truth = session.robot_truth();
        let nominal = &config.nominal;
        for i in 0..5 {
            let ratio = truth.params.joints.gear_ratio[i] / nominal.joints.gear_ratio[i];
            assert!((ratio - 1.0).abs() <= 0.03 + 1e-12, "GR {i}: {ratio}");
            let stop = truth.stops[i] - nominal.joints.home_stops[i];
            assert!(stop.abs() <= 2f64.to_radians() + 1e-12, "stop {i}: {stop}");
        }
        let front = truth.params.geometry.front_base;
        let shift = front.translation.vector - nominal.geometry.front_base.translation.vector;
        assert!(shift.amax() <= 1.5 + 1e-9, "{shift}");
        let tilt = front.rotation.scaled_axis();
        assert!(
            tilt.x.abs().max(tilt.y.abs()) <= 0.6f64.to_radians() + 1e-9,
            "{tilt}"
        );
        assert!(tilt.z.abs() < 1e-6, "no rotation about z: {tilt}");
        let needle = truth.params.geometry.l_n - nominal.geometry.l_n;
        assert!(needle.abs() <= 3.0 + 1e-12 && needle != 0.0, "{needle}");
        let mount = truth.params.markers.front_mount.translation.vector
            - nominal.markers.front_mount.translation.vector;
        assert!(mount.amax() <= 1.0 + 1e-9 && mount.amax() > 0.0, "{mount}");
        assert_eq!(
            truth.params.markers.base_to_robot,
            nominal.markers.base_to_robot
        );
        assert_eq!(truth.params.joints.offset, Some(truth.power_up_joints));
    }
}

#[test]
fn session_has_the_paper_phases_in_order_and_lasts_about_five_minutes() {
    let config = SimConfig::new(3);
    let session = Session::new(&config).unwrap();
    let plan = session.plan();
    let names: Vec<&str> = plan.phases().iter().map(|p| p.name).collect();
    assert_eq!(names, ["homing", "excitation", "tip", "validation"]);
    assert!(plan
        .phases()
        .windows(2)
        .all(|w| w[0].end_ns <= w[1].start_ns));
    let minutes = plan.end_ns() as f64 * 1e-9 / 60.0;
    assert!((4.5..=5.5).contains(&minutes), "{minutes} min");
    assert_eq!(plan.validation().len(), 20);

    let mut shorter = config.clone();
    shorter.duration_scale = 0.5;
    let half = Session::new(&shorter).unwrap().plan().end_ns() as f64 / plan.end_ns() as f64;
    assert!((0.45..=0.6).contains(&half), "{half}");
}

#[test]
fn excitation_moves_every_joint_about_0_2_rad_and_validation_poses_spread_out() {
    let config = short_config(4, 0.5);
    let (recording, truth) = record_session(&config).unwrap();
    let excitation = phase(&recording, "excitation");
    let joints = &truth.robot.params.joints;
    let mut low = [f64::INFINITY; 5];
    let mut high = [f64::NEG_INFINITY; 5];
    for row in recording
        .encoders
        .iter()
        .filter(|r| excitation.t_start_ns <= r.t_ns && r.t_ns <= excitation.t_end_ns)
    {
        let motor = truth.robot.params.motor_angles(&row.counts);
        for i in 0..5 {
            let q = joints.gear_ratio[i] * motor[i] + truth.robot.power_up_joints[i];
            low[i] = low[i].min(q);
            high[i] = high[i].max(q);
        }
    }
    for i in 0..5 {
        let half_range = 0.5 * (high[i] - low[i]);
        assert!(
            (0.14..=0.2).contains(&half_range),
            "joint {}: ±{half_range}",
            i + 1
        );
        // The envelope stays clear of the true stop.
        let side = truth.robot.stop_side[i];
        let extreme = if side > 0.0 { high[i] } else { low[i] };
        assert!(
            side * (truth.robot.stops[i] - extreme) > 0.01,
            "joint {}",
            i + 1
        );
    }

    let tips: Vec<_> = truth.validation.iter().map(|v| v.tip).collect();
    let mut closest = f64::INFINITY;
    for (a, p) in tips.iter().enumerate() {
        for q in &tips[a + 1..] {
            closest = closest.min((p - q).norm());
        }
    }
    assert!(closest > 3.0, "two validation poses {closest} mm apart");
    for axis in 0..2 {
        let values = tips.iter().map(|t| t[axis]);
        let span =
            values.clone().fold(f64::NEG_INFINITY, f64::max) - values.fold(f64::INFINITY, f64::min);
        assert!(span > 20.0, "validation tips span {span} mm on axis {axis}");
    }
    // Validation holds are static: the counts do not change within a hold.
    for pose in &truth.validation {
        let counts: Vec<_> = recording
            .encoders
            .iter()
            .filter(|r| pose.t_start_ns <= r.t_ns && r.t_ns <= pose.t_end_ns)
            .map(|r| r.counts)
            .collect();
        assert!(counts.len() > 400 && counts.iter().all(|c| *c == pose.counts));
    }
}

#[test]
fn plans_stay_reachable_over_many_seeds_and_bad_configs_are_refused() {
    for seed in 100..130 {
        Session::new(&short_config(seed, 0.1)).unwrap();
    }
    for scale in [0.0, -1.0, f64::NAN, 1e3] {
        let err = Session::new(&short_config(1, scale)).unwrap_err();
        assert!(matches!(err, SimError::Config(_)), "{err}");
        assert!(err.to_string().contains("duration scale"), "{err}");
    }
    for (name, twice) in [
        ("latency", ["latency:ms=5", "latency:ms=6"]),
        ("sag", ["sag:mm=0.4", "sag:mm=0.2"]),
        ("clockdrift", ["clockdrift:ppm=10", "clockdrift:ppm=10"]),
    ] {
        let mut config = SimConfig::new(1);
        config.effects = twice.iter().map(|s| s.parse().unwrap()).collect();
        let err = Session::new(&config).unwrap_err().to_string();
        assert!(
            err.contains(&format!("the {name} effect is given more than once")),
            "{err}"
        );
    }
}
