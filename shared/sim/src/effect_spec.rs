//! Effects injected into the simulated rig and their command-line syntax
//! `name:key=value,key=value`, e.g. `ripple:joint=2,harmonic=1,amplitude=0.002,phase=0.3`.
//!
//! Joints are numbered 1..5 (θ1..θ5) in the syntax, as in docs/robot-model.md; the model's
//! [`Effect`] values inside use its 0-based indices.

use std::fmt;
use std::str::FromStr;

use sabr_model::{Effect, Link};

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

/// A rejected effect specification: the spec text and the reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("effect `{spec}`: {reason}")]
pub struct EffectSpecError {
    /// The specification as given.
    pub spec: String,
    /// What is wrong with it.
    pub reason: String,
}

/// Largest accepted joint-side amplitude, width or gain (rad): beyond it the robot would
/// not be a plausible robot.
const MAX_JOINT_EFFECT_RAD: f64 = 0.05;
/// Largest accepted link-length change (mm).
const MAX_LINK_DELTA_MM: f64 = 10.0;
/// Largest accepted extra latency (ms).
const MAX_EXTRA_LATENCY_MS: f64 = 1000.0;
/// Default thermal time constant (s).
const DEFAULT_THERMAL_TAU_S: f64 = 120.0;

impl SimEffect {
    /// The effect in the model's form, if it is one of the model's library.
    pub fn model_effect(&self) -> Option<&Effect> {
        match self {
            SimEffect::Model(effect) => Some(effect),
            _ => None,
        }
    }
}

/// The `key=value` pairs of one spec, each consumed at most once.
struct Params<'a> {
    spec: &'a str,
    pairs: Vec<(&'a str, &'a str, bool)>,
}

impl<'a> Params<'a> {
    fn parse(spec: &'a str, text: &'a str) -> Result<Self, EffectSpecError> {
        let mut pairs: Vec<(&str, &str, bool)> = Vec::new();
        for item in text.split(',') {
            let item = item.trim();
            let Some((key, value)) = item.split_once('=') else {
                return Err(error(
                    spec,
                    format!("`{item}` is not of the form key=value"),
                ));
            };
            let (key, value) = (key.trim(), value.trim());
            if value.contains('=') {
                return Err(error(
                    spec,
                    format!("`{item}` holds more than one `=`: separate pairs with commas"),
                ));
            }
            if pairs.iter().any(|(k, _, _)| *k == key) {
                return Err(error(spec, format!("key `{key}` is given twice")));
            }
            pairs.push((key, value, false));
        }
        Ok(Params { spec, pairs })
    }

    fn take(&mut self, key: &str) -> Option<&'a str> {
        let pair = self.pairs.iter_mut().find(|(k, _, _)| *k == key)?;
        pair.2 = true;
        Some(pair.1)
    }

    fn number(&mut self, key: &str, default: Option<f64>) -> Result<f64, EffectSpecError> {
        let Some(text) = self.take(key) else {
            return default.ok_or_else(|| error(self.spec, format!("missing key `{key}`")));
        };
        let value: f64 = text
            .parse()
            .map_err(|_| error(self.spec, format!("`{key}={text}` is not a number")))?;
        if !value.is_finite() {
            return Err(error(self.spec, format!("`{key}={text}` is not finite")));
        }
        Ok(value)
    }

    fn bounded(&mut self, key: &str, limit: f64, positive: bool) -> Result<f64, EffectSpecError> {
        let value = self.number(key, None)?;
        if positive && value <= 0.0 {
            return Err(error(
                self.spec,
                format!("`{key}` must be > 0, got {value}"),
            ));
        }
        if value.abs() > limit {
            return Err(error(
                self.spec,
                format!("`{key}` = {value} is beyond the plausible limit ±{limit}"),
            ));
        }
        Ok(value)
    }

    fn joint(&mut self) -> Result<usize, EffectSpecError> {
        let text = self
            .take("joint")
            .ok_or_else(|| error(self.spec, "missing key `joint` (1..5)".into()))?;
        match text.parse::<usize>() {
            Ok(joint @ 1..=5) => Ok(joint - 1),
            _ => Err(error(
                self.spec,
                format!("`joint={text}` must be 1..5 (θ1..θ5)"),
            )),
        }
    }

    fn finish(self) -> Result<(), EffectSpecError> {
        match self.pairs.iter().find(|(_, _, used)| !used) {
            Some((key, _, _)) => Err(error(self.spec, format!("unknown key `{key}`"))),
            None => Ok(()),
        }
    }
}

