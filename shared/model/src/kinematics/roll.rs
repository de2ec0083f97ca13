//! The needle roll of docs/robot-model.md §4: the directions `v ⊥ z_N` from the needle line to the
//! back gimbal centre `p_b = p_r + d_offset·v` for which the needle line, `p_b` and the back
//! gimbal axis `a_b ∥ P·p_b` (`P = diag(0, 1, 1)`) lie in one plane.
//!
//! With `v = cos φ e1 + sin φ e2` the plane condition `det[z_N, v, P·p_b] = 0` reads
//! `A c + B s + C c² + D c s + E s² = 0` (`c = cos φ`, `s = sin φ`), a trigonometric polynomial
//! of degree 2 with at most 4 roots. They are bracketed by sampling φ at
//! [`SAMPLES`] points and polished by safeguarded Newton steps. In the robot's workspace the
//! linear part (amplitude ≈ |P·p_r| ≈ 90 mm) dominates the quadratic part (≤ d_offset), so
//! the two roots are about π apart; roots closer than 2π/[`SAMPLES`] (a near-singular,
//! far-outside pose) may be missed, which makes such a target unreachable, never wrong.
//!
//! Vectors are `[x, y, z]` arrays so that the nalgebra and the glam kinematics share this code.

use std::f64::consts::TAU;
use std::sync::LazyLock;

/// Largest number of roots of a degree-2 trigonometric polynomial.
pub(super) const MAX_ROOTS: usize = 4;
/// Number of φ samples used to bracket the roots.
const SAMPLES: usize = 32;
/// Newton iterations allowed per root (it converges in 3–6; bisection needs ≤ 50).
const MAX_ITERATIONS: usize = 60;

/// `A c + B s + C c² + D c s + E s²`.
struct PlaneCondition {
    a: f64,
    b: f64,
    c: f64,
    d: f64,
    e: f64,
}

impl PlaneCondition {
    fn value(&self, cos: f64, sin: f64) -> f64 {
        self.a * cos + self.b * sin + cos * (self.c * cos + self.d * sin) + self.e * sin * sin
    }

    /// Derivative with respect to φ.
    fn slope(&self, cos: f64, sin: f64) -> f64 {
        -self.a * sin
            + self.b * cos
            + 2.0 * (self.e - self.c) * cos * sin
            + self.d * (cos * cos - sin * sin)
    }

    /// The root in `[low, high]`, where the condition changes sign (`value_low` at `low`,
    /// `value_high` at `high`), as its cosine and sine: Newton steps from the secant's
    /// crossing that fall back to bisection when they leave the bracket. A small step turns
    /// the cosine and sine by a short series instead of evaluating them again.
    fn root_between(
        &self,
        mut low: f64,
        mut high: f64,
        value_low: f64,
        value_high: f64,
    ) -> (f64, f64) {
        let rising = value_low < 0.0;
        let secant = low + (high - low) * value_low / (value_low - value_high);
        let mut phi = if secant > low && secant < high {
            secant
        } else {
            0.5 * (low + high)
        };
        let (mut sin, mut cos) = phi.sin_cos();
        for _ in 0..MAX_ITERATIONS {
            let value = self.value(cos, sin);
            if value == 0.0 {
                return (cos, sin);
            }
            if (value < 0.0) == rising {
                low = phi;
            } else {
                high = phi;
            }
            let step = value / self.slope(cos, sin);
            let newton = phi - step;
            if newton >= low && newton <= high {
                // Quadratic convergence: after a step this small the error is far below
                // rounding (and the first order of the turn is exact to rounding).
                if step.abs() <= 1e-13 {
                    return (cos + step * sin, sin - step * cos);
                }
                phi = newton;
                if step.abs() <= SERIES_TURN_MAX {
                    (cos, sin) = turned(cos, sin, -step);
                } else {
                    (sin, cos) = phi.sin_cos();
                }
            } else {
                phi = 0.5 * (low + high);
                (sin, cos) = phi.sin_cos();
            }
            if high - low <= 1e-15 {
                break;
            }
        }
        (cos, sin)
    }
}

/// Largest turn (rad) that [`turned`] makes by its series: their next terms are below
/// 1e-16 up to here.
const SERIES_TURN_MAX: f64 = 0.03;

/// `(cos(φ + δ), sin(φ + δ))` from `(cos φ, sin φ)` for |δ| ≤ [`SERIES_TURN_MAX`], with the
/// cosine and sine of δ by their Taylor series to the δ⁶ and δ⁷ terms.
fn turned(cos: f64, sin: f64, delta: f64) -> (f64, f64) {
    let d2 = delta * delta;
    let cos_delta = 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0));
    let sin_delta = delta * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0)));
    (
        cos * cos_delta - sin * sin_delta,
        sin * cos_delta + cos * sin_delta,
    )
}

/// A vector `[x, y, z]` (`Bb`).
type Vector = [f64; 3];

