//! Sensing messages: encoder samples, tracker frames, matched samples and the rig's truth.

use iceoryx2::prelude::ZeroCopySend;

/// Number of joints (and encoders) of the robot.
pub const JOINTS: usize = 5;
/// Number of tools in a tracker frame, indexed by [`Tool`].
pub const TOOLS: usize = 4;
/// The graph's encoder sampling rate, Hz: `encoders` publishes an [`EncoderSample`] this
/// often unless told otherwise, and its consumers size their buffers and expectations by it.
pub const ENCODER_RATE_HZ: f64 = 1000.0;

/// One reading of the five incremental encoder counters (published by `encoders` at
/// [`ENCODER_RATE_HZ`]).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.EncoderSample.v1")]
pub struct EncoderSample {
    /// Sequence number, +1 per sample from the same publisher; a gap means lost samples.
    pub seq: u64,
    /// Host `CLOCK_MONOTONIC` time at which the counters were read, ns.
    pub t_ns: i64,
    /// Raw quadrature counts of joints 1..5 (0 at power-up; θ_enc = 2π·counts/cpr).
    pub counts: [i64; JOINTS],
}

/// The rig's quadrature counter register as latched by the (simulated) hardware, published by
/// the rig at ≥ 1 kHz on [`crate::services::RIG_COUNTERS`] and sampled by `encoders`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.CounterLatch.v1")]
pub struct CounterLatch {
    /// Sequence number, +1 per latch.
    pub seq: u64,
    /// Host `CLOCK_MONOTONIC` time at which the counts were latched, ns.
    pub latch_t_ns: i64,
    /// Raw quadrature counts of joints 1..5 (0 at power-up).
    pub counts: [i64; JOINTS],
}

/// The tools of a tracker frame, in their array order.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, ZeroCopySend)]
pub enum Tool {
    /// Base marker `M`, fixed to the robot base.
    Base = 0,
    /// Marker `Tf` on the front effector.
    Front = 1,
    /// Marker `Tb` on the back effector.
    Back = 2,
    /// Single sphere on the needle tip (a point, no orientation).
    Tip = 3,
}

impl Tool {
    /// All tools in array order.
    pub const ALL: [Tool; TOOLS] = [Tool::Base, Tool::Front, Tool::Back, Tool::Tip];

    /// The lower-case name used in recordings (`base`, `front`, `back`, `tip`).
    pub fn name(self) -> &'static str {
        match self {
            Tool::Base => "base",
            Tool::Front => "front",
            Tool::Back => "back",
            Tool::Tip => "tip",
        }
    }
}

/// Whether a tool was seen in a tracker frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, ZeroCopySend)]
pub enum ToolStatus {
    /// Pose (or tip point) valid.
    Ok,
    /// Enabled but not seen in this frame; the numbers are meaningless.
    #[default]
    Missing,
    /// Not enabled on the tracker (e.g. the tip sphere is not attached).
    Disabled,
}

/// One tool's measurement in the tracker frame `S`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.ToolSample.v1")]
pub struct ToolSample {
    /// Whether the numbers below are valid.
    pub status: ToolStatus,
    /// Orientation `T_S_X` as a unit quaternion `[w, x, y, z]`; `[1, 0, 0, 0]` for the tip.
    pub quaternion: [f64; 4],
    /// Position of the tool origin (or tip sphere) in `S`, mm.
    pub position_mm: [f64; 3],
    /// RMS marker fit error reported by the tracker, mm.
    pub rms_mm: f64,
}

impl ToolSample {
    /// True if the tool was seen in this frame.
    pub fn is_ok(&self) -> bool {
        self.status == ToolStatus::Ok
    }
}

/// One tracker frame as received by `tracker` (20 Hz on a Polaris Vicra).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.TrackerFrame.v3")]
pub struct TrackerFrame {
    /// Sequence number, +1 per published frame.
    pub seq: u64,
    /// Host `CLOCK_MONOTONIC` time at which the reply carrying the frame arrived, ns (later
    /// than [`Self::available_t_ns`] by the wait for the next poll and one serial exchange).
    pub arrival_t_ns: i64,
    /// Estimated host `CLOCK_MONOTONIC` time at which the frame became available at the
    /// device, ns: the midpoint between the last poll that did not see it and the poll that
    /// did (within ± half their gap). The exposure is earlier by the device latency; this is
    /// the stamp `sync` fits its frame clock through.
    pub available_t_ns: i64,
    /// Host `CLOCK_MONOTONIC` time right before `tracker` published the frame, ns: from
    /// [`Self::arrival_t_ns`] to here the tracker parsed the reply, estimated the
    /// availability and converted the tools (0 where unknown: a frame not published by
    /// `tracker`, or rebuilt from a recording).
    pub sent_t_ns: i64,
    /// The tracker's own frame counter.
    pub frame_number: u32,
    /// Per-tool measurements, indexed by [`Tool`] (`tools[Tool::Front as usize]`).
    pub tools: [ToolSample; TOOLS],
}

impl TrackerFrame {
    /// The measurement of one tool.
    pub fn tool(&self, tool: Tool) -> &ToolSample {
        &self.tools[tool as usize]
    }
}

/// Where the tracker latency used by `sync` came from.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, ZeroCopySend)]
pub enum LatencySource {
    /// Configured on the command line (`sabr-sync --latency-ms`).
    #[default]
    Configured,
    /// The `[calibration] latency_ms` of the parameter set announced by `calibrator`.
    Calibrated,
}

