//! Each injected effect changes the truth exactly as its parameters say, and nothing else.

mod common;

use common::short_config;
use nalgebra::Vector3;
use sabr_model::effects::gravity_feature;
use sabr_model::{forward, Joints};
use sabr_sim::{record_session, sag_deflection, Session, SimEffect, TrueRobot, Truth};

/// The same seed's true robot without and with `spec`.
fn robots(spec: &str) -> (TrueRobot, TrueRobot) {
    let plain = short_config(31, 0.05);
    let mut with = plain.clone();
    with.effects = vec![spec.parse::<SimEffect>().unwrap()];
    let a = Session::new(&plain).unwrap().robot_truth().clone();
    let b = Session::new(&with).unwrap().robot_truth().clone();
    let mut b_without_effects = b.clone();
    b_without_effects.params.effects.clear();
    b_without_effects.thermal.clear();
    b_without_effects.link_drift.clear();
    b_without_effects.needle_sag_mm = 0.0;
    assert_eq!(a, b_without_effects, "the effect changed more than itself");
    (TrueRobot::new(a), TrueRobot::new(b))
}

/// Motor setpoints (rad) sweeping every joint up by 0.1 rad, then back down, in `2·half`
/// steps.
fn sweep(robot: &TrueRobot, half: usize) -> Vec<Joints> {
    let centre = robot.truth().power_up_joints;
    (0..2 * half)
        .map(|k| {
            let s = if k < half { k } else { 2 * half - k } as f64 / half as f64;
            let q: Joints =
                std::array::from_fn(|i| centre[i] - 0.1 * s * robot.truth().stop_side[i]);
            robot.truth().motor_for_joints(&q)
        })
        .collect()
}

/// Drives both robots through `setpoints` (0.1 s apart) and calls `check` with both.
fn drive(
    plain: &mut TrueRobot,
    with: &mut TrueRobot,
    mut check: impl FnMut(&TrueRobot, &TrueRobot),
) {
    drive_in_steps(plain, with, 20, &mut check);
}

/// [`drive`] with `2·half` setpoints.
fn drive_in_steps(
    plain: &mut TrueRobot,
    with: &mut TrueRobot,
    half: usize,
    check: &mut impl FnMut(&TrueRobot, &TrueRobot),
) {
    for (k, setpoint) in sweep(plain, half).iter().enumerate() {
        let t_ns = (k as i64 + 1) * 100_000_000;
        plain.command(t_ns, setpoint);
        with.command(t_ns, setpoint);
        check(plain, with);
    }
}

fn difference(plain: &TrueRobot, with: &TrueRobot) -> Joints {
    let (a, b) = (plain.joints(), with.joints());
    std::array::from_fn(|i| b[i] - a[i])
}

fn assert_only(joint: usize, diff: &Joints, expected: f64) {
    for (i, d) in diff.iter().enumerate() {
        let want = if i == joint { expected } else { 0.0 };
        assert!((d - want).abs() < 1e-12, "joint {}: {d} vs {want}", i + 1);
    }
}

#[test]
fn ripple_adds_amplitude_times_sine_of_harmonic_motor_angle() {
    let (mut plain, mut with) = robots("ripple:joint=2,harmonic=3,amplitude=0.002,phase=0.3");
    let mut largest: f64 = 0.0;
    drive(&mut plain, &mut with, |a, b| {
        let expected = 0.002 * (3.0 * b.motor_angles()[1] + 0.3).sin();
        assert_only(1, &difference(a, b), expected);
        largest = largest.max(expected.abs());
    });
    assert!(largest > 0.0015, "{largest}");
}

/// Backlash is a play operator: the joint lags half the gap behind the motion and, after a
/// reversal, holds still until the motor has crossed the whole gap.
#[test]
fn backlash_is_a_play_operator_with_memory() {
    let width = 0.004;
    let (mut plain, mut with) = robots("backlash:joint=4,width=0.004");
    assert_only(3, &difference(&plain, &with), 0.0);
    // The reference play operator, run on the paper joint angle, centred at power-up.
    let mut output = with.paper_joints()[3];
    let (mut held, mut lagging) = (0, 0);
    // Steps of 0.5 mrad, so the reversal's first steps stay inside the 4 mrad gap.
    drive_in_steps(&mut plain, &mut with, 200, &mut |a, b| {
        let x = a.paper_joints()[3];
        let previous = output;
        output = output.clamp(x - 0.5 * width, x + 0.5 * width);
        assert_only(3, &difference(a, b), output - x);
        if output == previous && (output - x).abs() < 0.5 * width - 1e-9 {
            held += 1;
        } else if ((output - x).abs() - 0.5 * width).abs() < 1e-12 {
            lagging += 1;
        }
    });
    assert!(held > 0 && lagging > 0, "held {held}, lagging {lagging}");
}

