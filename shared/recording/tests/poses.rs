//! Poses v1: write → read gives back the same recording; malformed files are refused with
//! the file, line, column and reason; extra trailing columns are accepted.

use std::path::Path;

use sabr_recording::poses::{
    Measured, PoseRow, PosesRecording, PosesRobot, Target, TargetMeasurement,
};
use sabr_recording::RecordingError;

const URDF: &str = "<robot name=\"r\"><link name=\"a\"/></robot>\n";

fn robot() -> PosesRobot {
    PosesRobot::new(
        "arm.urdf",
        vec![
            Target {
                name: "probe".into(),
                link: "tool0".into(),
                measured: Measured::Pose,
                mounting_translation: Some([0.087, 0.0, 109.0]),
                mounting_rotation: Some([0.0, 0.0, 1.5716]),
            },
            Target {
                name: "prism".into(),
                link: "wrist_3_link".into(),
                measured: Measured::Point,
                mounting_translation: None,
                mounting_rotation: None,
            },
        ],
    )
}

fn row(index: u64, setup: &str, sequence: &str, with_prism: bool) -> PoseRow {
    let half = std::f64::consts::FRAC_1_SQRT_2;
    PoseRow {
        line: 0,
        setup: setup.into(),
        sequence: sequence.into(),
        index,
        joints: vec![0.1 * index as f64, -1.2345678901234567, 3.0e-7],
        targets: vec![
            Some(TargetMeasurement {
                position_mm: [2361.9831, -1368.5474, 119.39713 + index as f64],
                orientation: Some([half, 0.0, half, 0.0]),
                position_std_mm: index
                    .is_multiple_of(2)
                    .then_some([0.031674, 0.013252, 0.0037622]),
                orientation_std_rad: index.is_multiple_of(2).then_some([2.1e-5, 2.4e-5, 7.2e-5]),
            }),
            with_prism.then_some(TargetMeasurement {
                position_mm: [1.0, 2.0, 3.0],
                orientation: None,
                position_std_mm: None,
                orientation_std_rad: None,
            }),
        ],
        temperature_c: (index != 1).then_some(21.86750031),
    }
}

fn recording() -> PosesRecording {
    PosesRecording {
        dir: Default::default(),
        robot: robot(),
        urdf_text: URDF.into(),
        joints: vec!["shoulder".into(), "elbow".into(), "lift".into()],
        rows: vec![
            row(0, "tracker-1", "run-a", true),
            row(1, "tracker-1", "run-a", false),
            row(0, "tracker-2", "run-b", true),
            row(7, "tracker-1", "run-a", true),
        ],
    }
}

#[test]
fn write_then_read_gives_back_the_same_recording() {
    let tmp = tempfile::tempdir().unwrap();
    let original = recording();
    original.write(tmp.path()).unwrap();
    let read = PosesRecording::read(tmp.path()).unwrap();
    assert_eq!(read.robot, original.robot);
    assert_eq!(read.urdf_text, URDF);
    assert_eq!(read.joints, original.joints);
    assert_eq!(read.rows.len(), original.rows.len());
    for (i, (read, written)) in read.rows.iter().zip(&original.rows).enumerate() {
        assert_eq!(read.line, i as u64 + 2);
        let mut written = written.clone();
        written.line = read.line;
        assert_eq!(*read, written);
    }
    let header = std::fs::read_to_string(tmp.path().join("poses.csv")).unwrap();
    let header = header.lines().next().unwrap();
    assert_eq!(
        header,
        "setup,sequence,index,joint.shoulder,joint.elbow,joint.lift,probe.x,probe.y,probe.z,\
         probe.qw,probe.qx,probe.qy,probe.qz,probe.std_x,probe.std_y,probe.std_z,probe.std_rx,\
         probe.std_ry,probe.std_rz,prism.x,prism.y,prism.z,temperature_c"
    );
    // The writer refuses to overwrite.
    assert!(original.write(tmp.path()).is_err());
}

#[test]
fn joint_order_maps_the_urdf_variables_to_columns() {
    let recording = recording();
    assert_eq!(
        recording
            .joint_order(&["lift", "shoulder", "elbow"])
            .unwrap(),
        vec![2, 0, 1]
    );
    let extra = recording.joint_order(&["shoulder", "elbow"]).unwrap_err();
    assert!(
        extra
            .to_string()
            .contains("line 1: column `joint.lift`: the URDF has no joint variable `lift`"),
        "{extra}"
    );
    let missing = recording
        .joint_order(&["shoulder", "elbow", "lift", "wrist"])
        .unwrap_err();
    assert!(
        missing
            .to_string()
            .contains("column `joint.wrist`: missing"),
        "{missing}"
    );
}

