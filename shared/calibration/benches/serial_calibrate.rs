//! Benchmark of the serial-arm calibration (`sabr calibrate` on a poses-v1 recording): wall
//! time of reading the recording and running the whole pipeline (set-ups, geometric fit,
//! effect families, report), best and median of RUNS.
//!
//! `cargo bench -p sabr-calibration --bench serial_calibrate -- REC [RUNS]` with REC a
//! poses-v1 recording (e.g. the UR10 data imported by `sabr import ipa`, about 16 000
//! poses); without REC, 16 000 simulated UR10 poses with geometric and periodic errors.

use std::path::Path;
use std::time::Instant;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sabr_calibration::calibrate_serial::{calibrate_serial, SerialOptions};
use sabr_model::KinematicTree;
use sabr_recording::poses::{
    Measured, PoseRow, PosesRecording, PosesRobot, Target, TargetMeasurement,
};

/// 16 000 simulated poses of the UR10 with a few geometric errors and a harmonic.
fn simulated() -> PosesRecording {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../model/robots/ur10.urdf");
    let text = std::fs::read_to_string(path).unwrap();
    let tree = KinematicTree::from_urdf_str(&text).unwrap();
    let mut errors = tree.nominal_errors();
    errors[13] = 0.5;
    errors[20] = 3e-4;
    let tool = tree.link_id("tool0").unwrap();
    let setup = Isometry3::from_parts(
        Translation3::new(2400.0, -1300.0, 150.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 2.3),
    );
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let noise = Normal::new(0.0, 0.02).unwrap();
    let rows = (0..16_000)
        .map(|index| {
            let joints: Vec<f64> = (0..6).map(|_| rng.random_range(-2.5..2.5)).collect();
            let mut actual = joints.clone();
            actual[2] += 2e-4 * (3.0 * joints[2]).sin();
            let state = tree.forward(&actual, &errors).unwrap();
            let p = setup * (state.link_pose(tool) * Point3::new(0.0, 0.0, 100.0));
            PoseRow {
                line: 0,
                setup: "placement".into(),
                sequence: "run".into(),
                index,
                joints,
                targets: vec![Some(TargetMeasurement {
                    position_mm: [
                        p.x + noise.sample(&mut rng),
                        p.y + noise.sample(&mut rng),
                        p.z + noise.sample(&mut rng),
                    ],
                    orientation: None,
                    position_std_mm: None,
                    orientation_std_rad: None,
                })],
                temperature_c: None,
            }
        })
        .collect();
    PosesRecording {
        dir: "simulated".into(),
        robot: PosesRobot::new(
            "robot.urdf",
            vec![Target {
                name: "prism".into(),
                link: "tool0".into(),
                measured: Measured::Point,
                mounting_translation: Some([0.0, 0.0, 100.0]),
                mounting_rotation: None,
            }],
        ),
        urdf_text: text,
        joints: tree.variables().iter().map(|v| v.name.clone()).collect(),
        rows,
    }
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let runs: usize = args.get(1).map_or(3, |s| s.parse().unwrap());
    let mut times = Vec::new();
    for _ in 0..runs {
        let started = Instant::now();
        let recording = match args.first() {
            Some(dir) => PosesRecording::read(Path::new(dir)).unwrap(),
            None => simulated(),
        };
        let calibration = calibrate_serial(&recording, &SerialOptions::default()).unwrap();
        times.push(started.elapsed().as_secs_f64());
        let last = calibration.report.steps.last().unwrap();
        println!(
            "{} poses, {} steps, final held-out RMS {:.3} mm: {:.2} s",
            recording.rows.len(),
            calibration.report.steps.len(),
            last.held_out.map_or(f64::NAN, |s| s.rms_mm),
            times[times.len() - 1]
        );
    }
    times.sort_by(f64::total_cmp);
    println!(
        "serial calibrate: best {:.2} s, median {:.2} s over {runs} runs",
        times[0],
        times[runs / 2]
    );
}
