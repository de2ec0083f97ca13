//! Small rigid-motion helpers: rotation-vector logs, averaging of poses and points.

use nalgebra::{Isometry3, Matrix3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};

/// Rotation vector (axis · angle, rad) of `rotation`.
pub fn rotation_log(rotation: &UnitQuaternion<f64>) -> Vector3<f64> {
    rotation.scaled_axis()
}

/// Builds an isometry from a translation (mm) and a rotation vector (rad).
pub fn isometry(translation: Vector3<f64>, rotation_vector: Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_scaled_axis(rotation_vector),
    )
}

/// Raw pose residual: position (mm) and rotation vector (rad), measured minus predicted,
/// both in the frame the poses are given in.
pub fn pose_residual(measured: &Isometry3<f64>, predicted: &Isometry3<f64>) -> [f64; 6] {
    let dp = measured.translation.vector - predicted.translation.vector;
    let dr = rotation_log(&(measured.rotation * predicted.rotation.inverse()));
    [dp.x, dp.y, dp.z, dr.x, dr.y, dr.z]
}

/// Unit quaternion from tracker components (w, x, y, z); `None` unless finite and of norm
/// within 1 % of 1.
pub fn unit_quaternion(wxyz: [f64; 4]) -> Option<UnitQuaternion<f64>> {
    let q = Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
    let norm = q.norm();
    (norm.is_finite() && (norm - 1.0).abs() < 0.01).then(|| UnitQuaternion::from_quaternion(q))
}

/// Mean of rotations that are close to each other: sign-aligned quaternion average,
/// renormalised (the chordal L2 mean to first order). `None` for an empty slice.
pub fn mean_rotation(rotations: &[UnitQuaternion<f64>]) -> Option<UnitQuaternion<f64>> {
    let first = rotations.first()?;
    let mut sum = Quaternion::new(0.0, 0.0, 0.0, 0.0);
    for r in rotations {
        let q = r.quaternion();
        sum += if q.dot(first.quaternion()) < 0.0 {
            -q
        } else {
            *q
        };
    }
    Some(UnitQuaternion::from_quaternion(sum))
}

/// Mean pose: mean translation and [`mean_rotation`]. `None` for an empty slice.
pub fn mean_isometry(poses: &[Isometry3<f64>]) -> Option<Isometry3<f64>> {
    let rotations: Vec<_> = poses.iter().map(|p| p.rotation).collect();
    let rotation = mean_rotation(&rotations)?;
    let translation = mean_point(poses.iter().map(|p| Point3::from(p.translation.vector)))?;
    Some(Isometry3::from_parts(
        Translation3::from(translation.coords),
        rotation,
    ))
}

/// Mean of points; `None` when there are none.
pub fn mean_point(points: impl Iterator<Item = Point3<f64>>) -> Option<Point3<f64>> {
    let (sum, n) = points.fold((Vector3::zeros(), 0usize), |(s, n), p| {
        (s + p.coords, n + 1)
    });
    (n > 0).then(|| Point3::from(sum / n as f64))
}

/// Sample covariance (3×3) of vectors around their mean; `None` with fewer than 2.
pub fn covariance(vectors: &[Vector3<f64>]) -> Option<Matrix3<f64>> {
    if vectors.len() < 2 {
        return None;
    }
    let mean = vectors.iter().sum::<Vector3<f64>>() / vectors.len() as f64;
    let sum: Matrix3<f64> = vectors
        .iter()
        .map(|v| (v - mean) * (v - mean).transpose())
        .sum();
    Some(sum / (vectors.len() - 1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_rotation_handles_opposite_quaternion_signs() {
        let a = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.1));
        let b = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.3));
        let b_flipped = UnitQuaternion::new_unchecked(-b.into_inner());
        let mean = mean_rotation(&[a, b_flipped]).unwrap();
        assert!((rotation_log(&mean) - Vector3::new(0.0, 0.0, 0.2)).norm() < 1e-9);
    }

    #[test]
    fn unit_quaternion_rejects_non_unit_input() {
        assert!(unit_quaternion([1.0, 0.0, 0.0, 0.0]).is_some());
        assert!(unit_quaternion([2.0, 0.0, 0.0, 0.0]).is_none());
        assert!(unit_quaternion([f64::NAN, 0.0, 0.0, 0.0]).is_none());
    }

    #[test]
    fn covariance_of_known_spread() {
        let v = [Vector3::new(1.0, 0.0, 0.0), Vector3::new(-1.0, 0.0, 0.0)];
        let c = covariance(&v).unwrap();
        assert!((c[(0, 0)] - 2.0).abs() < 1e-12);
        assert!(c[(1, 1)].abs() < 1e-12);
    }
}
