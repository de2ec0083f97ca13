//! A simulated session exported as MCAP and read back with the `mcap` crate: channels,
//! schemas, message counts against the recording, time order, and what the frames say.

use std::collections::BTreeMap;
use std::path::Path;

use sabr_foxglove::{export_recording, ExportModel, Topic};
use sabr_model::CalibrationInfo;
use sabr_recording::{write_all, Recording, Tool, ToolReading};
use sabr_sim::{record_session, SimConfig, Truth};
use serde_json::Value;

/// A short simulated session written to `dir` and read back as a user's recording would be.
fn session(dir: &Path, seed: u64) -> (Recording, Truth) {
    let mut config = SimConfig::new(seed);
    config.duration_scale = 0.04;
    let (recording, truth) = record_session(&config).unwrap();
    let rec_dir = dir.join("rec");
    write_all(&recording, &rec_dir).unwrap();
    (Recording::read(&rec_dir).unwrap(), truth)
}

/// One message read back.
struct Read {
    topic: String,
    log_time: u64,
    json: Value,
}

/// Per topic: schema name, schema encoding, message encoding.
type Channels = BTreeMap<String, (String, String, String)>;

/// Every message of `path`, with the schema name and encodings of each topic.
fn read_mcap(path: &Path) -> (Vec<Read>, Channels) {
    let bytes = std::fs::read(path).unwrap();
    let mut channels = BTreeMap::new();
    let mut messages = Vec::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let channel = &message.channel;
        let schema = channel.schema.as_ref().expect("every channel has a schema");
        let schema_json: Value = serde_json::from_slice(&schema.data).unwrap();
        assert_eq!(schema_json["title"], schema.name.as_str());
        channels.insert(
            channel.topic.clone(),
            (
                schema.name.clone(),
                schema.encoding.clone(),
                channel.message_encoding.clone(),
            ),
        );
        let json: Value = serde_json::from_slice(&message.data).unwrap();
        let keys = |object: &Value| -> Vec<String> {
            let mut keys: Vec<String> = object.as_object().unwrap().keys().cloned().collect();
            keys.sort();
            keys
        };
        assert_eq!(
            keys(&json),
            keys(&schema_json["properties"]),
            "{}: the message has exactly the schema's fields",
            channel.topic
        );
        messages.push(Read {
            topic: channel.topic.clone(),
            log_time: message.log_time,
            json,
        });
    }
    (messages, channels)
}

fn count(messages: &[Read], topic: Topic) -> usize {
    messages.iter().filter(|m| m.topic == topic.name()).count()
}

#[test]
fn nominal_export_reads_back_with_one_message_per_sample_in_time_order() {
    let dir = tempfile::tempdir().unwrap();
    let (recording, _) = session(dir.path(), 3);
    let out = dir.path().join("session.mcap");
    let summary = export_recording(&recording, &ExportModel::Nominal, &out).unwrap();
    let (messages, channels) = read_mcap(&out);

    let expected: Channels = [
        (Topic::TrackerTf, "foxglove.FrameTransforms"),
        (Topic::TrackerTip, "foxglove.PoseInFrame"),
        (Topic::RobotTfStatic, "foxglove.FrameTransforms"),
        (Topic::RobotTf, "foxglove.FrameTransforms"),
        (Topic::JointStates, "sabr.JointState"),
        (Topic::RobotScene, "foxglove.SceneUpdate"),
        (Topic::Phases, "foxglove.Log"),
    ]
    .into_iter()
    .map(|(topic, schema)| {
        let encodings = ("jsonschema".to_owned(), "json".to_owned());
        (
            topic.name().to_owned(),
            (schema.to_owned(), encodings.0, encodings.1),
        )
    })
    .collect();
    assert_eq!(
        channels, expected,
        "no residual channel without a calibration"
    );

    let frames = sabr_foxglove::export::tracker_frames(&recording.tracker).len();
    let tips = recording
        .tracker
        .iter()
        .filter(|row| matches!(row.reading, ToolReading::Point { .. }))
        .count();
    assert!(tips > 0 && frames > 100, "{tips} tips, {frames} frames");
    assert_eq!(
        count(&messages, Topic::JointStates),
        recording.encoders.len()
    );
    assert_eq!(count(&messages, Topic::RobotTf), recording.encoders.len());
    assert_eq!(count(&messages, Topic::TrackerTf), frames);
    assert_eq!(count(&messages, Topic::TrackerTip), tips);
    assert_eq!(count(&messages, Topic::Phases), recording.phases.len());
    assert_eq!(count(&messages, Topic::RobotTfStatic), 1);
    assert_eq!(count(&messages, Topic::RobotScene), 1);
    let summed: u32 = summary.messages.values().sum();
    assert_eq!(summed as usize, messages.len());

    let mut last: BTreeMap<&str, u64> = BTreeMap::new();
    for message in &messages {
        let previous = last.insert(&message.topic, message.log_time);
        assert!(
            previous.is_none_or(|previous| previous <= message.log_time),
            "{} goes back in time at {}",
            message.topic,
            message.log_time
        );
    }
    let joint_times: Vec<u64> = messages
        .iter()
        .filter(|m| m.topic == Topic::JointStates.name())
        .map(|m| m.log_time)
        .collect();
    let encoder_times: Vec<u64> = recording.encoders.iter().map(|r| r.t_ns as u64).collect();
    assert_eq!(
        joint_times, encoder_times,
        "log time = the sample's time stamp"
    );

    let first_state = messages
        .iter()
        .find(|m| m.topic == Topic::JointStates.name())
        .unwrap();
    let counts: Vec<i64> = first_state.json["counts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_i64().unwrap())
        .collect();
    assert_eq!(counts, recording.encoders[0].counts.to_vec());
    let sec = first_state.json["timestamp"]["sec"].as_u64().unwrap();
    let nsec = first_state.json["timestamp"]["nsec"].as_u64().unwrap();
    assert_eq!(sec * 1_000_000_000 + nsec, first_state.log_time);
}

/// A pose (mm) from a Foxglove transform (m).
fn isometry(transform: &Value) -> nalgebra::Isometry3<f64> {
    let t = &transform["translation"];
    let r = &transform["rotation"];
    let f = |v: &Value| v.as_f64().unwrap();
    nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(f(&t["x"]) * 1e3, f(&t["y"]) * 1e3, f(&t["z"]) * 1e3),
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            f(&r["w"]),
            f(&r["x"]),
            f(&r["y"]),
            f(&r["z"]),
        )),
    )
}

