//! The header of `poses.csv`: which column holds what. Columns are found by name; the
//! format's columns come first, and every column from the first name that is not the
//! format's on is an extra column, kept by nobody and ignored.

use crate::error::Problem;

use crate::robot_toml::poses::{Measured, PosesRobot};

/// Prefix of the joint columns: `joint.<URDF joint name>`.
pub(crate) const JOINT_PREFIX: &str = "joint.";
/// The set-up column.
pub(crate) const SETUP: &str = "setup";
/// The sequence column.
pub(crate) const SEQUENCE: &str = "sequence";
/// The order-index column.
pub(crate) const INDEX: &str = "index";
/// The optional temperature column (°C).
pub(crate) const TEMPERATURE: &str = "temperature_c";

/// Field suffixes of a target's position, quaternion and standard deviations.
pub(crate) const POSITION: [&str; 3] = ["x", "y", "z"];
pub(crate) const QUATERNION: [&str; 4] = ["qw", "qx", "qy", "qz"];
pub(crate) const POSITION_STD: [&str; 3] = ["std_x", "std_y", "std_z"];
pub(crate) const ORIENTATION_STD: [&str; 3] = ["std_rx", "std_ry", "std_rz"];

/// Where one target's fields are.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct TargetColumns {
    pub position: [Option<usize>; 3],
    pub quaternion: [Option<usize>; 4],
    pub position_std: [Option<usize>; 3],
    pub orientation_std: [Option<usize>; 3],
}

/// Where every field of the format is, and the column names (for messages).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PosesHeader {
    pub names: Vec<String>,
    pub setup: usize,
    pub sequence: usize,
    pub index: usize,
    /// (joint name, column), in column order.
    pub joints: Vec<(String, usize)>,
    pub targets: Vec<TargetColumns>,
    pub temperature: Option<usize>,
}

/// What a column of the format is.
enum Role<'a> {
    Setup,
    Sequence,
    Index,
    Temperature,
    Joint(&'a str),
    /// Target index, group (0 position, 1 quaternion, 2 position std, 3 orientation std),
    /// component.
    Target(usize, usize, usize),
}

/// The role of column `name`: `Ok(None)` for a name that is not the format's.
fn classify<'a>(name: &'a str, robot: &PosesRobot) -> Result<Option<Role<'a>>, String> {
    Ok(Some(match name {
        SETUP => Role::Setup,
        SEQUENCE => Role::Sequence,
        INDEX => Role::Index,
        TEMPERATURE => Role::Temperature,
        _ => {
            if let Some(joint) = name.strip_prefix(JOINT_PREFIX) {
                if joint.is_empty() {
                    return Err("a joint column needs a joint name after `joint.`".into());
                }
                return Ok(Some(Role::Joint(joint)));
            }
            let Some((target, field)) = name.split_once('.') else {
                return Ok(None);
            };
            let Some(t) = robot.targets.iter().position(|t| t.name == target) else {
                return Ok(None);
            };
            let groups: [&[&str]; 4] = [&POSITION, &QUATERNION, &POSITION_STD, &ORIENTATION_STD];
            let found = groups
                .iter()
                .enumerate()
                .find_map(|(g, fields)| fields.iter().position(|&f| f == field).map(|c| (g, c)));
            let Some((group, component)) = found else {
                return Err(format!(
                    "unknown field `{field}` of target `{target}` (fields: x, y, z, qw, qx, qy, \
                     qz, std_x, std_y, std_z, std_rx, std_ry, std_rz)"
                ));
            };
            if robot.targets[t].measured == Measured::Point && (group == 1 || group == 3) {
                return Err(format!(
                    "target `{target}` is measured as a point: it has no orientation"
                ));
            }
            Role::Target(t, group, component)
        }
    }))
}

impl PosesHeader {
    /// Finds the format's columns in the header `names`.
    pub fn parse(names: Vec<String>, robot: &PosesRobot) -> Result<PosesHeader, Problem> {
        let bad = |column: &str, reason: String| Problem::BadColumn {
            column: column.to_owned(),
            reason,
        };
        let mut fixed = [None; 4];
        let mut joints: Vec<(String, usize)> = Vec::new();
        let mut targets = vec![TargetColumns::default(); robot.targets.len()];
        let mut first_extra: Option<&str> = None;
        for (column, name) in names.iter().enumerate() {
            let role = classify(name, robot).map_err(|reason| bad(name, reason))?;
            let Some(role) = role else {
                first_extra.get_or_insert(name);
                continue;
            };
            if let Some(extra) = first_extra {
                return Err(bad(
                    name,
                    format!("a column of the format after the extra column `{extra}` (extra columns go last)"),
                ));
            }
            let slot = match role {
                Role::Setup => &mut fixed[0],
                Role::Sequence => &mut fixed[1],
                Role::Index => &mut fixed[2],
                Role::Temperature => &mut fixed[3],
                Role::Joint(joint) => {
                    if joints.iter().any(|(j, _)| j == joint) {
                        return Err(bad(name, "appears twice".into()));
                    }
                    joints.push((joint.to_owned(), column));
                    continue;
                }
                Role::Target(t, group, component) => {
                    let columns = &mut targets[t];
                    match group {
                        0 => &mut columns.position[component],
                        1 => &mut columns.quaternion[component],
                        2 => &mut columns.position_std[component],
                        _ => &mut columns.orientation_std[component],
                    }
                }
            };
            if slot.replace(column).is_some() {
                return Err(bad(name, "appears twice".into()));
            }
        }
        let missing = |column: String| Problem::BadColumn {
            column,
            reason: "missing".into(),
        };
        let required = |slot: Option<usize>, name: &str| slot.ok_or_else(|| missing(name.into()));
        let setup = required(fixed[0], SETUP)?;
        let sequence = required(fixed[1], SEQUENCE)?;
        let index = required(fixed[2], INDEX)?;
        if joints.is_empty() {
            return Err(missing(format!("{JOINT_PREFIX}<name>")));
        }
        for (target, columns) in robot.targets.iter().zip(&targets) {
            let check = |slots: &[Option<usize>], fields: &[&str], required: bool| {
                let present = slots.iter().filter(|s| s.is_some()).count();
                if present == slots.len() || (present == 0 && !required) {
                    return Ok(());
                }
                let absent = slots
                    .iter()
                    .position(Option::is_none)
                    .expect("one is absent");
                Err(missing(format!("{}.{}", target.name, fields[absent])))
            };
            check(&columns.position, &POSITION, true)?;
            let pose = target.measured == Measured::Pose;
            check(&columns.quaternion, &QUATERNION, pose)?;
            check(&columns.position_std, &POSITION_STD, false)?;
            check(&columns.orientation_std, &ORIENTATION_STD, false)?;
        }
        Ok(PosesHeader {
            names,
            setup,
            sequence,
            index,
            joints,
            targets,
            temperature: fixed[3],
        })
    }
}
