//! The numeric parameters of the model's effects as entries of the optimiser's vector
//! ([`crate::ParamId::Effect`]): which effect of `RobotParams::effects` and which field.

use sabr_model::Effect;

use crate::layout::Channel;

/// A numeric field of an [`Effect`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EffectField {
    /// Ripple amplitude at the joint (rad).
    Amplitude,
    /// Ripple phase (rad).
    Phase,
    /// Backlash width at the joint (rad).
    Width,
    /// Link-length change (mm).
    Delta,
    /// Compliance gain (rad per unit gravity feature).
    Gain,
}

impl EffectField {
    /// Field name as in `params.toml`.
    pub fn name(self) -> &'static str {
        match self {
            EffectField::Amplitude => "amplitude",
            EffectField::Phase => "phase",
            EffectField::Width => "width",
            EffectField::Delta => "delta",
            EffectField::Gain => "gain",
        }
    }

    /// The fields an effect's fit moves (the ripple's harmonic is a discrete choice).
    pub fn of(effect: &Effect) -> &'static [EffectField] {
        match effect {
            Effect::TransmissionRipple { .. } => &[EffectField::Amplitude, EffectField::Phase],
            Effect::Backlash { .. } => &[EffectField::Width],
            Effect::LinkLength { .. } => &[EffectField::Delta],
            Effect::JointCompliance { .. } => &[EffectField::Gain],
        }
    }
}

/// One numeric parameter of the effect at `index` in `RobotParams::effects`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EffectParam {
    /// Index of the effect in `RobotParams::effects` (the `[[effects]]` array).
    pub index: usize,
    /// Which field.
    pub field: EffectField,
}

impl EffectParam {
    /// The parameters of every effect in `effects`, in order.
    pub fn all(effects: &[Effect]) -> Vec<EffectParam> {
        effects
            .iter()
            .enumerate()
            .flat_map(|(index, effect)| {
                EffectField::of(effect)
                    .iter()
                    .map(move |&field| EffectParam { index, field })
            })
            .collect()
    }

    /// Name, e.g. `effects[0].amplitude`.
    pub fn name(&self) -> String {
        format!("effects[{}].{}", self.index, self.field.name())
    }

    /// Unit of the value.
    pub fn unit(&self) -> &'static str {
        match self.field {
            EffectField::Delta => "mm",
            _ => "rad",
        }
    }

    /// How the parameter acts on a prediction: link lengths through the geometry, the
    /// joint-side effects through the joint angles.
    pub fn channel(&self) -> Channel {
        match self.field {
            EffectField::Delta => Channel::Geometry,
            _ => Channel::JointMap,
        }
    }

    /// Its value in `effects`; NaN when the index or the field does not match an effect.
    pub fn get(&self, effects: &[Effect]) -> f64 {
        match (effects.get(self.index), self.field) {
            (Some(Effect::TransmissionRipple { amplitude, .. }), EffectField::Amplitude) => {
                *amplitude
            }
            (Some(Effect::TransmissionRipple { phase, .. }), EffectField::Phase) => *phase,
            (Some(Effect::Backlash { width, .. }), EffectField::Width) => *width,
            (Some(Effect::LinkLength { delta, .. }), EffectField::Delta) => *delta,
            (Some(Effect::JointCompliance { gain, .. }), EffectField::Gain) => *gain,
            _ => f64::NAN,
        }
    }

    /// Sets its value in `effects` (nothing when the index or field does not match).
    pub fn set(&self, effects: &mut [Effect], value: f64) {
        let slot = match (effects.get_mut(self.index), self.field) {
            (Some(Effect::TransmissionRipple { amplitude, .. }), EffectField::Amplitude) => {
                amplitude
            }
            (Some(Effect::TransmissionRipple { phase, .. }), EffectField::Phase) => phase,
            (Some(Effect::Backlash { width, .. }), EffectField::Width) => width,
            (Some(Effect::LinkLength { delta, .. }), EffectField::Delta) => delta,
            (Some(Effect::JointCompliance { gain, .. }), EffectField::Gain) => gain,
            _ => return,
        };
        *slot = value;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_model::Link;

    #[test]
    fn every_field_round_trips_and_mismatches_are_inert() {
        let mut effects = vec![
            Effect::TransmissionRipple {
                joint: 1,
                harmonic: 2.0,
                amplitude: 0.001,
                phase: 0.3,
            },
            Effect::LinkLength {
                link: Link::LF,
                delta: 0.2,
            },
            Effect::Backlash {
                joint: 3,
                width: 0.004,
            },
            Effect::JointCompliance {
                joint: 2,
                gain: -0.002,
            },
        ];
        let params = EffectParam::all(&effects);
        assert_eq!(params.len(), 5);
        for (k, p) in params.iter().enumerate() {
            let value = 0.01 * (k + 1) as f64;
            p.set(&mut effects, value);
            assert_eq!(p.get(&effects), value, "{}", p.name());
        }
        assert_eq!(params[2].name(), "effects[1].delta");
        assert_eq!(params[2].unit(), "mm");
        assert_eq!(params[2].channel(), Channel::Geometry);
        let wrong = EffectParam {
            index: 1,
            field: EffectField::Gain,
        };
        assert!(wrong.get(&effects).is_nan());
        let before = effects.clone();
        wrong.set(&mut effects, 5.0);
        EffectParam {
            index: 9,
            field: EffectField::Width,
        }
        .set(&mut effects, 5.0);
        assert_eq!(effects, before);
    }
}
