//! The live streams turned into recording rows (docs/robot-model.md §7) and written as they come.

use sabr_foxglove::{McapExportError, McapSink, SessionStream, StreamOptions};
use sabr_model::RobotParams;
use sabr_msgs::{EncoderSample, PhaseMark, TrackerFrame};
use sabr_recording::live::{encoder_row, phase_row, tracker_rows};
use sabr_recording::{FlushPolicy, RecordingError, RecordingWriter, TrackerRow};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// The live MCAP stream of a recording: written next to the CSV files, robot frames from the
/// end of the homing phase on (when the joint offsets become known).
type LiveMcap = SessionStream<BufWriter<File>>;

/// Counters of a recording.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RecorderStats {
    /// Rows written to `encoders.csv`.
    pub encoder_rows: u64,
    /// Tracker frames written (one `tracker.csv` row per tool each).
    pub tracker_frames: u64,
    /// Rows written to `phases.csv`.
    pub phase_rows: u64,
    /// Encoder samples lost before they reached the recorder (sequence-number gaps).
    pub encoder_lost: u64,
    /// Times the encoder sequence restarted (the encoders process restarted).
    pub encoder_restarts: u64,
    /// Rows the writer refused (bad time order, non-finite numbers, ...); each is logged.
    pub refused: u64,
    /// Rows the MCAP stream refused (a topic going back in time); each is logged.
    pub mcap_refused: u64,
}

/// What an encoder sample revealed about the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Continuity {
    /// Next in sequence (or the first).
    InSequence,
    /// `lost` samples are missing before it.
    Lost(u64),
    /// The sequence started over.
    Restarted,
}

/// Writes the live streams into one recording directory.
#[derive(Debug)]
pub struct Recorder {
    writer: RecordingWriter,
    last_encoder_seq: Option<u64>,
    stats: RecorderStats,
    /// The MCAP stream and its file, if asked for and not failed.
    mcap: Option<(LiveMcap, PathBuf)>,
}

impl Recorder {
    /// Creates the recording in `dir` with `robot_toml` as its nominal model.
    pub fn create(
        dir: &Path,
        robot_toml: &str,
        flush: FlushPolicy,
    ) -> Result<Self, RecordingError> {
        Ok(Self {
            writer: RecordingWriter::create_with(dir, robot_toml, flush)?,
            last_encoder_seq: None,
            stats: RecorderStats::default(),
            mcap: None,
        })
    }

    /// Also writes every row that reaches the CSV files to the new MCAP file `path`
    /// (Foxglove schemas, docs/robot-model.md §8), placing the robot with `params`.
    pub fn with_mcap(mut self, path: &Path, params: RobotParams) -> Result<Self, McapExportError> {
        let file = File::create_new(path).map_err(|cause| McapExportError::Io {
            path: path.to_path_buf(),
            action: "create (it must not exist yet)",
            cause,
        })?;
        let sink = McapSink::new(BufWriter::new(file), path)?;
        let stream = SessionStream::new(sink, params, StreamOptions::default());
        self.mcap = Some((stream, path.to_path_buf()));
        Ok(self)
    }

    /// The MCAP file being written, if any.
    pub fn mcap_path(&self) -> Option<&Path> {
        self.mcap.as_ref().map(|(_, path)| path.as_path())
    }

    /// The recording directory.
    pub fn dir(&self) -> &Path {
        self.writer.dir()
    }

    /// What was written so far.
    pub fn stats(&self) -> RecorderStats {
        self.stats
    }

