//! The synchroniser of the SABR graph (`sabr-sync`): pairs every tracker frame with the encoder
//! state at the frame's exposure time.
//!
//! - [`clock::FrameClock`]: online robust line through the tracker's frame counter and the host
//!   stamps of when each frame became available at the device (`TrackerFrame::available_t_ns`,
//!   not the later arrival of the reply): the engine's clock line (`sabr_calibration::data::clock::ClockLine`,
//!   Huber IRLS; robust to skipped frames, counter steps ≠ 1, jitter and late frames) over a
//!   sliding window. `exposure = line − latency`, the same definition of the latency
//!   as the calibrator's.
//! - [`latency::LatencySetting`]: the configured latency (`--latency-ms`) until a parameter set
//!   with a calibrated latency is announced; every matched sample says which was used.
//! - [`encoder_buffer::EncoderBuffer`]: the recent encoder samples, interpolated linearly.
//! - [`matcher::Matcher`]: the whole matching, free of any I/O, so it is unit-tested on
//!   synthetic streams.

pub mod clock;
pub mod encoder_buffer;
pub mod latency;
pub mod matcher;

#[cfg(test)]
mod test_streams;
