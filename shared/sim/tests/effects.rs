//! Each injected effect changes the truth exactly as its parameters say, and nothing else.

mod common;

use common::short_config;
use sabr_model::effects::gravity_feature;
use sabr_model::{forward, Joints};
use sabr_sim::{record_session, Session, SimEffect, TrueRobot};

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
