//! The base every layer stands on: small robust statistics, rigid-motion helpers and point
//! registration. No calibration concepts here.

pub mod registration;
pub mod se3;
pub mod stats;
