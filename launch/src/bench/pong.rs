//! The echo side of a ping-pong baseline: `sabr bench --role pong ...`, started by the
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

/// The role of a `sabr bench` process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Role {
    /// Echo side of one ping-pong baseline (spawned by `sabr bench` itself).
    Pong,
}

/// Hidden arguments of a pong process (set by the measuring `sabr bench`).
#[derive(Debug, Clone, clap::Args)]
pub struct PongArgs {
    /// Internal: run as the echo side of one ping-pong.
    #[arg(long, hide = true, value_enum)]
    pub role: Option<Role>,
    /// Internal: the pong's transport.
    #[arg(long, hide = true, value_enum, requires = "role")]
    pub transport: Option<Transport>,
    /// Internal: the pong's payload.
    #[arg(long, hide = true, value_enum, requires = "role")]
    pub payload: Option<Payload>,
    /// Internal: messages to answer before exiting.
    #[arg(long, hide = true, requires = "role")]
    pub count: Option<u64>,
    /// Internal: iceoryx2 domain of the ping-pong services.
    #[arg(long, hide = true, requires = "role")]
    pub domain: Option<String>,
    /// Internal: Unix socket to connect to.
    #[arg(long, hide = true, requires = "role")]
    pub socket: Option<PathBuf>,
}

/// Runs the pong: answers `--count` messages, then exits.
pub fn run(args: &PongArgs) -> anyhow::Result<()> {
    let missing = |name: &str| format!("--role pong needs --{name}");
    let transport = args.transport.with_context(|| missing("transport"))?;
    let payload = args.payload.with_context(|| missing("payload"))?;
    let count = args.count.with_context(|| missing("count"))?;
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
