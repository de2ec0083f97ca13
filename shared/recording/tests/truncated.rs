//! Files cut off mid-write: a strict read names the truncated line; a lenient read keeps every
//! complete row before it and says what it dropped. Checked at every possible cut point, and
//! on recordings whose writer process was really killed with SIGKILL.

use std::fmt::Debug;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use sabr_recording::{
    write_all, CsvFormat, EncoderRow, EncodersCsv, FlushPolicy, PhasesCsv, ReadOptions, Recording,
    RecordingError, RecordingWriter, RowReader, Tool, ToolReading, TrackerCsv, TrackerRow,
};

const LENIENT: ReadOptions = ReadOptions {
    allow_truncated_tail: true,
};

/// The line number and text of a dropped final line.
type Dropped = Option<(u64, String)>;

/// Reads `content` as a file of format `F`: its rows and the line dropped.
fn read<F: CsvFormat>(
    content: &[u8],
    options: ReadOptions,
) -> Result<(Vec<F::Row>, Dropped), RecordingError> {
    let mut reader = RowReader::<F, _>::from_reader(content, F::FILE_NAME, options)?;
    let rows = reader.by_ref().collect::<Result<Vec<_>, _>>()?;
    let dropped = reader.dropped_tail().map(|d| (d.line, d.text.clone()));
    Ok((rows, dropped))
}

/// Cuts `content` (a valid file whose records end at the byte offsets `ends`, the header's
/// first) at every byte and checks both reads against the complete file's rows.
fn check_every_cut<F: CsvFormat>(content: &str, ends: &[usize])
where
    F::Row: PartialEq + Debug,
{
    assert_eq!(ends.last(), Some(&content.len()));
    let (all_rows, none) = read::<F>(content.as_bytes(), ReadOptions::default()).unwrap();
    assert_eq!(none, None);
    assert_eq!(all_rows.len(), ends.len() - 1);
    for cut in 0..=content.len() {
        let piece = &content.as_bytes()[..cut];
        let complete = ends.iter().filter(|&&end| end <= cut).count();
        let start = if complete == 0 { 0 } else { ends[complete - 1] };
        let rows = &all_rows[..complete.saturating_sub(1)];
        let (salvaged, dropped) = read::<F>(piece, LENIENT).unwrap();
        assert_eq!(salvaged, rows, "cut at {cut}");
        let strict = read::<F>(piece, ReadOptions::default());
        if cut == start && cut > 0 {
            assert_eq!(dropped, None, "cut at {cut}");
            assert_eq!(strict.unwrap().0, rows, "cut at {cut}");
            continue;
        }
        let line = 1 + content[..start].matches('\n').count() as u64;
        let text = content[start..cut].to_owned();
        assert_eq!(dropped, Some((line, text.clone())), "cut at {cut}");
        let message = strict.unwrap_err().to_string();
        let expected = if cut == 0 {
            format!("{} line 1: empty file", F::FILE_NAME)
        } else {
            format!(
                "{} line {line}: truncated final line {text:?}",
                F::FILE_NAME
            )
        };
        assert!(
            message.starts_with(&expected),
            "{message:?} vs {expected:?}"
        );
    }
}

/// Offsets just after each `\n` of `content`.
fn line_ends(content: &str) -> Vec<usize> {
    content.match_indices('\n').map(|(i, _)| i + 1).collect()
}

#[test]
fn encoders_cut_at_every_byte() {
    let mut content = String::from("t_ns,c1,c2,c3,c4,c5\n");
    for i in 0..25i64 {
        content += &format!(
            "{},{},{},-{},0,{}\n",
            1000 + i * 997,
            i,
            i * i,
            i * 31,
            1 << i
        );
    }
    check_every_cut::<EncodersCsv>(&content, &line_ends(&content));
}

#[test]
fn tracker_cut_at_every_byte() {
    let content = "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms\n\
                   10,1,base,ok,0.5,-0.5,0.5,0.5,100.25,-3,7e-5,0.12\n\
                   10,1,front,missing,,,,,,,,\n\
                   10,1,tip,ok,,,,,1.5,2.5,-3.5,0.3\n\
                   60,2,back,ok,1,0,0,0,1,2,3,0.2,extra\n\
                   60,2,tip,missing,,,,,,,,\n";
    check_every_cut::<TrackerCsv>(content, &line_ends(content));
}

