//! What the ping-pong baselines carry (the graph's own messages) and over what.

use sabr_model::RobotParams;
use sabr_node::msgs::{
    EncoderSample, IkRequest, IkResponse, MatchedSample, MotorSetpoint, TrackerFrame,
    ENCODER_RATE_HZ, IK_REQUESTS_PER_SETPOINT_PERIOD, SETPOINT_PERIOD_NS,
};
use std::time::Duration;

/// Time between two bursts of IK requests of the live graph: the motion node's setpoint
/// period.
pub const IK_PERIOD: Duration = Duration::from_nanos(SETPOINT_PERIOD_NS.unsigned_abs());

/// The request → response message pair of a ping-pong, one per live-graph hop, so each hop is
/// compared with a baseline carrying the same bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Payload {
    /// [`EncoderSample`] → [`EncoderSample`] (the encoder sample → sync hop).
    EncoderSample,
    /// [`TrackerFrame`] → [`MatchedSample`] (the tracker frame → matched sample hop).
    TrackerFrame,
    /// [`IkRequest`] → [`IkResponse`] (the IK round trip).
    Ik,
    /// [`MotorSetpoint`] → [`MotorSetpoint`] (the motor setpoint → rig hop).
    MotorSetpoint,
}

impl Payload {
    /// Every payload, in the order measured and printed.
    pub const ALL: [Payload; 4] = [
        Payload::EncoderSample,
        Payload::TrackerFrame,
        Payload::Ik,
        Payload::MotorSetpoint,
    ];

    /// How often the live graph sends the request of this payload, for the hops compared
    /// with a ping-pong (the encoders' samples, the simulated tracker's frames, IK requests);
    /// `None` for the setpoints, whose hop is judged against the rig's tick.
    pub fn live_period(self) -> Option<Duration> {
        match self {
            Payload::EncoderSample => Some(Duration::from_secs_f64(1.0 / ENCODER_RATE_HZ)),
            Payload::TrackerFrame => Some(Duration::from_secs_f64(
                1.0 / RobotParams::nominal().tracker_rate_hz,
            )),
            Payload::Ik => Some(IK_PERIOD),
            Payload::MotorSetpoint => None,
        }
    }

    /// How many requests of this payload the live graph sends back to back in each
    /// [`Payload::live_period`]: the motion node's burst of IK requests, one of every other.
    pub fn live_burst(self) -> u64 {
        match self {
            Payload::Ik => IK_REQUESTS_PER_SETPOINT_PERIOD as u64,
            Payload::EncoderSample | Payload::TrackerFrame | Payload::MotorSetpoint => 1,
        }
    }

    /// Name used in measurement names and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Payload::EncoderSample => "encoder-sample",
            Payload::TrackerFrame => "tracker-frame",
            Payload::Ik => "ik",
            Payload::MotorSetpoint => "motor-setpoint",
        }
    }

    /// Size of the request message in bytes.
    pub fn request_bytes(self) -> usize {
        match self {
            Payload::EncoderSample => size_of::<EncoderSample>(),
            Payload::TrackerFrame => size_of::<TrackerFrame>(),
            Payload::Ik => size_of::<IkRequest>(),
            Payload::MotorSetpoint => size_of::<MotorSetpoint>(),
        }
    }

    /// Size of the response message in bytes.
    pub fn response_bytes(self) -> usize {
        match self {
            Payload::EncoderSample => size_of::<EncoderSample>(),
            Payload::TrackerFrame => size_of::<MatchedSample>(),
            Payload::Ik => size_of::<IkResponse>(),
            Payload::MotorSetpoint => size_of::<MotorSetpoint>(),
        }
    }

    /// `request → response` types and sizes, for the printed legend.
    pub fn describe(self) -> String {
        let (request, response) = match self {
            Payload::EncoderSample => ("EncoderSample", "EncoderSample"),
            Payload::TrackerFrame => ("TrackerFrame", "MatchedSample"),
            Payload::Ik => ("IkRequest", "IkResponse"),
            Payload::MotorSetpoint => ("MotorSetpoint", "MotorSetpoint"),
        };
        format!(
            "{}: {request} ({} B) → {response} ({} B)",
            self.name(),
            self.request_bytes(),
            self.response_bytes()
        )
    }
}

