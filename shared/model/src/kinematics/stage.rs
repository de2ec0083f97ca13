//! The planar 5-bar of each stage (paper eqs. 1, 2 and 12): the effector point
//! `l (cos θp, sin θp) + l (cos θd, sin θd) + l_e (cos(θd − π/4), sin(θd − π/4))`.

use std::f64::consts::FRAC_1_SQRT_2;

use super::scalar::planar_length;
use crate::Geometry;

/// One stage: proximal link `l` on joint θp, distal link `l` plus the effector extension `l_e`
/// at −45° on joint θd. Lengths in mm.
#[derive(Debug, Clone)]
pub(super) struct FiveBar {
    l: f64,
    l_e: f64,
    /// Length of the combined distal vector `l + l_e·e^{−iπ/4}` (mm).
    distal: f64,
    /// Cosine and sine of that vector's angle relative to θd.
    distal_direction: (f64, f64),
}

impl FiveBar {
    fn new(l: f64, l_e: f64) -> Self {
        let along = l + l_e * FRAC_1_SQRT_2;
        let across = -l_e * FRAC_1_SQRT_2;
        let distal = (along * along + across * across).sqrt();
        Self {
            l,
            l_e,
            distal,
            distal_direction: (along / distal, across / distal),
        }
    }

    /// The front stage (θ1, θ2), in the x-y plane of `Bf`.
    pub(super) fn front(geometry: &Geometry) -> Self {
        Self::new(geometry.l_f, geometry.l_fe)
    }

    /// The back stage (θ4, θ5), in its own plane before the θ3 turn.
    pub(super) fn back(geometry: &Geometry) -> Self {
        Self::new(geometry.l_b, geometry.l_be)
    }

    /// The proximal vector (driven by θp) and the distal vector with the effector extension
    /// (driven by θd), in the stage plane (mm); their sum is the effector point.
    pub(super) fn link_vectors(&self, proximal: f64, distal: f64) -> [(f64, f64); 2] {
        let (s1, c1) = proximal.sin_cos();
        let (s2, c2) = distal.sin_cos();
        let (ce, se) = ((c2 + s2) * FRAC_1_SQRT_2, (s2 - c2) * FRAC_1_SQRT_2);
        [
            (self.l * c1, self.l * s1),
            (self.l * c2 + self.l_e * ce, self.l * s2 + self.l_e * se),
        ]
    }

    /// Both joint solutions (θp, θd) (rad, not wrapped) reaching the effector point `(x, y)` (mm);
    /// an error says why the point is out of reach.
    pub(super) fn inverse(&self, x: f64, y: f64) -> Result<[(f64, f64); 2], String> {
        let reach = planar_length(x, y);
        let (inner, outer) = ((self.l - self.distal).abs(), self.l + self.distal);
        if !(reach >= inner && reach <= outer) {
            return Err(format!(
                "the point ({x:.3}, {y:.3}) mm is {reach:.3} mm from the base, outside the \
                 reachable annulus [{inner:.3}, {outer:.3}] mm"
            ));
        }
        let cos_spread = ((reach * reach + self.l * self.l - self.distal * self.distal)
            / (2.0 * self.l * reach))
            .clamp(-1.0, 1.0);
        let spread = cos_spread.acos();
        // The spread is in [0, π]: its sine is not negative.
        let sin_spread = (1.0 - cos_spread * cos_spread).sqrt();
        let bearing = y.atan2(x);
        let (cos_bearing, sin_bearing) = (x / reach, y / reach);
        let (cos_beta, sin_beta) = self.distal_direction;
        // θp = bearing ∓ spread, its cosine and sine by the angle sums (no sin_cos call).
        let solve = |proximal: f64, c: f64, s: f64| {
            let (dx, dy) = (x - self.l * c, y - self.l * s);
            // θd: the distal vector's bearing minus its angle β relative to θd.
            let distal = (dy * cos_beta - dx * sin_beta).atan2(dx * cos_beta + dy * sin_beta);
            (proximal, distal)
        };
        let (along, across) = (cos_bearing * cos_spread, sin_bearing * sin_spread);
        let (lift, turn) = (sin_bearing * cos_spread, cos_bearing * sin_spread);
        Ok([
            solve(bearing - spread, along + across, lift - turn),
            solve(bearing + spread, along - across, lift + turn),
        ])
    }
}