#[test]
fn tracker_v2_cut_at_every_byte() {
    let content = "t_ns,frame,tool,status,qw,qx,qy,qz,x,y,z,rms,arrival_t_ns\n\
                   10,1,base,ok,0.5,-0.5,0.5,0.5,100.25,-3,7e-5,0.12,11\n\
                   10,1,front,missing,,,,,,,,,11\n\
                   60,2,back,ok,1,0,0,0,1,2,3,0.2,61,extra\n\
                   60,2,tip,ok,,,,,1.5,2.5,-3.5,0.3,61\n";
    check_every_cut::<TrackerCsv>(content, &line_ends(content));
}

#[test]
fn phases_with_quoted_names_cut_at_every_byte() {
    let records = [
        "t_start_ns,t_end_ns,phase\n",
        "0,10,homing\n",
        "10,20,\"two\nlines\"\n",
        "20,30,\"a \"\"quoted\"\", name\"\n",
        "30,40,my own\n",
    ];
    let ends: Vec<usize> = records
        .iter()
        .scan(0, |end, record| {
            *end += record.len();
            Some(*end)
        })
        .collect();
    check_every_cut::<PhasesCsv>(&records.concat(), &ends);
}

#[test]
fn read_salvage_reports_what_each_file_dropped() {
    let tmp = tempfile::tempdir().unwrap();
    let recording = Recording {
        dir: tmp.path().to_path_buf(),
        robot_toml: "format = 1\n".to_owned(),
        encoders: (0..10)
            .map(|i| EncoderRow {
                t_ns: i,
                counts: [i; 5],
            })
            .collect(),
        tracker: vec![TrackerRow {
            t_ns: 3,
            arrival_t_ns: 4,
            frame: 1,
            tool: Tool::Tip,
            reading: ToolReading::Missing,
        }],
        phases: vec![],
    };
    write_all(&recording, tmp.path()).unwrap();
    let encoders = tmp.path().join("encoders.csv");
    let text = std::fs::read_to_string(&encoders).unwrap();
    std::fs::write(&encoders, format!("{text}10,10,1")).unwrap();

    let error = Recording::read(tmp.path()).unwrap_err();
    assert!(matches!(
        error,
        RecordingError::TruncatedTail { line: 12, .. }
    ));
    let salvage = Recording::read_salvage(tmp.path()).unwrap();
    assert_eq!(salvage.recording, recording);
    assert_eq!(salvage.dropped.len(), 1);
    let dropped = &salvage.dropped[0];
    assert_eq!(
        (dropped.path.as_path(), dropped.line),
        (encoders.as_path(), 12)
    );
    let note = dropped.to_string();
    assert!(note.ends_with("encoders.csv line 12: dropped the truncated final line \"10,10,1\""));
}

#[test]
fn lenient_read_still_rejects_malformed_complete_rows() {
    let content = b"t_ns,c1,c2,c3,c4,c5\n1,0,0,0,0,0\n2,0,zero,0,0,0\n3,0,0";
    let message = read::<EncodersCsv>(content, LENIENT)
        .unwrap_err()
        .to_string();
    assert!(message.contains("encoders.csv line 3: field `c2`: invalid integer \"zero\""));
}

// ---- a real SIGKILL ----

/// Environment variable telling a re-run of this test binary to act as the killed writer:
/// the recording directory.
const CHILD_DIR: &str = "SABR_RECORDING_TEST_WRITER_DIR";
/// Environment variable with the writer's flush policy: `every-row` or `on-request`.
const CHILD_POLICY: &str = "SABR_RECORDING_TEST_WRITER_POLICY";
/// Rows the writer reports flushed before it is killed.
const ROWS_BEFORE_KILL: u64 = 20_000;

fn encoder_row(i: u64) -> EncoderRow {
    let i = i as i64;
    EncoderRow {
        t_ns: 1_000_000 + i * 1_000,
        counts: [i, -i, 3 * i, i % 7, 123_456_789],
    }
}

fn tracker_row(i: u64) -> TrackerRow {
    let x = i as f64 / 3.0;
    TrackerRow {
        t_ns: 1_000_000 + i as i64 * 50_000,
        arrival_t_ns: 1_600_000 + i as i64 * 50_000,
        frame: i as u32,
        tool: Tool::Front,
        reading: ToolReading::Pose {
            quaternion: [0.5, 0.5, -0.5, 0.5],
            position: [x, -x, 1e-9 * x],
            rms: 0.1,
        },
    }
}