fn dot(a: &Vector, b: &Vector) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: &Vector, b: &Vector) -> Vector {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Up to [`MAX_ROOTS`] unit vectors `v`.
pub(super) struct Directions {
    items: [Vector; MAX_ROOTS],
    len: usize,
}

impl Directions {
    /// The directions found, `[x, y, z]` in `Bb`.
    pub(super) fn iter(&self) -> impl Iterator<Item = &[f64; 3]> {
        self.items[..self.len].iter()
    }

    fn push(&mut self, v: Vector) {
        if self.len < MAX_ROOTS {
            self.items[self.len] = v;
            self.len += 1;
        }
    }
}

/// An orthonormal pair `e1, e2` with `e1 × e2 = z` (z a unit vector).
fn perpendicular_basis(z: &Vector) -> (Vector, Vector) {
    let helper = if z[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let along = dot(&helper, z);
    let e1: Vector = std::array::from_fn(|i| helper[i] - along * z[i]);
    let norm = dot(&e1, &e1).sqrt();
    let e1 = e1.map(|v| v / norm);
    (e1, cross(z, &e1))
}

/// All directions `v ⊥ z` (unit) for which `p_b = p_r + offset·v` satisfies the gimbal plane
/// condition. `p_r` in mm (`Bb`), `z` the unit needle direction, `offset` = `d_offset` (mm).
pub(super) fn gimbal_plane_directions(p_r: &[f64; 3], z: &[f64; 3], offset: f64) -> Directions {
    let (e1, e2) = perpendicular_basis(z);
    // det[z, v, P p_r] = v · (P p_r × z)
    let k = cross(&[0.0, p_r[1], p_r[2]], z);
    // det[z, v, P v] = −v_x · v·(x̂ × z)
    let m = [0.0, -z[2], z[1]];
    let (a1, b1, p1, q1) = (e1[0], e2[0], dot(&e1, &m), dot(&e2, &m));
    let condition = PlaneCondition {
        a: dot(&e1, &k),
        b: dot(&e2, &k),
        c: -offset * a1 * p1,
        d: -offset * (a1 * q1 + b1 * p1),
        e: -offset * b1 * q1,
    };

    let mut roots = Directions {
        items: [[0.0; 3]; MAX_ROOTS],
        len: 0,
    };
    let samples = &*SAMPLED;
    // All samples first: independent evaluations, no chain through a recurrence.
    let values: [f64; SAMPLES] =
        std::array::from_fn(|k| condition.value(samples[k].0, samples[k].1));
    let step = TAU / SAMPLES as f64;
    for (k, &value) in values.iter().enumerate() {
        // The last interval ends where the first starts (φ = 2π is φ = 0).
        let next_value = values[(k + 1) % SAMPLES];
        let root = if value == 0.0 {
            Some(samples[k])
        } else if (value < 0.0) != (next_value < 0.0) && next_value != 0.0 {
            let low = k as f64 * step;
            Some(condition.root_between(low, low + step, value, next_value))
        } else {
            None
        };
        if let Some((c, s)) = root {
            roots.push(std::array::from_fn(|i| c * e1[i] + s * e2[i]));
        }
    }
    roots
}

/// `(cos φ, sin φ)` of the sampled rolls φ = k·2π/[`SAMPLES`], k = 0..[`SAMPLES`].
static SAMPLED: LazyLock<[(f64, f64); SAMPLES]> = LazyLock::new(|| {
    std::array::from_fn(|k| {
        let (sin, cos) = (k as f64 * TAU / SAMPLES as f64).sin_cos();
        (cos, sin)
    })
});

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// At home (needle along +z, p_r = (0, −90, 0), d_offset = 20) the condition is
    /// `v_x (−90 + 20 v_y) = 0`: exactly the two rolls v = (0, ±1, 0).
    #[test]
    fn home_has_the_two_vertical_rolls() {
        let roots = gimbal_plane_directions(&[0.0, -90.0, 0.0], &[0.0, 0.0, 1.0], 20.0);
        let mut ys: Vec<f64> = roots.iter().map(|v| v[1]).collect();
        ys.sort_by(f64::total_cmp);
        assert_eq!(ys.len(), 2);
        assert!(
            (ys[0] + 1.0).abs() < 1e-12 && (ys[1] - 1.0).abs() < 1e-12,
            "{ys:?}"
        );
        assert!(roots
            .iter()
            .all(|v| v[0].abs() < 1e-12 && v[2].abs() < 1e-12));
    }

    /// The series turn agrees with `sin_cos` of the turned angle to rounding over its range.
    #[test]
    fn series_turns_match_sin_cos() {
        for phi in [0.0, 0.7, 2.0, -2.9] {
            for delta in [
                0.0,
                1e-9,
                -1e-5,
                0.003,
                -0.017,
                SERIES_TURN_MAX,
                -SERIES_TURN_MAX,
            ] {
                let (sin, cos) = f64::sin_cos(phi);
                let (turned_cos, turned_sin) = turned(cos, sin, delta);
                let (expected_sin, expected_cos) = (phi + delta).sin_cos();
                assert!(
                    (turned_cos - expected_cos).abs() < 4e-16
                        && (turned_sin - expected_sin).abs() < 4e-16,
                    "φ {phi}, δ {delta}: ({turned_cos}, {turned_sin}) vs ({expected_cos}, {expected_sin})"
                );
            }
        }
    }

    /// Every root found satisfies the plane condition det[z, v, P(p_r + d v)] = 0 and is ⊥ z.
    #[test]
    fn roots_satisfy_the_plane_condition() {
        let z = Vector3::new(0.1, -0.2, 0.97).normalize();
        let p_r = Vector3::new(4.0, -80.0, 6.0);
        let roots = gimbal_plane_directions(&p_r.into(), &z.into(), 20.0);
        assert!(roots.iter().count() >= 2);
        for &v in roots.iter() {
            let v = Vector3::from(v);
            let p_b = p_r + 20.0 * v;
            let projected = Vector3::new(0.0, p_b.y, p_b.z);
            let det = z.dot(&v.cross(&projected));
            assert!(det.abs() < 1e-10, "{det}");
            assert!(v.dot(&z).abs() < 1e-12 && (v.norm() - 1.0).abs() < 1e-12);
        }
    }
}
