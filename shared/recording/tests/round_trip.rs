//! Write → read gives back exactly what was written (floats bit for bit), and readers accept
//! extra trailing columns and unknown phase names.

use std::path::Path;

use sabr_recording::{
    write_all, EncoderReader, EncoderRow, FlushPolicy, PhaseReader, PhaseRow, ReadOptions,
    Recording, RecordingWriter, Tool, ToolReading, TrackerReader, TrackerRow,
};

/// A deterministic stream of 64-bit values (splitmix64).
struct Bits(u64);

impl Bits {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Any finite f64, from every bit pattern (subnormals, huge and tiny exponents, -0).
    fn finite(&mut self) -> f64 {
        loop {
            let value = f64::from_bits(self.next());
            if value.is_finite() {
                return value;
            }
        }
    }
}

/// Awkward floats written by hand: decimal non-representables, extremes, signed zero.
const AWKWARD: [f64; 10] = [
    0.1 + 0.2,
    -0.0,
    5e-324,
    f64::MIN_POSITIVE,
    f64::MAX,
    f64::MIN,
    1e-300,
    123456.78901234567,
    -1.0 / 3.0,
    1_152_921_504_606_846_976.0,
];

fn sample_recording() -> Recording {
    let mut bits = Bits(42);
    let encoders = (0..500)
        .map(|i| EncoderRow {
            t_ns: 1_700_000_000_000_000 + i * 1_000_123,
            counts: [
                i * 7 - 1000,
                -(i * i),
                i64::MIN + i,
                i64::MAX - i,
                (bits.next() as i64) >> 20,
            ],
        })
        .collect();
    let mut tracker = Vec::new();
    for frame in 0..60u32 {
        let t_ns = 1_700_000_000_000_000 + i64::from(frame) * 50_000_000;
        for tool in Tool::ALL {
            let reading = match (frame % 5, tool) {
                (0, _) | (3, Tool::Back) => ToolReading::Missing,
                (_, Tool::Tip) => ToolReading::Point {
                    position: [bits.finite(), AWKWARD[frame as usize % 10], -12.5],
                    rms: bits.finite(),
                },
                _ => ToolReading::Pose {
                    quaternion: [
                        bits.finite(),
                        bits.finite(),
                        AWKWARD[frame as usize % 10],
                        0.5,
                    ],
                    position: [bits.finite(), bits.finite(), bits.finite()],
                    rms: 0.0123,
                },
            };
            tracker.push(TrackerRow {
                t_ns,
                arrival_t_ns: t_ns + i64::from(frame % 7) * 150_000,
                frame: u32::MAX - frame,
                tool,
                reading,
            });
        }
    }
    let phase = |t_start_ns, t_end_ns, name: &str| PhaseRow {
        t_start_ns,
        t_end_ns,
        phase: name.to_owned(),
    };
    let phases = vec![
        phase(0, 10, "homing"),
        phase(10, 20, "excitation"),
        phase(20, 20, "tip"),
        phase(20, 30, "validation"),
        phase(30, 40, "my own, with \"quotes\" and a comma"),
        phase(40, 50, "ünïcode ✓"),
        phase(-5, i64::MAX, " spaced "),
    ];
    Recording {
        dir: Default::default(),
        robot_toml: "format = 1\n[geometry]\nl_f = 50.0\n".to_owned(),
        encoders,
        tracker,
        phases,
    }
}

/// The bits of every float of a tracker row, so -0.0 and 0.0 differ.
fn float_bits(row: &TrackerRow) -> Vec<u64> {
    let values: Vec<f64> = match row.reading {
        ToolReading::Missing => vec![],
        ToolReading::Pose {
            quaternion,
            position,
            rms,
        } => [quaternion.as_slice(), &position, &[rms]].concat(),
        ToolReading::Point { position, rms } => [position.as_slice(), &[rms]].concat(),
    };
    values.into_iter().map(f64::to_bits).collect()
}

fn assert_same(read: &Recording, written: &Recording, dir: &Path) {
    assert_eq!(read.dir, dir);
    assert_eq!(read.robot_toml, written.robot_toml);
    assert_eq!(read.encoders, written.encoders);
    assert_eq!(read.tracker, written.tracker);
    assert_eq!(read.phases, written.phases);
    for (read_row, written_row) in read.tracker.iter().zip(&written.tracker) {
        assert_eq!(
            float_bits(read_row),
            float_bits(written_row),
            "{written_row:?}"
        );
    }
}

