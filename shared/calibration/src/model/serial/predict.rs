//! Prediction of a measured target and its exact derivatives: the arm's forward kinematics
//! at the joint readings moved by the joint effects, the target's mounting, thermal
//! expansion in the root frame, the set-up frame and its drift.
//!
//! `p_instrument = S · ((1 + α·ΔT) · T_root_link(q + Δq, e) · M) + d·s`. Derivatives are of
//! the prediction in the instrument frame: position rows (mm per unit), angular rows (rad
//! per unit, `δR = [δθ]× R`); the residual's are their negatives. The small factor
//! `1 + α·ΔT` is left out of the derivatives of the other parameters.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use sabr_model::{TargetJacobian, TreeState};

use crate::model::serial::candidates::SerialEffect;
use crate::model::serial::observation::{MeasuredTarget, PoseObservation};
use crate::model::serial::{SerialArm, SerialParam};

/// A target's predicted pose.
pub(super) struct TargetPrediction {
    /// Predicted pose in the instrument frame.
    pub(super) pose: Isometry3<f64>,
    /// Predicted position in the root frame before thermal expansion (mm).
    pub(super) root_position: Vector3<f64>,
    /// Temperature above the reference (°C; 0 when not recorded).
    pub(super) delta_t: f64,
}

/// A prediction with what its derivatives need.
pub(super) struct Linearised {
    /// The prediction.
    pub(super) prediction: TargetPrediction,
    /// Kinematic Jacobian of the target in the root frame.
    pub(super) jacobian: TargetJacobian,
    /// Rotation instrument ← root of the pose's set-up.
    to_instrument: UnitQuaternion<f64>,
    /// The set-up frame's origin and correction axes (instrument frame).
    setup_origin: Vector3<f64>,
    setup_axes: [Vector3<f64>; 3],
    /// The set-up's drift at this pose (mm).
    drift: Vector3<f64>,
    /// Rotation root ← link of the target's link, and the mounting's correction axes (link
    /// frame).
    link_rotation: UnitQuaternion<f64>,
    mounting_axes: [Vector3<f64>; 3],
}

/// Position and angular rows as one derivative column.
fn stack(p: Vector3<f64>, w: Vector3<f64>) -> [f64; 6] {
    [p.x, p.y, p.z, w.x, w.y, w.z]
}

impl SerialArm {
    /// The joint vector the arm stands at: the readings moved by the joint effects.
    pub(super) fn effective_joints(&self, obs: &PoseObservation) -> Vec<f64> {
        let mut joints = obs.joints.clone();
        for (effect, coefficients) in &self.effects {
            if let Some((variable, features)) = effect.joint_features(obs, &self.covered) {
                joints[variable] += coefficients[0] * features[0] + coefficients[1] * features[1];
            }
        }
        joints
    }

    fn thermal_alpha(&self) -> f64 {
        self.effects
            .iter()
            .filter(|(e, _)| *e == SerialEffect::Thermal)
            .map(|(_, c)| c[0])
            .sum()
    }

    fn drift(&self, obs: &PoseObservation) -> Vector3<f64> {
        let own = SerialEffect::Drift {
            setup: obs.setup as u16,
        };
        self.effects
            .iter()
            .filter(|(e, _)| *e == own)
            .map(|(_, c)| Vector3::new(c[0], c[1], c[2]) * obs.order)
            .sum()
    }

    /// The tree state at `obs` (`None` where the kinematics refuse the joint vector).
    pub(super) fn state(&self, obs: &PoseObservation) -> Option<TreeState> {
        self.tree
            .forward(&self.effective_joints(obs), &self.errors)
            .ok()
    }

    /// The prediction of `measured` at `state`.
    pub(super) fn predict(
        &self,
        obs: &PoseObservation,
        state: &TreeState,
        measured: &MeasuredTarget,
    ) -> TargetPrediction {
        let target = &self.targets[measured.target];
        let mounting = self.mountings[measured.target].pose();
        let root = state.link_pose(target.link) * mounting;
        let delta_t = obs
            .temperature_c
            .map_or(0.0, |t| t - self.reference_temperature_c);
        let grown = Isometry3::from_parts(
            Translation3::from(root.translation.vector * (1.0 + self.thermal_alpha() * delta_t)),
            root.rotation,
        );
        let mut pose = self.setup_frames[obs.setup].pose() * grown;
        pose.translation.vector += self.drift(obs);
        TargetPrediction {
            pose,
            root_position: root.translation.vector,
            delta_t,
        }
    }

