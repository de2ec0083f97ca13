//! The echo side of a ping-pong baseline: the `sabr-pong` executable, started by the
//! measuring `sabr bench` process, answers a fixed number of messages and exits.

use super::iox::IoxEnd;
use super::payload::{Payload, Transport};
use super::pingpong::{service_names, wait_mode, PEER_TIMEOUT};
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
        Transport::IoxPoll | Transport::IoxEvent => {
            let domain = Domain::new(args.domain.as_deref().with_context(|| missing("domain"))?)?;
            match payload {
                Payload::EncoderSample => {
                    echo::<EncoderSample, EncoderSample>(transport, payload, &domain, count)
                }
                Payload::TrackerFrame => {
                    echo::<TrackerFrame, MatchedSample>(transport, payload, &domain, count)
                }
                Payload::Ik => echo::<IkRequest, IkResponse>(transport, payload, &domain, count),
                Payload::MotorSetpoint => {
                    echo::<MotorSetpoint, MotorSetpoint>(transport, payload, &domain, count)
                }
            }
        }
    }
}

fn echo<Req: Message, Resp: Message + Default>(
    transport: Transport,
    payload: Payload,
    domain: &Domain,
    count: u64,
) -> anyhow::Result<()> {
    let (ping, pong) = service_names(transport, payload);
    let end = IoxEnd::<Resp, Req>::open(domain, &pong, &ping, wait_mode(transport)?)?;
    for index in 0..count {
        end.receive(Instant::now() + PEER_TIMEOUT)
            .with_context(|| format!("pong: message {index} of {count}"))?;
        end.send(Resp::default())?;
    }
    Ok(())
}
