//! The observations of a serial or branched arm: the rows of a poses-v1 recording turned
//! into joint vectors in the kinematic tree's order, the measured targets, temperature, the
//! order within the sequence and the static gravity torques of the pose.

use std::path::PathBuf;
use std::sync::Arc;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use sabr_model::tree::{Payload, STANDARD_GRAVITY};
use sabr_model::{KinematicTree, LinkId};
use sabr_recording::poses::{Measured, PosesRecording, POSES_CSV};

use crate::math::se3::isometry;
use crate::model::serial::error::SerialError;

/// One measured target of a pose, in the set-up's instrument frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredTarget {
    /// Index of the target in [`ArmData::targets`].
    pub target: usize,
    /// Measured position (mm).
    pub position: Vector3<f64>,
    /// Measured orientation (pose targets only).
    pub orientation: Option<UnitQuaternion<f64>>,
}

/// One static pose of the arm.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseObservation {
    /// The 1-based line of `poses.csv` (0 for a simulated pose).
    pub line: u64,
    /// Index of its set-up in [`ArmData::setups`].
    pub setup: usize,
    /// Joint vector (rad or mm) in the tree's variable order.
    pub joints: Vec<f64>,
    /// What was measured.
    pub measured: Vec<MeasuredTarget>,
    /// Ambient temperature (°C), if recorded.
    pub temperature_c: Option<f64>,
    /// Position in its sequence: 0 at the first pose, 1 at the last.
    pub order: f64,
    /// Per joint variable: the gravity torque of the links (N·m or N) and the torque of
    /// 1 kg at the first target (N·m/kg or N/kg), at the nominal geometry.
    pub gravity: Vec<[f64; 2]>,
}

/// A measured target as the model knows it.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetSpec {
    /// Name (the prefix of its columns).
    pub name: String,
    /// The link it is mounted on.
    pub link: LinkId,
    /// The link's name.
    pub link_name: String,
    /// Whether the instrument measures its orientation too.
    pub measured: Measured,
    /// Nominal mounting `T_link_target` (mm), the start of its fit.
    pub nominal: Isometry3<f64>,
}

/// A whole measured set of an arm: the tree, its targets, set-ups and poses.
#[derive(Debug, Clone)]
pub struct ArmData {
    /// The kinematic tree.
    pub tree: Arc<KinematicTree>,
    /// The measured targets.
    pub targets: Vec<TargetSpec>,
    /// Set-up ids, in order of first appearance.
    pub setups: Vec<String>,
    /// The poses, in file order.
    pub observations: Vec<PoseObservation>,
    /// The pose table they came from (for messages).
    pub source: PathBuf,
}

impl ArmData {
    /// The observations of a poses-v1 recording (whose URDF and columns were read and
    /// checked by the reader); errors name the file, line or target.
    pub fn from_recording(recording: &PosesRecording) -> Result<Self, SerialError> {
        let urdf_path = recording.dir.join(&recording.robot.urdf);
        let tree = KinematicTree::from_urdf_str(&recording.urdf_text).map_err(|source| {
            SerialError::Urdf {
                path: urdf_path,
                source,
            }
        })?;
        let toml_path = recording.dir.join(sabr_recording::ROBOT_TOML);
        let targets = recording
            .robot
            .targets
            .iter()
            .map(|t| {
                let link = tree
                    .link_id(&t.link)
                    .map_err(|source| SerialError::Target {
                        path: toml_path.clone(),
                        target: t.name.clone(),
                        source,
                    })?;
                Ok(TargetSpec {
                    name: t.name.clone(),
                    link,
                    link_name: t.link.clone(),
                    measured: t.measured,
                    nominal: isometry(
                        Vector3::from(t.mounting_translation.unwrap_or([0.0; 3])),
                        Vector3::from(t.mounting_rotation.unwrap_or([0.0; 3])),
                    ),
                })
            })
            .collect::<Result<Vec<_>, SerialError>>()?;
        let names: Vec<&str> = tree.variables().iter().map(|v| v.name.as_str()).collect();
        let order = recording.joint_order(&names)?;
        let gravity = recording
            .robot
            .gravity_m_s2
            .map_or(STANDARD_GRAVITY, Vector3::from);
        let source = recording.dir.join(POSES_CSV);
        let mut setups: Vec<String> = Vec::new();
        let mut last_index: std::collections::HashMap<&str, u64> = Default::default();
        for row in &recording.rows {
            let last = last_index.entry(row.sequence.as_str()).or_default();
            *last = (*last).max(row.index);
        }
        let mut observations = Vec::with_capacity(recording.rows.len());
        for row in &recording.rows {
            let setup = match setups.iter().position(|s| *s == row.setup) {
                Some(k) => k,
                None => {
                    setups.push(row.setup.clone());
                    setups.len() - 1
                }
            };
            let joints: Vec<f64> = order.iter().map(|&k| row.joints[k]).collect();
            let measured = row
                .targets
                .iter()
                .enumerate()
                .filter_map(|(target, m)| {
                    let m = m.as_ref()?;
                    Some(MeasuredTarget {
                        target,
                        position: Vector3::from(m.position_mm),
                        orientation: m.orientation.map(|[w, x, y, z]| {
                            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
                        }),
                    })
                })
                .collect();
            let last = last_index[row.sequence.as_str()].max(1) as f64;
            let torques = gravity_torques(&tree, &targets, &joints, &gravity).map_err(|e| {
                SerialError::Row {
                    path: source.clone(),
                    line: row.line,
                    reason: e.to_string(),
                }
            })?;
            observations.push(PoseObservation {
                line: row.line,
                setup,
                joints,
                measured,
                temperature_c: row.temperature_c,
                order: row.index as f64 / last,
                gravity: torques,
            });
        }
        Ok(ArmData {
            tree: Arc::new(tree),
            targets,
            setups,
            observations,
            source,
        })
    }
}

/// Per variable: the links' gravity torque and the torque of 1 kg at the first target, at
/// the nominal geometry.
pub fn gravity_torques(
    tree: &KinematicTree,
    targets: &[TargetSpec],
    joints: &[f64],
    gravity: &Vector3<f64>,
) -> Result<Vec<[f64; 2]>, sabr_model::TreeError> {
    let state = tree.forward(joints, &tree.nominal_errors())?;
    let links = tree.gravity_torques(&state, gravity, &[]);
    let unit = match targets.first() {
        Some(t) => {
            let payload = Payload {
                link: t.link,
                mass_kg: 1.0,
                centre_of_mass_mm: Point3::from(t.nominal.translation.vector),
            };
            let with = tree.gravity_torques(&state, gravity, &[payload]);
            with.iter().zip(&links).map(|(a, b)| a - b).collect()
        }
        None => vec![0.0; links.len()],
    };
    Ok(links.into_iter().zip(unit).map(|(a, b)| [a, b]).collect())
}
