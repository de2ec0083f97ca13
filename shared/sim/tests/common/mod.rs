//! Helpers shared by the simulator's tests.

#![allow(dead_code)]

use std::f64::consts::PI;
use std::path::PathBuf;

use sabr_model::{forward, JointMotion};
use sabr_recording::{PhaseRow, Recording};
use sabr_sim::{SimConfig, Truth};

/// A fresh, empty temporary directory unique to this test and process.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sabr-sim-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A short session for debug-build tests.
pub fn short_config(seed: u64, scale: f64) -> SimConfig {
    let mut config = SimConfig::new(seed);
    config.duration_scale = scale;
    config
}

/// The phase named `name`.
pub fn phase<'a>(recording: &'a Recording, name: &str) -> &'a PhaseRow {
    recording
        .phases
        .iter()
        .find(|p| p.phase == name)
        .unwrap_or_else(|| panic!("no {name} phase"))
}

/// RMS tip error (mm) at the validation poses of the nominal model with the offsets a homing
/// gives (nominal stops minus the nominal map of the homing dwell counts).
pub fn nominal_validation_rms(config: &SimConfig, recording: &Recording, truth: &Truth) -> f64 {
    let homing = phase(recording, "homing");
    let dwell: Vec<_> = recording
        .encoders
        .iter()
        .filter(|r| homing.t_start_ns <= r.t_ns && r.t_ns <= homing.t_end_ns)
        .collect();
    assert!(
        dwell.len() > 100,
        "homing dwell has {} samples",
        dwell.len()
    );
    let counts = dwell[dwell.len() / 2].counts;
    let mut nominal = config.nominal.clone();
    let joints = &nominal.joints;
    nominal.joints.offset = Some(std::array::from_fn(|i| {
        joints.home_stops[i]
            - joints.gear_ratio[i] * 2.0 * PI * counts[i] as f64 / joints.counts_per_rev[i] as f64
    }));
    let mut sum = 0.0;
    for pose in &truth.validation {
        let row = recording
            .encoders
            .iter()
            .find(|r| r.t_ns >= (pose.t_start_ns + pose.t_end_ns) / 2)
            .unwrap();
        let q = nominal
            .joints_from_counts(&row.counts, &JointMotion::default())
            .unwrap();
        let tip = forward(&nominal.geometry, &q).unwrap().tip;
        sum += (tip - pose.tip).norm_squared();
    }
    (sum / truth.validation.len() as f64).sqrt()
}
