//! Time per call of forward and inverse kinematics (nominal geometry, targets near home).
//! Run: `cargo bench -p sabr-model --bench kinematics`.
//!
//! Each is measured twice: in wall-clock time (criterion's default) and in the benchmark
//! thread's own CPU time (`CLOCK_THREAD_CPUTIME_ID`), which does not count
//! the time the thread waits for a core on a busy machine.

use std::hint::black_box;

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{criterion_main, Criterion};
use nalgebra::{Point3, Vector3};
use nix::time::{clock_gettime, ClockId};
use sabr_model::{forward, inverse, Joints, RobotParams, HOME_JOINTS};

/// A fixed spread of joint vectors within ±0.15 rad of home.
fn joint_samples() -> Vec<Joints> {
    (0..64)
        .map(|k| std::array::from_fn(|i| HOME_JOINTS[i] + 0.15 * ((k * (2 * i + 3)) as f64).sin()))
        .collect()
}

/// Criterion measurement: CPU time (ns) the current thread has run
/// (`CLOCK_THREAD_CPUTIME_ID`).
struct ThreadCpuTime;

impl ThreadCpuTime {
    fn now() -> u64 {
        let time = clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID)
            .expect("the thread CPU clock is readable");
        time.tv_sec() as u64 * 1_000_000_000 + time.tv_nsec() as u64
    }
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;

    fn start(&self) -> u64 {
        Self::now()
    }
    fn end(&self, start: u64) -> u64 {
        Self::now() - start
    }
    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }
    fn zero(&self) -> u64 {
        0
    }
    fn to_f64(&self, value: &u64) -> f64 {
        *value as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        WallTime.formatter()
    }
}

/// Benchmarks FK and IK with measurement `M`, labelled `clock`.
fn kinematics_with<M: Measurement + 'static>(c: &mut Criterion<M>, clock: &str) {
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
    c.bench_function(&format!("forward (one call, {clock})"), |b| {
        b.iter(|| {
            k = (k + 1) % joints.len();
            forward(black_box(&geometry), black_box(&joints[k]))
        })
    });
    let mut k = 0;
    c.bench_function(&format!("inverse (one call, {clock})"), |b| {
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

fn wall_clock(c: &mut Criterion) {
    kinematics_with(c, "wall clock");
}

fn thread_cpu(c: &mut Criterion<ThreadCpuTime>) {
    kinematics_with(c, "thread CPU time");
}

/// The criterion groups (their generated functions are public, so they live in a private
/// module).
mod groups {
    criterion::criterion_group!(wall, super::wall_clock);
    criterion::criterion_group! {
        name = cpu;
        config = criterion::Criterion::default().with_measurement(super::ThreadCpuTime);
        targets = super::thread_cpu
    }
}

criterion_main!(groups::wall, groups::cpu);