#[test]
fn write_all_then_read_gives_the_same_recording() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let written = sample_recording();
    write_all(&written, &dir).unwrap();
    let read = Recording::read(&dir).unwrap();
    assert_same(&read, &written, &dir);
}

#[test]
fn random_finite_floats_round_trip_bit_for_bit() {
    let tmp = tempfile::tempdir().unwrap();
    let mut bits = Bits(7);
    let mut written = sample_recording();
    written.tracker = (0..20_000)
        .map(|i| TrackerRow {
            t_ns: i,
            arrival_t_ns: i + 1_000_000,
            frame: i as u32,
            tool: Tool::Front,
            reading: ToolReading::Pose {
                quaternion: [bits.finite(), bits.finite(), bits.finite(), bits.finite()],
                position: [bits.finite(), bits.finite(), bits.finite()],
                rms: bits.finite(),
            },
        })
        .collect();
    write_all(&written, tmp.path()).unwrap();
    let read = Recording::read(tmp.path()).unwrap();
    assert_same(&read, &written, tmp.path());
}

#[test]
fn interleaved_streaming_writes_read_back_with_streaming_readers() {
    let tmp = tempfile::tempdir().unwrap();
    let written = sample_recording();
    let policy = FlushPolicy::EveryRows(3.try_into().unwrap());
    let mut writer = RecordingWriter::create_with(tmp.path(), &written.robot_toml, policy).unwrap();
    let mut tracker_rows = written.tracker.iter();
    for (i, row) in written.encoders.iter().enumerate() {
        writer.write_encoder(row).unwrap();
        if i % 2 == 0 {
            if let Some(tracker_row) = tracker_rows.next() {
                writer.write_tracker(tracker_row).unwrap();
            }
        }
    }
    tracker_rows
        .try_for_each(|row| writer.write_tracker(row))
        .unwrap();
    for row in &written.phases {
        writer.write_phase(row).unwrap();
    }
    writer.finish().unwrap();

    let dir = tmp.path();
    let encoders: Vec<_> = EncoderReader::open(dir.join("encoders.csv"))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let tracker: Vec<_> = TrackerReader::open(dir.join("tracker.csv"))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let phases: Vec<_> = PhaseReader::open(dir.join("phases.csv"))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(encoders, written.encoders);
    assert_eq!(tracker, written.tracker);
    assert_eq!(phases, written.phases);
}

#[test]
fn tracker_rows_have_the_documented_text_form() {
    let tmp = tempfile::tempdir().unwrap();
    let mut recording = sample_recording();
    recording.tracker = vec![
        TrackerRow {
            t_ns: 5,
            arrival_t_ns: 7,
            frame: 9,
            tool: Tool::Base,
            reading: ToolReading::Missing,
        },
        TrackerRow {
            t_ns: 5,
            arrival_t_ns: 7,
            frame: 9,
            tool: Tool::Tip,
            reading: ToolReading::Point {
                position: [1.5, -2.0, 0.1],
                rms: 0.25,
            },
        },
        TrackerRow {
            t_ns: 5,
            arrival_t_ns: 5,
            frame: 9,
            tool: Tool::Front,
            reading: ToolReading::Pose {
                quaternion: [1.0, 0.0, -0.0, 0.1 + 0.2],
                position: [1e-7, 2.0, 3.0],
                rms: 0.5,
            },
        },
    ];
    write_all(&recording, tmp.path()).unwrap();
    let text = std::fs::read_to_string(tmp.path().join("tracker.csv")).unwrap();
    assert_eq!(
        text,
        "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms,arrival_t_ns\n\
         5,9,base,missing,,,,,,,,,7\n\
         5,9,tip,ok,,,,,1.5,-2,0.1,0.25,7\n\
         5,9,front,ok,1,0,-0,0.30000000000000004,0.0000001,2,3,0.5,5\n"
    );
    let encoders = std::fs::read_to_string(tmp.path().join("encoders.csv")).unwrap();
    assert!(encoders.starts_with("t_ns,c1,c2,c3,c4,c5\n1700000000000000,-1000,0,"));
}

