//! Cost of the serial-arm kinematics the calibration engine calls per pose: UR10 forward
//! kinematics of every link plus the 6-D Jacobian of the probe (36 error parameters, 6
//! joints), and one Gauss-Newton normal-equation build over 16,000 poses.
//! Run: `cargo bench -p sabr-model --bench tree`.

use std::hint::black_box;

use criterion::{criterion_main, Criterion};
use nalgebra::{DMatrix, Isometry3, Vector3};
use sabr_model::KinematicTree;

const UR10: &str = include_str!("../robots/ur10.urdf");

/// A fixed spread of joint vectors.
fn joint_samples(count: usize) -> Vec<Vec<f64>> {
    (0..count)
        .map(|k| {
            (0..6)
                .map(|i| 2.0 * ((k * (2 * i + 3)) as f64 * 0.37).sin())
                .collect()
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let tree = KinematicTree::from_urdf_str(UR10).unwrap();
    let tool0 = tree.link_id("tool0").unwrap();
    let mounting = Isometry3::new(Vector3::new(0.0, 0.0, 109.0), Vector3::new(0.0, 0.0, 1.57));
    let errors: Vec<f64> = (0..tree.error_parameters().len())
        .map(|i| 1e-4 * i as f64)
        .collect();
    let samples = joint_samples(64);
    let mut state = tree.forward(&samples[0], &errors).unwrap();
    let mut k = 0;
    c.bench_function("ur10 forward + pose jacobian", |b| {
        b.iter(|| {
            k = (k + 1) % samples.len();
            tree.forward_into(&mut state, black_box(&samples[k]), &errors)
                .unwrap();
            black_box(tree.pose_jacobian(&state, tool0, &mounting))
        })
    });
    let poses = joint_samples(16_000);
    let mut group = c.benchmark_group("gauss-newton");
    group.sample_size(10);
    group.bench_function("normal equations, 16000 poses x 6 rows x 42 columns", |b| {
        b.iter(|| {
            let mut normal = DMatrix::<f64>::zeros(42, 42);
            let mut block = DMatrix::<f64>::zeros(6, 42);
            for joints in &poses {
                tree.forward_into(&mut state, joints, &errors).unwrap();
                let jacobian = tree.pose_jacobian(&state, tool0, &mounting);
                block.columns_mut(0, 36).copy_from(&jacobian.errors);
                block.columns_mut(36, 6).copy_from(&jacobian.joints);
                normal.gemm_tr(1.0, &block, &block, 1.0);
            }
            black_box(normal)
        })
    });
    group.finish();
}

/// The criterion group (its generated function is public, so it lives in a private module).
mod groups {
    criterion::criterion_group!(tree, super::bench);
}

criterion_main!(groups::tree);
