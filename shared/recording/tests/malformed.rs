//! One malformed file per kind of error: the read fails and the message names the file, the
//! 1-based line and the reason. The writer refuses rows the reader would reject.

use std::path::Path;

use sabr_recording::{
    write_all, EncoderRow, PhaseRow, Problem, Recording, RecordingError, RecordingWriter, Tool,
    ToolReading, TrackerRow,
};

const ENCODERS_HEADER: &str = "t_ns,c1,c2,c3,c4,c5\n";
/// The header of a format v1 `tracker.csv` (still read).
const TRACKER_HEADER: &str = "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms\n";
/// The header of a format v2 `tracker.csv`.
const TRACKER_HEADER_V2: &str = "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms,arrival_t_ns\n";
const PHASES_HEADER: &str = "t_start_ns,t_end_ns,phase\n";

/// A valid recording in a fresh directory, then `file` replaced by `content`; returns the
/// read error.
fn read_error(file: &str, content: &[u8]) -> RecordingError {
    let tmp = tempfile::tempdir().unwrap();
    let recording = Recording {
        dir: Default::default(),
        robot_toml: "format = 1\n".to_owned(),
        encoders: vec![EncoderRow {
            t_ns: 1,
            counts: [0; 5],
        }],
        tracker: vec![],
        phases: vec![],
    };
    write_all(&recording, tmp.path()).unwrap();
    Recording::read(tmp.path()).expect("the untouched recording is valid");
    std::fs::write(tmp.path().join(file), content).unwrap();
    Recording::read(tmp.path()).unwrap_err()
}

/// Asserts that reading `content` as `file` fails with a message naming `file`, `line` and
/// `reason`, and returns the error.
fn assert_rejected(file: &str, content: &str, line: u64, reason: &str) -> RecordingError {
    let error = read_error(file, content.as_bytes());
    let message = error.to_string();
    let expected = format!("{file} line {line}: {reason}");
    assert!(
        message.contains(&expected),
        "message {message:?} lacks {expected:?}"
    );
    error
}

/// Valid tracker rows to put before a bad one, so the bad one is on line `line`.
fn tracker_rows_before(line: u64) -> String {
    (2..line)
        .map(|i| format!("{i},{i},base,ok,1,0,0,0,1,2,3,0.1\n"))
        .collect()
}

#[test]
fn missing_file() {
    let tmp = tempfile::tempdir().unwrap();
    let recording = Recording {
        dir: Default::default(),
        robot_toml: String::new(),
        encoders: vec![],
        tracker: vec![],
        phases: vec![],
    };
    write_all(&recording, tmp.path()).unwrap();
    std::fs::remove_file(tmp.path().join("tracker.csv")).unwrap();
    let error = Recording::read(tmp.path()).unwrap_err();
    assert!(matches!(error, RecordingError::MissingFile { .. }));
    assert!(
        error.to_string().ends_with("tracker.csv: missing file"),
        "{error}"
    );
}

#[test]
fn missing_robot_toml() {
    let tmp = tempfile::tempdir().unwrap();
    let error = Recording::read(tmp.path()).unwrap_err();
    assert!(
        error.to_string().ends_with("robot.toml: missing file"),
        "{error}"
    );
}

#[test]
fn empty_file() {
    let error = assert_rejected("phases.csv", "", 1, "empty file");
    assert!(error.to_string().contains(PHASES_HEADER.trim_end()));
}

#[test]
fn wrong_header() {
    let content = "time,c1,c2,c3,c4,c5\n1,0,0,0,0,0\n";
    let error = assert_rejected(
        "encoders.csv",
        content,
        1,
        "wrong header: expected `t_ns,c1",
    );
    assert!(error.to_string().contains("found `time,c1,c2,c3,c4,c5`"));
}

#[test]
fn header_with_a_column_missing() {
    let content = "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z\n";
    assert_rejected(
        "tracker.csv",
        content,
        1,
        "missing column `rms` (found 11 fields)",
    );
}