/// How the two processes of a ping-pong exchange messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Transport {
    /// iceoryx2 publish-subscribe, both sides spinning on `receive()`.
    #[value(name = "iox2-poll")]
    IoxPoll,
    /// iceoryx2 publish-subscribe plus an event per sample; both sides sleep in the listener
    /// (stock iceoryx2: the event is a Unix datagram socket).
    #[value(name = "iox2-event")]
    IoxEvent,
    /// A blocking Unix-domain stream socket carrying the same bytes.
    #[value(name = "uds")]
    Uds,
    /// The graph's transport: `sabr_node` publish-subscribe whose publisher rings the
    /// subscriber's futex doorbell; both sides sleep on their doorbell.
    #[value(name = "doorbell")]
    Doorbell,
    /// The floor: two counters in shared memory and `FUTEX_WAKE`/`FUTEX_WAIT`, nothing else;
    /// placed as the shipped graph places the hop.
    #[value(name = "futex")]
    Futex,
    /// The same raw futex ping-pong with the two processes on different cores.
    #[value(name = "futex-cross")]
    FutexCross,
}

impl Transport {
    /// Every transport, in the order measured and printed.
    pub const ALL: [Transport; 6] = [
        Transport::IoxPoll,
        Transport::IoxEvent,
        Transport::Uds,
        Transport::Doorbell,
        Transport::Futex,
        Transport::FutexCross,
    ];

    /// Name used in measurement names and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Transport::IoxPoll => "iox2-poll",
            Transport::IoxEvent => "iox2-event",
            Transport::Uds => "uds",
            Transport::Doorbell => "doorbell",
            Transport::Futex => "futex",
            Transport::FutexCross => "futex-cross",
        }
    }
}

/// Name of the round-trip measurement of `payload` over `transport`.
pub fn baseline_name(transport: Transport, payload: Payload) -> String {
    format!("{}/{}", transport.name(), payload.name())
}

/// Name of the round-trip measurement of `payload` over `transport` paced at the payload's
/// [`Payload::live_period`]: `<transport>-paced/<payload>`.
pub fn paced_name(transport: Transport, payload: Payload) -> String {
    format!("{}-paced/{}", transport.name(), payload.name())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    #[test]
    fn command_line_names_match_measurement_names() {
        for payload in Payload::ALL {
            let value = payload.to_possible_value().unwrap();
            assert_eq!(value.get_name(), payload.name());
        }
        for transport in Transport::ALL {
            let value = transport.to_possible_value().unwrap();
            assert_eq!(value.get_name(), transport.name());
        }
    }

    #[test]
    fn the_hops_with_a_ping_pong_have_a_live_period() {
        assert_eq!(
            Payload::EncoderSample.live_period(),
            Some(Duration::from_millis(1))
        );
        assert_eq!(
            Payload::TrackerFrame.live_period(),
            Some(Duration::from_millis(50)),
            "the simulated tracker runs at 20 Hz"
        );
        assert_eq!(Payload::MotorSetpoint.live_period(), None);
        assert_eq!(
            (Payload::Ik.live_period(), Payload::Ik.live_burst()),
            (Some(Duration::from_millis(1)), 10),
            "the motion node's line planner: 10 requests per setpoint period"
        );
        for payload in [Payload::EncoderSample, Payload::TrackerFrame] {
            assert_eq!(payload.live_burst(), 1, "{}", payload.name());
        }
        assert_eq!(paced_name(Transport::Futex, Payload::Ik), "futex-paced/ik");
    }

    #[test]
    fn sizes_are_the_message_sizes() {
        assert_eq!(Payload::EncoderSample.request_bytes(), 56);
        assert!(Payload::TrackerFrame.response_bytes() > Payload::TrackerFrame.request_bytes());
        assert_eq!(
            Payload::Ik.describe(),
            format!(
                "ik: IkRequest ({} B) → IkResponse ({} B)",
                size_of::<IkRequest>(),
                size_of::<IkResponse>()
            )
        );
    }
}
