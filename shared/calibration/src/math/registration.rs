//! Rigid registration of point pairs (Horn/Kabsch): the rotation and translation that best
//! map one set of points onto another in least squares. It starts the set-up frames of a
//! measured arm, which may be anywhere relative to the robot.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// The rigid motion `T` minimising `Σ |to_i − T·from_i|²`; `None` for fewer than three
/// pairs or points that do not span a plane.
pub fn register(from: &[Point3<f64>], to: &[Point3<f64>]) -> Option<Isometry3<f64>> {
    if from.len() < 3 || from.len() != to.len() {
        return None;
    }
    let n = from.len() as f64;
    let centre =
        |points: &[Point3<f64>]| points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n;
    let (cf, ct) = (centre(from), centre(to));
    let mut h = Matrix3::zeros();
    for (a, b) in from.iter().zip(to) {
        h += (a.coords - cf) * (b.coords - ct).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut sorted = svd.singular_values.as_slice().to_vec();
    sorted.sort_by(|a, b| b.total_cmp(a));
    if sorted[1] <= 1e-9 * sorted[0].max(f64::MIN_POSITIVE) {
        return None;
    }
    let mut correction = Matrix3::identity();
    if (v_t.transpose() * u.transpose()).determinant() < 0.0 {
        correction[(2, 2)] = -1.0;
    }
    let rotation = Rotation3::from_matrix_unchecked(v_t.transpose() * correction * u.transpose());
    let translation = ct - rotation * cf;
    Some(Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_rigid_motion() {
        let truth = Isometry3::new(
            Vector3::new(2000.0, -1300.0, 40.0),
            Vector3::new(0.1, -0.4, 2.5),
        );
        let from: Vec<Point3<f64>> = (0..20)
            .map(|i| {
                let t = i as f64;
                Point3::new(300.0 * t.sin(), 200.0 * (1.3 * t).cos(), 50.0 * t)
            })
            .collect();
        let to: Vec<Point3<f64>> = from.iter().map(|p| truth * p).collect();
        let found = register(&from, &to).unwrap();
        assert!((found.translation.vector - truth.translation.vector).norm() < 1e-6);
        assert!(found.rotation.angle_to(&truth.rotation) < 1e-9);
        assert!(register(&from[..2], &to[..2]).is_none());
    }
}
