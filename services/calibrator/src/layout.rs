//! The calibrated model and its parameter vector.
//!
//! A [`ParamLayout`] is a list of [`ParamId`]s: which scalar of the model each entry of the
//! optimiser's vector is. The paper's layout ([`ParamLayout::paper`]) holds the tracker
//! latency, `GR_1..5`, `θ_off,1..5`, `T_Bb_Bf` (3 translations, rotations about x and y),
//! `l_n` and the two marker mountings (6 each). Effect models extend it by adding ids
//! (a new variant with its [`Channel`], getter and setter); everything downstream
//! (residuals, Jacobian, identifiability, report) works per id.

use nalgebra::{DVector, Isometry3, Vector3};
use sabr_model::RobotParams;

use crate::residual_loop::EffectParam;
use crate::se3;

/// The model being calibrated: the robot parameters plus the tracker latency.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibModel {
    /// Robot parameters (joint offsets always defined).
    pub robot: RobotParams,
    /// Tracker latency from exposure to the clock line (s); see `timesync`.
    pub latency_s: f64,
}

/// How a parameter acts on a prediction; the Jacobian uses it to avoid needless FK calls.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    /// Only through the joint angles computed from the counts.
    JointMap,
    /// Through the kinematic geometry in general (needs forward kinematics).
    Geometry,
    /// Through `T_Bb_Bf`: the front effector moves rigidly with it (no FK needed for the
    /// marker poses), the needle needs FK.
    FrontBase,
    /// Through the needle length: only the tip moves, along `z_N`.
    NeedleLength,
    /// Only through a marker mounting (composed after forward kinematics).
    Mount,
}

/// One scalar of the model. Axis indices: 0 = x, 1 = y, 2 = z; joint indices 0..5.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ParamId {
    /// Tracker latency (s).
    Latency,
    /// Gear ratio `GR_j`.
    GearRatio(usize),
    /// Joint offset `θ_off,j` (rad).
    JointOffset(usize),
    /// Translation of `T_Bb_Bf` along an axis (mm).
    FrontBaseTranslation(usize),
    /// Rotation-vector component of `T_Bb_Bf` (rad).
    FrontBaseRotation(usize),
    /// Needle length `l_n` (mm).
    NeedleLength,
    /// Translation of `T_Ef_Tf` (mm).
    FrontMountTranslation(usize),
    /// Rotation-vector component of `T_Ef_Tf` (rad).
    FrontMountRotation(usize),
    /// Translation of `T_Eb_Tb` (mm).
    BackMountTranslation(usize),
    /// Rotation-vector component of `T_Eb_Tb` (rad).
    BackMountRotation(usize),
    /// A numeric parameter of one of the model's effects (see `residual_loop`).
    Effect(EffectParam),
}

const AXES: [&str; 3] = ["x", "y", "z"];

impl ParamId {
    /// Human-readable name, joints numbered 1..5 as in the paper (e.g. `gear_ratio[3]`).
    pub fn name(&self) -> String {
        match *self {
            ParamId::Latency => "latency".into(),
            ParamId::GearRatio(j) => format!("gear_ratio[{}]", j + 1),
            ParamId::JointOffset(j) => format!("joint_offset[{}]", j + 1),
            ParamId::FrontBaseTranslation(a) => format!("front_base.translation.{}", AXES[a]),
            ParamId::FrontBaseRotation(a) => format!("front_base.rotation.{}", AXES[a]),
            ParamId::NeedleLength => "needle_length".into(),
            ParamId::FrontMountTranslation(a) => format!("front_mount.translation.{}", AXES[a]),
            ParamId::FrontMountRotation(a) => format!("front_mount.rotation.{}", AXES[a]),
            ParamId::BackMountTranslation(a) => format!("back_mount.translation.{}", AXES[a]),
            ParamId::BackMountRotation(a) => format!("back_mount.rotation.{}", AXES[a]),
            ParamId::Effect(p) => p.name(),
        }
    }

