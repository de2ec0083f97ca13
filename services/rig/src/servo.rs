//! The motor position servo of the simulated drive: each motor follows its setpoint with a
//! first-order lag whose speed is limited, `dx/dt = clamp((s − x) / τ, −v_max, v_max)`,
//! integrated exactly for a setpoint held over the step. Positions are encoder counts
//! (fractional: the true motor angle before quantisation).

use std::f64::consts::TAU;

/// Dynamics of one motor's position loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoConfig {
    /// Time constant of the position loop, s (0: the motor reaches the setpoint as fast as the
    /// speed limit allows).
    pub time_constant_s: f64,
    /// Highest motor speed, counts/s.
    pub max_speed: f64,
}

impl ServoConfig {
    /// A servo with time constant `tau_s` (s) and top motor speed `max_motor_rad_s` (rad/s of
    /// the motor shaft) for an encoder of `counts_per_rev` counts per revolution.
    pub fn new(tau_s: f64, max_motor_rad_s: f64, counts_per_rev: u32) -> Result<Self, String> {
        if !(tau_s.is_finite() && tau_s >= 0.0) {
            return Err(format!("servo time constant must be ≥ 0 s, got {tau_s} s"));
        }
        if !(max_motor_rad_s.is_finite() && max_motor_rad_s > 0.0) {
            return Err(format!(
                "servo top speed must be a positive number of rad/s, got {max_motor_rad_s}"
            ));
        }
        Ok(ServoConfig {
            time_constant_s: tau_s,
            max_speed: max_motor_rad_s * f64::from(counts_per_rev) / TAU,
        })
    }

    /// The position after holding setpoint `target` for `dt_s` seconds from `position`
    /// (counts). Exact solution of the rate-limited first-order lag.
    pub fn step(&self, position: f64, target: f64, dt_s: f64) -> f64 {
        if dt_s <= 0.0 {
            return position;
        }
        let error = target - position;
        let v = self.max_speed;
        let tau = self.time_constant_s;
        // Beyond |error| = τ·v the speed limit binds: the motor moves at full speed until the
        // error shrinks to that band, then decays exponentially.
        let band = tau * v;
        let mut position = position;
        let mut dt = dt_s;
        if error.abs() > band {
            let saturated_s = (error.abs() - band) / v;
            if dt <= saturated_s {
                return position + error.signum() * v * dt;
            }
            position += error.signum() * v * saturated_s;
            dt -= saturated_s;
        }
        if tau == 0.0 {
            return target;
        }
        target - (target - position) * (-dt / tau).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn servo(tau_s: f64, max_speed: f64) -> ServoConfig {
        ServoConfig {
            time_constant_s: tau_s,
            max_speed,
        }
    }

    #[test]
    fn small_step_decays_exponentially_with_the_time_constant() {
        let s = servo(0.005, 1e6);
        let x = s.step(0.0, 100.0, 0.005);
        assert!((x - 100.0 * (1.0 - (-1f64).exp())).abs() < 1e-9, "{x}");
        // Splitting the step changes nothing: the solution is exact.
        let halves = s.step(s.step(0.0, 100.0, 0.0025), 100.0, 0.0025);
        assert!((halves - x).abs() < 1e-9);
        assert!((s.step(0.0, 100.0, 1.0) - 100.0).abs() < 1e-9);
    }

    #[test]
    fn large_step_is_rate_limited_then_settles() {
        let s = servo(0.01, 1000.0);
        // Error 100 counts > band 10: 0.05 s at full speed.
        assert!((s.step(0.0, 100.0, 0.05) - 50.0).abs() < 1e-9);
        assert!((s.step(0.0, -100.0, 0.05) + 50.0).abs() < 1e-9);
        // Full speed for 0.09 s reaches the band (90 counts), then 0.01 s = one τ of decay.
        let x = s.step(0.0, 100.0, 0.1);
        let expected = 100.0 - 10.0 * (-1f64).exp();
        assert!((x - expected).abs() < 1e-9, "{x} vs {expected}");
        // Speed never exceeds the limit, and the motor never overshoots.
        let mut x = 0.0;
        for _ in 0..1000 {
            let next = s.step(x, 100.0, 0.001);
            assert!(next - x <= 1000.0 * 0.001 + 1e-9);
            assert!(next <= 100.0);
            x = next;
        }
        assert!((x - 100.0).abs() < 1e-6);
    }

    #[test]
    fn zero_time_constant_is_a_pure_speed_limit() {
        let s = servo(0.0, 200.0);
        assert_eq!(s.step(0.0, 10.0, 0.01), 2.0);
        assert_eq!(s.step(0.0, 10.0, 0.1), 10.0);
        assert_eq!(s.step(5.0, 5.0, 0.1), 5.0);
    }

    #[test]
    fn config_converts_motor_speed_to_counts_and_rejects_bad_values() {
        let c = ServoConfig::new(0.005, TAU, 2000).unwrap();
        assert!((c.max_speed - 2000.0).abs() < 1e-9);
        assert!(ServoConfig::new(-1.0, 10.0, 2000).is_err());
        assert!(ServoConfig::new(0.005, 0.0, 2000).is_err());
        assert!(ServoConfig::new(f64::NAN, 10.0, 2000).is_err());
    }
}
