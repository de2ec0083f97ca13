//! The calibrated parameters of a serial arm as a JSON file (`serial-params-v1`,
//! documented in `docs/measured-data.md`): set-up frames (instrument ← root), target
//! mountings (link ← target), geometric errors by name, and the effects with their
//! coefficients. `sabr evaluate` reads it back onto a recording of the same robot.

use std::path::Path;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::math::se3::{isometry, rotation_log};
use crate::model::serial::{Frame, SerialArm, SerialEffect, SerialError};

/// The value of the `format` field.
pub const SERIAL_PARAMS_FORMAT: &str = "serial-params-v1";

/// A rigid frame: translation (mm) and rotation vector (rad).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameEntry {
    /// Set-up or target name.
    pub name: String,
    /// Translation (mm).
    pub translation_mm: [f64; 3],
    /// Rotation vector (rad).
    pub rotation_rad: [f64; 3],
}

/// One effect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectEntry {
    /// `periodic`, `gravity_compliance`, `thermal_expansion` or `drift`.
    pub class: String,
    /// Joint variable name (periodic, gravity_compliance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<String>,
    /// Harmonic number (periodic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub harmonic: Option<u16>,
    /// Set-up name (drift).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub setup: Option<String>,
    /// Coefficients, named by the class (periodic: sin, cos rad; gravity_compliance:
    /// rad/(N·m), rad/kg; thermal_expansion: 1/°C; drift: mm per sequence).
    pub coefficients: Vec<f64>,
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialParamsFile {
    /// Always [`SERIAL_PARAMS_FORMAT`].
    pub format: String,
    /// The URDF robot name.
    pub robot: String,
    /// Whether orientations were fitted.
    pub use_orientation: bool,
    /// Reference temperature of the thermal expansion (°C).
    pub reference_temperature_c: f64,
    /// Instrument ← root frame per set-up.
    pub setups: Vec<FrameEntry>,
    /// Link ← target per target.
    pub targets: Vec<FrameEntry>,
    /// Geometric errors by parameter name (mm or rad); absent ones are zero.
    pub geometric_errors: std::collections::BTreeMap<String, f64>,
    /// Per joint variable: the range the calibration poses covered (rad or mm), outside
    /// which periodic effects hold their value.
    pub covered_ranges: std::collections::BTreeMap<String, [f64; 2]>,
    /// Effects.
    pub effects: Vec<EffectEntry>,
}

fn entry(name: &str, frame: &Frame) -> FrameEntry {
    let pose = frame.pose();
    FrameEntry {
        name: name.to_string(),
        translation_mm: pose.translation.vector.into(),
        rotation_rad: rotation_log(&pose.rotation).into(),
    }
}

impl SerialParamsFile {
    /// The parameters of `arm`.
    pub fn of(arm: &SerialArm) -> Self {
        let names = arm.tree.error_parameters();
        let variables = arm.tree.variables();
        SerialParamsFile {
            format: SERIAL_PARAMS_FORMAT.into(),
            robot: arm.tree.name().into(),
            use_orientation: arm.use_orientation,
            reference_temperature_c: arm.reference_temperature_c,
            setups: arm
                .setups
                .iter()
                .zip(&arm.setup_frames)
                .map(|(n, f)| entry(n, f))
                .collect(),
            targets: arm
                .targets
                .iter()
                .zip(&arm.mountings)
                .map(|(t, f)| entry(&t.name, f))
                .collect(),
            geometric_errors: names
                .iter()
                .zip(&arm.errors)
                .filter(|(_, v)| **v != 0.0)
                .map(|(p, v)| (p.name.clone(), *v))
                .collect(),
            covered_ranges: variables
                .iter()
                .zip(&arm.covered)
                .map(|(v, r)| (v.name.clone(), *r))
                .collect(),
            effects: arm
                .effects
                .iter()
                .map(|(effect, coefficients)| {
                    let (joint, harmonic, setup) = match *effect {
                        SerialEffect::Periodic { variable, harmonic } => (
                            Some(variables[usize::from(variable)].name.clone()),
                            Some(harmonic),
                            None,
                        ),
                        SerialEffect::Compliance { variable } => (
                            Some(variables[usize::from(variable)].name.clone()),
                            None,
                            None,
                        ),
                        SerialEffect::Thermal => (None, None, None),
                        SerialEffect::Drift { setup } => {
                            (None, None, Some(arm.setups[usize::from(setup)].clone()))
                        }
                    };
                    EffectEntry {
                        class: effect.class().into(),
                        joint,
                        harmonic,
                        setup,
                        coefficients: coefficients.clone(),
                    }
                })
                .collect(),
        }
    }