#[test]
fn with_the_true_model_the_frames_and_residuals_match_the_tracker_to_its_noise() {
    let dir = tempfile::tempdir().unwrap();
    let (recording, truth) = session(dir.path(), 5);
    let mut params = truth.robot.params.clone();
    params.calibration = Some(CalibrationInfo {
        latency_ms: Some(truth.tracker.base_latency_ms + truth.tracker.extra_latency_ms),
        ..CalibrationInfo::default()
    });
    let out = dir.path().join("true.mcap");
    export_recording(&recording, &ExportModel::Calibrated(Box::new(params)), &out).unwrap();
    let (messages, channels) = read_mcap(&out);
    assert_eq!(channels[Topic::Residual.name()].0, "sabr.MarkerResidual");

    let frames = sabr_foxglove::export::tracker_frames(&recording.tracker);
    let residuals: Vec<&Read> = messages
        .iter()
        .filter(|m| m.topic == Topic::Residual.name())
        .collect();
    assert_eq!(residuals.len(), frames.len());
    let mut front_seen = 0;
    for (residual, rows) in residuals.iter().zip(&frames) {
        assert_eq!(
            residual.json["frame"].as_u64().unwrap(),
            u64::from(rows[0].frame)
        );
        let front_measured = rows
            .iter()
            .any(|r| r.tool == Tool::Front && r.reading != ToolReading::Missing);
        let base_measured = rows
            .iter()
            .any(|r| r.tool == Tool::Base && r.reading != ToolReading::Missing);
        let front = &residual.json["front"];
        if !(front_measured && base_measured) {
            assert!(front.is_null(), "no residual without both markers seen");
            continue;
        }
        if front.is_null() {
            // Before the first or after the last encoder sample.
            continue;
        }
        front_seen += 1;
        let distance = front["distance_mm"].as_f64().unwrap();
        let angle = front["angle_deg"].as_f64().unwrap();
        assert!(distance < 2.0, "frame {}: {distance} mm", rows[0].frame);
        assert!(angle < 1.0, "frame {}: {angle} deg", rows[0].frame);
    }
    assert!(
        front_seen * 10 > frames.len() * 8,
        "{front_seen} of {}",
        frames.len()
    );

    // The model chain tracker → base_marker → robot_base → front_effector → front_marker
    // lands on the measured front marker.
    let mut tree: BTreeMap<String, nalgebra::Isometry3<f64>> = BTreeMap::new();
    let mut checked = 0;
    for message in &messages {
        let Some(transforms) = message.json["transforms"].as_array() else {
            continue;
        };
        for transform in transforms {
            let child = transform["child_frame_id"].as_str().unwrap().to_owned();
            tree.insert(child, isometry(transform));
        }
        if message.topic != Topic::TrackerTf.name() {
            continue;
        }
        let names = [
            "base_marker",
            "robot_base",
            "front_effector",
            "front_marker",
            "front_marker_measured",
        ];
        let [Some(m), Some(bb), Some(ef), Some(tf), Some(measured)] =
            names.map(|name| tree.get(name))
        else {
            continue;
        };
        let model = m * bb * ef * tf;
        let distance = (model.translation.vector - measured.translation.vector).norm();
        // Up to 20 ms between the last encoder sample and the frame's exposure.
        assert!(distance < 3.0, "{distance} mm at {}", message.log_time);
        checked += 1;
    }
    assert!(checked > 100, "{checked} frames checked");
}

#[test]
fn an_existing_file_is_not_overwritten_and_a_recording_without_homing_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (mut recording, _) = session(dir.path(), 7);
    let out = dir.path().join("exists.mcap");
    std::fs::write(&out, b"keep").unwrap();
    let error = export_recording(&recording, &ExportModel::Nominal, &out).unwrap_err();
    assert!(error.to_string().contains("exists.mcap"), "{error}");
    assert_eq!(std::fs::read(&out).unwrap(), b"keep");

    recording.phases.retain(|phase| phase.phase != "homing");
    let error = export_recording(
        &recording,
        &ExportModel::Nominal,
        &dir.path().join("new.mcap"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        error.contains("phases.csv") && error.contains("homing"),
        "{error}"
    );
}
