//! The text syntax of effects, `name:key=value,key=value`, e.g.
//! `ripple:joint=2,harmonic=1,amplitude=0.002,phase=0.3`: the model's effects parse from and
//! display as it, and [`EffectSpec`] lets a caller (the simulator) add effects of its own
//! in the same syntax.
//!
//! Joints are numbered 1..5 (θ1..θ5) in the syntax, as in docs/robot-model.md; [`Effect`] values
//! use the model's 0-based indices.

use std::fmt;
use std::str::FromStr;

use crate::effects::{Effect, Link};
use crate::JOINT_COUNT;

/// Largest accepted joint-side amplitude, width or gain (rad): beyond it the robot would not
/// be a plausible robot.
pub const MAX_JOINT_EFFECT_RAD: f64 = 0.05;
/// Largest accepted link-length change (mm).
pub const MAX_LINK_DELTA_MM: f64 = 10.0;
/// Largest accepted ripple harmonic (cycles per motor revolution).
const MAX_HARMONIC: f64 = 100.0;

/// An effect specification that cannot be used: the spec text and the reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("effect `{spec}`: {reason}")]
pub struct EffectSpecError {
    /// The specification as given.
    pub spec: String,
    /// What is wrong with it.
    pub reason: String,
}

/// A parsed `name:key=value,...` specification whose pairs are consumed at most once each.
#[derive(Debug)]
pub struct EffectSpec<'a> {
    text: &'a str,
    name: &'a str,
    pairs: Vec<(&'a str, &'a str, bool)>,
}

impl<'a> EffectSpec<'a> {
    /// Splits `text` into its name and `key=value` pairs; `names` lists the known effect
    /// names for the error message.
    pub fn parse(text: &'a str, names: &[&str]) -> Result<Self, EffectSpecError> {
        let error = |reason: String| EffectSpecError {
            spec: text.to_string(),
            reason,
        };
        let Some((name, rest)) = text.split_once(':') else {
            return Err(error(format!(
                "expected `name:key=value,...` (names: {})",
                names.join(", ")
            )));
        };
        let mut pairs: Vec<(&str, &str, bool)> = Vec::new();
        for item in rest.split(',') {
            let item = item.trim();
            let Some((key, value)) = item.split_once('=') else {
                return Err(error(format!("`{item}` is not of the form key=value")));
            };
            let (key, value) = (key.trim(), value.trim());
            if value.contains('=') {
                return Err(error(format!(
                    "`{item}` holds more than one `=`: separate pairs with commas"
                )));
            }
            if pairs.iter().any(|(k, _, _)| *k == key) {
                return Err(error(format!("key `{key}` is given twice")));
            }
            pairs.push((key, value, false));
        }
        Ok(Self {
            text,
            name: name.trim(),
            pairs,
        })
    }

    /// The effect's name (before the `:`).
    pub fn name(&self) -> &'a str {
        self.name
    }

    /// An error about this specification.
    pub fn error(&self, reason: String) -> EffectSpecError {
        EffectSpecError {
            spec: self.text.to_string(),
            reason,
        }
    }

    /// The value of `key`, marking it used.
    pub fn take(&mut self, key: &str) -> Option<&'a str> {
        let pair = self.pairs.iter_mut().find(|(k, _, _)| *k == key)?;
        pair.2 = true;
        Some(pair.1)
    }

    /// A finite number under `key`, or `default` when absent (an error without default).
    pub fn number(&mut self, key: &str, default: Option<f64>) -> Result<f64, EffectSpecError> {
        let Some(text) = self.take(key) else {
            return default.ok_or_else(|| self.error(format!("missing key `{key}`")));
        };
        let value: f64 = text
            .parse()
            .map_err(|_| self.error(format!("`{key}={text}` is not a number")))?;
        if !value.is_finite() {
            return Err(self.error(format!("`{key}={text}` is not finite")));
        }
        Ok(value)
    }

    /// A required number under `key` with `|value| ≤ limit`, and `> 0` if `positive`.
    pub fn bounded(
        &mut self,
        key: &str,
        limit: f64,
        positive: bool,
    ) -> Result<f64, EffectSpecError> {
        let value = self.number(key, None)?;
        if positive && value <= 0.0 {
            return Err(self.error(format!("`{key}` must be > 0, got {value}")));
        }
        if value.abs() > limit {
            return Err(self.error(format!(
                "`{key}` = {value} is beyond the plausible limit ±{limit}"
            )));
        }
        Ok(value)
    }

    /// The joint under `joint`, given 1..5, returned 0-based.
    pub fn joint(&mut self) -> Result<usize, EffectSpecError> {
        let text = self
            .take("joint")
            .ok_or_else(|| self.error("missing key `joint` (1..5)".into()))?;
        match text.parse::<usize>() {
            Ok(joint) if (1..=JOINT_COUNT).contains(&joint) => Ok(joint - 1),
            _ => Err(self.error(format!("`joint={text}` must be 1..5 (θ1..θ5)"))),
        }
    }

    /// The link under `link`, by its `params.toml` name.
    pub fn link(&mut self) -> Result<Link, EffectSpecError> {
        match self.take("link") {
            Some(name) => Link::from_name(name).ok_or_else(|| {
                let names: Vec<&str> = Link::ALL.iter().map(|l| l.name()).collect();
                self.error(format!("`link={name}` must be one of {}", names.join(", ")))
            }),
            None => Err(self.error("missing key `link`".into())),
        }
    }

    /// Errors on a key nobody took.
    pub fn finish(self) -> Result<(), EffectSpecError> {
        match self.pairs.iter().find(|(_, _, used)| !used) {
            Some((key, _, _)) => Err(self.error(format!("unknown key `{key}`"))),
            None => Ok(()),
        }
    }
}