    /// The prediction of `measured` at `state` with its kinematic Jacobian.
    pub(super) fn linearise(
        &self,
        obs: &PoseObservation,
        state: &TreeState,
        measured: &MeasuredTarget,
    ) -> Linearised {
        let target = &self.targets[measured.target];
        let mounting = &self.mountings[measured.target];
        let setup = &self.setup_frames[obs.setup];
        let setup_pose = setup.pose();
        Linearised {
            prediction: self.predict(obs, state, measured),
            jacobian: self
                .tree
                .pose_jacobian(state, target.link, &mounting.pose()),
            to_instrument: setup_pose.rotation,
            setup_origin: setup_pose.translation.vector,
            setup_axes: setup.rotation_axes(),
            drift: self.drift(obs),
            link_rotation: state.link_pose(target.link).rotation,
            mounting_axes: mounting.rotation_axes(),
        }
    }

    /// Derivative of the prediction with respect to `param`.
    pub(super) fn derivative(
        &self,
        obs: &PoseObservation,
        measured: &MeasuredTarget,
        lin: &Linearised,
        param: SerialParam,
    ) -> [f64; 6] {
        let r = lin.to_instrument;
        match param {
            SerialParam::Setup { setup, component } => {
                if usize::from(setup) != obs.setup {
                    return [0.0; 6];
                }
                let k = usize::from(component);
                if k < 3 {
                    let mut d = [0.0; 6];
                    d[k] = 1.0;
                    return d;
                }
                let axis = lin.setup_axes[k - 3];
                let lever = lin.prediction.pose.translation.vector - lin.drift - lin.setup_origin;
                stack(axis.cross(&lever), axis)
            }
            SerialParam::Mounting { target, component } => {
                if usize::from(target) != measured.target {
                    return [0.0; 6];
                }
                let k = usize::from(component);
                if k < 3 {
                    let mut e = Vector3::zeros();
                    e[k] = 1.0;
                    stack(r * (lin.link_rotation * e), Vector3::zeros())
                } else {
                    let axis = lin.mounting_axes[k - 3];
                    stack(Vector3::zeros(), r * (lin.link_rotation * axis))
                }
            }
            SerialParam::Error(index) => {
                let c = lin.jacobian.errors.column(usize::from(index));
                stack(
                    r * Vector3::new(c[0], c[1], c[2]),
                    r * Vector3::new(c[3], c[4], c[5]),
                )
            }
            SerialParam::Effect { effect, k } => {
                let candidate = self.effects[usize::from(effect)].0;
                self.effect_derivative(obs, lin, candidate)[usize::from(k)]
            }
        }
    }

    /// Derivatives of the prediction with respect to the coefficients of `effect` (one
    /// column per coefficient; the effect is linear, so they hold at any value).
    pub(super) fn effect_derivative(
        &self,
        obs: &PoseObservation,
        lin: &Linearised,
        effect: SerialEffect,
    ) -> Vec<[f64; 6]> {
        let r = lin.to_instrument;
        match effect {
            SerialEffect::Periodic { .. } | SerialEffect::Compliance { .. } => {
                let Some((variable, features)) = effect.joint_features(obs, &self.covered) else {
                    return vec![[0.0; 6]; effect.dim()];
                };
                let c = lin.jacobian.joints.column(variable);
                let p = r * Vector3::new(c[0], c[1], c[2]);
                let w = r * Vector3::new(c[3], c[4], c[5]);
                features.iter().map(|f| stack(p * *f, w * *f)).collect()
            }
            SerialEffect::Thermal => {
                let p = r * (lin.prediction.root_position * lin.prediction.delta_t);
                vec![stack(p, Vector3::zeros())]
            }
            SerialEffect::Drift { setup } => (0..3)
                .map(|k| {
                    let mut d = [0.0; 6];
                    if usize::from(setup) == obs.setup {
                        d[k] = obs.order;
                    }
                    d
                })
                .collect(),
        }
    }
}