#[test]
fn row_with_a_column_missing() {
    let content = format!("{ENCODERS_HEADER}1,0,0,0,0,0\n2,0,0,0,0\n");
    assert_rejected(
        "encoders.csv",
        &content,
        3,
        "missing column `c5` (found 5 fields)",
    );
}

#[test]
fn invalid_float() {
    let content = format!(
        "{TRACKER_HEADER}{}17,17,front,ok,abc,0,0,0,1,2,3,0.1\n",
        tracker_rows_before(17)
    );
    let error = assert_rejected(
        "tracker.csv",
        &content,
        17,
        "field `qw`: invalid float \"abc\"",
    );
    assert!(matches!(
        error.problem(),
        Some(Problem::InvalidFloat { column: "qw", .. })
    ));
}

#[test]
fn float_that_is_not_finite() {
    let content = format!("{TRACKER_HEADER}1,1,back,ok,1,0,0,0,1,NaN,3,0.1\n");
    assert_rejected(
        "tracker.csv",
        &content,
        2,
        "field `y`: NaN is not a finite number",
    );
}

#[test]
fn invalid_integer() {
    let content = format!("{ENCODERS_HEADER}1,0,0,0,0,0\n2,0,0,12x,0,0\n");
    assert_rejected(
        "encoders.csv",
        &content,
        3,
        "field `c3`: invalid integer \"12x\"",
    );
}

#[test]
fn frame_counter_out_of_range() {
    let content = format!("{TRACKER_HEADER}1,-1,base,missing,,,,,,,,\n");
    assert_rejected(
        "tracker.csv",
        &content,
        2,
        "field `frame`: invalid integer \"-1\"",
    );
}

#[test]
fn missing_number_on_an_ok_row() {
    let content = format!("{TRACKER_HEADER}1,1,tip,ok,,,,,1,2,,0.1\n");
    assert_rejected(
        "tracker.csv",
        &content,
        2,
        "field `z`: empty, expected a number",
    );
}

#[test]
fn unknown_tool() {
    let content = format!("{TRACKER_HEADER}1,1,needle,missing,,,,,,,,\n");
    assert_rejected(
        "tracker.csv",
        &content,
        2,
        "field `tool`: unknown tool \"needle\" (expected base, front, back or tip)",
    );
}

#[test]
fn unknown_status() {
    let content = format!("{TRACKER_HEADER}1,1,base,partial,,,,,,,,\n");
    assert_rejected(
        "tracker.csv",
        &content,
        2,
        "field `status`: unknown status \"partial\" (expected ok or missing)",
    );
}

#[test]
fn quaternion_on_a_tip_row() {
    let content = format!("{TRACKER_HEADER}1,1,tip,ok,1,,,,1,2,3,0.1\n");
    assert_rejected(
        "tracker.csv",
        &content,
        2,
        "field `qw`: a tip row has no quaternion, found \"1\"",
    );
}

#[test]
fn numbers_on_a_missing_row() {
    let content = format!("{TRACKER_HEADER}1,1,front,missing,,,,,,,,0.2\n");
    assert_rejected(
        "tracker.csv",
        &content,
        2,
        "field `rms`: must be empty when status is missing, found \"0.2\"",
    );
}

#[test]
fn version_2_rows_without_a_valid_arrival_stamp() {
    let missing_column =
        format!("{TRACKER_HEADER_V2}1,1,base,missing,,,,,,,,,3\n2,2,tip,ok,,,,,1,2,3,0\n");
    assert_rejected(
        "tracker.csv",
        &missing_column,
        3,
        "missing column `arrival_t_ns` (found 12 fields)",
    );
    let empty = format!("{TRACKER_HEADER_V2}1,1,base,missing,,,,,,,,,\n");
    assert_rejected(
        "tracker.csv",
        &empty,
        2,
        "field `arrival_t_ns`: empty, expected a number",
    );
    let invalid = format!("{TRACKER_HEADER_V2}1,1,front,ok,1,0,0,0,1,2,3,0.1,soon\n");
    assert_rejected(
        "tracker.csv",
        &invalid,
        2,
        "field `arrival_t_ns`: invalid integer \"soon\"",
    );
    let early =
        format!("{TRACKER_HEADER_V2}10,1,base,missing,,,,,,,,,10\n10,1,tip,missing,,,,,,,,,9\n");
    let error = assert_rejected(
        "tracker.csv",
        &early,
        3,
        "field `arrival_t_ns`: 9 is before the frame became available at t_ns 10",
    );
    assert_eq!(
        error.problem(),
        Some(&Problem::ArrivalBeforeAvailable {
            t_ns: 10,
            arrival_t_ns: 9
        })
    );
}