    /// The file's JSON text.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("parameters serialise to JSON")
    }

    /// Parses the JSON text of `path`; errors name the line and column.
    pub fn parse(path: &Path, text: &str) -> Result<Self, SerialError> {
        let file: SerialParamsFile =
            serde_json::from_str(text).map_err(|e| SerialError::Params {
                path: path.to_path_buf(),
                line: e.line(),
                column: e.column(),
                reason: e.to_string(),
            })?;
        if file.format != SERIAL_PARAMS_FORMAT {
            return Err(field_error(
                path,
                "format",
                format!("{:?}, expected {SERIAL_PARAMS_FORMAT:?}", file.format),
            ));
        }
        Ok(file)
    }

    /// Applies the parameters to `arm` (built on the recording to evaluate): every target
    /// and geometric error must exist in its robot; set-ups are matched by name, and
    /// `refit_setup` allows set-ups the file does not have (they keep their registration).
    pub fn apply(
        &self,
        path: &Path,
        arm: &mut SerialArm,
        refit_setup: bool,
    ) -> Result<(), SerialError> {
        let frame = |e: &FrameEntry| {
            Frame::at(isometry(
                Vector3::from(e.translation_mm),
                Vector3::from(e.rotation_rad),
            ))
        };
        if self.robot != arm.tree.name() {
            return Err(field_error(
                path,
                "robot",
                format!(
                    "{:?}, but the recording's URDF is {:?}",
                    self.robot,
                    arm.tree.name()
                ),
            ));
        }
        arm.use_orientation = self.use_orientation;
        arm.reference_temperature_c = self.reference_temperature_c;
        for (k, target) in arm.targets.iter().enumerate() {
            let found = self
                .targets
                .iter()
                .find(|e| e.name == target.name)
                .ok_or_else(|| {
                    field_error(
                        path,
                        "targets",
                        format!("no entry for target `{}`", target.name),
                    )
                })?;
            arm.mountings[k] = frame(found);
        }
        for (k, setup) in arm.setups.iter().enumerate() {
            match self.setups.iter().find(|e| e.name == *setup) {
                Some(found) => arm.setup_frames[k] = frame(found),
                None if refit_setup => {}
                None => {
                    return Err(field_error(
                        path,
                        "setups",
                        format!(
                            "no entry for set-up `{setup}` of the recording (use --refit-setup \
                             to register a new instrument placement)"
                        ),
                    ))
                }
            }
        }
        let names = arm.tree.error_parameters();
        for (name, value) in &self.geometric_errors {
            let index = names.iter().position(|p| p.name == *name).ok_or_else(|| {
                field_error(
                    path,
                    "geometric_errors",
                    format!("the robot has no parameter `{name}`"),
                )
            })?;
            arm.errors[index] = *value;
        }
        for (name, range) in &self.covered_ranges {
            let v = arm
                .tree
                .variable_index(name)
                .map_err(|e| field_error(path, "covered_ranges", e.to_string()))?;
            arm.covered[v] = *range;
        }
        arm.effects.clear();
        for (k, e) in self.effects.iter().enumerate() {
            // A drift belongs to an instrument placement; a new placement has its own.
            let foreign_drift = e.class == "drift"
                && !arm
                    .setups
                    .iter()
                    .any(|s| Some(s.as_str()) == e.setup.as_deref());
            if refit_setup && foreign_drift {
                continue;
            }
            let effect = self.effect(path, arm, k, e)?;
            if e.coefficients.len() != effect.dim() {
                return Err(field_error(
                    path,
                    &format!("effects[{k}].coefficients"),
                    format!(
                        "{} values, a {} effect has {}",
                        e.coefficients.len(),
                        e.class,
                        effect.dim()
                    ),
                ));
            }
            arm.effects.push((effect, e.coefficients.clone()));
        }
        Ok(())
    }

    fn effect(
        &self,
        path: &Path,
        arm: &SerialArm,
        k: usize,
        e: &EffectEntry,
    ) -> Result<SerialEffect, SerialError> {
        let field = |name: &str| format!("effects[{k}].{name}");
        let variable = || -> Result<u16, SerialError> {
            let name = e
                .joint
                .as_deref()
                .ok_or_else(|| field_error(path, &field("joint"), "missing".into()))?;
            arm.tree
                .variable_index(name)
                .map(|v| v as u16)
                .map_err(|err| field_error(path, &field("joint"), err.to_string()))
        };
        Ok(match e.class.as_str() {
            "periodic" => SerialEffect::Periodic {
                variable: variable()?,
                harmonic: e
                    .harmonic
                    .filter(|h| *h >= 1)
                    .ok_or_else(|| field_error(path, &field("harmonic"), "missing or 0".into()))?,
            },
            "gravity_compliance" => SerialEffect::Compliance {
                variable: variable()?,
            },
            "thermal_expansion" => SerialEffect::Thermal,
            "drift" => {
                let name = e.setup.as_deref().unwrap_or_default();
                match arm.setups.iter().position(|s| s == name) {
                    Some(setup) => SerialEffect::Drift {
                        setup: setup as u16,
                    },
                    None => {
                        return Err(field_error(
                            path,
                            &field("setup"),
                            format!("`{name}` is not a set-up of the recording"),
                        ))
                    }
                }
            }
            other => {
                return Err(field_error(
                    path,
                    &field("class"),
                    format!("unknown effect class `{other}`"),
                ))
            }
        })
    }
}

fn field_error(path: &Path, field: &str, reason: String) -> SerialError {
    SerialError::Params {
        path: path.to_path_buf(),
        line: 0,
        column: 0,
        reason: format!("field `{field}`: {reason}"),
    }
}
