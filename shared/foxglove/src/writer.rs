//! The MCAP file itself: one channel per topic (registered with its schema when its first
//! message is written), JSON messages, log time = the sample's time stamp, and a check that
//! no topic goes back in time.

use std::collections::BTreeMap;
use std::io::{Seek, Write};
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;
use mcap::{WriteOptions, Writer};
use serde::Serialize;

use crate::error::McapExportError;
use crate::schemas::{self, Schema};

/// The MCAP profile: none of the ROS ones (messages are JSON).
const PROFILE: &str = "";
/// Message encoding of every channel.
const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every schema.
const SCHEMA_ENCODING: &str = "jsonschema";

/// The topics this crate writes, each with one message type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Topic {
    /// `/tracker/tf`: the pose tools seen in a tracker frame (`foxglove.FrameTransforms`).
    TrackerTf,
    /// `/tracker/tip`: the tip sphere in the tracker frame (`foxglove.PoseInFrame`).
    TrackerTip,
    /// `/robot/tf_static`: the model's fixed transforms (`foxglove.FrameTransforms`), once.
    RobotTfStatic,
    /// `/robot/tf`: the model's moving frames per encoder sample (`foxglove.FrameTransforms`).
    RobotTf,
    /// `/robot/joint_states`: counts and joint angles per encoder sample (`sabr.JointState`).
    JointStates,
    /// `/robot/scene`: the needle and gimbal centres drawn on the model frames
    /// (`foxglove.SceneUpdate`), once.
    RobotScene,
    /// `/phases`: one line per session phase, at its end (`foxglove.Log`).
    Phases,
    /// `/calibration/residual`: the calibrated model against each tracker frame
    /// (`sabr.MarkerResidual`).
    Residual,
}

impl Topic {
    /// The topic name.
    pub fn name(self) -> &'static str {
        match self {
            Topic::TrackerTf => "/tracker/tf",
            Topic::TrackerTip => "/tracker/tip",
            Topic::RobotTfStatic => "/robot/tf_static",
            Topic::RobotTf => "/robot/tf",
            Topic::JointStates => "/robot/joint_states",
            Topic::RobotScene => "/robot/scene",
            Topic::Phases => "/phases",
            Topic::Residual => "/calibration/residual",
        }
    }

    /// The schema of its messages.
    pub fn schema(self) -> Schema {
        match self {
            Topic::TrackerTf | Topic::RobotTfStatic | Topic::RobotTf => schemas::frame_transforms(),
            Topic::TrackerTip => schemas::pose_in_frame(),
            Topic::JointStates => schemas::joint_state(),
            Topic::RobotScene => schemas::scene_update(),
            Topic::Phases => schemas::log(),
            Topic::Residual => schemas::marker_residual(),
        }
    }
}

/// A registered channel: its id, the next sequence number and the last log time.
#[derive(Debug, Clone, Copy)]
struct Channel {
    id: u16,
    sequence: u32,
    last_ns: Option<u64>,
}

/// Writes messages of the [`Topic`]s to an MCAP file (zstd-compressed chunks).
pub struct McapSink<W: Write + Seek> {
    path: PathBuf,
    writer: Writer<W>,
    schemas: BTreeMap<&'static str, u16>,
    channels: BTreeMap<Topic, Channel>,
}

impl<W: Write + Seek> McapSink<W> {
    /// Starts an MCAP file on `output`, naming it `path` in errors.
    pub fn new(output: W, path: &Path) -> Result<Self, McapExportError> {
        let path = path.to_path_buf();
        let writer = WriteOptions::new()
            .profile(PROFILE)
            .library(concat!("sabr-foxglove ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .create(output)
            .map_err(|cause| McapExportError::Mcap {
                path: path.clone(),
                cause,
            })?;
        Ok(McapSink {
            path,
            writer,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
        })
    }

    /// Messages written per topic so far.
    pub fn message_counts(&self) -> BTreeMap<Topic, u32> {
        self.channels
            .iter()
            .map(|(&topic, channel)| (topic, channel.sequence))
            .collect()
    }

    /// Writes `message` on `topic` at log time `t_ns`; refused if it is before the topic's
    /// previous message.
    pub fn write<M: Serialize>(
        &mut self,
        topic: Topic,
        t_ns: u64,
        message: &M,
    ) -> Result<(), McapExportError> {
        let mut channel = self.channel(topic)?;
        if let Some(previous_ns) = channel.last_ns.filter(|&last| t_ns < last) {
            return Err(McapExportError::BackInTime {
                topic: topic.name(),
                t_ns,
                previous_ns,
            });
        }
        let data = serde_json::to_vec(message).expect("the messages always serialise to JSON");
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time: t_ns,
            publish_time: t_ns,
        };
        self.writer
            .write_to_known_channel(&header, &data)
            .map_err(|cause| self.mcap_error(cause))?;
        channel.sequence += 1;
        channel.last_ns = Some(t_ns);
        self.channels.insert(topic, channel);
        Ok(())
    }

    /// Ends the current chunk and hands it to `output`, so a reader (or a recovery tool) sees
    /// every message written so far even if the process dies before [`McapSink::finish`].
    pub fn flush(&mut self) -> Result<(), McapExportError> {
        self.writer.flush().map_err(|cause| self.mcap_error(cause))
    }

    /// Writes the summary and footer and returns the output.
    pub fn finish(mut self) -> Result<W, McapExportError> {
        self.writer
            .finish()
            .map_err(|cause| self.mcap_error(cause))?;
        Ok(self.writer.into_inner())
    }

    fn channel(&mut self, topic: Topic) -> Result<Channel, McapExportError> {
        if let Some(&channel) = self.channels.get(&topic) {
            return Ok(channel);
        }
        let schema = topic.schema();
        let schema_id = match self.schemas.get(schema.name) {
            Some(&id) => id,
            None => {
                let id = self
                    .writer
                    .add_schema(schema.name, SCHEMA_ENCODING, &schema.bytes())
                    .map_err(|cause| self.mcap_error(cause))?;
                self.schemas.insert(schema.name, id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic.name(), MESSAGE_ENCODING, &BTreeMap::new())
            .map_err(|cause| self.mcap_error(cause))?;
        let channel = Channel {
            id,
            sequence: 0,
            last_ns: None,
        };
        self.channels.insert(topic, channel);
        Ok(channel)
    }

    fn mcap_error(&self, cause: mcap::McapError) -> McapExportError {
        McapExportError::Mcap {
            path: self.path.clone(),
            cause,
        }
    }
}

impl<W: Write + Seek> std::fmt::Debug for McapSink<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapSink")
            .field("path", &self.path)
            .field("messages", &self.message_counts())
            .finish_non_exhaustive()
    }
}
