//! Effects injected into the simulated rig, in the effect syntax of `sabr_model`
//! (`name:key=value,key=value`, e.g. `ripple:joint=2,harmonic=1,amplitude=0.002,phase=0.3`):
//! the model's effects, plus the simulator's own: `latency` (extra tracker latency),
//! `thermal` (drift of a joint offset or of a link length), `sag` (needle tip sag under
//! gravity) and `clockdrift` (exact tracker clock rate error).
//!
//! Joints are numbered 1..5 (θ1..θ5) in the syntax, as in docs/robot-model.md; the model's
//! [`Effect`] values inside use its 0-based indices.

use std::fmt;
use std::str::FromStr;

use sabr_model::effects::spec::{MAX_JOINT_EFFECT_RAD, MAX_LINK_DELTA_MM};
use sabr_model::{Effect, EffectSpec, EffectSpecError, Link};

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
    /// Simulator-only: a thermal drift of a link length, `delta · (1 − exp(−t / tau_s))` (mm)
    /// with `t` the time since power-up (s), on top of the true geometry.
    LinkThermal {
        /// The link whose length drifts.
        link: Link,
        /// Final length change (mm).
        delta: f64,
        /// Time constant (s).
        tau_s: f64,
    },
    /// Simulator-only: the needle sags under gravity (−y of `Bb`); the true tip moves by
    /// `mm · (g − z_N (g·z_N))` with `g = (0, −1, 0)`, `z_N` the needle direction.
    NeedleSag {
        /// Deflection of a horizontal needle (mm).
        mm: f64,
    },
    /// Simulator-only: the tracker clock has exactly this rate error instead of a random one
    /// within ±`TrackerConfig::clock_drift_ppm`: the frame period on the host clock is the
    /// nominal period times `1 + ppm · 10⁻⁶`.
    TrackerClockDrift {
        /// Tracker clock rate error (ppm).
        ppm: f64,
    },
}

/// Largest accepted extra latency (ms).
const MAX_EXTRA_LATENCY_MS: f64 = 1000.0;
/// Default thermal time constant (s).
const DEFAULT_THERMAL_TAU_S: f64 = 120.0;
/// Largest accepted needle sag (mm).
const MAX_SAG_MM: f64 = 5.0;
/// Largest accepted tracker clock rate error (ppm).
const MAX_CLOCK_DRIFT_PPM: f64 = 1000.0;
/// Every effect name the simulator knows.
const NAMES: [&str; 9] = [
    "ripple",
    "backlash",
    "link",
    "compliance",
    "tilt",
    "latency",
    "thermal",
    "sag",
    "clockdrift",
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
                "thermal" => thermal(&mut spec)?,
                "sag" => SimEffect::NeedleSag {
                    mm: spec.bounded("mm", MAX_SAG_MM, true)?,
                },
                "clockdrift" => SimEffect::TrackerClockDrift {
                    ppm: spec.bounded("ppm", MAX_CLOCK_DRIFT_PPM, false)?,
                },
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

/// A `thermal` spec: a joint offset drift (`joint`, `amplitude` in rad) or a link length
/// drift (`link`, `delta` in mm), never both; `tau_s` (s) defaults to 120.
fn thermal(spec: &mut EffectSpec<'_>) -> Result<SimEffect, EffectSpecError> {
    let joint_given = spec.take("joint").is_some();
    let link_given = spec.take("link").is_some();
    if joint_given == link_given {
        let reason = if joint_given {
            "give either `joint` (a joint offset drift) or `link` (a link length drift), not both"
        } else {
            "missing key `joint` (a joint offset drift, 1..5) or `link` (a link length drift)"
        };
        return Err(spec.error(reason.into()));
    }
    let tau_s = spec.number("tau_s", Some(DEFAULT_THERMAL_TAU_S))?;
    if tau_s <= 0.0 {
        return Err(spec.error(format!("`tau_s` must be > 0, got {tau_s}")));
    }
    Ok(if joint_given {
        SimEffect::Thermal {
            joint: spec.joint()?,
            amplitude: spec.bounded("amplitude", MAX_JOINT_EFFECT_RAD, false)?,
            tau_s,
        }
    } else {
        SimEffect::LinkThermal {
            link: spec.link()?,
            delta: spec.bounded("delta", MAX_LINK_DELTA_MM, false)?,
            tau_s,
        }
    })
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
            SimEffect::LinkThermal { link, delta, tau_s } => write!(
                f,
                "thermal:link={},delta={delta},tau_s={tau_s}",
                link.name()
            ),
            SimEffect::NeedleSag { mm } => write!(f, "sag:mm={mm}"),
            SimEffect::TrackerClockDrift { ppm } => write!(f, "clockdrift:ppm={ppm}"),
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
            "thermal:link=l_f,delta=0.3,tau_s=120",
            "thermal:link=d_offset,delta=-0.2,tau_s=45.5",
            "sag:mm=0.4",
            "clockdrift:ppm=120",
            "clockdrift:ppm=-35.5",
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
        assert_eq!(
            "thermal:link=l_b,delta=0.3".parse::<SimEffect>(),
            Ok(SimEffect::LinkThermal {
                link: Link::LB,
                delta: 0.3,
                tau_s: DEFAULT_THERMAL_TAU_S
            })
        );
        assert_eq!(
            "thermal:joint=2,amplitude=0.001".parse::<SimEffect>(),
            Ok(SimEffect::Thermal {
                joint: 1,
                amplitude: 0.001,
                tau_s: DEFAULT_THERMAL_TAU_S
            })
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
            (
                "thermal:joint=1,link=l_f,amplitude=0.001",
                "either `joint` (a joint offset drift) or `link` (a link length drift), not both",
            ),
            (
                "thermal:amplitude=0.001",
                "missing key `joint` (a joint offset drift, 1..5) or `link`",
            ),
            ("thermal:link=l_q,delta=0.3", "must be one of l_f"),
            ("thermal:link=l_f", "missing key `delta`"),
            (
                "thermal:link=l_f,delta=10.5",
                "beyond the plausible limit ±10",
            ),
            ("thermal:link=l_f,delta=0.3,tau_s=-1", "`tau_s` must be > 0"),
            (
                "thermal:link=l_f,delta=0.3,amplitude=0.001",
                "unknown key `amplitude`",
            ),
            (
                "thermal:joint=2,amplitude=0.001,delta=0.3",
                "unknown key `delta`",
            ),
            ("sag:mm=0", "`mm` must be > 0"),
            ("sag:mm=-0.4", "`mm` must be > 0"),
            ("sag:mm=5.5", "`mm` = 5.5 is beyond the plausible limit ±5"),
            ("sag:length=0.4", "missing key `mm`"),
            (
                "clockdrift:ppm=1200",
                "`ppm` = 1200 is beyond the plausible limit ±1000",
            ),
            ("clockdrift:ppm=-1000.5", "beyond the plausible limit ±1000"),
            ("clockdrift:ppm=fast", "is not a number"),
            ("clockdrift:rate=5", "missing key `ppm`"),
            (
                "drift:ppm=5",
                "known: ripple, backlash, link, compliance, tilt, latency, thermal, sag, clockdrift",
            ),
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