#[test]
fn encoder_time_stamps_going_back() {
    let content = format!("{ENCODERS_HEADER}10,0,0,0,0,0\n20,0,0,0,0,0\n15,0,0,0,0,0\n");
    assert_rejected(
        "encoders.csv",
        &content,
        4,
        "field `t_ns`: 15 is not after the previous row's 20 (encoder time stamps must increase)",
    );
}

#[test]
fn repeated_encoder_time_stamp() {
    let content = format!("{ENCODERS_HEADER}10,0,0,0,0,0\n10,1,0,0,0,0\n");
    assert_rejected(
        "encoders.csv",
        &content,
        3,
        "field `t_ns`: 10 is not after the previous row's 10",
    );
}

#[test]
fn phase_ending_before_it_starts() {
    let content = format!("{PHASES_HEADER}0,10,homing\n30,20,tip\n");
    assert_rejected(
        "phases.csv",
        &content,
        3,
        "phase ends before it starts: t_end_ns 20 < t_start_ns 30",
    );
}

#[test]
fn empty_phase_name() {
    let content = format!("{PHASES_HEADER}0,10,\n");
    assert_rejected("phases.csv", &content, 2, "field `phase`: empty phase name");
}

#[test]
fn phase_name_not_utf8() {
    let content = [PHASES_HEADER.as_bytes(), b"0,10,bad\xff\n"].concat();
    let message = read_error("phases.csv", &content).to_string();
    assert!(
        message.contains("phases.csv line 2: field `phase`: not valid UTF-8"),
        "{message}"
    );
}

#[test]
fn line_numbers_count_quoted_newlines() {
    let content = format!("{PHASES_HEADER}0,1,\"two\nlines\"\n5,4,x\n");
    assert_rejected("phases.csv", &content, 4, "phase ends before it starts");
}

#[test]
fn line_numbers_count_crlf_line_ends() {
    let content = "t_start_ns,t_end_ns,phase\r\n0,1,a\r\n\r\n5,4,x\r\n";
    assert_rejected("phases.csv", content, 4, "phase ends before it starts");
}

#[test]
fn line_numbers_count_blank_lines() {
    let content = format!("{PHASES_HEADER}0,1,a\n\n\n5,4,x\n");
    assert_rejected("phases.csv", &content, 5, "phase ends before it starts");
}

#[test]
fn truncated_final_line_in_a_strict_read() {
    let content = format!("{ENCODERS_HEADER}1,0,0,0,0,0\n2,0,0,0,0,0\n3,0,0,1");
    let error = assert_rejected(
        "encoders.csv",
        &content,
        4,
        "truncated final line \"3,0,0,1\"",
    );
    assert!(matches!(
        error,
        RecordingError::TruncatedTail { line: 4, .. }
    ));
}

/// Asserts the writer refuses `write` with a message naming `file`, `line` and `reason`, and
/// that the file is left holding only the rows written before.
fn assert_refused(
    file: &str,
    line: u64,
    reason: &str,
    write: impl FnOnce(&mut RecordingWriter) -> Result<(), RecordingError>,
) {
    let tmp = tempfile::tempdir().unwrap();
    let mut writer = RecordingWriter::create(tmp.path(), "").unwrap();
    let message = write(&mut writer).unwrap_err().to_string();
    let expected = format!("{file} line {line}: refusing to write the row: {reason}");
    assert!(
        message.contains(&expected),
        "{message:?} lacks {expected:?}"
    );
    writer.finish().unwrap();
    let kept = Recording::read(tmp.path()).expect("refused rows leave a valid recording");
    let rows = kept.encoders.len() + kept.tracker.len() + kept.phases.len();
    assert_eq!(rows as u64, line - 2);
}

