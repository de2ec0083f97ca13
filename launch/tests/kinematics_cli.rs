//! `sabr fk` and `sabr ik` end to end: the built binary on files in a temporary directory.

mod common;

use common::{arg, run};
use std::path::PathBuf;

use sabr_model::RobotParams;

/// The four test vectors of docs/robot-model.md §3: joints, then tip and direction.
const VECTORS: [[f64; 11]; 4] = [
    [
        -2.368404, -0.777628, 0.0, -2.685073, -0.601543, 0.0, -90.0, 180.0, 0.0, 0.0, 1.0,
    ],
    [
        -2.281138, -0.829988, 0.069813, -2.789793, -0.566636, 0.6994, -102.5676, 172.3905,
        0.006198, -0.106914, 0.994249,
    ],
    [
        -2.508031, -0.672909, -0.174533, -2.597807, -0.723716, 6.8652, -61.6116, 193.7630,
        0.060675, 0.198498, 0.978221,
    ],
    [
        -2.193871, -0.603095, 0.174533, -2.510540, -0.427010, 17.6674, -89.0828, 167.8082,
        0.030056, -0.006635, 0.999526,
    ],
];

struct Workspace {
    dir: tempfile::TempDir,
}

impl Workspace {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let workspace = Self { dir };
        workspace.write("robot.toml", &RobotParams::nominal().to_toml_string());
        let mut calibrated = RobotParams::nominal();
        calibrated.joints.offset = Some([-2.21, -0.89, -0.19, -2.56, -0.74]);
        workspace.write("params.toml", &calibrated.to_toml_string());
        workspace
    }

    fn write(&self, name: &str, text: &str) -> PathBuf {
        let path = self.dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
}

