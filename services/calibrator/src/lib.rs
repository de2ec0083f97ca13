//! The SABR calibration engine: turns a recording (docs/robot-model.md §7) into a calibrated
//! robot model, a JSON report and an HTML report. The `sabr calibrate` command and the live
//! calibrator process share this one code path.
//!
//! Pipeline ([`calibrate`]):
//! 1. **Time sync** ([`timesync`], [`latency`]): a robust line through the tracker frame
//!    counter and the arrival stamps gives each frame's clock time; the latency (exposure
//!    before that line) is first found model-free (the delay that best explains the marker
//!    motion by the encoders), then refined as a parameter of the joint fit; encoder counts
//!    are interpolated at the exposure times ([`observations`]).
//! 2. **Stepwise method** ([`stepwise`]): the paper's baseline.
//! 3. **Joint fit** ([`joint_fit`]): Levenberg–Marquardt on all parameters of a
//!    [`ParamLayout`] with whitened, Huber-weighted residuals ([`residuals`], [`problem`]),
//!    then identifiability ([`identifiability`]).
//! 4. **Validation** ([`validation`]): the validation phase is held out.
//! 5. **Outputs** ([`output`]): `params.toml`, `report.json`, `report.html`, atomically.
//!
//! Extending the model (effects): add [`ParamId`] variants (with their [`layout::Channel`])
//! and pass a larger layout to [`joint_fit::joint_fit`]; residuals, Jacobian,
//! identifiability and the report work per parameter.

pub mod calibrate;
pub mod error;
pub mod frames;
pub mod html;
pub mod identifiability;
pub mod joint_fit;
pub mod latency;
pub mod layout;
pub mod marker_ik;
pub mod noise;
pub mod observations;
pub mod output;
pub mod problem;
pub mod report;
pub mod residual_loop;
pub mod residuals;
pub mod se3;
pub mod session_span;
pub mod stats;
pub mod stepwise;
pub mod timesync;
pub mod validation;

pub use calibrate::{calibrate, Calibration, CalibrationOptions};
pub use error::CalibrationError;
pub use layout::{CalibModel, ParamId, ParamLayout};
pub use output::{write_outputs, OutputError};
pub use report::Report;
