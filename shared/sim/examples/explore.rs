use sabr_model::{forward, JointMotion};
use sabr_sim::*;
use std::f64::consts::PI;

fn main() {
    let scale: f64 = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(0.2);
    for seed in 0..40u64 {
        let mut config = SimConfig::new(seed);
        config.duration_scale = scale;
        let t0 = std::time::Instant::now();
        let (rec, truth) = record_session(&config).unwrap();
        let dt = t0.elapsed();
        let homing = rec.phases.iter().find(|p| p.phase == "homing").unwrap();
        let c = rec
            .encoders
            .iter()
            .filter(|r| r.t_ns >= homing.t_start_ns && r.t_ns <= homing.t_end_ns)
            .last()
            .unwrap()
            .counts;
        let mut nominal = config.nominal.clone();
        let cpr = nominal.joints.counts_per_rev;
        let gr = nominal.joints.gear_ratio;
        let stops = nominal.joints.home_stops;
        nominal.joints.offset = Some(std::array::from_fn(|i| {
            stops[i] - gr[i] * 2.0 * PI * c[i] as f64 / cpr[i] as f64
        }));
        let mut sq = 0.0;
        let mut tips = vec![];
        for v in &truth.validation {
            let q = nominal
                .joints_from_counts(&v.counts, &JointMotion::default())
                .unwrap();
            let p = forward(&nominal.geometry, &q).unwrap();
            sq += (p.tip - v.tip).norm_squared();
            tips.push(v.tip);
        }
        let rms = (sq / truth.validation.len() as f64).sqrt();
        let (mut lo, mut hi) = ([1e9f64; 3], [-1e9f64; 3]);
        for t in &tips {
            for k in 0..3 {
                lo[k] = lo[k].min(t[k]);
                hi[k] = hi[k].max(t[k]);
            }
        }
        println!("seed {seed}: {} enc {} trk rows, {:.1}s robot, rec {:?}, nominal val rms {rms:.2} mm, lat {:.1} ms, val tips x[{:.0},{:.0}] y[{:.0},{:.0}] z[{:.0},{:.0}]",
            rec.encoders.len(), rec.tracker.len(), (rec.encoders.last().unwrap().t_ns - rec.encoders[0].t_ns) as f64 *1e-9, dt, truth.tracker.latency_ms(), lo[0],hi[0],lo[1],hi[1],lo[2],hi[2]);
    }
}