#[test]
fn compliance_adds_gain_times_the_gravity_feature() {
    let (mut plain, mut with) = robots("compliance:joint=1,gain=0.003");
    drive(&mut plain, &mut with, |a, b| {
        let expected = 0.003 * gravity_feature(0, &a.paper_joints());
        assert!(expected.abs() > 1e-4);
        assert_only(0, &difference(a, b), expected);
    });
}

#[test]
fn thermal_drift_follows_its_time_constant() {
    let (mut plain, mut with) = robots("thermal:joint=3,amplitude=0.002,tau_s=2");
    drive(&mut plain, &mut with, |a, b| {
        let t_s = b.time_ns() as f64 * 1e-9;
        assert_only(2, &difference(a, b), 0.002 * (1.0 - (-t_s / 2.0).exp()));
    });
}

#[test]
fn link_length_error_changes_the_geometry_by_delta() {
    let (mut plain, mut with) = robots("link:link=l_f,delta=0.4");
    let mut geometry = with.truth().params.geometry.clone();
    geometry.l_f += 0.4;
    let mut largest: f64 = 0.0;
    drive(&mut plain, &mut with, |a, b| {
        assert_eq!(a.joints(), b.joints());
        let tip = b.pose().unwrap().tip;
        let expected = forward(&geometry, &b.joints()).unwrap().tip;
        assert!((tip - expected).norm() < 1e-9);
        largest = largest.max((tip - a.pose().unwrap().tip).norm());
    });
    assert!(largest > 0.1, "{largest} mm");
}

#[test]
fn latency_effect_adds_to_the_tracker_latency() {
    let plain = short_config(32, 0.05);
    let mut with = plain.clone();
    with.effects = vec!["latency:ms=25".parse().unwrap()];
    let (_, a) = record_session(&plain).unwrap();
    let (_, b) = record_session(&with).unwrap();
    assert_eq!(a.tracker.base_latency_ms, b.tracker.base_latency_ms);
    assert_eq!(b.tracker.latency_ms(), a.tracker.latency_ms() + 25.0);
    let median_delay = |frames: &[sabr_sim::FrameTruth]| {
        let mut delays: Vec<f64> = frames
            .iter()
            .filter_map(|f| f.arrival_ns.map(|t| (t - f.exposure_ns) as f64 * 1e-6))
            .collect();
        delays.sort_by(f64::total_cmp);
        delays[delays.len() / 2]
    };
    let added = median_delay(&b.frames) - median_delay(&a.frames);
    assert!((added - 25.0).abs() < 2.5, "{added} ms");
}

#[test]
fn effects_combine() {
    let plain = short_config(33, 0.05);
    let mut with = plain.clone();
    with.effects = [
        "ripple:joint=1,harmonic=1,amplitude=0.001",
        "backlash:joint=5,width=0.002",
    ]
    .iter()
    .map(|s| s.parse().unwrap())
    .collect();
    let (_, truth) = record_session(&with).unwrap();
    assert_eq!(truth.robot.params.effects.len(), 2);
    let (_, clean) = record_session(&plain).unwrap();
    let moved = truth
        .validation
        .iter()
        .zip(&clean.validation)
        .map(|(a, b)| {
            (a.joints[0] - b.joints[0])
                .abs()
                .max((a.joints[4] - b.joints[4]).abs())
        })
        .fold(0.0, f64::max);
    assert!(moved > 1e-4, "{moved}");
}

#[test]
fn link_thermal_drift_grows_the_link_with_its_time_constant() {
    let (mut plain, mut with) = robots("thermal:link=l_f,delta=0.3,tau_s=2");
    let undrifted = with.truth().params.effective_geometry();
    assert_eq!(
        with.pose().unwrap(),
        plain.pose().unwrap(),
        "drift at power-up"
    );
    let mut gaps = Vec::new();
    drive(&mut plain, &mut with, |a, b| {
        assert_eq!(a.joints(), b.joints());
        let t_s = b.time_ns() as f64 * 1e-9;
        let mut drifted = undrifted.clone();
        drifted.l_f += 0.3 * (1.0 - (-t_s / 2.0).exp());
        assert!((b.geometry().l_f - drifted.l_f).abs() < 1e-12);
        let tip = b.pose().unwrap().tip;
        let expected = forward(&drifted, &b.joints()).unwrap().tip;
        assert!((tip - expected).norm() < 1e-9, "{t_s} s");
        let rigid = forward(&undrifted, &b.joints()).unwrap().tip;
        assert!((a.pose().unwrap().tip - rigid).norm() < 1e-12);
        gaps.push((tip - rigid).norm());
    });
    // 4 s of 2 s time constant: the drift grows to 0.3 · (1 − e⁻²) mm of l_f.
    assert!(gaps[2] < gaps[20] && gaps[20] < gaps[39], "{gaps:?}");
    assert!(gaps[39] > 0.05, "{gaps:?}");

    // Long after power-up the link has grown by the whole delta.
    let setpoint = *sweep(&with, 20).last().unwrap();
    with.command(3_600_000_000_000, &setpoint);
    let mut grown = undrifted.clone();
    grown.l_f += 0.3;
    let expected = forward(&grown, &with.joints()).unwrap();
    let pose = with.pose().unwrap();
    assert!((pose.tip - expected.tip).norm() < 1e-9);
    let front = pose.front_effector.translation.vector;
    assert!((front - expected.front_effector.translation.vector).norm() < 1e-9);
}