    /// Appends an encoder sample. The continuity is checked before the row is written; a
    /// refused row is an error (the recording stays valid without it).
    pub fn encoder(&mut self, sample: &EncoderSample) -> Result<Continuity, RecordingError> {
        let continuity = match self.last_encoder_seq {
            Some(last) if sample.seq == last.wrapping_add(1) => Continuity::InSequence,
            Some(last) if sample.seq > last => Continuity::Lost(sample.seq - last - 1),
            Some(_) => Continuity::Restarted,
            None => Continuity::InSequence,
        };
        self.last_encoder_seq = Some(sample.seq);
        match continuity {
            Continuity::Lost(lost) => self.stats.encoder_lost += lost,
            Continuity::Restarted => self.stats.encoder_restarts += 1,
            Continuity::InSequence => {}
        }
        let row = encoder_row(sample);
        let written = self.writer.write_encoder(&row);
        self.count(written)?;
        self.stats.encoder_rows += 1;
        self.forward_to_mcap(|mcap| mcap.encoder(&row));
        Ok(continuity)
    }

    /// Appends one `tracker.csv` row per tool of a frame (base, front, back, tip). A refused
    /// row does not stop the other tools' rows; the first refusal is returned.
    pub fn frame(&mut self, frame: &TrackerFrame) -> Result<(), RecordingError> {
        let mut first_error = None;
        let mut accepted: Vec<TrackerRow> = Vec::new();
        for row in tracker_rows(frame) {
            let written = self.writer.write_tracker(&row);
            match self.count(written) {
                Ok(()) => accepted.push(row),
                Err(error) => {
                    first_error.get_or_insert(error);
                }
            }
        }
        self.stats.tracker_frames += 1;
        self.forward_to_mcap(|mcap| mcap.tracker_frame(&accepted));
        first_error.map_or(Ok(()), Err)
    }

    /// Appends a phase.
    pub fn phase(&mut self, mark: &PhaseMark) -> Result<(), RecordingError> {
        let row = phase_row(mark);
        let written = self.writer.write_phase(&row);
        self.count(written)?;
        self.stats.phase_rows += 1;
        self.forward_to_mcap(|mcap| mcap.phase(&row));
        Ok(())
    }