/// How well a tracker frame's exposure time was estimated and bracketed by encoder samples.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.MatchQuality.v2")]
pub struct MatchQuality {
    /// Time between the two encoder samples interpolated between, ns (≈1 ms when healthy).
    pub interpolation_span_ns: i64,
    /// Distance from the exposure time to the nearest encoder sample, ns.
    pub nearest_sample_ns: i64,
    /// Latency used: the frame clock line at this frame minus the exposure time, ns.
    pub latency_ns: i64,
    /// Where `latency_ns` came from.
    pub latency_source: LatencySource,
    /// This frame's availability stamp ([`TrackerFrame::available_t_ns`]) minus the frame
    /// clock line, ns (large and positive: a late frame).
    pub clock_residual_ns: i64,
    /// Robust spread (1.4826 · MAD) of the availability stamps about the clock line over the
    /// fit window, ns: the stamp jitter.
    pub clock_spread_ns: i64,
    /// Tracker frames in the clock fit window.
    pub clock_frames: u32,
}

/// A tracker frame paired with the encoder state at its exposure time (published by `sync`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.MatchedSample.v4")]
pub struct MatchedSample {
    /// Sequence number, +1 per matched sample.
    pub seq: u64,
    /// Estimated exposure time of the frame, host `CLOCK_MONOTONIC` ns.
    pub exposure_t_ns: i64,
    /// Arrival time of the frame (as in [`TrackerFrame::arrival_t_ns`]), host
    /// `CLOCK_MONOTONIC` ns.
    pub arrival_t_ns: i64,
    /// Estimated time the frame became available at the device (as in
    /// [`TrackerFrame::available_t_ns`]), host `CLOCK_MONOTONIC` ns.
    pub available_t_ns: i64,
    /// When `tracker` published the frame (as in [`TrackerFrame::sent_t_ns`]), host
    /// `CLOCK_MONOTONIC` ns.
    pub frame_sent_t_ns: i64,
    /// When `sync` took the frame from its subscriber, host `CLOCK_MONOTONIC` ns.
    pub frame_received_t_ns: i64,
    /// Host `CLOCK_MONOTONIC` time right before `sync` published this sample, ns (0 in a
    /// sample that was not published). With the two stamps before it and
    /// [`Self::arrival_t_ns`], the frame's way from the tracker's port to a subscriber in
    /// parts: the tracker's work, the hop to `sync`, the match, the hop on.
    pub sent_t_ns: i64,
    /// The tracker's frame counter.
    pub frame_number: u32,
    /// Encoder counts of joints 1..5 interpolated to the exposure time.
    pub counts: [f64; JOINTS],
    /// Encoder angles θ_enc = 2π·counts/cpr of joints 1..5 at the exposure time, rad.
    pub encoder_angle_rad: [f64; JOINTS],
    /// The frame's tool measurements, indexed by [`Tool`].
    pub tools: [ToolSample; TOOLS],
    /// Quality figures of the match.
    pub quality: MatchQuality,
}

/// Ground truth the simulated rig publishes per tracker frame, for tests and benchmarks only.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.RigTruth.v1")]
pub struct RigTruth {
    /// Sequence number, +1 per frame.
    pub seq: u64,
    /// The tracker frame counter this truth belongs to.
    pub frame_number: u32,
    /// True exposure time of the frame, host `CLOCK_MONOTONIC` ns.
    pub exposure_t_ns: i64,
    /// True joint angles θ1..θ5 at the exposure, rad.
    pub joints_rad: [f64; JOINTS],
    /// True encoder counts at the exposure (fractional: before quantisation).
    pub counts: [f64; JOINTS],
    /// True needle tip `p_n` in the robot base `Bb`, mm.
    pub tip_mm: [f64; 3],
    /// True needle direction `z_N` in `Bb` (unit vector).
    pub direction: [f64; 3],
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::size_of;

    /// The type name of message `T` as iceoryx2 sees it.
    fn type_name<T: ZeroCopySend>() -> &'static str {
        // SAFETY: reading the name has no precondition; the contract of `type_name` is about
        // the layouts of the types sharing a name, which this test pins.
        unsafe { <T as ZeroCopySend>::type_name() }
    }

    /// Every sensing message's stable type name and size: a layout change shows up here and
    /// must come with a bumped version in the name.
    #[test]
    fn type_names_and_sizes_are_pinned() {
        let pinned = [
            (type_name::<EncoderSample>(), size_of::<EncoderSample>()),
            (type_name::<CounterLatch>(), size_of::<CounterLatch>()),
            (type_name::<ToolSample>(), size_of::<ToolSample>()),
            (type_name::<TrackerFrame>(), size_of::<TrackerFrame>()),
            (type_name::<MatchQuality>(), size_of::<MatchQuality>()),
            (type_name::<MatchedSample>(), size_of::<MatchedSample>()),
            (type_name::<RigTruth>(), size_of::<RigTruth>()),
        ];
        assert_eq!(
            pinned,
            [
                ("sabr.EncoderSample.v1", 56),
                ("sabr.CounterLatch.v1", 56),
                ("sabr.ToolSample.v1", 72),
                ("sabr.TrackerFrame.v3", 328),
                ("sabr.MatchQuality.v2", 56),
                ("sabr.MatchedSample.v4", 488),
                ("sabr.RigTruth.v1", 152),
            ]
        );
    }
}