    /// Unit of the value as stored in the model.
    pub fn unit(&self) -> &'static str {
        match self {
            ParamId::Latency => "s",
            ParamId::Effect(p) => p.unit(),
            ParamId::GearRatio(_) => "1",
            ParamId::JointOffset(_)
            | ParamId::FrontBaseRotation(_)
            | ParamId::FrontMountRotation(_)
            | ParamId::BackMountRotation(_) => "rad",
            _ => "mm",
        }
    }

    /// How the parameter acts on a prediction.
    pub fn channel(&self) -> Channel {
        match self {
            ParamId::Latency | ParamId::GearRatio(_) | ParamId::JointOffset(_) => Channel::JointMap,
            ParamId::FrontBaseTranslation(_) | ParamId::FrontBaseRotation(_) => Channel::FrontBase,
            ParamId::NeedleLength => Channel::NeedleLength,
            ParamId::Effect(p) => p.channel(),
            _ => Channel::Mount,
        }
    }

    /// Finite-difference step for the Jacobian, in the parameter's unit.
    pub fn step(&self) -> f64 {
        match self.unit() {
            "s" => 1e-5,
            "mm" => 1e-4,
            _ => 1e-7,
        }
    }

    /// The parameter's value in `model`.
    pub fn get(&self, model: &CalibModel) -> f64 {
        let robot = &model.robot;
        match *self {
            ParamId::Latency => model.latency_s,
            ParamId::GearRatio(j) => robot.joints.gear_ratio[j],
            ParamId::JointOffset(j) => robot.joints.offset.unwrap_or_default()[j],
            ParamId::FrontBaseTranslation(a) => robot.geometry.front_base.translation.vector[a],
            ParamId::FrontBaseRotation(a) => {
                se3::rotation_log(&robot.geometry.front_base.rotation)[a]
            }
            ParamId::NeedleLength => robot.geometry.l_n,
            ParamId::FrontMountTranslation(a) => robot.markers.front_mount.translation.vector[a],
            ParamId::FrontMountRotation(a) => {
                se3::rotation_log(&robot.markers.front_mount.rotation)[a]
            }
            ParamId::BackMountTranslation(a) => robot.markers.back_mount.translation.vector[a],
            ParamId::BackMountRotation(a) => {
                se3::rotation_log(&robot.markers.back_mount.rotation)[a]
            }
            ParamId::Effect(p) => p.get(&robot.effects),
        }
    }

    /// Sets the parameter's value in `model`.
    pub fn set(&self, model: &mut CalibModel, value: f64) {
        let robot = &mut model.robot;
        match *self {
            ParamId::Latency => model.latency_s = value,
            ParamId::GearRatio(j) => robot.joints.gear_ratio[j] = value,
            ParamId::JointOffset(j) => robot.joints.offset.get_or_insert([0.0; 5])[j] = value,
            ParamId::FrontBaseTranslation(a) => {
                robot.geometry.front_base.translation.vector[a] = value;
            }
            ParamId::FrontBaseRotation(a) => set_rotation(&mut robot.geometry.front_base, a, value),
            ParamId::NeedleLength => robot.geometry.l_n = value,
            ParamId::FrontMountTranslation(a) => {
                robot.markers.front_mount.translation.vector[a] = value;
            }
            ParamId::FrontMountRotation(a) => {
                set_rotation(&mut robot.markers.front_mount, a, value)
            }
            ParamId::BackMountTranslation(a) => {
                robot.markers.back_mount.translation.vector[a] = value;
            }
            ParamId::BackMountRotation(a) => set_rotation(&mut robot.markers.back_mount, a, value),
            ParamId::Effect(p) => p.set(&mut robot.effects, value),
        }
    }
}

fn set_rotation(pose: &mut Isometry3<f64>, axis: usize, value: f64) {
    let mut vector: Vector3<f64> = se3::rotation_log(&pose.rotation);
    vector[axis] = value;
    *pose = se3::isometry(pose.translation.vector, vector);
}

/// An ordered list of the model scalars the optimiser moves.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamLayout {
    /// The parameters, in vector order.
    pub ids: Vec<ParamId>,
}

impl ParamLayout {
    /// The paper's parameters (docs/robot-model.md §6) plus the tracker latency; the rotation of
    /// `T_Bb_Bf` about z is not identifiable apart from θ_off,1 and θ_off,2 and stays out.
    pub fn paper() -> Self {
        let mut ids = vec![ParamId::Latency];
        ids.extend((0..5).map(ParamId::GearRatio));
        ids.extend((0..5).map(ParamId::JointOffset));
        ids.extend((0..3).map(ParamId::FrontBaseTranslation));
        ids.extend((0..2).map(ParamId::FrontBaseRotation));
        ids.push(ParamId::NeedleLength);
        ids.extend((0..3).map(ParamId::FrontMountTranslation));
        ids.extend((0..3).map(ParamId::FrontMountRotation));
        ids.extend((0..3).map(ParamId::BackMountTranslation));
        ids.extend((0..3).map(ParamId::BackMountRotation));
        Self { ids }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether the layout is empty.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The layout without `id`.
    pub fn without(&self, id: ParamId) -> Self {
        Self {
            ids: self.ids.iter().copied().filter(|i| *i != id).collect(),
        }
    }

    /// The parameter vector of `model`.
    pub fn values(&self, model: &CalibModel) -> DVector<f64> {
        DVector::from_iterator(self.ids.len(), self.ids.iter().map(|id| id.get(model)))
    }

    /// Writes the vector `x` into `model`.
    pub fn apply(&self, model: &mut CalibModel, x: &DVector<f64>) {
        for (id, value) in self.ids.iter().zip(x.iter()) {
            id.set(model, *value);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_and_apply_round_trip_every_parameter() {
        let mut model = CalibModel {
            robot: RobotParams::nominal(),
            latency_s: 0.03,
        };
        model.robot.joints.offset = Some([0.1, 0.2, 0.3, 0.4, 0.5]);
        let layout = ParamLayout::paper();
        assert_eq!(layout.len(), 29);
        let x = layout.values(&model);
        let shifted = x.map(|v| v + 0.01);
        layout.apply(&mut model, &shifted);
        let back = layout.values(&model);
        assert!((back - shifted).amax() < 1e-12);
        assert!((model.robot.geometry.front_base.rotation.scaled_axis().z).abs() < 1e-12);
    }
}