    /// Hands every buffered row to the operating system.
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.forward_to_mcap(SessionStream::flush);
        self.writer.flush()
    }

    /// Flushes, syncs every file to disk and returns the counters. The MCAP file, if any, is
    /// finished (summary and index) first.
    pub fn finish(mut self) -> Result<RecorderStats, RecordingError> {
        if let Some((mcap, path)) = self.mcap.take() {
            let finished = mcap.finish().and_then(|output| {
                output
                    .into_inner()
                    .map_err(|e| e.into_error())
                    .and_then(|file| file.sync_all())
                    .map_err(|cause| McapExportError::Io {
                        path: path.clone(),
                        action: "write",
                        cause,
                    })
            });
            if let Err(error) = finished {
                tracing::error!("MCAP {}: cannot finish: {error}", path.display());
            }
        }
        self.writer.finish()?;
        Ok(self.stats)
    }

    /// Passes a row to the MCAP stream. A refused message is counted and logged; any other
    /// MCAP error is logged and ends the MCAP stream (the CSV recording goes on).
    fn forward_to_mcap(
        &mut self,
        write: impl FnOnce(&mut LiveMcap) -> Result<(), McapExportError>,
    ) {
        let Some((mcap, path)) = &mut self.mcap else {
            return;
        };
        match write(mcap) {
            Ok(()) => {}
            Err(error @ McapExportError::BackInTime { .. }) => {
                self.stats.mcap_refused += 1;
                tracing::warn!("MCAP {}: message not written: {error}", path.display());
            }
            Err(error) => {
                tracing::error!("MCAP {}: stopped: {error}", path.display());
                self.mcap = None;
            }
        }
    }

    fn count(&mut self, written: Result<(), RecordingError>) -> Result<(), RecordingError> {
        if matches!(written, Err(RecordingError::Refused { .. })) {
            self.stats.refused += 1;
        }
        written
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_msgs::{FixedString, ToolSample, ToolStatus};
    use sabr_recording::{Recording, Tool, ToolReading};
    use std::num::NonZeroUsize;

    fn encoder(seq: u64) -> EncoderSample {
        EncoderSample {
            seq,
            t_ns: 1_000_000 * seq as i64,
            counts: [seq as i64, -1, 2, 3, 4],
        }
    }

    fn frame(frame_number: u32) -> TrackerFrame {
        let pose = ToolSample {
            status: ToolStatus::Ok,
            quaternion: [0.5, 0.5, -0.5, 0.5],
            position_mm: [1.0, 2.5, -900.0],
            rms_mm: 0.125,
        };
        let mut tools = [pose; 4];
        tools[2].status = ToolStatus::Missing;
        tools[3] = ToolSample {
            status: ToolStatus::Ok,
            quaternion: [1.0, 0.0, 0.0, 0.0],
            position_mm: [3.0, 4.0, -850.0],
            rms_mm: 0.0,
        };
        TrackerFrame {
            seq: u64::from(frame_number),
            arrival_t_ns: 50_000_000 * i64::from(frame_number) + 600_000,
            available_t_ns: 50_000_000 * i64::from(frame_number),
            sent_t_ns: 50_000_000 * i64::from(frame_number) + 602_000,
            frame_number,
            tools,
        }
    }

    #[test]
    fn streams_round_trip_through_the_reader() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("rec");
        let toml = sabr_model::RobotParams::nominal().to_toml_string();
        let mut recorder = Recorder::create(&out, &toml, FlushPolicy::default()).unwrap();
        for seq in 1..=5 {
            assert_eq!(
                recorder.encoder(&encoder(seq)).unwrap(),
                Continuity::InSequence
            );
        }
        assert_eq!(recorder.encoder(&encoder(9)).unwrap(), Continuity::Lost(3));
        recorder.frame(&frame(7)).unwrap();
        recorder
            .phase(&PhaseMark {
                seq: 1,
                t_start_ns: 10,
                t_end_ns: 20,
                phase: FixedString::new("excitation").unwrap(),
            })
            .unwrap();
        let stats = recorder.finish().unwrap();
        assert_eq!(stats.encoder_rows, 6);
        assert_eq!(stats.encoder_lost, 3);
        assert_eq!(stats.tracker_frames, 1);

        let recording = Recording::read(&out).unwrap();
        assert_eq!(recording.robot_toml, toml);
        assert_eq!(recording.encoders.len(), 6);
        assert_eq!(recording.encoders[5].counts, [9, -1, 2, 3, 4]);
        assert_eq!(recording.tracker.len(), 4);
        let tools: Vec<Tool> = recording.tracker.iter().map(|r| r.tool).collect();
        assert_eq!(tools, Tool::ALL);
        assert!(
            matches!(recording.tracker[0].reading, ToolReading::Pose { rms, .. } if rms == 0.125)
        );
        assert_eq!(recording.tracker[2].reading, ToolReading::Missing);
        assert_eq!(
            recording.tracker[3].reading,
            ToolReading::Point {
                position: [3.0, 4.0, -850.0],
                rms: 0.0
            }
        );
        assert_eq!(
            (recording.tracker[3].t_ns, recording.tracker[3].arrival_t_ns),
            (350_000_000, 350_600_000)
        );
        assert_eq!(recording.phases[0].phase, "excitation");
    }

    #[test]
    fn refused_rows_are_counted_and_the_rest_stays_readable() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("rec");
        let mut recorder = Recorder::create(&out, "format = 1\n", FlushPolicy::default()).unwrap();
        recorder.encoder(&encoder(2)).unwrap();
        // Same time stamp again, then a restarted sequence going back in time.
        let error = recorder.encoder(&encoder(2)).unwrap_err();
        assert!(error.to_string().contains("encoders.csv"), "{error}");
        let mut bad = frame(1);
        bad.tools[0].position_mm[0] = f64::NAN;
        assert!(recorder.frame(&bad).is_err());
        assert_eq!(recorder.stats().refused, 2);
        assert_eq!(recorder.stats().encoder_restarts, 1);
        recorder.finish().unwrap();
        let recording = Recording::read(&out).unwrap();
        assert_eq!(recording.encoders.len(), 1);
        let tools: Vec<Tool> = recording.tracker.iter().map(|r| r.tool).collect();
        assert_eq!(
            tools,
            [Tool::Front, Tool::Back, Tool::Tip],
            "the other tools are kept"
        );
    }

    /// Messages per topic of an MCAP file, and whether each topic's log times never decrease.
    fn mcap_topics(path: &Path) -> std::collections::BTreeMap<String, (usize, bool)> {
        let bytes = std::fs::read(path).unwrap();
        let mut topics = std::collections::BTreeMap::new();
        let mut last = std::collections::BTreeMap::new();
        for message in mcap::MessageStream::new(&bytes).unwrap() {
            let message = message.unwrap();
            let topic = message.channel.topic.clone();
            let previous = last.insert(topic.clone(), message.log_time);
            let entry = topics.entry(topic).or_insert((0, true));
            entry.0 += 1;
            entry.1 &= previous.is_none_or(|p| p <= message.log_time);
        }
        topics
    }

    #[test]
    fn the_mcap_stream_gets_every_recorded_row_and_the_robot_from_homing_on() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("rec");
        let params = sabr_model::RobotParams::nominal();
        let toml = params.to_toml_string();
        let path = dir.path().join("live.mcap");
        let mut recorder = Recorder::create(&out, &toml, FlushPolicy::default())
            .unwrap()
            .with_mcap(&path, params)
            .unwrap();
        assert_eq!(recorder.mcap_path(), Some(path.as_path()));
        let at_stops = |seq: u64| EncoderSample {
            seq,
            t_ns: 1_000_000 * seq as i64,
            counts: [0; 5],
        };
        for seq in 1..=10 {
            recorder.encoder(&at_stops(seq)).unwrap();
        }
        recorder
            .phase(&PhaseMark {
                seq: 1,
                t_start_ns: 2_000_000,
                t_end_ns: 9_000_000,
                phase: FixedString::new("homing").unwrap(),
            })
            .unwrap();
        for seq in 11..=15 {
            recorder.encoder(&at_stops(seq)).unwrap();
        }
        recorder.frame(&frame(1)).unwrap();
        recorder.flush().unwrap();
        // A frame stamped before the previous one: in tracker.csv, but not on the MCAP topic.
        let mut early = frame(1);
        early.available_t_ns -= 1;
        recorder.frame(&early).unwrap();
        let stats = recorder.finish().unwrap();
        assert_eq!(stats.mcap_refused, 1);

        let topics = mcap_topics(&path);
        let count = |topic: &str| topics.get(topic).map_or(0, |(n, _)| *n);
        assert_eq!(count("/robot/joint_states"), 15);
        assert_eq!(
            count("/robot/tf"),
            5,
            "robot frames once homing set the offsets"
        );
        assert_eq!(count("/robot/tf_static"), 1);
        assert_eq!(count("/tracker/tf"), 1);
        assert_eq!(count("/tracker/tip"), 1);
        assert_eq!(count("/phases"), 1);
        assert!(topics.values().all(|(_, ordered)| *ordered), "{topics:?}");
        assert_eq!(Recording::read(&out).unwrap().tracker.len(), 8);
    }

    #[test]
    fn flushed_rows_survive_without_finish() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("rec");
        let policy = FlushPolicy::EveryRows(NonZeroUsize::MIN);
        let mut recorder = Recorder::create(&out, "format = 1\n", policy).unwrap();
        for seq in 1..=100 {
            recorder.encoder(&encoder(seq)).unwrap();
        }
        recorder.frame(&frame(3)).unwrap();
        // As after SIGKILL: the process never finishes, the rows handed over are there.
        std::mem::forget(recorder);
        let salvage = Recording::read_salvage(&out).unwrap();
        assert_eq!(salvage.recording.encoders.len(), 100);
        assert_eq!(salvage.recording.tracker.len(), 4);
        assert!(salvage.dropped.is_empty());
    }
}
