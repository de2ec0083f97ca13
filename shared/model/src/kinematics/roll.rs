//! The needle roll of docs/robot-model.md §4: the directions `v ⊥ z_N` from the needle line to the
//! back gimbal centre `p_b = p_r + d_offset·v` for which the needle line, `p_b` and the back
//! gimbal axis `a_b ∥ P·p_b` (`P = diag(0, 1, 1)`) lie in one plane.
//!
//! With `v = cos φ e1 + sin φ e2` the plane condition `det[z_N, v, P·p_b] = 0` reads
//! `A c + B s + C c² + D c s + E s² = 0` (`c = cos φ`, `s = sin φ`), a trigonometric polynomial
//! of degree 2 with at most 4 roots. In the robot's workspace the linear part (amplitude
//! `R` ≈ |P·p_r| ≈ 90 mm) dominates the quadratic part (amplitude `Q` ≤ d_offset): where
//! `Q ≤` [`LINEAR_DOMINANCE`]`·R` there are exactly two roots, one within `asin(Q/R)` of each
//! zero of the linear part, where the condition is monotonic, and each is found by
//! safeguarded Newton steps from that zero, without a trigonometric call for the start.
//! Otherwise the roots are bracketed by sampling φ at [`SAMPLES`] points and polished the
//! same way; roots closer than 2π/[`SAMPLES`] (a near-singular, far-outside pose) may then be
//! missed, which makes such a target unreachable, never wrong.
//!
//! Vectors are `[x, y, z]` arrays so that the nalgebra and the glam kinematics share this code.

use std::f64::consts::{FRAC_PI_2, TAU};
use std::sync::LazyLock;

use super::scalar::planar_length;

/// Largest number of roots of a degree-2 trigonometric polynomial.
pub(super) const MAX_ROOTS: usize = 4;
/// Number of φ samples used to bracket the roots.
const SAMPLES: usize = 32;
/// Newton iterations allowed per root (it converges in 3–6; bisection needs ≤ 50).
const MAX_ITERATIONS: usize = 60;