/// A valid recording in a fresh directory with `poses.csv` replaced by `csv`.
fn read_with_poses(csv: &str) -> Result<PosesRecording, RecordingError> {
    let tmp = tempfile::tempdir().unwrap();
    recording().write(tmp.path()).unwrap();
    std::fs::write(tmp.path().join("poses.csv"), csv).unwrap();
    PosesRecording::read(tmp.path())
}

const HEADER: &str = "setup,sequence,index,joint.a,probe.x,probe.y,probe.z,probe.qw,probe.qx,probe.qy,probe.qz,prism.x,prism.y,prism.z";
const GOOD: &str = "s,q,0,0.5,1,2,3,1,0,0,0,,,";

fn assert_rejected(csv: &str, line: u64, reason: &str) {
    let error = read_with_poses(csv).unwrap_err().to_string();
    let expected = format!("poses.csv line {line}: {reason}");
    assert!(error.contains(&expected), "{error:?} lacks {expected:?}");
}

#[test]
fn extra_trailing_columns_and_crlf_are_accepted() {
    let csv = format!("{HEADER},comment,more\r\n{GOOD},hello,1\r\ns,q,1,0.5,,,,,,,,4,5,6,x,y");
    let read = read_with_poses(&csv).unwrap();
    assert_eq!(read.rows.len(), 2);
    assert_eq!(read.rows[1].line, 3);
    assert!(read.rows[1].targets[0].is_none());
    assert_eq!(
        read.rows[1].targets[1].unwrap().position_mm,
        [4.0, 5.0, 6.0]
    );
    assert_eq!(read.rows[0].temperature_c, None);
}

#[test]
fn malformed_headers_name_the_column() {
    assert_rejected("", 1, "column `setup`: empty file");
    assert_rejected(
        "sequence,index,joint.a,probe.x,probe.y,probe.z,probe.qw,probe.qx,probe.qy,probe.qz,prism.x,prism.y,prism.z\n",
        1,
        "column `setup`: missing",
    );
    assert_rejected(
        &HEADER.replace(",probe.qz", ""),
        1,
        "column `probe.qz`: missing",
    );
    assert_rejected(
        &HEADER.replace(",joint.a", ""),
        1,
        "column `joint.<name>`: missing",
    );
    assert_rejected(
        &format!("{HEADER},joint.a"),
        1,
        "column `joint.a`: appears twice",
    );
    assert_rejected(
        &format!("{HEADER},prism.qw"),
        1,
        "column `prism.qw`: target `prism` is measured as a point",
    );
    assert_rejected(
        &format!("{HEADER},probe.speed"),
        1,
        "column `probe.speed`: unknown field `speed` of target `probe`",
    );
    assert_rejected(
        &format!("{HEADER},note,temperature_c"),
        1,
        "column `temperature_c`: a column of the format after the extra column `note`",
    );
    assert_rejected(
        &format!("{HEADER},probe.std_x,probe.std_y"),
        1,
        "column `probe.std_z`: missing",
    );
}

#[test]
fn malformed_rows_name_the_line_column_and_reason() {
    let with = |rows: &[&str]| format!("{HEADER}\n{GOOD}\n{}\n", rows.join("\n"));
    assert_rejected(
        &with(&["s,q,1,abc,1,2,3,1,0,0,0,,,"]),
        3,
        "field `joint.a`: invalid number \"abc\"",
    );
    assert_rejected(
        &with(&["s,q,1,,1,2,3,1,0,0,0,,,"]),
        3,
        "field `joint.a`: empty, expected a number",
    );
    assert_rejected(
        &with(&["s,q,1,NaN,1,2,3,1,0,0,0,,,"]),
        3,
        "field `joint.a`: NaN is not a finite number",
    );
    assert_rejected(
        &with(&[",q,1,0,1,2,3,1,0,0,0,,,"]),
        3,
        "field `setup`: empty",
    );
    assert_rejected(
        &with(&["s,q,-1,0,1,2,3,1,0,0,0,,,"]),
        3,
        "field `index`: invalid order index \"-1\"",
    );
    assert_rejected(
        &with(&["s,q,0,0,1,2,3,1,0,0,0,,,"]),
        3,
        "field `index`: 0 is not after 0 of the previous pose of sequence \"q\"",
    );
    assert_rejected(
        &with(&["s,q,1,0,1,2,3,0.5,0,0,0,,,"]),
        3,
        "field `probe.qw`: not a unit quaternion (norm 0.5)",
    );
    assert_rejected(
        &with(&["s,q,1,0,1,,3,1,0,0,0,,,"]),
        3,
        "field `probe.y`: empty while the other fields of its group are set",
    );
    assert_rejected(
        &with(&["s,q,1,0,1,2,3,,,,,,,"]),
        3,
        "field `probe.qw`: empty while the target's position is set",
    );
    assert_rejected(
        &with(&["s,q,1,0,,,,1,0,0,0,,,"]),
        3,
        "field `probe.qw`: set while the target's position is empty",
    );
    assert_rejected(
        &with(&["s,q,1,0,,,,,,,,,,"]),
        3,
        "field `probe.x`: no target is measured at this pose",
    );
    assert_rejected(
        &with(&["s,q,1,0,1,2,3,1,0,0"]),
        3,
        "field `probe.qz`: missing (the row has 10 fields)",
    );
    // Another sequence may reuse an index.
    read_with_poses(&with(&["s,other,0,0,1,2,3,1,0,0,0,,,"])).unwrap();
}

