//! The base every layer stands on: small robust statistics and rigid-motion helpers. No
//! calibration concepts here.

pub mod se3;
pub mod stats;
