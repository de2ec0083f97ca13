//! Compute costs: forward and inverse kinematics per solve (the nalgebra kinematics and the
//! real-time glam one), recording a simulated session (`sabr sim record`) and calibrating it
//! (what `sabr calibrate` does: read, calibrate, write).

use super::stats::{duration_ns, Measurement};
use anyhow::{bail, Context};
use glam::DVec3;
use sabr_calibration::{calibrate, write_outputs, CalibrationOptions};
use sabr_model::realtime::RealtimeGeometry;
use sabr_model::{forward, inverse, Geometry, Joints, RobotParams, HOME_JOINTS};
use sabr_recording::Recording;
use sabr_sim::{record_session, write_session, SimConfig};
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

/// Solves per timed batch: the batch time / this is one recorded value, so the clock read
/// (~25 ns) does not distort a sub-microsecond solve.
pub const SOLVES_PER_BATCH: u64 = 100;

/// Joint vectors tried around [`HOME_JOINTS`] (those FK and IK both solve are used).
const POSE_CANDIDATES: usize = 64;

/// Largest offset from home of a candidate joint angle (rad).
const POSE_SPREAD_RAD: f64 = 0.08;

/// Seed of the simulated session (as `sabr sim record --seed 1`).
pub const SESSION_SEED: u64 = 1;

/// An IK target: the tip (mm, `Bb`) and needle direction of a joint vector, and the joints.
pub struct Target {
    /// Joints θ1..θ5 (rad).
    pub joints: Joints,
    /// Needle tip `p_n` in `Bb` (mm).
    pub tip: nalgebra::Point3<f64>,
    /// Needle direction `z_N` in `Bb` (unit vector).
    pub direction: nalgebra::Vector3<f64>,
}

/// Deterministic joint vectors around home, each reachable by FK and solvable back by IK
/// (from [`HOME_JOINTS`]) with `geometry`.
pub fn targets(geometry: &Geometry) -> anyhow::Result<Vec<Target>> {
    let mut found = Vec::new();
    for index in 0..POSE_CANDIDATES {
        let mut joints = HOME_JOINTS;
        for (axis, angle) in joints.iter_mut().enumerate() {
            let phase = index as f64 * 1.618 + axis as f64 * 2.399;
            *angle += POSE_SPREAD_RAD * phase.sin();
        }
        let Ok(pose) = forward(geometry, &joints) else {
            continue;
        };
        let direction = pose.direction.into_inner();
        if inverse(geometry, &pose.tip, &direction, &HOME_JOINTS).is_ok() {
            found.push(Target {
                joints,
                tip: pose.tip,
                direction,
            });
        }
    }
    if found.len() < POSE_CANDIDATES / 2 {
        bail!(
            "only {} of {POSE_CANDIDATES} poses near home are solvable by FK and IK",
            found.len()
        );
    }
    Ok(found)
}

/// Per-solve times with the nominal model, in batches of [`SOLVES_PER_BATCH`] (`batches`
/// recorded values each, ns/solve), in the order of [`KinematicsCosts`].
pub fn kinematics(batches: u64) -> anyhow::Result<KinematicsCosts> {
    let geometry = RobotParams::nominal().effective_geometry();
    let realtime = RealtimeGeometry::from(&geometry);
    let targets = targets(&geometry)?;
    let glam_targets: Vec<(DVec3, DVec3)> = targets
        .iter()
        .map(|target| {
            (
                DVec3::from_array(target.tip.coords.into()),
                DVec3::from_array(target.direction.into()),
            )
        })
        .collect();
    let mut fk = Measurement::new("compute/fk", "ns/solve");
    let mut ik = Measurement::new("compute/ik", "ns/solve");
    let mut fk_glam = Measurement::new("compute/fk-glam", "ns/solve");
    let mut ik_glam = Measurement::new("compute/ik-glam", "ns/solve");
    let mut next = targets.iter().zip(&glam_targets).cycle();
    for _ in 0..batches {
        let started = Instant::now();
        for (target, _) in next.by_ref().take(SOLVES_PER_BATCH as usize) {
            black_box(forward(black_box(&geometry), black_box(&target.joints)))?;
        }
        fk.record(duration_ns(started.elapsed()) / SOLVES_PER_BATCH)?;

        let started = Instant::now();
        for (target, _) in next.by_ref().take(SOLVES_PER_BATCH as usize) {
            black_box(inverse(
                black_box(&geometry),
                black_box(&target.tip),
                black_box(&target.direction),
                black_box(&HOME_JOINTS),
            ))?;
        }
        ik.record(duration_ns(started.elapsed()) / SOLVES_PER_BATCH)?;

        let started = Instant::now();
        for (target, _) in next.by_ref().take(SOLVES_PER_BATCH as usize) {
            black_box(black_box(&realtime).forward(black_box(&target.joints)))?;
        }
        fk_glam.record(duration_ns(started.elapsed()) / SOLVES_PER_BATCH)?;

        let started = Instant::now();
        for (_, &(tip, direction)) in next.by_ref().take(SOLVES_PER_BATCH as usize) {
            black_box(black_box(&realtime).inverse(
                black_box(tip),
                black_box(direction),
                black_box(&HOME_JOINTS),
            ))?;
        }
        ik_glam.record(duration_ns(started.elapsed()) / SOLVES_PER_BATCH)?;
    }
    Ok(KinematicsCosts {
        fk,
        ik,
        fk_glam,
        ik_glam,
    })
}

