//! Development aid for the residual loop: simulates a session for a seed with injected
//! effects (the calibrator is not told), calibrates it, and prints what the loop found and
//! the tip error against the simulator's truth.
//!
//! `cargo run --release -p sabr-calibration --example effects_sim -- SEED SCALE [EFFECT...]`,
//! e.g. `... -- 3 0.25 ripple:joint=2,harmonic=1,amplitude=0.002,phase=0.4`. With
//! `EFFECTS_OUT=DIR` the calibration outputs are written to DIR.

use sabr_calibration::data::motion::MotionTrack;
use sabr_calibration::{calibrate, CalibrationOptions};
use sabr_model::DIRECTION_DEAD_BAND_COUNTS;
use sabr_model::{forward, RobotParams};
use sabr_recording::Recording;
use sabr_sim::{record_session, SimConfig, SimEffect, Truth};

/// RMS tip error (mm) of `params` against the truth at the validation holds, with the
/// motion direction the encoder history gives.
fn truth_tip_rms(
    params: &RobotParams,
    recording: &Recording,
    truth: &Truth,
) -> anyhow::Result<f64> {
    let times: Vec<i64> = recording.encoders.iter().map(|r| r.t_ns).collect();
    let counts: Vec<[i64; 5]> = recording.encoders.iter().map(|r| r.counts).collect();
    let motion = MotionTrack::new(&times, &counts, DIRECTION_DEAD_BAND_COUNTS);
    let mut sum = 0.0;
    for hold in &truth.validation {
        let middle = 0.5 * (hold.t_start_ns + hold.t_end_ns) as f64;
        let q = params.joints_from_counts(&hold.counts, &motion.at(middle))?;
        sum += (forward(&params.effective_geometry(), &q)?.tip - hold.tip).norm_squared();
    }
    Ok((sum / truth.validation.len() as f64).sqrt())
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map_or(Ok(1), |s| s.parse())?;
    let scale: f64 = args.next().map_or(Ok(0.25), |s| s.parse())?;
    let effects: Vec<SimEffect> = args.map(|s| s.parse()).collect::<Result<_, _>>()?;
    let mut config = SimConfig::new(seed);
    config.duration_scale = scale;
    config.durations.validation_poses = 60;
    config.effects = effects;
    let (recording, truth) = record_session(&config)?;
    let started = std::time::Instant::now();
    let calibration = calibrate(&recording, &CalibrationOptions::default())?;
    println!("calibrated in {:.2} s", started.elapsed().as_secs_f64());
    if let Some(dir) = std::env::var_os("EFFECTS_OUT") {
        sabr_calibration::write_outputs(&calibration, std::path::Path::new(&dir))?;
    }
    let report = &calibration.report;
    print!("{}", sabr_calibration::report::summary_text(report));
    for e in &report.effects {
        println!("  {} evidence {:?}", e.label, e.evidence);
        if !e.evidence.aliases.is_empty() {
            println!(
                "  {} could equally be: {}",
                e.label,
                e.evidence.aliases.join(", ")
            );
        }
    }
    println!("leads:");
    for c in &report.r#final.leads {
        println!(
            "  {:40} Δχ² {:10.1} share {:.4} held-out {:10.1} sig {}",
            c.label, c.chi2_gain, c.explained_share, c.held_out_gain, c.significant
        );
    }
    println!("hysteresis (joint error by direction; direction × error along the travel):");
    for h in &report.r#final.hysteresis {
        let travel: Vec<String> = h
            .by_travel_mrad
            .iter()
            .map(|(t, e, _)| format!("{t:.1}:{e:+.3}"))
            .collect();
        println!(
            "  θ{} down/up {:?} mrad; {}",
            h.joint,
            h.mean_by_direction_mrad
                .map(|m| m.map(|v| (v * 1e3).round() / 1e3)),
            travel.join(" ")
        );
    }
    println!("strongest correlates of the final residual:");
    for c in &report.r#final.strongest_correlates {
        println!(
            "  {:40} Δχ² {:10.1} share {:.4} held-out {:10.1} sig {}",
            c.label, c.chi2_gain, c.explained_share, c.held_out_gain, c.significant
        );
    }
    for t in &report.r#final.metrics.noise_test {
        println!(
            "noise test {}: ratio {:.3} dof {:.0}/{:.0} p {:.2e}",
            t.tool, t.variance_ratio, t.dof, t.reference_dof, t.p_value
        );
    }
    let mut paper = calibration.params.clone();
    paper.effects.clear();
    println!(
        "truth tip RMS mm: final model {:.4}, its paper part alone {:.4}; latency {:.2} ms (truth {:.2})",
        truth_tip_rms(&calibration.params, &recording, &truth)?,
        truth_tip_rms(&paper, &recording, &truth)?,
        report.latency_ms,
        truth.tracker.latency_ms()
    );
    println!("true effects: {:?}", truth.robot.params.effects);
    println!("fitted effects: {:?}", calibration.params.effects);
    Ok(())
}
