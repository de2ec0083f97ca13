//! `sabr-calibrator`: the live calibrator process of the SABR graph.
//!
//! It listens to the raw streams the recorder writes (encoder samples, tracker frames, the
//! motion's phase marks), keeps them as the same recording rows in memory, and once the
//! calibration phases (homing, excitation, tip, validation) are complete calibrates with the
//! library ([`sabr_calibration::calibrate`], the code path of `sabr calibrate`, residual loop
//! included). It writes `params.toml`, `report.json` and `report.html` atomically into
//! `$SABR_RUN_DIR/calibration/` and announces the new parameter set on
//! `sabr/calibrator/parameters`. With `--line-test` it then evaluates the straight-line test
//! the motion node drives with the new parameters, against the simulated rig's truth.
//!
//! See [`live`] for why it takes the raw streams rather than `sync`'s matched samples.

mod live;

use std::process::ExitCode;

fn main() -> ExitCode {
    sabr_node::service_main("calibrator", live::run)
}