/// `A c + B s + C c² + D c s + E s²`.
#[derive(Debug)]
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

    /// `R`, the amplitude of the linear part `A c + B s`.
    fn linear_amplitude(&self) -> f64 {
        planar_length(self.a, self.b)
    }

    /// `Q`, a bound on |C c² + D c s + E s²| over φ: the quadratic part is
    /// `(C + E)/2 + (C − E)/2·cos 2φ + D/2·sin 2φ`, so `Q = |C + E|/2 + |((C − E)/2, D/2)|`;
    /// its derivative with respect to φ is at most `2Q`.
    fn quadratic_bound(&self) -> f64 {
        let (half_difference, half_d) = (0.5 * (self.c - self.e), 0.5 * self.d);
        0.5 * (self.c + self.e).abs() + planar_length(half_difference, half_d)
    }

    /// All roots as cosines and sines, in the order of their rolls φ in [0, 2π).
    fn roots(&self) -> Roots {
        self.roots_near_linear_zeros()
            .unwrap_or_else(|| self.sampled_roots())
    }

    /// The two roots when the linear part dominates (`Q ≤` [`LINEAR_DOMINANCE`]`·R`), else
    /// `None`. With `A c + B s = R cos(φ − ψ)`, the linear part falls through zero at
    /// `ψ + π/2` and rises through zero at `ψ − π/2`. Within `δ = r·π/2` (`r = Q/R`) of each
    /// zero the condition's slope is at least `R·(cos δ − 2r) > 0` in magnitude and its
    /// value changes sign (`|R sin δ| ≥ Q` at the ends); elsewhere `|R cos(φ − ψ)| > Q`: no
    /// root. So each window holds exactly one root, and Newton starts at the zero itself,
    /// whose cosine and sine are `A/R` and `B/R` turned by a quarter.
    fn roots_near_linear_zeros(&self) -> Option<Roots> {
        let amplitude = self.linear_amplitude();
        let ratio = self.quadratic_bound() / amplitude;
        // R = 0 gives a NaN or infinite ratio: not dominant.
        if ratio.is_nan() || ratio > LINEAR_DOMINANCE {
            return None;
        }
        let half_width = ratio * FRAC_PI_2;
        let (cos_psi, sin_psi) = (self.a / amplitude, self.b / amplitude);
        let zeros = [((-sin_psi, cos_psi), false), ((sin_psi, -cos_psi), true)];
        let [near_falling_zero, near_rising_zero] = zeros.map(|(zero, rising)| {
            let bracket = Bracket {
                reference: zero,
                low: -half_width,
                high: half_width,
                rising,
            };
            self.root_in(bracket, 0.0, zero)
        });
        let (first, second) = if roll_order(near_falling_zero) <= roll_order(near_rising_zero) {
            (near_falling_zero, near_rising_zero)
        } else {
            (near_rising_zero, near_falling_zero)
        };
        let mut roots = Roots::default();
        roots.push(first);
        roots.push(second);
        Some(roots)
    }

    /// The roots bracketed by sampling φ at [`SAMPLES`] points and polished by
    /// [`Self::root_in`] from the secant's crossing in each bracket.
    fn sampled_roots(&self) -> Roots {
        let samples = &*SAMPLED;
        // All samples first: independent evaluations, no chain through a recurrence.
        let values: [f64; SAMPLES] =
            std::array::from_fn(|k| self.value(samples[k].0, samples[k].1));
        let step = TAU / SAMPLES as f64;
        let mut roots = Roots::default();
        for (k, &value) in values.iter().enumerate() {
            // The last interval ends where the first starts (φ = 2π is φ = 0).
            let next_value = values[(k + 1) % SAMPLES];
            if value == 0.0 {
                roots.push(samples[k]);
            } else if (value < 0.0) != (next_value < 0.0) && next_value != 0.0 {
                let low = k as f64 * step;
                let high = low + step;
                let secant = low + (high - low) * value / (value - next_value);
                let start = if secant > low && secant < high {
                    secant
                } else {
                    0.5 * (low + high)
                };
                let bracket = Bracket {
                    reference: (1.0, 0.0),
                    low,
                    high,
                    rising: value < 0.0,
                };
                let at_start = bracket.at(start);
                roots.push(self.root_in(bracket, start, at_start));
            }
        }
        roots
    }

    /// The root in `bracket`, as its cosine and sine: Newton steps from the roll `start`
    /// (rad from the bracket's reference; `at_start` its cosine and sine) that fall back to
    /// bisection when they leave the bracket. A small step turns the cosine and sine by a
    /// short series instead of evaluating them again.
    fn root_in(&self, mut bracket: Bracket, start: f64, at_start: (f64, f64)) -> (f64, f64) {
        let mut delta = start;
        let (mut cos, mut sin) = at_start;
        for _ in 0..MAX_ITERATIONS {
            let value = self.value(cos, sin);
            if value == 0.0 {
                return (cos, sin);
            }
            if (value < 0.0) == bracket.rising {
                bracket.low = delta;
            } else {
                bracket.high = delta;
            }
            let step = value / self.slope(cos, sin);
            let newton = delta - step;
            if newton >= bracket.low && newton <= bracket.high {
                // Quadratic convergence: after a step this small the error is far below
                // rounding (and the first order of the turn is exact to rounding).
                if step.abs() <= 1e-13 {
                    return (cos + step * sin, sin - step * cos);
                }
                delta = newton;
                (cos, sin) = if step.abs() <= SERIES_TURN_MAX {
                    turned(cos, sin, -step)
                } else {
                    bracket.at(delta)
                };
            } else {
                delta = 0.5 * (bracket.low + bracket.high);
                (cos, sin) = bracket.at(delta);
            }
            if bracket.high - bracket.low <= 1e-15 {
                break;
            }
        }
        (cos, sin)
    }
}

/// Largest `Q / R` for which [`PlaneCondition::roots_near_linear_zeros`] applies: up to it
/// `cos(r·π/2) − 2r` stays above 0.29, so the condition is monotonic next to each zero of
/// the linear part (it must stay positive up to the bound; it is 0 at r ≈ 0.36).
const LINEAR_DOMINANCE: f64 = 0.3;

/// Where one root of the condition lies: between the rolls `low` and `high` (rad, measured
/// from the roll whose cosine and sine are `reference`), the condition rising through it
/// when `rising`.
struct Bracket {
    reference: (f64, f64),
    low: f64,
    high: f64,
    rising: bool,
}

