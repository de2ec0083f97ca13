//! The live matcher and the engine's offline time sync agree on a recording.
//!
//! A simulated session (`sabr_sim::record_session`) is replayed through [`Matcher`] in host
//! time order, as the sync process would receive it, with the session's true latency
//! configured. The engine synchronises the same recording offline
//! (`SessionData::synchronise`) and puts every frame's exposure at the same latency. The two
//! differ only by their clock lines: the live one over a sliding window at the newest frame,
//! the offline one over the whole session. With ~1 ms of arrival jitter the live line's
//! predicted uncertainty is at most 250 µs once locked, so:
//!
//! - every matched exposure lies within [`MAX_DIFFERENCE_NS`] (1 ms) of the offline one, and
//!   99 % within [`P99_DIFFERENCE_NS`] (0.5 ms);
//! - the mean difference is below [`MEAN_DIFFERENCE_NS`] (0.1 ms): the two lines have the same
//!   definition (the same robust fit), so there is no systematic offset between them;
//! - the encoder counts the matcher interpolated at its exposure equal the engine's encoder
//!   track at that instant (the two interpolate the same samples linearly).

use sabr_calibration::data::encoders::EncoderTrack;
use sabr_calibration::data::phases::PhaseTable;
use sabr_calibration::data::session::SessionData;
use sabr_model::RobotParams;
use sabr_msgs::{EncoderSample, LatencySource, MatchedSample, TrackerFrame};
use sabr_recording::Recording;
use sabr_sim::{record_session, SimConfig};
use sabr_sync::latency::Latency;
use sabr_sync::matcher::{Matcher, MatcherConfig};
use std::collections::HashMap;

/// Largest difference between a live and the offline exposure time (ns).
const MAX_DIFFERENCE_NS: f64 = 1_000_000.0;
/// 99th percentile of the absolute differences (ns).
const P99_DIFFERENCE_NS: f64 = 500_000.0;
/// Largest mean difference (ns).
const MEAN_DIFFERENCE_NS: f64 = 100_000.0;
/// Largest gap the engine's encoder track interpolates across (ns), as `sabr calibrate`.
const MAX_ENCODER_GAP_NS: i64 = 5_000_000;

/// The tracker frames of a recording (rows grouped by frame counter and stamp), in order,
/// stamped as the tracker node does: `t_ns` is the availability, `arrival_t_ns` the arrival.
fn tracker_frames(recording: &Recording) -> Vec<TrackerFrame> {
    let mut frames: Vec<TrackerFrame> = Vec::new();
    for row in &recording.tracker {
        let same = frames
            .last()
            .is_some_and(|f| f.frame_number == row.frame && f.available_t_ns == row.t_ns);
        if !same {
            frames.push(TrackerFrame {
                seq: frames.len() as u64 + 1,
                arrival_t_ns: row.arrival_t_ns,
                available_t_ns: row.t_ns,
                sent_t_ns: 0, // not recorded
                frame_number: row.frame,
                tools: Default::default(),
            });
        }
    }
    frames
}

/// Replays `recording` through a matcher at `latency`, polling at every encoder sample as
/// the node does; returns the matched samples.
fn replay(recording: &Recording, robot: &RobotParams, latency: Latency) -> Vec<MatchedSample> {
    let mut matcher = Matcher::new(MatcherConfig::default(), robot.joints.counts_per_rev);
    let frames = tracker_frames(recording);
    let mut matched = Vec::new();
    let mut collect = |result: Result<MatchedSample, _>| {
        if let Ok(sample) = result {
            matched.push(sample);
        }
    };
    let mut next_frame = 0;
    for (seq, row) in recording.encoders.iter().enumerate() {
        while next_frame < frames.len() && frames[next_frame].arrival_t_ns <= row.t_ns {
            let frame = frames[next_frame];
            let _ = matcher.push_frame(frame, Some(latency), frame.arrival_t_ns);
            next_frame += 1;
        }
        matcher.push_encoder(EncoderSample {
            seq: seq as u64 + 1,
            t_ns: row.t_ns,
            counts: row.counts,
        });
        matcher.poll(row.t_ns, &mut collect);
    }
    matcher.poll(i64::MAX, &mut collect);
    matched
}

#[test]
fn live_matched_exposures_agree_with_the_offline_time_sync() {
    let mut config = SimConfig::new(2);
    config.duration_scale = 0.5;
    let (recording, truth) = record_session(&config).expect("simulated session");
    let robot = RobotParams::from_toml_str(&recording.robot_toml).expect("robot.toml");
    let latency_ns = (truth.tracker.latency_ms() * 1e6).round() as i64;
    let latency = Latency {
        ns: latency_ns,
        source: LatencySource::Configured,
    };

    let offline = SessionData::synchronise(
        &recording,
        &robot,
        PhaseTable::new(&recording.phases),
        MAX_ENCODER_GAP_NS,
    )
    .expect("offline time sync");
    let offline_exposure: HashMap<u32, f64> = offline
        .frames
        .iter()
        .enumerate()
        .map(|(index, frame)| {
            (
                frame.frame,
                offline.exposure_ns(index, latency_ns as f64 * 1e-9),
            )
        })
        .collect();
    let encoders = EncoderTrack::new(&recording.encoders, MAX_ENCODER_GAP_NS).expect("encoders");

    let matched = replay(&recording, &robot, latency);
    let compared: Vec<(&MatchedSample, f64)> = matched
        .iter()
        .filter_map(|m| {
            let offline = offline_exposure.get(&m.frame_number)?;
            Some((m, m.exposure_t_ns as f64 - offline))
        })
        .collect();
    assert!(
        compared.len() * 10 >= offline.frames.len() * 9,
        "only {} of {} offline frames matched live",
        compared.len(),
        offline.frames.len()
    );

    let mut magnitudes: Vec<f64> = compared.iter().map(|(_, d)| d.abs()).collect();
    magnitudes.sort_by(f64::total_cmp);
    let largest = *magnitudes.last().expect("frames compared");
    let p99 = magnitudes[magnitudes.len() * 99 / 100];
    let mean = compared.iter().map(|(_, d)| d).sum::<f64>() / compared.len() as f64;
    println!(
        "{} frames compared: live − offline exposure mean {mean:.0} ns, p99 |·| {p99:.0} ns, \
         largest {largest:.0} ns",
        compared.len()
    );
    assert!(
        largest <= MAX_DIFFERENCE_NS,
        "largest difference {largest} ns"
    );
    assert!(p99 <= P99_DIFFERENCE_NS, "p99 difference {p99} ns");
    assert!(
        mean.abs() <= MEAN_DIFFERENCE_NS,
        "mean difference {mean} ns"
    );

    for (sample, _) in &compared {
        let expected = encoders
            .counts_at(sample.exposure_t_ns as f64)
            .expect("the engine's track covers every live match");
        for (live, offline) in sample.counts.iter().zip(expected) {
            assert!(
                (live - offline).abs() < 1e-6,
                "frame {}: counts {:?} vs {expected:?}",
                sample.frame_number,
                sample.counts
            );
        }
    }
}
