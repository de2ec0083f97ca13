//! The parameters of the biopsy model: which scalar of [`BiopsyModel`] each [`ParamId`] is,
//! its unit and step, and how it acts on a prediction ([`Channel`], which the channel
//! Jacobian uses).
//!
//! The paper's layout ([`paper_layout`]) holds the tracker latency, `GR_1..5`, `θ_off,1..5`,
//! `T_Bb_Bf` (3 translations, rotations about x and y), `l_n` and the two marker mountings
//! (6 each). Effects extend it with the parameters of the effects the model carries.

use nalgebra::{Isometry3, Vector3};
use sabr_model::{Effect, EffectField};

use crate::math::se3;
use crate::model::biopsy::BiopsyModel;
use crate::model::ParamLayout;

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
    pub fn get(&self, model: &BiopsyModel) -> f64 {
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
    pub fn set(&self, model: &mut BiopsyModel, value: f64) {
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

/// One numeric parameter of the effect at `index` in `RobotParams::effects`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EffectParam {
    /// Index of the effect in `RobotParams::effects` (the `[[effects]]` array).
    pub index: usize,
    /// Which field.
    pub field: EffectField,
}

impl EffectParam {
    /// The parameters of every effect in `effects`, in order.
    pub fn all(effects: &[Effect]) -> Vec<EffectParam> {
        effects
            .iter()
            .enumerate()
            .flat_map(|(index, effect)| {
                effect
                    .fields()
                    .iter()
                    .map(move |&field| EffectParam { index, field })
            })
            .collect()
    }

    /// Name, e.g. `effects[0].amplitude`.
    pub fn name(&self) -> String {
        format!("effects[{}].{}", self.index, self.field.name())
    }

    /// Unit of the value.
    pub fn unit(&self) -> &'static str {
        self.field.unit()
    }

    /// How the parameter acts on a prediction: link lengths and axis tilts through the
    /// geometry, the joint-side effects through the joint angles.
    pub fn channel(&self) -> Channel {
        match self.field {
            EffectField::Delta | EffectField::Angle => Channel::Geometry,
            _ => Channel::JointMap,
        }
    }

    /// Its value in `effects`; NaN when the index or the field does not match an effect.
    pub fn get(&self, effects: &[Effect]) -> f64 {
        effects
            .get(self.index)
            .and_then(|e| e.field(self.field))
            .unwrap_or(f64::NAN)
    }

    /// Sets its value in `effects` (nothing when the index or field does not match).
    pub fn set(&self, effects: &mut [Effect], value: f64) {
        if let Some(effect) = effects.get_mut(self.index) {
            effect.set_field(self.field, value);
        }
    }
}

/// The paper's parameters (docs/robot-model.md §6) plus the tracker latency; the rotation of
/// `T_Bb_Bf` about z is not identifiable apart from θ_off,1 and θ_off,2 and stays out.
pub fn paper_layout() -> ParamLayout<ParamId> {
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
    ParamLayout::new(ids)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_and_apply_round_trip_every_parameter() {
        let mut model = BiopsyModel {
            robot: sabr_model::RobotParams::nominal(),
            latency_s: 0.03,
        };
        model.robot.joints.offset = Some([0.1, 0.2, 0.3, 0.4, 0.5]);
        let layout = paper_layout();
        assert_eq!(layout.len(), 29);
        let x = layout.values(&model);
        let shifted = x.map(|v| v + 0.01);
        layout.apply(&mut model, &shifted);
        let back = layout.values(&model);
        assert!((back - shifted).amax() < 1e-12);
        assert!((model.robot.geometry.front_base.rotation.scaled_axis().z).abs() < 1e-12);
    }

    #[test]
    fn effect_parameters_name_their_effect_and_mismatches_are_inert() {
        let mut effects = vec![
            Effect::TransmissionRipple {
                joint: 1,
                harmonic: 2.0,
                amplitude: 0.001,
                phase: 0.3,
            },
            Effect::LinkLength {
                link: sabr_model::Link::LF,
                delta: 0.2,
            },
        ];
        let params = EffectParam::all(&effects);
        assert_eq!(params.len(), 3);
        assert_eq!(params[2].name(), "effects[1].delta");
        assert_eq!(params[2].unit(), "mm");
        assert_eq!(params[2].channel(), Channel::Geometry);
        assert_eq!(params[0].channel(), Channel::JointMap);
        params[1].set(&mut effects, 0.7);
        assert_eq!(params[1].get(&effects), 0.7);
        let wrong = EffectParam {
            index: 1,
            field: EffectField::Gain,
        };
        assert!(wrong.get(&effects).is_nan());
        let before = effects.clone();
        wrong.set(&mut effects, 5.0);
        EffectParam {
            index: 9,
            field: EffectField::Width,
        }
        .set(&mut effects, 5.0);
        assert_eq!(effects, before);
    }
}