impl Bracket {
    /// The cosine and sine of the roll `delta` (rad) from the reference.
    fn at(&self, delta: f64) -> (f64, f64) {
        let (cos_reference, sin_reference) = self.reference;
        let (sin, cos) = delta.sin_cos();
        (
            cos_reference * cos - sin_reference * sin,
            sin_reference * cos + cos_reference * sin,
        )
    }
}

/// A number that increases with the roll φ in [0, 2π) whose cosine and sine are given (the
/// order in which the sampled search finds roots).
fn roll_order((cos, sin): (f64, f64)) -> f64 {
    if sin >= 0.0 {
        1.0 - cos
    } else {
        3.0 + cos
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

/// Up to [`MAX_ROOTS`] things found, one per root of the condition, in the order of their
/// rolls φ in [0, 2π).
#[derive(Default)]
pub(super) struct Found<T> {
    items: [T; MAX_ROOTS],
    len: usize,
}

impl<T: Copy> Found<T> {
    /// The things found, in order.
    pub(super) fn iter(&self) -> impl Iterator<Item = &T> {
        self.items[..self.len].iter()
    }

    fn push(&mut self, item: T) {
        if self.len < MAX_ROOTS {
            self.items[self.len] = item;
            self.len += 1;
        }
    }
}

/// The roots as the cosines and sines of their rolls φ.
type Roots = Found<(f64, f64)>;

/// The unit vectors `v`, `[x, y, z]` in `Bb`.
pub(super) type Directions = Found<Vector>;

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

    let mut directions = Directions::default();
    for &(c, s) in condition.roots().iter() {
        directions.push(std::array::from_fn(|i| c * e1[i] + s * e2[i]));
    }
    directions
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

    /// Where the linear part dominates, the roots next to its zeros are the sampled search's
    /// roots, in the same order; past the bound (up to four roots) every condition is
    /// searched by sampling, so no root is lost.
    #[test]
    fn roots_next_to_the_linear_zeros_are_the_sampled_ones() {
        use proptest::prelude::*;
        use proptest::test_runner::{Config, TestRunner};
        use std::cell::Cell;
        let coefficient = -1.0..1.0_f64;
        let conditions = (
            0.0..TAU,
            1.0..100.0_f64,
            coefficient.clone(),
            coefficient.clone(),
            coefficient,
            0.0..2.0_f64,
        )
            .prop_map(|(psi, amplitude, c, d, e, ratio)| {
                let quadratic = PlaneCondition {
                    a: 0.0,
                    b: 0.0,
                    c,
                    d,
                    e,
                };
                // Quadratic part scaled to `ratio` × the linear amplitude.
                let scale = ratio * amplitude / quadratic.quadratic_bound().max(1e-12);
                PlaneCondition {
                    a: amplitude * psi.cos(),
                    b: amplitude * psi.sin(),
                    c: c * scale,
                    d: d * scale,
                    e: e * scale,
                }
            });
        let (near_zeros, sampled_only) = (Cell::new(0), Cell::new(0));
        TestRunner::new(Config {
            cases: 2000,
            failure_persistence: None,
            ..Config::default()
        })
        .run(&conditions, |condition| {
            let sampled = condition.sampled_roots();
            let found = condition.roots();
            match condition.roots_near_linear_zeros() {
                Some(_) => near_zeros.set(near_zeros.get() + 1),
                None => sampled_only.set(sampled_only.get() + 1),
            }
            let (sampled, found): (Vec<_>, Vec<_>) =
                (sampled.iter().collect(), found.iter().collect());
            prop_assert_eq!(sampled.len(), found.len(), "{:?} vs {:?}", sampled, found);
            for (s, f) in sampled.iter().zip(&found) {
                prop_assert!(
                    (s.0 - f.0).abs() < 1e-12 && (s.1 - f.1).abs() < 1e-12,
                    "{:?} vs {:?}",
                    sampled,
                    found
                );
            }
            Ok(())
        })
        .unwrap();
        // Both ways were taken, each many times.
        assert!(
            near_zeros.get() > 200 && sampled_only.get() > 200,
            "{} next to the zeros, {} sampled only",
            near_zeros.get(),
            sampled_only.get()
        );
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
