//! Time per call of forward and inverse kinematics (nominal geometry, targets near home).
//! Run: `cargo bench -p sabr-model --bench kinematics`.

use std::hint::black_box;

use criterion::{criterion_main, Criterion};
use nalgebra::{Point3, Vector3};
use sabr_model::{forward, inverse, Joints, RobotParams, HOME_JOINTS};

/// A fixed spread of joint vectors within ±0.15 rad of home.
fn joint_samples() -> Vec<Joints> {
    (0..64)
        .map(|k| std::array::from_fn(|i| HOME_JOINTS[i] + 0.15 * ((k * (2 * i + 3)) as f64).sin()))
        .collect()
}

fn kinematics(c: &mut Criterion) {
    let geometry = RobotParams::nominal().geometry;
    let joints = joint_samples();
    let targets: Vec<(Point3<f64>, Vector3<f64>)> = joints
        .iter()
        .map(|q| {
            let pose = forward(&geometry, q).unwrap();
            (pose.tip, pose.direction.into_inner())
        })
        .collect();

    let mut k = 0;
    c.bench_function("forward (one call)", |b| {
        b.iter(|| {
            k = (k + 1) % joints.len();
            forward(black_box(&geometry), black_box(&joints[k]))
        })
    });
    let mut k = 0;
    c.bench_function("inverse (one call)", |b| {
        b.iter(|| {
            k = (k + 1) % targets.len();
            let (tip, direction) = &targets[k];
            inverse(
                black_box(&geometry),
                black_box(tip),
                black_box(direction),
                black_box(&HOME_JOINTS),
            )
        })
    });
}

/// The criterion group (its generated function is public, so it lives in a private module).
mod group {
    criterion::criterion_group!(benches, super::kinematics);
}

criterion_main!(group::benches);