fn error(spec: &str, reason: String) -> EffectSpecError {
    EffectSpecError {
        spec: spec.to_string(),
        reason,
    }
}

fn parse_link(spec: &str, text: Option<&str>) -> Result<Link, EffectSpecError> {
    match text {
        Some("l_f") => Ok(Link::LF),
        Some("l_fe") => Ok(Link::LFe),
        Some("l_b") => Ok(Link::LB),
        Some("l_be") => Ok(Link::LBe),
        Some("d_offset") => Ok(Link::DOffset),
        Some(other) => Err(error(
            spec,
            format!("`link={other}` must be one of l_f, l_fe, l_b, l_be, d_offset"),
        )),
        None => Err(error(spec, "missing key `link`".into())),
    }
}

fn link_name(link: Link) -> &'static str {
    match link {
        Link::LF => "l_f",
        Link::LFe => "l_fe",
        Link::LB => "l_b",
        Link::LBe => "l_be",
        Link::DOffset => "d_offset",
    }
}

impl FromStr for SimEffect {
    type Err = EffectSpecError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let Some((name, rest)) = spec.split_once(':') else {
            return Err(error(
                spec,
                "expected `name:key=value,...` (names: ripple, backlash, link, compliance, \
                 latency, thermal)"
                    .into(),
            ));
        };
        let mut params = Params::parse(spec, rest)?;
        let effect = match name.trim() {
            "ripple" => {
                let joint = params.joint()?;
                let harmonic = params.bounded("harmonic", 100.0, true)?;
                let amplitude = params.bounded("amplitude", MAX_JOINT_EFFECT_RAD, false)?;
                let phase = params.number("phase", Some(0.0))?;
                SimEffect::Model(Effect::TransmissionRipple {
                    joint,
                    harmonic,
                    amplitude,
                    phase,
                })
            }
            "backlash" => {
                let joint = params.joint()?;
                let width = params.bounded("width", MAX_JOINT_EFFECT_RAD, true)?;
                SimEffect::Model(Effect::Backlash { joint, width })
            }
            "link" => {
                let link = parse_link(spec, params.take("link"))?;
                let delta = params.bounded("delta", MAX_LINK_DELTA_MM, false)?;
                SimEffect::Model(Effect::LinkLength { link, delta })
            }
            "compliance" => {
                let joint = params.joint()?;
                let gain = params.bounded("gain", MAX_JOINT_EFFECT_RAD, false)?;
                SimEffect::Model(Effect::JointCompliance { joint, gain })
            }
            "latency" => SimEffect::TrackerLatency {
                extra_ms: params.bounded("ms", MAX_EXTRA_LATENCY_MS, true)?,
            },
            "thermal" => {
                let joint = params.joint()?;
                let amplitude = params.bounded("amplitude", MAX_JOINT_EFFECT_RAD, false)?;
                let tau_s = params.number("tau_s", Some(DEFAULT_THERMAL_TAU_S))?;
                if tau_s <= 0.0 {
                    return Err(error(spec, format!("`tau_s` must be > 0, got {tau_s}")));
                }
                SimEffect::Thermal {
                    joint,
                    amplitude,
                    tau_s,
                }
            }
            other => {
                return Err(error(
                    spec,
                    format!(
                        "unknown effect `{other}` (known: ripple, backlash, link, compliance, \
                         latency, thermal)"
                    ),
                ))
            }
        };
        params.finish()?;
        Ok(effect)
    }
}

/// The canonical spec text, parseable by [`SimEffect::from_str`] (joints 1-based).
impl fmt::Display for SimEffect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimEffect::Model(Effect::TransmissionRipple {
                joint,
                harmonic,
                amplitude,
                phase,
            }) => write!(
                f,
                "ripple:joint={},harmonic={harmonic},amplitude={amplitude},phase={phase}",
                joint + 1
            ),
            SimEffect::Model(Effect::Backlash { joint, width }) => {
                write!(f, "backlash:joint={},width={width}", joint + 1)
            }
            SimEffect::Model(Effect::LinkLength { link, delta }) => {
                write!(f, "link:link={},delta={delta}", link_name(*link))
            }
            SimEffect::Model(Effect::JointCompliance { joint, gain }) => {
                write!(f, "compliance:joint={},gain={gain}", joint + 1)
            }
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
