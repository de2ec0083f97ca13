//! Statistical tests of the sensor emulation against the configured values (within 10 %),
//! and counts against the quantised truth.

mod common;

use std::f64::consts::PI;

use common::{phase, short_config};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use sabr_recording::{Recording, Tool, ToolReading};
use sabr_sim::{record_session, Session, SimConfig, Truth};

fn session(config: &SimConfig) -> (Recording, Truth) {
    record_session(config).unwrap()
}

fn within(value: f64, target: f64, relative: f64) -> bool {
    (value - target).abs() <= relative * target.abs()
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

#[test]
fn base_tool_noise_matches_the_configured_position_and_rotation_noise() {
    let config = short_config(21, 0.2);
    let (recording, truth) = session(&config);
    let expected = truth.tracker.tracker_from_base;
    let mut squared = Vector3::zeros();
    let mut angles_squared = 0.0;
    let mut rms_sum = [0.0; 3];
    let mut rms_count = [0usize; 3];
    let mut n = 0;
    for row in &recording.tracker {
        let ToolReading::Pose {
            quaternion,
            position,
            rms,
        } = row.reading
        else {
            continue;
        };
        let index = match row.tool {
            Tool::Base => 0,
            Tool::Front => 1,
            Tool::Back => 2,
            Tool::Tip => unreachable!("the tip is a point"),
        };
        rms_sum[index] += rms;
        rms_count[index] += 1;
        if row.tool != Tool::Base {
            continue;
        }
        let error = Vector3::from(position) - expected.translation.vector;
        squared += error.component_mul(&error);
        let [w, x, y, z] = quaternion;
        let measured = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        angles_squared += measured.angle_to(&expected.rotation).powi(2);
        n += 1;
    }
    assert!(n > 1000, "only {n} base readings");
    let position_rms = (squared.sum() / n as f64).sqrt();
    let configured = config.tracker.position_noise_rms_mm;
    assert!(
        within(position_rms, configured, 0.1),
        "{position_rms} vs {configured}"
    );
    let sigma = (squared / n as f64).map(f64::sqrt);
    assert!(
        sigma.z > 2.0 * sigma.x && sigma.z > 2.0 * sigma.y,
        "depth {sigma:?}"
    );
    let ratio = sigma.z / (0.5 * (sigma.x + sigma.y));
    assert!(
        within(ratio, config.tracker.depth_to_lateral, 0.1),
        "{ratio}"
    );

    let rotation_rms_deg = (angles_squared / n as f64).sqrt().to_degrees();
    let configured = config.tracker.rotation_noise_rms_deg;
    assert!(
        within(rotation_rms_deg, configured, 0.1),
        "{rotation_rms_deg}°"
    );

    for tool in 0..3 {
        let mean = rms_sum[tool] / rms_count[tool] as f64;
        assert!(
            within(mean, truth.tracker.fit_rms_mm[tool], 0.1),
            "tool {tool}: {mean}"
        );
    }
}

#[test]
fn latency_frame_rate_and_frame_counter_match_the_configuration() {
    let mut config = short_config(22, 0.2);
    config.tracker.frame_increment = 3;
    let (recording, truth) = session(&config);
    let latency = truth.tracker.latency_ms();
    assert!((20.0..=60.0).contains(&latency), "{latency}");
    let delays: Vec<f64> = truth
        .frames
        .iter()
        .filter_map(|f| f.arrival_ns.map(|a| (a - f.exposure_ns) as f64 * 1e-6))
        .collect();
    let measured = median(delays.clone());
    assert!(
        within(measured, latency, 0.1),
        "median {measured} ms vs {latency} ms"
    );
    let spread = median(delays.iter().map(|d| (d - measured).abs()).collect());
    assert!(
        spread > 0.1 && spread < 3.0 * config.tracker.jitter_ms,
        "{spread}"
    );

    let first = truth.frames.first().unwrap();
    let last = truth.frames.last().unwrap();
    let rate =
        (truth.frames.len() - 1) as f64 / ((last.exposure_ns - first.exposure_ns) as f64 * 1e-9);
    assert!(
        within(rate, config.tracker.rate_hz, 0.1),
        "exposure rate {rate}"
    );

    // Recorded rows: stamped with the arrival of their frame, frame counter steps of 3.
    let mut received: Vec<(u32, i64)> = recording
        .tracker
        .iter()
        .map(|r| (r.frame, r.t_ns))
        .collect();
    received.dedup();
    for (frame, t_ns) in &received {
        let truth_frame = truth.frames.iter().find(|f| f.frame == *frame).unwrap();
        assert_eq!(truth_frame.arrival_ns, Some(*t_ns));
    }
    let steps: Vec<u32> = received.windows(2).map(|w| w[1].0 - w[0].0).collect();
    assert!(steps.iter().all(|s| s % 3 == 0 && *s > 0), "{steps:?}");
    assert!(steps.iter().filter(|s| **s == 3).count() as f64 > 0.95 * steps.len() as f64);
    let span_s = (received.last().unwrap().1 - received[0].1) as f64 * 1e-9;
    let received_rate = (received.len() - 1) as f64 / span_s;
    assert!(
        within(received_rate, config.tracker.rate_hz, 0.1),
        "arrival rate {received_rate}"
    );

    let dropped = truth
        .frames
        .iter()
        .filter(|f| f.arrival_ns.is_none())
        .count();
    assert_eq!(dropped, truth.frames.len() - received.len());
    assert!(dropped < truth.frames.len() / 20, "{dropped} dropped");
    let missing = recording
        .tracker
        .iter()
        .filter(|r| r.tool != Tool::Tip && r.reading == ToolReading::Missing)
        .count();
    assert!(
        missing > 0 && missing < recording.tracker.len() / 20,
        "{missing} missing"
    );

    let encoder_span = recording.encoders.last().unwrap().t_ns - recording.encoders[0].t_ns;
    let encoder_rate = (recording.encoders.len() - 1) as f64 / (encoder_span as f64 * 1e-9);
    assert!(
        within(encoder_rate, config.encoder.rate_hz, 0.1),
        "{encoder_rate}"
    );
}

#[test]
fn tip_sphere_is_seen_only_in_the_tip_phase() {
    let (recording, _) = session(&short_config(23, 0.1));
    let tip = phase(&recording, "tip");
    let rows: Vec<_> = recording
        .tracker
        .iter()
        .filter(|r| r.tool == Tool::Tip)
        .collect();
    let seen: Vec<_> = rows
        .iter()
        .filter(|r| matches!(r.reading, ToolReading::Point { .. }))
        .collect();
    let latency_ns = 200_000_000;
    assert!(seen
        .iter()
        .all(|r| tip.t_start_ns <= r.t_ns && r.t_ns <= tip.t_end_ns + latency_ns));
    let in_phase = rows
        .iter()
        .filter(|r| tip.t_start_ns + latency_ns <= r.t_ns && r.t_ns <= tip.t_end_ns)
        .count();
    assert!(
        seen.len() as f64 > 0.9 * in_phase as f64,
        "{} of {in_phase}",
        seen.len()
    );
}

#[test]
fn counts_equal_the_quantised_true_motor_angles() {
    let config = short_config(24, 0.1);
    let prepared = Session::new(&config).unwrap();
    let (recording, truth) = prepared.record().unwrap();
    let robot = &truth.robot;
    let params = &robot.params.joints;
    let offsets = robot.power_up_joints;
    let mut largest = [0i64; 5];
    for row in &recording.encoders {
        let t = row.t_ns - truth.host_start_ns;
        let commanded = prepared.plan().joints_at(t);
        for i in 0..5 {
            let blocked = robot.stop_side[i] * (commanded[i] - robot.stops[i]) > 0.0;
            let q = if blocked {
                robot.stops[i]
            } else {
                commanded[i]
            };
            let motor = (q - offsets[i]) / params.gear_ratio[i];
            let counts = (motor * params.counts_per_rev[i] as f64 / (2.0 * PI)).round() as i64;
            assert_eq!(row.counts[i], counts, "joint {} at t = {t} ns", i + 1);
            largest[i] = largest[i].max(counts.abs());
        }
    }
    assert_eq!(recording.encoders[0].counts, [0; 5], "counts start at zero");
    assert!(
        largest.iter().all(|c| *c > 200),
        "the robot barely moved: {largest:?}"
    );

    // In the homing dwell the true map of the counts gives the true stops.
    let homing = phase(&recording, "homing");
    for row in recording
        .encoders
        .iter()
        .filter(|r| homing.t_start_ns <= r.t_ns && r.t_ns <= homing.t_end_ns)
    {
        let motor = robot.params.motor_angles(&row.counts);
        for (i, stop) in robot.stops.iter().enumerate() {
            let q = params.gear_ratio[i] * motor[i] + offsets[i];
            let count_step = params.gear_ratio[i] * 2.0 * PI / params.counts_per_rev[i] as f64;
            assert!((q - stop).abs() <= count_step, "joint {}", i + 1);
        }
    }
}