/// Per-solve costs of the kinematics (ns/solve).
pub struct KinematicsCosts {
    /// `compute/fk`: `sabr_model::forward` (nalgebra).
    pub fk: Measurement,
    /// `compute/ik`: `sabr_model::inverse` (nalgebra).
    pub ik: Measurement,
    /// `compute/fk-glam`: `RealtimeGeometry::forward` (glam).
    pub fk_glam: Measurement,
    /// `compute/ik-glam`: `RealtimeGeometry::inverse` (glam), what the IK server runs.
    pub ik_glam: Measurement,
}

impl KinematicsCosts {
    /// The four measurements, in the order of the report's rows.
    pub fn into_rows(self) -> Vec<Measurement> {
        vec![self.fk, self.ik, self.fk_glam, self.ik_glam]
    }
}

/// Solves per second of the median batch of a `ns/solve` measurement (the mean would fold in
/// the batches the scheduler interrupted).
pub fn solves_per_second(per_solve: &Measurement) -> f64 {
    1e9 / per_solve.summary().p50 as f64
}

/// Times recording the default simulated session (seed [`SESSION_SEED`], phase durations ×
/// `duration_scale`) and writing it to `dir`, as `sabr sim record` does.
pub fn sim_record(dir: &Path, duration_scale: f64) -> anyhow::Result<Measurement> {
    let mut config = SimConfig::new(SESSION_SEED);
    config.duration_scale = duration_scale;
    let started = Instant::now();
    let (recording, truth) = record_session(&config).context("sim record failed")?;
    write_session(dir, &recording, &truth).context("sim record: writing failed")?;
    let mut measurement = Measurement::new(format!("compute/sim-record-x{duration_scale}"), "ns");
    measurement.record_duration(started.elapsed())?;
    Ok(measurement)
}

/// Times calibrating the recording in `recording_dir` (read, calibrate, write the outputs to
/// `out_dir`), as `sabr calibrate` does.
pub fn calibration(
    recording_dir: &Path,
    out_dir: &Path,
    name: &str,
) -> anyhow::Result<Measurement> {
    let started = Instant::now();
    let recording = Recording::read(recording_dir)?;
    let result =
        calibrate(&recording, &CalibrationOptions::default()).context("calibration failed")?;
    write_outputs(&result, out_dir)?;
    let mut measurement = Measurement::new(name, "ns");
    measurement.record_duration(started.elapsed())?;
    Ok(measurement)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_reproduce_their_joints_through_ik() {
        let geometry = RobotParams::nominal().effective_geometry();
        let targets = targets(&geometry).unwrap();
        assert!(targets.len() >= POSE_CANDIDATES / 2);
        for target in &targets {
            let q = inverse(&geometry, &target.tip, &target.direction, &HOME_JOINTS).unwrap();
            let tip = forward(&geometry, &q).unwrap().tip;
            assert!((tip - target.tip).norm() < 1e-6);
        }
    }

    #[test]
    fn kinematics_records_one_value_per_batch() {
        let rows = kinematics(3).unwrap().into_rows();
        let names: Vec<&str> = rows.iter().map(|row| row.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "compute/fk",
                "compute/ik",
                "compute/fk-glam",
                "compute/ik-glam"
            ]
        );
        for row in &rows {
            assert_eq!(row.summary().count, 3);
            assert!(row.summary().p50 > 0);
        }
        let ik = &rows[1];
        let rate = solves_per_second(ik);
        let median_ns = ik.summary().p50 as f64;
        assert!(
            (rate * median_ns - 1e9).abs() < 1.0,
            "{rate} solves/s vs {median_ns} ns"
        );
    }
}