/// The data rows of a CSV output as numbers (header checked).
fn numbers(stdout: &str, header: &str) -> Vec<Vec<f64>> {
    let mut lines = stdout.lines();
    assert_eq!(lines.next(), Some(header), "{stdout}");
    lines
        .map(|line| line.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

#[test]
fn fk_reproduces_the_contract_vectors() {
    let ws = Workspace::new();
    let mut csv = "q1,q2,q3,q4,q5,comment\n".to_owned();
    for v in VECTORS {
        csv += &format!(
            "{},{},{},{},{},extra column\n",
            v[0], v[1], v[2], v[3], v[4]
        );
    }
    let joints = ws.write("joints.csv", &csv);
    let (ok, stdout, stderr) = run(&[
        "fk",
        "--params",
        arg(&ws.path("robot.toml")),
        "--joints",
        arg(&joints),
    ]);
    assert!(ok, "{stderr}");
    let rows = numbers(&stdout, "x,y,z,ux,uy,uz");
    assert_eq!(rows.len(), 4);
    for (row, v) in rows.iter().zip(VECTORS) {
        for i in 0..3 {
            assert!((row[i] - v[5 + i]).abs() < 1e-4, "{row:?} vs {v:?}");
            assert!((row[3 + i] - v[8 + i]).abs() < 1e-6, "{row:?} vs {v:?}");
        }
    }
}

#[test]
fn fk_refuses_counts_without_offsets() {
    let ws = Workspace::new();
    let counts = ws.write("counts.csv", "c1,c2,c3,c4,c5\n0,0,0,0,0\n");
    let (ok, stdout, stderr) = run(&[
        "fk",
        "--params",
        arg(&ws.path("robot.toml")),
        "--counts",
        arg(&counts),
    ]);
    assert!(!ok);
    assert!(stdout.is_empty(), "{stdout}");
    assert!(
        stderr.contains("--counts") && stderr.contains("joint_offset"),
        "{stderr}"
    );
}

#[test]
fn ik_then_fk_from_counts_returns_the_targets() {
    let ws = Workspace::new();
    let targets: [[f64; 6]; 3] = [
        [0.0, -90.0, 180.0, 0.0, 0.0, 1.0],
        [5.0, -95.0, 185.0, 0.05, -0.1, 1.0],
        [-8.0, -80.0, 172.0, -0.1, 0.08, 0.99],
    ];
    let mut csv = "x,y,z,ux,uy,uz\n".to_owned();
    for t in targets {
        csv += &format!("{},{},{},{},{},{}\n", t[0], t[1], t[2], t[3], t[4], t[5]);
    }
    let target_file = ws.write("targets.csv", &csv);
    let (ok, ik_out, stderr) = run(&[
        "ik",
        "--params",
        arg(&ws.path("params.toml")),
        "--targets",
        arg(&target_file),
    ]);
    assert!(ok, "{stderr}");
    let rows = numbers(&ik_out, "q1,q2,q3,q4,q5,c1,c2,c3,c4,c5");
    assert_eq!(rows.len(), 3);
    // The IK output has both q and c columns: feed it back to FK by counts.
    let solved = ws.write("solved.csv", &ik_out);
    let (ok, fk_out, stderr) = run(&[
        "fk",
        "--params",
        arg(&ws.path("params.toml")),
        "--counts",
        arg(&solved),
    ]);
    assert!(ok, "{stderr}");
    let poses = numbers(&fk_out, "x,y,z,ux,uy,uz");
    for (pose, target) in poses.iter().zip(targets) {
        let norm = (target[3] * target[3] + target[4] * target[4] + target[5] * target[5]).sqrt();
        for i in 0..3 {
            assert!((pose[i] - target[i]).abs() < 1e-6, "{pose:?} vs {target:?}");
            assert!(
                (pose[3 + i] - target[3 + i] / norm).abs() < 1e-9,
                "{pose:?}"
            );
        }
    }
}

#[test]
fn ik_with_a_robot_toml_prints_joints_only_and_flags_unreachable_rows() {
    let ws = Workspace::new();
    let targets = ws.write(
        "targets.csv",
        "x,y,z,ux,uy,uz\n0,-90,180,0,0,1\n0,-90,900,0,0,1\n0,-90,180,1,0,0.02\n",
    );
    let (ok, stdout, stderr) = run(&[
        "ik",
        "--params",
        arg(&ws.path("robot.toml")),
        "--targets",
        arg(&targets),
    ]);
    assert!(!ok, "an unreachable row must fail the command");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines[0], "q1,q2,q3,q4,q5");
    assert_eq!(lines.len(), 4, "{stdout}");
    assert_eq!(lines[1].split(',').count(), 5);
    // `error,<reason>` (CSV-quoted if the reason has a comma).
    for line in &lines[2..] {
        let reason = line.strip_prefix("error,").expect(line).trim_matches('"');
        assert!(reason.starts_with("unreachable: "), "{stdout}");
    }
    assert!(stderr.contains("2 of 3"), "{stderr}");
}

#[test]
fn malformed_inputs_name_the_file_line_and_reason() {
    let ws = Workspace::new();
    let robot = ws.path("robot.toml");
    let not_a_number = ws.write("bad.csv", "q1,q2,q3,q4,q5\n0,0,0,0,0\n0,0,zero,0,0\n");
    let (ok, _, stderr) = run(&[
        "fk",
        "--params",
        arg(&robot),
        "--joints",
        arg(&not_a_number),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("bad.csv: line 3: column `q3`: `zero` is not a number"),
        "{stderr}"
    );

    let short_row = ws.write("short.csv", "q1,q2,q3,q4,q5\n0,0,0\n");
    let (ok, _, stderr) = run(&["fk", "--params", arg(&robot), "--joints", arg(&short_row)]);
    assert!(!ok);
    assert!(
        stderr.contains("short.csv: line 2: column `q4` is missing"),
        "{stderr}"
    );

    let no_column = ws.write("header.csv", "x,y,z,ux,uy\n0,0,0,0,0\n");
    let (ok, _, stderr) = run(&["ik", "--params", arg(&robot), "--targets", arg(&no_column)]);
    assert!(!ok);
    assert!(
        stderr.contains("header.csv: line 1: the header has no column `uz`"),
        "{stderr}"
    );

    let text = std::fs::read_to_string(&robot)
        .unwrap()
        .replace("l_b = 50.0", "l_b = [50.0");
    let broken = ws.write("broken.toml", &text);
    let (ok, _, stderr) = run(&[
        "fk",
        "--params",
        arg(&broken),
        "--joints",
        arg(&not_a_number),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("broken.toml") && stderr.contains("line "),
        "{stderr}"
    );

    let missing = ws.path("missing.toml");
    let (ok, _, stderr) = run(&[
        "fk",
        "--params",
        arg(&missing),
        "--joints",
        arg(&not_a_number),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("cannot read parameter file") && stderr.contains("missing.toml"),
        "{stderr}"
    );
}

/// `sabr fk --counts` on a sequence of static poses carries the backlash's play through
/// the rows: after θ1 reverses, the tip stays put until the motor has crossed the gap, then
/// follows again.
#[test]
fn fk_from_counts_carries_the_backlash_play_through_the_sequence() {
    let ws = Workspace::new();
    let mut params = RobotParams::nominal();
    params.joints.offset = Some([-2.21, -0.89, -0.19, -2.56, -0.74]);
    params.effects = vec!["backlash:joint=1,width=0.01".parse().unwrap()];
    let file = ws.write("backlash.toml", &params.to_toml_string());
    // θ1 up by 600 counts, then back down 60 counts in steps of 2 (the gap: 0.01 rad is
    // 0.01 / (0.1·2π/2000) ≈ 31.8 counts).
    let mut counts: Vec<i64> = (0..=600).step_by(20).collect();
    counts.extend((1..=30).map(|k| 600 - 2 * k));
    let mut csv = "c1,c2,c3,c4,c5\n".to_owned();
    for c in &counts {
        csv += &format!("{c},100,50,-80,40\n");
    }
    let input = ws.write("sequence.csv", &csv);
    let (ok, stdout, stderr) = run(&["fk", "--params", arg(&file), "--counts", arg(&input)]);
    assert!(ok, "{stderr}");
    let rows = numbers(&stdout, "x,y,z,ux,uy,uz");
    assert_eq!(rows.len(), counts.len());
    let top = counts.iter().position(|&c| c == 600).unwrap();
    let moved = |k: usize| {
        let (a, b) = (&rows[top], &rows[k]);
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    for (k, &c) in counts.iter().enumerate().skip(top + 1) {
        let travel = 600 - c;
        if travel <= 28 {
            assert!(
                moved(k) < 1e-9,
                "{travel} counts back: moved {} mm",
                moved(k)
            );
        } else if travel >= 36 {
            assert!(moved(k) > 1e-3, "{travel} counts back: still held");
        }
    }
}

/// Axis tilts in a parameter file act in `sabr fk` and `sabr ik`: IK of an FK pose returns
/// the joints, and the tilt moves the tip.
#[test]
fn fk_and_ik_honour_axis_tilts_of_the_parameter_file() {
    let ws = Workspace::new();
    let mut params = RobotParams::nominal();
    params.effects = vec![
        "tilt:joint=3,axis=1,angle=0.0175".parse().unwrap(),
        "tilt:joint=5,axis=2,angle=-0.006".parse().unwrap(),
    ];
    let file = ws.write("tilted.toml", &params.to_toml_string());
    let q = VECTORS[1];
    let joints = ws.write(
        "joints.csv",
        &format!(
            "q1,q2,q3,q4,q5\n{},{},{},{},{}\n",
            q[0], q[1], q[2], q[3], q[4]
        ),
    );
    let (ok, fk_out, stderr) = run(&["fk", "--params", arg(&file), "--joints", arg(&joints)]);
    assert!(ok, "{stderr}");
    let pose = &numbers(&fk_out, "x,y,z,ux,uy,uz")[0];
    let shift = (0..3)
        .map(|i| (pose[i] - q[5 + i]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(shift > 0.05, "the tilts move the tip by {shift} mm");
    let targets = ws.write("targets.csv", &fk_out);
    let (ok, ik_out, stderr) = run(&["ik", "--params", arg(&file), "--targets", arg(&targets)]);
    assert!(ok, "{stderr}");
    let solved = &numbers(&ik_out, "q1,q2,q3,q4,q5")[0];
    for i in 0..5 {
        assert!((solved[i] - q[i]).abs() < 1e-6, "{solved:?} vs {q:?}");
    }
}