impl Effect {
    /// The names of the model's effects in the spec syntax.
    pub const SPEC_NAMES: [&'static str; 5] = ["ripple", "backlash", "link", "compliance", "tilt"];

    /// The model effect `spec` names, with its values; `None` when the name is not one of
    /// [`Effect::SPEC_NAMES`]. Consumes the keys it uses (call [`EffectSpec::finish`] after).
    pub fn from_spec(spec: &mut EffectSpec<'_>) -> Option<Result<Effect, EffectSpecError>> {
        let effect = match spec.name() {
            "ripple" => (|| {
                let joint = spec.joint()?;
                let harmonic = spec.bounded("harmonic", MAX_HARMONIC, true)?;
                let amplitude = spec.bounded("amplitude", MAX_JOINT_EFFECT_RAD, false)?;
                let phase = spec.number("phase", Some(0.0))?;
                Ok(Effect::TransmissionRipple {
                    joint,
                    harmonic,
                    amplitude,
                    phase,
                })
            })(),
            "backlash" => (|| {
                let joint = spec.joint()?;
                let width = spec.bounded("width", MAX_JOINT_EFFECT_RAD, true)?;
                Ok(Effect::Backlash { joint, width })
            })(),
            "link" => (|| {
                let link = spec.link()?;
                let delta = spec.bounded("delta", MAX_LINK_DELTA_MM, false)?;
                Ok(Effect::LinkLength { link, delta })
            })(),
            "compliance" => (|| {
                let joint = spec.joint()?;
                let gain = spec.bounded("gain", MAX_JOINT_EFFECT_RAD, false)?;
                Ok(Effect::JointCompliance { joint, gain })
            })(),
            "tilt" => (|| {
                let joint = spec.joint()?;
                let axis = spec.number("axis", None)?;
                if axis != 1.0 && axis != 2.0 {
                    return Err(spec.error(format!("`axis={axis}` must be 1 or 2")));
                }
                let angle = spec.bounded("angle", MAX_JOINT_EFFECT_RAD, false)?;
                Ok(Effect::AxisTilt {
                    joint,
                    axis: axis as usize - 1,
                    angle,
                })
            })(),
            _ => return None,
        };
        Some(effect)
    }
}

impl FromStr for Effect {
    type Err = EffectSpecError;

    /// Parses one of the model's effects (see the module docs).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let mut spec = EffectSpec::parse(text, &Effect::SPEC_NAMES)?;
        let effect = Effect::from_spec(&mut spec).unwrap_or_else(|| {
            Err(spec.error(format!(
                "unknown effect `{}` (known: {})",
                spec.name(),
                Effect::SPEC_NAMES.join(", ")
            )))
        })?;
        spec.finish()?;
        Ok(effect)
    }
}

/// The canonical spec text, parseable by [`Effect::from_str`] (joints 1-based).
impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Effect::TransmissionRipple {
                joint,
                harmonic,
                amplitude,
                phase,
            } => write!(
                f,
                "ripple:joint={},harmonic={harmonic},amplitude={amplitude},phase={phase}",
                joint + 1
            ),
            Effect::Backlash { joint, width } => {
                write!(f, "backlash:joint={},width={width}", joint + 1)
            }
            Effect::LinkLength { link, delta } => {
                write!(f, "link:link={},delta={delta}", link.name())
            }
            Effect::JointCompliance { joint, gain } => {
                write!(f, "compliance:joint={},gain={gain}", joint + 1)
            }
            Effect::AxisTilt { joint, axis, angle } => {
                write!(
                    f,
                    "tilt:joint={},axis={},angle={angle}",
                    joint + 1,
                    axis + 1
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_model_effect_and_displays_back_the_same_effect() {
        let specs = [
            "ripple:joint=2,harmonic=1,amplitude=0.002,phase=0.3",
            "backlash:joint=4,width=0.004",
            "link:link=l_f,delta=0.4",
            "compliance:joint=1,gain=0.003",
            "tilt:joint=3,axis=2,angle=-0.0087",
        ];
        for spec in specs {
            let effect: Effect = spec.parse().unwrap();
            assert_eq!(effect.to_string(), spec);
            assert_eq!(effect.to_string().parse::<Effect>().unwrap(), effect);
            assert_eq!(effect.validate(), Ok(()));
        }
        assert_eq!(
            "ripple:joint=2,harmonic=1,amplitude=0.002".parse::<Effect>(),
            Ok(Effect::TransmissionRipple {
                joint: 1,
                harmonic: 1.0,
                amplitude: 0.002,
                phase: 0.0
            })
        );
    }

    #[test]
    fn rejects_bad_specs_naming_the_spec_and_the_reason() {
        let cases = [
            ("ripple", "expected `name:key=value"),
            ("wobble:joint=1", "unknown effect `wobble`"),
            ("latency:ms=3", "unknown effect `latency`"),
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
            ("tilt:joint=2,axis=3,angle=0.01", "must be 1 or 2"),
        ];
        for (spec, reason) in cases {
            let err = spec.parse::<Effect>().unwrap_err();
            assert_eq!(err.spec, spec);
            let message = err.to_string();
            assert!(message.contains(spec), "{message}");
            assert!(message.contains(reason), "{spec}: {message}");
        }
    }
}