fn point(tool: Tool) -> TrackerRow {
    TrackerRow {
        t_ns: 1,
        arrival_t_ns: 2,
        frame: 1,
        tool,
        reading: ToolReading::Point {
            position: [1.0, 2.0, 3.0],
            rms: 0.1,
        },
    }
}

#[test]
fn writer_refuses_non_increasing_encoder_time() {
    assert_refused(
        "encoders.csv",
        4,
        "field `t_ns`: 5 is not after the previous row's 7",
        |w| {
            w.write_encoder(&EncoderRow {
                t_ns: 3,
                counts: [0; 5],
            })?;
            w.write_encoder(&EncoderRow {
                t_ns: 7,
                counts: [0; 5],
            })?;
            w.write_encoder(&EncoderRow {
                t_ns: 5,
                counts: [0; 5],
            })
        },
    );
}

#[test]
fn writer_refuses_a_pose_for_the_tip_and_a_point_for_a_marker() {
    let pose_on_tip = TrackerRow {
        tool: Tool::Tip,
        reading: ToolReading::Pose {
            quaternion: [1.0, 0.0, 0.0, 0.0],
            position: [0.0; 3],
            rms: 0.1,
        },
        ..point(Tool::Tip)
    };
    assert_refused("tracker.csv", 3, "a tip row cannot hold a pose", |w| {
        w.write_tracker(&point(Tool::Tip))?;
        w.write_tracker(&pose_on_tip)
    });
    assert_refused("tracker.csv", 2, "a front row cannot hold a point", |w| {
        w.write_tracker(&point(Tool::Front))
    });
}

#[test]
fn writer_refuses_an_arrival_before_the_availability() {
    let early = TrackerRow {
        t_ns: 5,
        arrival_t_ns: 4,
        ..point(Tool::Tip)
    };
    assert_refused(
        "tracker.csv",
        2,
        "field `arrival_t_ns`: 4 is before the frame became available at t_ns 5",
        |w| w.write_tracker(&early),
    );
}

#[test]
fn writer_refuses_non_finite_numbers() {
    let mut row = point(Tool::Tip);
    row.reading = ToolReading::Point {
        position: [1.0, 2.0, 3.0],
        rms: f64::INFINITY,
    };
    assert_refused(
        "tracker.csv",
        2,
        "field `rms`: inf is not a finite number",
        |w| w.write_tracker(&row),
    );
}

#[test]
fn writer_refuses_bad_phases() {
    let phase = |t_start_ns, t_end_ns, name: &str| PhaseRow {
        t_start_ns,
        t_end_ns,
        phase: name.to_owned(),
    };
    assert_refused(
        "phases.csv",
        3,
        "phase ends before it starts: t_end_ns 1 < t_start_ns 2",
        |w| {
            w.write_phase(&phase(0, 1, "homing"))?;
            w.write_phase(&phase(2, 1, "tip"))
        },
    );
    assert_refused("phases.csv", 2, "field `phase`: empty phase name", |w| {
        w.write_phase(&phase(0, 1, ""))
    });
}

#[test]
fn errors_name_the_full_path() {
    let error = read_error("encoders.csv", b"nonsense\n");
    let RecordingError::Malformed { path, line, .. } = &error else {
        panic!("unexpected {error:?}");
    };
    assert_eq!(*line, 1);
    assert_eq!(
        path.file_name(),
        Some(Path::new("encoders.csv").as_os_str())
    );
    assert!(path.is_absolute());
    assert!(error.to_string().starts_with(&path.display().to_string()));
}