#[test]
fn sag_deflection_is_mm_when_horizontal_and_zero_when_vertical() {
    for horizontal in [
        Vector3::x(),
        Vector3::z(),
        Vector3::new(1.0, 0.0, -1.0).normalize(),
    ] {
        let d = sag_deflection(0.4, &horizontal);
        assert!((d - Vector3::new(0.0, -0.4, 0.0)).norm() < 1e-15, "{d}");
    }
    for vertical in [Vector3::y(), -Vector3::y()] {
        assert!(sag_deflection(0.4, &vertical).norm() < 1e-15);
    }
    let tilted = Vector3::new(0.0, 30f64.to_radians().sin(), 30f64.to_radians().cos());
    let d = sag_deflection(0.4, &tilted);
    assert!(
        (d.norm() - 0.4 * 30f64.to_radians().cos()).abs() < 1e-15,
        "{d}"
    );
    assert!(d.dot(&tilted).abs() < 1e-15, "not across the needle: {d}");
    assert!(d.y < 0.0, "not downwards: {d}");
}

#[test]
fn sag_moves_only_the_tip_across_the_needle_downwards() {
    let (mut plain, mut with) = robots("sag:mm=0.4");
    let mut largest: f64 = 0.0;
    drive(&mut plain, &mut with, |a, b| {
        let (pa, pb) = (a.pose().unwrap(), b.pose().unwrap());
        let (ta, tb) = (a.tool_poses().unwrap(), b.tool_poses().unwrap());
        assert_eq!((ta.front, ta.back), (tb.front, tb.back));
        assert_eq!(
            (pa.front_effector, pa.back_effector),
            (pb.front_effector, pb.back_effector)
        );
        assert_eq!(pa.direction, pb.direction);
        let z = pb.direction.into_inner();
        let moved = tb.tip - ta.tip;
        let horizontal = (1.0 - z.y * z.y).sqrt();
        assert!((moved - sag_deflection(0.4, &z)).norm() < 1e-12);
        assert!((moved.norm() - 0.4 * horizontal).abs() < 1e-12, "{moved}");
        assert!(moved.dot(&z).abs() < 1e-12 && moved.y < 0.0, "{moved}");
        assert!((pb.tip - tb.tip).norm() < 1e-12);
        assert!((pb.needle.translation.vector - pb.tip.coords).norm() < 1e-12);
        largest = largest.max(moved.norm());
    });
    // The needle points roughly along z of `Bb`, i.e. nearly horizontally.
    assert!(largest > 0.35, "{largest} mm");
}

/// Tracker clock rate error (ppm) measured from the exposure times of every frame.
fn measured_clock_drift_ppm(truth: &Truth, rate_hz: f64) -> f64 {
    let (first, last) = (truth.frames[0], *truth.frames.last().unwrap());
    let frames = (truth.frames.len() - 1) as f64;
    let period_ns = (last.exposure_ns - first.exposure_ns) as f64 / frames;
    (period_ns * rate_hz * 1e-9 - 1.0) * 1e6
}

#[test]
fn clock_drift_sets_the_tracker_frame_period_error_exactly() {
    let plain = short_config(34, 0.05);
    let rate_hz = plain.tracker.rate_hz;
    let (_, a) = record_session(&plain).unwrap();
    let random = measured_clock_drift_ppm(&a, rate_hz);
    assert!(
        random.abs() <= plain.tracker.clock_drift_ppm + 0.01,
        "{random}"
    );
    for ppm in [120.0, -400.0] {
        let mut with = plain.clone();
        with.effects = vec![format!("clockdrift:ppm={ppm}").parse().unwrap()];
        let (_, b) = record_session(&with).unwrap();
        assert!(b.frames.len() > 200, "{} frames", b.frames.len());
        let measured = measured_clock_drift_ppm(&b, rate_hz);
        assert!(
            (measured - ppm).abs() < 0.01,
            "{measured} ppm, wanted {ppm}"
        );
        assert_eq!(b.tracker.period_ns, 1e9 / rate_hz * (1.0 + ppm * 1e-6));
        let (ta, tb) = (&a.tracker, &b.tracker);
        assert_eq!(ta.tracker_from_base, tb.tracker_from_base);
        assert_eq!(ta.base_latency_ms, tb.base_latency_ms);
        assert_eq!(ta.first_frame, tb.first_frame);
        assert_eq!(ta.fit_rms_mm, tb.fit_rms_mm);
        assert_eq!(a.robot, b.robot);
    }
}
