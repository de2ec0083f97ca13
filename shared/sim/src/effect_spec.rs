//! Effects injected into the simulated rig, in the effect syntax of `sabr_model`
//! (`name:key=value,key=value`, e.g. `ripple:joint=2,harmonic=1,amplitude=0.002,phase=0.3`):
//! the model's effects, plus two of the simulator's own (`latency`, `thermal`).
//!
//! Joints are numbered 1..5 (θ1..θ5) in the syntax, as in docs/robot-model.md; the model's
//! [`Effect`] values inside use its 0-based indices.

use std::fmt;
use std::str::FromStr;

use sabr_model::effects::spec::MAX_JOINT_EFFECT_RAD;
use sabr_model::{Effect, EffectSpec, EffectSpecError};

/// An effect injected into the true robot or the tracker. Each is off unless given.
#[derive(Debug, Clone, PartialEq)]
pub enum SimEffect {
    /// An effect of the model's library (ripple, backlash, link length, compliance): the true
    /// robot applies it exactly as `sabr_model::effects` defines it.
    Model(Effect),
    /// Extra tracker latency (ms) added to the session's base exposure→arrival latency.
    TrackerLatency {
        /// Added latency (ms).
        extra_ms: f64,
    },
    /// Simulator-only (outside the model's library): a thermal drift of a joint offset,
    /// `amplitude · (1 − exp(−t / tau_s))` (rad) with `t` the time since power-up (s).
    Thermal {
        /// Joint index 0..5 (θ1 = 0).
        joint: usize,
        /// Final drift (rad).
        amplitude: f64,
        /// Time constant (s).
        tau_s: f64,
    },
}

/// Largest accepted extra latency (ms).
const MAX_EXTRA_LATENCY_MS: f64 = 1000.0;
/// Default thermal time constant (s).
const DEFAULT_THERMAL_TAU_S: f64 = 120.0;
/// Every effect name the simulator knows.
const NAMES: [&str; 6] = [
    "ripple",
    "backlash",
    "link",
    "compliance",
    "latency",
    "thermal",
];

impl SimEffect {
    /// The effect in the model's form, if it is one of the model's library.
    pub fn model_effect(&self) -> Option<&Effect> {
        match self {
            SimEffect::Model(effect) => Some(effect),
            _ => None,
        }
    }
}

impl FromStr for SimEffect {
    type Err = EffectSpecError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let mut spec = EffectSpec::parse(text, &NAMES)?;
        let effect = match Effect::from_spec(&mut spec) {
            Some(effect) => SimEffect::Model(effect?),
            None => match spec.name() {
                "latency" => SimEffect::TrackerLatency {
                    extra_ms: spec.bounded("ms", MAX_EXTRA_LATENCY_MS, true)?,
                },
                "thermal" => {
                    let joint = spec.joint()?;
                    let amplitude = spec.bounded("amplitude", MAX_JOINT_EFFECT_RAD, false)?;
                    let tau_s = spec.number("tau_s", Some(DEFAULT_THERMAL_TAU_S))?;
                    if tau_s <= 0.0 {
                        return Err(spec.error(format!("`tau_s` must be > 0, got {tau_s}")));
                    }
                    SimEffect::Thermal {
                        joint,
                        amplitude,
                        tau_s,
                    }
                }
                other => {
                    return Err(spec.error(format!(
                        "unknown effect `{other}` (known: {})",
                        NAMES.join(", ")
                    )))
                }
            },
        };
        spec.finish()?;
        Ok(effect)
    }
}

/// The canonical spec text, parseable by [`SimEffect::from_str`] (joints 1-based).
impl fmt::Display for SimEffect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimEffect::Model(effect) => effect.fmt(f),
            SimEffect::TrackerLatency { extra_ms } => write!(f, "latency:ms={extra_ms}"),
            SimEffect::Thermal {
                joint,
                amplitude,
                tau_s,
            } => write!(
                f,
                "thermal:joint={},amplitude={amplitude},tau_s={tau_s}",
                joint + 1
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_kind_and_displays_back_the_same_effect() {
        let specs = [
            "ripple:joint=2,harmonic=1,amplitude=0.002,phase=0.3",
            "backlash:joint=4,width=0.004",
            "link:link=l_f,delta=0.4",
            "compliance:joint=1,gain=0.003",
            "latency:ms=45",
            "thermal:joint=3,amplitude=0.002,tau_s=90",
        ];
        for spec in specs {
            let effect: SimEffect = spec.parse().unwrap();
            assert_eq!(effect.to_string(), spec);
            assert_eq!(effect.to_string().parse::<SimEffect>().unwrap(), effect);
        }
        assert_eq!(
            "ripple:joint=2,harmonic=1,amplitude=0.002".parse::<SimEffect>(),
            Ok(SimEffect::Model(Effect::TransmissionRipple {
                joint: 1,
                harmonic: 1.0,
                amplitude: 0.002,
                phase: 0.0
            }))
        );
    }

    #[test]
    fn rejects_bad_specs_naming_the_spec_and_the_reason() {
        let cases = [
            ("ripple", "expected `name:key=value"),
            ("wobble:joint=1", "unknown effect `wobble`"),
            ("backlash:joint=6,width=0.01", "must be 1..5"),
            ("backlash:joint=0,width=0.01", "must be 1..5"),
            ("backlash:joint=2", "missing key `width`"),
            ("backlash:joint=2,width=-0.01", "must be > 0"),
            ("backlash:joint=2,width=abc", "is not a number"),
            ("backlash:joint=2,width=NaN", "is not finite"),
            (
                "backlash:joint=2,width=0.01,colour=red",
                "unknown key `colour`",
            ),
            ("backlash:joint=2,joint=3,width=0.01", "given twice"),
            ("backlash:joint=2;width=0.01", "separate pairs with commas"),
            ("backlash:joint=2,width", "not of the form key=value"),
            ("link:link=l_x,delta=1", "must be one of l_f"),
            ("link:link=l_f,delta=50", "beyond the plausible limit"),
            (
                "thermal:joint=1,amplitude=0.001,tau_s=0",
                "`tau_s` must be > 0",
            ),
            ("latency:ms=0", "must be > 0"),
        ];
        for (spec, reason) in cases {
            let err = spec.parse::<SimEffect>().unwrap_err();
            assert_eq!(err.spec, spec);
            let message = err.to_string();
            assert!(message.contains(spec), "{message}");
            assert!(message.contains(reason), "{spec}: {message}");
        }
    }
}
