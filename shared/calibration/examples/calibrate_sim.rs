//! Development aid: simulates a session for a seed and calibrates it, printing the errors
//! against the simulator's truth. `cargo run --release -p sabr-calibration --example
//! calibrate_sim -- SEED [DURATION_SCALE]`.

use sabr_calibration::{calibrate, CalibrationOptions};
use sabr_sim::{record_session, SimConfig};

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map_or(Ok(1), |s| s.parse())?;
    let scale: f64 = args.next().map_or(Ok(1.0), |s| s.parse())?;
    let mut config = SimConfig::new(seed);
    config.duration_scale = scale;
    let (recording, truth) = record_session(&config)?;
    let started = std::time::Instant::now();
    let calibration = calibrate(&recording, &CalibrationOptions::default())?;
    println!("calibrated in {:.2} s", started.elapsed().as_secs_f64());
    println!(
        "{}",
        serde_json::to_string_pretty(&calibration.report.residual_rms)?
    );
    println!("validation {:?}", calibration.report.validation.tip_error);
    println!(
        "latency {:.3} ms, truth {:.3} ms, model-free {:.3}",
        calibration.report.latency_ms,
        truth.tracker.latency_ms(),
        calibration.report.time_sync.model_free_latency_ms
    );
    let p = &calibration.params;
    let t = &truth.robot.params;
    for j in 0..5 {
        println!(
            "GR{} rel err {:+.5}%  stepwise {:+.5}%",
            j + 1,
            (p.joints.gear_ratio[j] / t.joints.gear_ratio[j] - 1.0) * 100.0,
            (calibration.stepwise.robot.joints.gear_ratio[j] / t.joints.gear_ratio[j] - 1.0)
                * 100.0
        );
    }
    let mut errors = Vec::new();
    let mut errors_step = Vec::new();
    let mut errors_nom = Vec::new();
    for v in &truth.validation {
        let tip = |params: &sabr_model::RobotParams| -> anyhow::Result<f64> {
            let q = params.joints_from_counts(&v.counts, &Default::default())?;
            let pose = sabr_model::forward(&params.effective_geometry(), &q)?;
            Ok((pose.tip - v.tip).norm())
        };
        errors.push(tip(p)?);
        errors_step.push(tip(&calibration.stepwise.robot)?);
        errors_nom.push(tip(&calibration.nominal.robot)?);
    }
    let rms = |e: &[f64]| (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
    println!(
        "truth tip RMS: nominal {:.4} stepwise {:.4} joint {:.4} (max {:.4})",
        rms(&errors_nom),
        rms(&errors_step),
        rms(&errors),
        errors.iter().copied().fold(0.0, f64::max)
    );
    println!(
        "ident rank {} cond {:.3e} fixed {:?}",
        calibration.report.identifiability.rank,
        calibration.report.identifiability.condition_number,
        calibration.report.identifiability.fixed
    );
    println!("noise {:?}", calibration.report.noise.fitted);
    for row in &calibration.report.parameters {
        println!(
            "{:28} nom {:12.6} step {:12.6} joint {:12.6} ± {:?}",
            row.name, row.nominal, row.stepwise, row.joint, row.std_dev
        );
    }
    println!(
        "truth mounts f {:?} b {:?} base {:?} l_n {}",
        t.markers.front_mount, t.markers.back_mount, t.geometry.front_base, t.geometry.l_n
    );
    Ok(())
}
