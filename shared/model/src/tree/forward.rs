//! Forward kinematics of every link and the Jacobian of a target with respect to the
//! geometric errors and the joint variables.
//!
//! Each moving joint is a chain of elementary screws — three error translations, three error
//! rotations, the joint's own motion — so every Jacobian column is exact at any parameter
//! value: a translation along a unit axis `a` moves the target by `a`; a rotation about `a`
//! through the point `o` moves it by `a × (p − o)` and turns it by `a`.

use nalgebra::{Isometry3, Matrix6xX, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::{check_vector, JointType, KinematicTree, LinkId, TreeError};

/// The axes of the elementary screws of one moving joint, in the root frame, at one
/// configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct JointScrews {
    /// Where the error rotations and the joint motion act: the joint origin moved by the
    /// error translation (mm).
    pub(super) point: Vector3<f64>,
    /// Directions of the error translations `tx`, `ty`, `tz` (the joint frame's axes).
    pub(super) translation_axes: [Vector3<f64>; 3],
    /// Axes of the error rotations `rx`, `ry`, `rz`.
    pub(super) rotation_axes: [Vector3<f64>; 3],
    /// The joint's axis of motion.
    pub(super) motion_axis: Vector3<f64>,
}

impl Default for JointScrews {
    fn default() -> Self {
        let zero = Vector3::zeros();
        JointScrews {
            point: zero,
            translation_axes: [zero; 3],
            rotation_axes: [zero; 3],
            motion_axis: zero,
        }
    }
}

/// The kinematic state of a tree at one joint vector and error vector: every link's pose in
/// the root frame (mm), and what the Jacobians need.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeState {
    pub(super) link_poses: Vec<Isometry3<f64>>,
    pub(super) screws: Vec<JointScrews>,
}

impl TreeState {
    /// `T_root_link`: the pose of `link`'s frame in the root frame (mm).
    pub fn link_pose(&self, link: LinkId) -> &Isometry3<f64> {
        &self.link_poses[link.0]
    }

    /// Every link's pose, indexed like [`KinematicTree::links`].
    pub fn link_poses(&self) -> &[Isometry3<f64>] {
        &self.link_poses
    }
}

/// The derivatives of a target's pose: rows 0–2 its position (mm per unit of the parameter),
/// rows 3–5 its rotation as an angular displacement in the root frame (rad per unit:
/// `δR = [δθ]× R`). One column per error parameter in `errors`, per joint variable in
/// `joints`.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetJacobian {
    /// The target's pose in the root frame (mm).
    pub pose: Isometry3<f64>,
    /// With respect to the geometric errors (mm or rad each).
    pub errors: Matrix6xX<f64>,
    /// With respect to the joint variables (rad or mm each).
    pub joints: Matrix6xX<f64>,
}

impl KinematicTree {
    /// Forward kinematics: every link's pose for the joint vector `joints` (rad or mm, in
    /// [`KinematicTree::variables`] order) and the geometric errors `errors` (in
    /// [`KinematicTree::error_parameters`] order; [`KinematicTree::nominal_errors`] for the
    /// nominal geometry). Limits are not checked ([`KinematicTree::check_limits`]).
    pub fn forward(&self, joints: &[f64], errors: &[f64]) -> Result<TreeState, TreeError> {
        let mut state = TreeState {
            link_poses: vec![Isometry3::identity(); self.links.len()],
            screws: vec![JointScrews::default(); self.joints.len()],
        };
        self.forward_into(&mut state, joints, errors)?;
        Ok(state)
    }