#[test]
fn malformed_robot_toml_names_the_key() {
    let cases = [
        ("format = \"poses-v2\"\nurdf = \"a.urdf\"\ntargets = []\n", "key `format`"),
        ("format = \"poses-v1\"\nurdf = \"a.urdf\"\ntargets = []\n", "at least one target"),
        (
            "format = \"poses-v1\"\nurdf = \"../a.urdf\"\n[[targets]]\nname = \"t\"\nlink = \"l\"\nmeasured = \"point\"\n",
            "key `urdf`: \"../a.urdf\" must be a relative path inside the recording",
        ),
        (
            "format = \"poses-v1\"\nurdf = \"a.urdf\"\n[[targets]]\nname = \"t\"\nlink = \"l\"\nmeasured = \"point\"\nmounting_rotation = [0.0, 0.0, 1.0]\n",
            "a point target has no orientation",
        ),
        (
            "format = \"poses-v1\"\nurdf = \"a.urdf\"\n[[targets]]\nname = \"t x\"\nlink = \"l\"\nmeasured = \"pose\"\n",
            "a target name is letters, digits",
        ),
        (
            "format = \"poses-v1\"\nurdf = \"a.urdf\"\n[[targets]]\nname = \"t\"\nlink = \"l\"\nmeasured = \"laser\"\n",
            "unknown variant `laser`",
        ),
    ];
    for (toml, reason) in cases {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("robot.toml"), toml).unwrap();
        std::fs::write(tmp.path().join("a.urdf"), URDF).unwrap();
        let error = PosesRecording::read(tmp.path()).unwrap_err().to_string();
        assert!(error.contains("robot.toml"), "{error}");
        assert!(error.contains(reason), "{error:?} lacks {reason:?}");
    }
}

#[test]
fn a_missing_urdf_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    recording().write(tmp.path()).unwrap();
    std::fs::remove_file(tmp.path().join("arm.urdf")).unwrap();
    let error = PosesRecording::read(tmp.path()).unwrap_err();
    assert!(
        matches!(&error, RecordingError::MissingFile { path } if path.ends_with(Path::new("arm.urdf"))),
        "{error}"
    );
}

#[test]
fn the_writer_refuses_rows_a_reader_would_reject() {
    let tmp = tempfile::tempdir().unwrap();
    let mut bad = recording();
    bad.rows[1].index = 0;
    let error = bad
        .write(&tmp.path().join("order"))
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("poses.csv line 3: refusing to write the row: field `index`"),
        "{error}"
    );
    let mut bad = recording();
    bad.rows[0].targets[1] = Some(TargetMeasurement {
        position_mm: [1.0, 2.0, 3.0],
        orientation: Some([1.0, 0.0, 0.0, 0.0]),
        position_std_mm: None,
        orientation_std_rad: None,
    });
    let error = bad
        .write(&tmp.path().join("point"))
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("field `prism.x`: a point target has no orientation"),
        "{error}"
    );
    let mut bad = recording();
    bad.rows[2].joints[0] = f64::INFINITY;
    let error = bad.write(&tmp.path().join("inf")).unwrap_err().to_string();
    assert!(
        error.contains(
            "line 4: refusing to write the row: field `joint.shoulder`: inf is not a finite number"
        ),
        "{error}"
    );
}
