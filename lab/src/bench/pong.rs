//! The echo side of a ping-pong baseline: the `sabr-pong` executable, started by the
//! measuring `sabr bench` process, answers a fixed number of messages and exits.

use super::doorbell::DoorbellEnd;
use super::futex::FutexEnd;
use super::iox::IoxEnd;
use super::payload::{Payload, Transport};
use super::pingpong::{futex_segment, service_names, wait_mode, PEER_TIMEOUT};
use super::uds::UdsEnd;
use anyhow::Context;
use sabr_node::msgs::{
    EncoderSample, IkRequest, IkResponse, MatchedSample, MotorSetpoint, TrackerFrame,
};
use sabr_node::{Domain, Message};
use std::path::PathBuf;
use std::time::Instant;

/// Command line of `sabr-pong`, the echo side of one ping-pong baseline (started by
/// `sabr bench` with the measuring side's transport, payload and message count).
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "sabr-pong", about)]
pub struct PongArgs {
    /// Transport of the ping-pong.
    #[arg(long, value_enum)]
    pub transport: Transport,
    /// Payload of the ping-pong.
    #[arg(long, value_enum)]
    pub payload: Payload,
    /// Messages to answer before exiting.
    #[arg(long)]
    pub count: u64,
    /// iceoryx2 domain of the ping-pong services (iceoryx2 transports).
    #[arg(long)]
    pub domain: Option<String>,
    /// Unix socket to connect to (`uds`).
    #[arg(long)]
    pub socket: Option<PathBuf>,
}

/// Runs the pong: answers `--count` messages, then exits.
pub fn run(args: &PongArgs) -> anyhow::Result<()> {
    let missing = |name: &str| format!("--transport {} needs --{name}", args.transport.name());
    let (transport, payload, count) = (args.transport, args.payload, args.count);
    match transport {
        Transport::Uds => {
            let socket = args.socket.as_ref().with_context(|| missing("socket"))?;
            let mut end = UdsEnd::connect(
                socket,
                payload.response_bytes(),
                payload.request_bytes(),
                PEER_TIMEOUT,
            )?;
            for index in 0..count {
                end.receive()
                    .with_context(|| format!("pong: message {index} of {count}"))?;
                end.send()?;
            }
            Ok(())
        }
        Transport::IoxPoll | Transport::IoxEvent | Transport::Doorbell => {
            let domain = Domain::new(args.domain.as_deref().with_context(|| missing("domain"))?)?;
            let echo = Echo {
                transport,
                payload,
                domain: &domain,
                count,
            };
            match payload {
                Payload::EncoderSample => echo.run::<EncoderSample, EncoderSample>(),
                Payload::TrackerFrame => echo.run::<TrackerFrame, MatchedSample>(),
                Payload::Ik => echo.run::<IkRequest, IkResponse>(),
                Payload::MotorSetpoint => echo.run::<MotorSetpoint, MotorSetpoint>(),
            }
        }
        Transport::Futex | Transport::FutexCross => {
            let domain = Domain::new(args.domain.as_deref().with_context(|| missing("domain"))?)?;
            let segment = futex_segment(&domain, transport, payload);
            let mut end = FutexEnd::open(&segment, PEER_TIMEOUT)?;
            for index in 0..count {
                let expected = u32::try_from(index + 1).context("too many messages")?;
                end.receive(expected, Instant::now() + PEER_TIMEOUT)
                    .with_context(|| format!("pong: message {index} of {count}"))?;
                end.send()?;
            }
            Ok(())
        }
    }
}

/// The echo loop of an iceoryx2 or doorbell pong.
struct Echo<'a> {
    transport: Transport,
    payload: Payload,
    domain: &'a Domain,
    count: u64,
}

impl Echo<'_> {
    fn run<Req: Message, Resp: Message + Default>(&self) -> anyhow::Result<()> {
        let (ping, pong) = service_names(self.transport, self.payload);
        let count = self.count;
        if self.transport == Transport::Doorbell {
            let end = DoorbellEnd::<Resp, Req>::open(self.domain, "bench-pong", &pong, &ping)?;
            for index in 0..count {
                end.receive(Instant::now() + PEER_TIMEOUT)
                    .with_context(|| format!("pong: message {index} of {count}"))?;
                end.send(Resp::default())?;
            }
            return Ok(());
        }
        let end = IoxEnd::<Resp, Req>::open(self.domain, &pong, &ping, wait_mode(self.transport)?)?;
        for index in 0..count {
            end.receive(Instant::now() + PEER_TIMEOUT)
                .with_context(|| format!("pong: message {index} of {count}"))?;
            end.send(Resp::default())?;
        }
        Ok(())
    }
}
