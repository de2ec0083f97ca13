//! A rigid frame the calibration moves: a start pose and six small corrections, composed so
//! that every derivative is an exact elementary screw (as for the kinematic tree's joint
//! errors).
//!
//! `pose = Trans(t₀ + δt) · Rx(δrx) · Ry(δry) · Rz(δrz) · R₀`: the corrections translate the
//! frame's origin and turn the frame about its own origin, about axes of the frame it is
//! expressed in. Set-up frames (tracker ← robot root) and target mountings (link ← target)
//! are both of this kind.

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// A frame: its start pose and its six corrections (mm, mm, mm, rad, rad, rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// The start pose.
    pub start: Isometry3<f64>,
    /// Corrections `tx, ty, tz` (mm) and `rx, ry, rz` (rad).
    pub delta: [f64; 6],
}

impl Frame {
    /// A frame at `start` with no correction.
    pub fn at(start: Isometry3<f64>) -> Self {
        Self {
            start,
            delta: [0.0; 6],
        }
    }

    /// The corrected pose.
    pub fn pose(&self) -> Isometry3<f64> {
        let d = &self.delta;
        let turn = Rotation3::from_axis_angle(&Vector3::x_axis(), d[3])
            * Rotation3::from_axis_angle(&Vector3::y_axis(), d[4])
            * Rotation3::from_axis_angle(&Vector3::z_axis(), d[5]);
        Isometry3::from_parts(
            Translation3::from(self.start.translation.vector + Vector3::new(d[0], d[1], d[2])),
            UnitQuaternion::from_rotation_matrix(&turn) * self.start.rotation,
        )
    }

    /// The axes of the three correction rotations at the current corrections, in the frame
    /// the pose is expressed in: `x`, `Rx·y`, `Rx·Ry·z`.
    pub fn rotation_axes(&self) -> [Vector3<f64>; 3] {
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), self.delta[3]);
        let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), self.delta[4]);
        [Vector3::x(), rx * Vector3::y(), rx * ry * Vector3::z()]
    }

    /// The same pose with the corrections folded into the start (all corrections zero).
    pub fn folded(&self) -> Self {
        Self::at(self.pose())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_axes_are_the_exact_derivatives_of_the_pose() {
        let mut frame = Frame::at(Isometry3::new(
            Vector3::new(100.0, -20.0, 5.0),
            Vector3::new(0.3, -0.2, 1.0),
        ));
        frame.delta = [0.5, -0.2, 0.1, 0.02, -0.03, 0.05];
        let point = Vector3::new(300.0, 40.0, -70.0);
        let p = |f: &Frame| f.pose() * nalgebra::Point3::from(point);
        let base = p(&frame);
        let origin = frame.pose().translation.vector;
        for (k, axis) in frame.rotation_axes().iter().enumerate() {
            let mut moved = frame;
            moved.delta[3 + k] += 1e-7;
            let numeric = (p(&moved) - base) / 1e-7;
            let exact = axis.cross(&(base.coords - origin));
            assert!(
                (numeric - exact).norm() < 1e-4,
                "axis {k}: {numeric} vs {exact}"
            );
        }
        let folded = frame.folded();
        assert!(
            (folded.pose().translation.vector - frame.pose().translation.vector).norm() < 1e-12
        );
        assert_eq!(folded.delta, [0.0; 6]);
    }
}