    /// Like [`KinematicTree::forward`], reusing `state`'s storage (it must come from this
    /// tree).
    pub fn forward_into(
        &self,
        state: &mut TreeState,
        joints: &[f64],
        errors: &[f64],
    ) -> Result<(), TreeError> {
        self.check_joints(joints)?;
        check_vector("error vector", errors, self.errors.len())?;
        if let Some((value, parameter)) = errors
            .iter()
            .zip(&self.errors)
            .find(|(v, _)| !v.is_finite())
        {
            return Err(TreeError::NotFinite {
                what: "error parameter",
                name: parameter.name.clone(),
                value: *value,
            });
        }
        state.link_poses[self.root] = Isometry3::identity();
        for (index, joint) in self.joints.iter().enumerate() {
            let parent = state.link_poses[joint.parent_link];
            let frame = parent * joint.origin;
            let (Some(drive), Some(first)) = (joint.drive, joint.first_error) else {
                state.link_poses[joint.child_link] = frame;
                continue;
            };
            let e = &errors[first..first + 6];
            let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), e[3]);
            let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), e[4]);
            let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), e[5]);
            let frame_rotation = frame.rotation.to_rotation_matrix();
            let after_x = frame_rotation * rx;
            let after_y = after_x * ry;
            let error = Isometry3::from_parts(
                Translation3::new(e[0], e[1], e[2]),
                UnitQuaternion::from_rotation_matrix(&(rx * ry * rz)),
            );
            let moved = frame * error;
            let value = drive.multiplier * joints[drive.variable] + drive.offset;
            let motion = match joint.kind {
                JointType::Revolute => Isometry3::from_parts(
                    Translation3::identity(),
                    UnitQuaternion::from_axis_angle(&joint.axis, value),
                ),
                _ => Isometry3::translation(
                    joint.axis.x * value,
                    joint.axis.y * value,
                    joint.axis.z * value,
                ),
            };
            state.screws[index] = JointScrews {
                point: moved.translation.vector,
                translation_axes: std::array::from_fn(|i| frame_rotation.matrix().column(i).into()),
                rotation_axes: [
                    frame_rotation * Vector3::x(),
                    after_x * Vector3::y(),
                    after_y * Vector3::z(),
                ],
                motion_axis: moved.rotation * joint.axis.into_inner(),
            };
            state.link_poses[joint.child_link] = moved * motion;
        }
        Ok(())
    }

    /// The pose of a target rigidly mounted on `link` at `mounting` (`T_link_target`, mm) and
    /// its Jacobian, from a state of this tree.
    pub fn pose_jacobian(
        &self,
        state: &TreeState,
        link: LinkId,
        mounting: &Isometry3<f64>,
    ) -> TargetJacobian {
        let pose = state.link_poses[link.0] * mounting;
        let point = pose.translation.vector;
        let mut errors = Matrix6xX::zeros(self.errors.len());
        let mut joints = Matrix6xX::zeros(self.variables.len());
        for &index in &self.chains[link.0] {
            let joint = &self.joints[index];
            let screws = &state.screws[index];
            let lever = point - screws.point;
            let (Some(drive), Some(first)) = (joint.drive, joint.first_error) else {
                continue;
            };
            for (i, axis) in screws.translation_axes.iter().enumerate() {
                errors.fixed_view_mut::<3, 1>(0, first + i).copy_from(axis);
            }
            for (i, axis) in screws.rotation_axes.iter().enumerate() {
                let mut column = errors.column_mut(first + 3 + i);
                column.fixed_rows_mut::<3>(0).copy_from(&axis.cross(&lever));
                column.fixed_rows_mut::<3>(3).copy_from(axis);
            }
            let axis = screws.motion_axis;
            let mut column = joints.column_mut(drive.variable);
            match joint.kind {
                JointType::Revolute => {
                    let mut linear = column.fixed_rows_mut::<3>(0);
                    linear += axis.cross(&lever) * drive.multiplier;
                    let mut angular = column.fixed_rows_mut::<3>(3);
                    angular += axis * drive.multiplier;
                }
                _ => {
                    let mut linear = column.fixed_rows_mut::<3>(0);
                    linear += axis * drive.multiplier;
                }
            }
        }
        TargetJacobian {
            pose,
            errors,
            joints,
        }
    }

    /// The position of a point fixed on `link` (`point` in the link's frame, mm) in the root
    /// frame, and its Jacobian (only the position rows 0–2 are meaningful; rows 3–5 are the
    /// link's angular displacement).
    pub fn point_jacobian(
        &self,
        state: &TreeState,
        link: LinkId,
        point: &Point3<f64>,
    ) -> TargetJacobian {
        self.pose_jacobian(
            state,
            link,
            &Isometry3::translation(point.x, point.y, point.z),
        )
    }
}