/// The writer process: writes rows until killed, printing `flushed N` whenever its first `N`
/// encoder rows are known to be in the file.
fn run_killed_writer(dir: &Path, policy: &str) {
    let (flush_policy, report_every) = match policy {
        "every-row" => (FlushPolicy::EveryRows(1.try_into().unwrap()), 1_000),
        _ => (FlushPolicy::OnRequest, 5_000),
    };
    let mut writer = RecordingWriter::create_with(dir, "format = 1\n", flush_policy).unwrap();
    let started = Instant::now();
    for i in 0.. {
        writer.write_encoder(&encoder_row(i)).unwrap();
        if i % 20 == 0 {
            writer.write_tracker(&tracker_row(i / 20)).unwrap();
        }
        if (i + 1) % report_every == 0 {
            if flush_policy == FlushPolicy::OnRequest {
                writer.flush().unwrap();
            }
            // Panics (ending this process) once the parent has gone.
            println!("flushed {}", i + 1);
        }
        assert!(started.elapsed() < Duration::from_secs(20), "never killed");
    }
}

/// Kills the child on drop, so a failing test leaves no writer behind.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts this test binary as the writer, waits until it reports `ROWS_BEFORE_KILL` rows
/// flushed, kills it with SIGKILL and returns the rows it reported.
fn write_and_kill(dir: &Path, policy: &str, test_name: &str) -> u64 {
    let child = Command::new(std::env::current_exe().unwrap())
        .args([test_name, "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD_DIR, dir)
        .env(CHILD_POLICY, policy)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut child = KillOnDrop(child);
    // Kept open until the kill: the writer ends itself when its stdout closes.
    let mut stdout = BufReader::new(child.0.stdout.take().unwrap());
    let mut reported = 0;
    for line in (&mut stdout).lines() {
        if let Some(count) = line.unwrap().strip_prefix("flushed ") {
            reported = count.parse().unwrap();
            if reported >= ROWS_BEFORE_KILL {
                break;
            }
        }
    }
    assert!(reported >= ROWS_BEFORE_KILL, "the writer stopped early");
    // Let it write on, so the kill lands in the middle of writing.
    std::thread::sleep(Duration::from_millis(20));
    // `Child::kill` sends SIGKILL on Unix.
    child.0.kill().unwrap();
    let status = child.0.wait().unwrap();
    assert!(!status.success());
    reported
}

/// Checks a recording whose writer was killed: every complete row is there and right, the
/// reported rows are all there, and at most the final line of each file is dropped.
fn check_killed_recording(dir: &Path, reported: u64) {
    let salvage = Recording::read_salvage(dir).unwrap();
    let recording = &salvage.recording;
    assert!(recording.encoders.len() as u64 >= reported);
    for (i, row) in recording.encoders.iter().enumerate() {
        assert_eq!(*row, encoder_row(i as u64));
    }
    for (i, row) in recording.tracker.iter().enumerate() {
        assert_eq!(*row, tracker_row(i as u64));
    }
    let strict = Recording::read(dir);
    assert_eq!(strict.is_ok(), salvage.dropped.is_empty());
    if let Err(error) = strict {
        assert!(
            matches!(error, RecordingError::TruncatedTail { .. }),
            "{error}"
        );
    }
    for dropped in &salvage.dropped {
        let file = dropped.path.file_name().unwrap();
        let rows = if file == "encoders.csv" {
            recording.encoders.len()
        } else {
            recording.tracker.len()
        };
        assert_eq!(dropped.line, rows as u64 + 2, "{dropped}");
        assert!(!dropped.text.is_empty() && !dropped.text.contains('\n'));
    }
}

fn killed_writer_test(policy: &str, test_name: &str) {
    if let Some(dir) = std::env::var_os(CHILD_DIR) {
        run_killed_writer(Path::new(&dir), &std::env::var(CHILD_POLICY).unwrap());
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("recording");
    let reported = write_and_kill(&dir, policy, test_name);
    check_killed_recording(&dir, reported);
}

#[test]
fn sigkilled_writer_flushing_every_row_loses_no_reported_row() {
    killed_writer_test(
        "every-row",
        "sigkilled_writer_flushing_every_row_loses_no_reported_row",
    );
}

#[test]
fn sigkilled_buffered_writer_is_readable_up_to_its_last_complete_row() {
    killed_writer_test(
        "on-request",
        "sigkilled_buffered_writer_is_readable_up_to_its_last_complete_row",
    );
}