#[test]
fn extra_trailing_columns_and_unknown_phases_are_accepted() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("robot.toml"), "format = 1\n").unwrap();
    std::fs::write(
        dir.join("encoders.csv"),
        "t_ns,c1,c2,c3,c4,c5,temperature\n10,1,2,3,4,5,36.6\n20,-1,-2,-3,-4,-5\n30,0,0,0,0,0,x,y\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("tracker.csv"),
        "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms,arrival_t_ns,port\n\
         10,1,back,ok,1,0,0,0,4,5,6,0.1,12,2\n\
         10,1,tip,missing,,,,,,,,,12,\n\
         10,1,front,ok,1,0,0,0,4,5,6,0.1,12\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("phases.csv"),
        "t_start_ns,t_end_ns,phase,note\n0,5,warm-up,first\n5,9,validation\n",
    )
    .unwrap();
    let read = Recording::read(dir).unwrap();
    assert_eq!(
        read.encoders,
        vec![
            EncoderRow {
                t_ns: 10,
                counts: [1, 2, 3, 4, 5]
            },
            EncoderRow {
                t_ns: 20,
                counts: [-1, -2, -3, -4, -5]
            },
            EncoderRow {
                t_ns: 30,
                counts: [0; 5]
            },
        ]
    );
    let pose = ToolReading::Pose {
        quaternion: [1.0, 0.0, 0.0, 0.0],
        position: [4.0, 5.0, 6.0],
        rms: 0.1,
    };
    let row = |tool, reading| TrackerRow {
        t_ns: 10,
        arrival_t_ns: 12,
        frame: 1,
        tool,
        reading,
    };
    assert_eq!(
        read.tracker,
        vec![
            row(Tool::Back, pose),
            row(Tool::Tip, ToolReading::Missing),
            row(Tool::Front, pose)
        ]
    );
    let names: Vec<_> = read.phases.iter().map(|p| p.phase.as_str()).collect();
    assert_eq!(names, ["warm-up", "validation"]);
}

#[test]
fn a_version_1_recording_is_read_with_its_arrival_stamp_as_the_availability() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("robot.toml"), "format = 1\n").unwrap();
    std::fs::write(
        dir.join("encoders.csv"),
        "t_ns,c1,c2,c3,c4,c5\n10,1,2,3,4,5\n",
    )
    .unwrap();
    std::fs::write(dir.join("phases.csv"), "t_start_ns,t_end_ns,phase\n").unwrap();
    // Format v1: no `arrival_t_ns`; an extra column after `rms` is someone's own.
    std::fs::write(
        dir.join("tracker.csv"),
        "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms\n\
         50,3,base,ok,1,0,0,0,4,5,6,0.1\n\
         50,3,tip,missing,,,,,,,,\n\
         100,4,tip,ok,,,,,1,2,3,0\n",
    )
    .unwrap();
    let read = Recording::read(dir).unwrap();
    let stamps: Vec<_> = read
        .tracker
        .iter()
        .map(|r| (r.t_ns, r.arrival_t_ns, r.frame, r.tool))
        .collect();
    assert_eq!(
        stamps,
        [
            (50, 50, 3, Tool::Base),
            (50, 50, 3, Tool::Tip),
            (100, 100, 4, Tool::Tip)
        ]
    );
    std::fs::write(
        dir.join("tracker.csv"),
        "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms,port\n\
         50,3,base,ok,1,0,0,0,4,5,6,0.1,7\n",
    )
    .unwrap();
    let read = Recording::read(dir).unwrap();
    assert_eq!(
        (read.tracker[0].t_ns, read.tracker[0].arrival_t_ns),
        (50, 50)
    );
    // Written again, it is a v2 recording.
    let copy = tempfile::tempdir().unwrap();
    write_all(&read, copy.path()).unwrap();
    let text = std::fs::read_to_string(copy.path().join("tracker.csv")).unwrap();
    assert_eq!(
        text,
        "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms,arrival_t_ns\n\
         50,3,base,ok,1,0,0,0,4,5,6,0.1,50\n"
    );
}

#[test]
fn crlf_line_ends_and_blank_lines_are_read() {
    let input = "t_ns,c1,c2,c3,c4,c5\r\n1,1,1,1,1,1\r\n\r\n2,2,2,2,2,2\r\n";
    let rows: Vec<_> =
        EncoderReader::from_reader(input.as_bytes(), "e.csv", ReadOptions::default())
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
    assert_eq!(rows.iter().map(|r| r.t_ns).collect::<Vec<_>>(), [1, 2]);
}

#[test]
fn writer_refuses_to_overwrite_an_existing_recording() {
    let tmp = tempfile::tempdir().unwrap();
    write_all(&sample_recording(), tmp.path()).unwrap();
    let before = std::fs::read(tmp.path().join("encoders.csv")).unwrap();
    let error = RecordingWriter::create(tmp.path(), "format = 1\n").unwrap_err();
    let message = error.to_string();
    assert!(message.contains("robot.toml: cannot create"), "{message}");
    let after = std::fs::read(tmp.path().join("encoders.csv")).unwrap();
    assert_eq!(before, after);
}
