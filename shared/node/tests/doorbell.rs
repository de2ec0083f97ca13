//! The doorbell transport in one process and between two: wake-ups, timeouts, several
//! producers ringing one doorbell, request-response, and a consumer killed and restarted.
//! Each test runs in its own domain; the second process is this test binary again, running
//! [`peer`] (it does nothing unless started as a peer).

use sabr_msgs::EncoderSample;
use sabr_node::iceoryx2::identifiers::UniqueNodeId;
use sabr_node::iceoryx2::prelude::{CallbackProgression, PortFactory, ServiceName};
use sabr_node::{release_domain, Domain, Doorbell, Exit, NodeRuntime, DOMAIN_ENV};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

type Runtime = NodeRuntime<Doorbell>;

/// Env var that makes [`peer`] act: `echo` or `server`.
const PEER_ROLE_ENV: &str = "SABR_DOORBELL_TEST_PEER";
/// The peer's silence limit: it exits after this long without a message.
const PEER_IDLE: Duration = Duration::from_secs(20);
/// Longest a peer waits in one `recv_timeout`: far above a round trip, so a round trip that
/// completes within [`ROUND_TRIP_LIMIT`] was woken by the doorbell, not by the timeout.
const PEER_WAIT: Duration = Duration::from_secs(10);
/// Longest accepted round trip to a peer.
const ROUND_TRIP_LIMIT: Duration = Duration::from_secs(2);

const PING: &str = "sabr/test/ping";
const PONG: &str = "sabr/test/pong";
const ECHO: &str = "sabr/test/echo";

fn unique_domain(test: &str) -> Domain {
    Domain::new(&format!("d-{test}-{}", std::process::id())).unwrap()
}

fn release(domain: &Domain) {
    let left = release_domain(domain);
    assert!(left.is_empty(), "left behind: {left:?}");
}

fn sample(seq: u64) -> EncoderSample {
    EncoderSample {
        seq,
        t_ns: sabr_node::monotonic_ns(),
        counts: [seq as i64, 0, 0, 0, 0],
    }
}

#[test]
fn samples_wake_the_subscriber_and_silence_times_out() {
    let domain = unique_domain("flow");
    {
        let rt = Runtime::in_domain("producer", domain.clone()).unwrap();
        let publisher = rt.publisher::<EncoderSample>(PING).unwrap();
        let subscriber = rt.subscriber::<EncoderSample>(PING).unwrap();
        publisher.send(sample(7)).unwrap();
        let received = subscriber.recv_timeout(Duration::from_secs(1)).unwrap();
        assert_eq!(received.map(|s| s.seq), Some(7));

        let start = Instant::now();
        let nothing = subscriber.recv_timeout(Duration::from_millis(50)).unwrap();
        assert_eq!(nothing, None);
        assert!(start.elapsed() >= Duration::from_millis(50));
    }
    release(&domain);
}

#[test]
fn run_on_data_wakes_on_samples_and_idles_without() {
    let domain = unique_domain("wake");
    {
        let mut rt = Runtime::in_domain("consumer", domain.clone()).unwrap();
        let publisher = rt.publisher::<EncoderSample>(PING).unwrap();
        let subscriber = rt.subscriber::<EncoderSample>(PING).unwrap();
        let mut seen = Vec::new();
        let mut idle_calls = 0;
        let exit = rt
            .run_on_data(&[&subscriber], Duration::from_millis(20), |ctx| {
                if ctx.woke_on_data() {
                    subscriber.drain(|s| seen.push(s.seq))?;
                } else {
                    idle_calls += 1;
                }
                match ctx.tick() {
                    0..=2 => publisher.send(sample(ctx.tick()))?,
                    _ => ctx.stop(),
                }
                Ok::<_, sabr_node::NodeError>(())
            })
            .unwrap();
        assert_eq!(exit, Exit::Stopped);
        assert_eq!(seen, vec![0, 1, 2]);
        assert_eq!(idle_calls, 1);
    }
    release(&domain);
}

/// The node and port name of each of `service`'s subscribers (the name carries the event id).
fn subscribers(rt: &Runtime, service: &str) -> Vec<(UniqueNodeId, String)> {
    let factory = rt
        .node()
        .service_builder(&ServiceName::new(service).unwrap())
        .publish_subscribe::<EncoderSample>()
        .open()
        .unwrap();
    let mut found = Vec::new();
    factory.dynamic_config().list_subscribers(|details| {
        found.push((details.node_id, details.subscriber_name.as_str().to_owned()));
        CallbackProgression::Continue
    });
    found
}

/// The port names of `service`'s subscribers.
fn subscriber_port_names(rt: &Runtime, service: &str) -> Vec<String> {
    subscribers(rt, service)
        .into_iter()
        .map(|(_, name)| name)
        .collect()
}

#[test]
fn a_process_has_fifteen_inbound_ports_and_a_dropped_one_frees_its_id() {
    let domain = unique_domain("full");
    {
        let rt = Runtime::in_domain("consumer", domain.clone()).unwrap();
        let service = |i: usize| format!("sabr/test/inbound-{i}");
        let mut subscribers: Vec<_> = (0..15)
            .map(|i| rt.subscriber::<EncoderSample>(&service(i)).unwrap())
            .collect();
        let error = rt
            .subscriber::<EncoderSample>(&service(15))
            .err()
            .expect("a 16th inbound port got an event id");
        assert!(
            error
                .to_string()
                .contains("all 15 event ids of the doorbell are in use"),
            "{error}"
        );
        // The freed id serves a new port, which its producer's ring wakes.
        subscribers.swap_remove(3);
        let late = rt.subscriber::<EncoderSample>(&service(15)).unwrap();
        let publisher = rt.publisher::<EncoderSample>(&service(15)).unwrap();
        publisher.send(sample(4)).unwrap();
        let got = late.recv_timeout(Duration::from_secs(1)).unwrap();
        assert_eq!(got.map(|s| s.seq), Some(4));
    }
    release(&domain);
}

#[test]
fn several_producers_ring_one_doorbell_with_their_own_ids() {
    let domain = unique_domain("ids");
    {
        let consumer = Runtime::in_domain("consumer", domain.clone()).unwrap();
        let from_a = consumer.subscriber::<EncoderSample>(PING).unwrap();
        let from_b = consumer.subscriber::<EncoderSample>(PONG).unwrap();
        let producer_a = Runtime::in_domain("a", domain.clone()).unwrap();
        let producer_b = Runtime::in_domain("b", domain.clone()).unwrap();
        let a = producer_a.publisher::<EncoderSample>(PING).unwrap();
        let b = producer_b.publisher::<EncoderSample>(PONG).unwrap();

        let (name_a, name_b) = (
            subscriber_port_names(&consumer, PING),
            subscriber_port_names(&consumer, PONG),
        );
        assert_eq!(name_a.len(), 1);
        assert_eq!(name_b.len(), 1);
        assert!(name_a[0].starts_with("doorbell-"), "{name_a:?}");
        assert_ne!(name_a, name_b, "the two inbound ports share an event id");

        // Only A rings: B's subscriber sleeps through it (its id did not ring) and times out.
        a.send(sample(1)).unwrap();
        let start = Instant::now();
        assert_eq!(
            from_b.recv_timeout(Duration::from_millis(100)).unwrap(),
            None
        );
        assert!(start.elapsed() >= Duration::from_millis(100));
        // A's ring stayed pending for A's subscriber.
        let start = Instant::now();
        let got = from_a.recv_timeout(Duration::from_secs(1)).unwrap();
        assert_eq!(got.map(|s| s.seq), Some(1));
        assert!(start.elapsed() < Duration::from_millis(50));

        // Both ring: one loop wake-up drains both.
        let mut consumer = consumer;
        a.send(sample(2)).unwrap();
        b.send(sample(3)).unwrap();
        let mut seen = Vec::new();
        consumer
            .run_on_data(&[&from_a, &from_b], Duration::from_secs(5), |ctx| {
                assert!(ctx.woke_on_data(), "idle timeout instead of the rings");
                from_a.drain(|s| seen.push(s.seq))?;
                from_b.drain(|s| seen.push(s.seq))?;
                if seen.len() == 2 {
                    ctx.stop();
                }
                Ok::<_, sabr_node::NodeError>(())
            })
            .unwrap();
        seen.sort();
        assert_eq!(seen, [2, 3]);
    }
    release(&domain);
}

#[test]
fn request_response_in_one_process() {
    let domain = unique_domain("rr");
    {
        let rt = Runtime::in_domain("both", domain.clone()).unwrap();
        let server = rt.server::<EncoderSample, EncoderSample>(ECHO).unwrap();
        let client = rt.client::<EncoderSample, EncoderSample>(ECHO).unwrap();
        let pending = client
            .send(sample(41))
            .unwrap()
            .expect("a server is connected");
        // Not answered yet: the wait times out.
        let start = Instant::now();
        assert_eq!(
            client.receive(&pending, Duration::from_millis(50)).unwrap(),
            None
        );
        assert!(start.elapsed() >= Duration::from_millis(50));
        let answered = server.answer(|request| sample(request.seq + 1)).unwrap();
        assert_eq!((answered.sent, answered.undelivered), (1, 0));
        let response = client.receive(&pending, Duration::from_secs(1)).unwrap();
        assert_eq!(response.map(|r| r.seq), Some(42));
        // The server is done with the request: no wait for more.
        let start = Instant::now();
        assert_eq!(
            client.receive(&pending, Duration::from_secs(5)).unwrap(),
            None
        );
        assert!(start.elapsed() < Duration::from_secs(1));
    }
    release(&domain);
}

/// A peer process (this test binary running only [`peer`]) in `domain`.
struct Peer {
    child: Child,
}

impl Peer {
    fn spawn(domain: &Domain, role: &str, name: &str) -> Self {
        let exe = std::env::current_exe().unwrap();
        let child = Command::new(exe)
            .args(["--exact", "peer", "--nocapture", "--test-threads", "1"])
            .env(PEER_ROLE_ENV, role)
            .env(DOMAIN_ENV, domain.as_str())
            .env(sabr_node::NODE_NAME_ENV, name)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .spawn()
            .unwrap();
        Self { child }
    }

    fn kill(mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }

    fn finish(mut self) {
        let status = self.child.wait().unwrap();
        assert!(status.success(), "peer failed: {status}");
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The peer side, only when started by [`Peer::spawn`]: `echo` answers every ping with a pong
/// of the same sequence number, `server` answers every request on [`ECHO`] with seq + 1;
/// both stop after sequence number `u64::MAX` or [`PEER_IDLE`] of silence.
#[test]
fn peer() {
    let Ok(role) = std::env::var(PEER_ROLE_ENV) else {
        return;
    };
    let mut rt = Runtime::start_on("peer").unwrap();
    match role.as_str() {
        "echo" => {
            let pings = rt
                .subscriber_with_history::<EncoderSample>(PING, 0)
                .unwrap();
            let pongs = rt.publisher::<EncoderSample>(PONG).unwrap();
            let mut last_message = Instant::now();
            while last_message.elapsed() < PEER_IDLE && rt.keep_running() {
                if let Some(ping) = pings.recv_timeout(PEER_WAIT).unwrap() {
                    last_message = Instant::now();
                    if ping.seq == u64::MAX {
                        return;
                    }
                    pongs.send(ping).unwrap();
                }
            }
        }
        "server" => {
            let server = rt.server::<EncoderSample, EncoderSample>(ECHO).unwrap();
            let mut done = false;
            rt.run_on_data(&[&server], PEER_IDLE, |ctx| {
                if !ctx.woke_on_data() {
                    ctx.stop();
                }
                server.answer(|request| {
                    done |= request.seq == u64::MAX;
                    sample(request.seq.wrapping_add(1))
                })?;
                if done {
                    ctx.stop();
                }
                Ok::<_, sabr_node::NodeError>(())
            })
            .unwrap();
        }
        other => panic!("unknown peer role {other:?}"),
    }
}

/// The parent side of the echo ping-pong.
struct Pinger {
    pings: sabr_node::Publisher<EncoderSample, Doorbell>,
    pongs: sabr_node::Subscriber<EncoderSample, Doorbell>,
    factory_rt: Runtime,
}

impl Pinger {
    fn open(domain: &Domain) -> Self {
        let rt = Runtime::in_domain("pinger", domain.clone()).unwrap();
        Self {
            pongs: rt.subscriber::<EncoderSample>(PONG).unwrap(),
            pings: rt.publisher::<EncoderSample>(PING).unwrap(),
            factory_rt: rt,
        }
    }

    /// Waits until a peer subscribes to the pings (it publishes pongs right after).
    fn wait_for_peer(&self) {
        let start = Instant::now();
        while subscriber_port_names(&self.factory_rt, PING).is_empty() {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "no peer appeared"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// `count` round trips from `first` on, each within [`ROUND_TRIP_LIMIT`].
    fn round_trips(&self, first: u64, count: u64) {
        for seq in first..first + count {
            let start = Instant::now();
            self.pings.send(sample(seq)).unwrap();
            let pong = self.pongs.recv_timeout(ROUND_TRIP_LIMIT).unwrap();
            assert_eq!(pong.map(|p| p.seq), Some(seq), "round trip {seq}");
            assert!(
                start.elapsed() < ROUND_TRIP_LIMIT,
                "round trip {seq} timed out"
            );
        }
    }
}

#[test]
fn two_processes_wake_each_other() {
    let domain = unique_domain("two");
    {
        let pinger = Pinger::open(&domain);
        let peer = Peer::spawn(&domain, "echo", "echo");
        pinger.wait_for_peer();
        pinger.round_trips(1, 500);
        pinger.pings.send(sample(u64::MAX)).unwrap();
        peer.finish();
    }
    release(&domain);
}

#[test]
fn a_killed_and_restarted_consumer_is_rung_again() {
    let domain = unique_domain("restart");
    {
        let pinger = Pinger::open(&domain);
        let first = Peer::spawn(&domain, "echo", "echo");
        pinger.wait_for_peer();
        pinger.round_trips(1, 100);
        let dead = subscribers(&pinger.factory_rt, PING);
        first.kill();
        // A ping to nobody: the dead peer's ports stay listed until someone cleans up.
        pinger.pings.send(sample(1000)).unwrap();

        let second = Peer::spawn(&domain, "echo", "echo");
        // The new peer removes the dead one's resources when it starts, then subscribes.
        let start = Instant::now();
        loop {
            let now = subscribers(&pinger.factory_rt, PING);
            if now.len() == 1 && now[0].0 != dead[0].0 {
                break;
            }
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "no new peer: {now:?}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        pinger.round_trips(2000, 100);
        pinger.pings.send(sample(u64::MAX)).unwrap();
        second.finish();
    }
    release(&domain);
}

#[test]
fn request_response_between_two_processes() {
    let domain = unique_domain("rr2");
    {
        let rt = Runtime::in_domain("client", domain.clone()).unwrap();
        let client = rt.client::<EncoderSample, EncoderSample>(ECHO).unwrap();
        let server = Peer::spawn(&domain, "server", "server");
        let start = Instant::now();
        let mut seq = 0;
        // Until the server exists, requests go nowhere.
        while client.send(sample(seq)).unwrap().is_none() {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "no server appeared"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        for _ in 0..300 {
            seq += 1;
            let started = Instant::now();
            let pending = client.send(sample(seq)).unwrap().expect("server connected");
            let response = client.receive(&pending, ROUND_TRIP_LIMIT).unwrap();
            assert_eq!(response.map(|r| r.seq), Some(seq + 1), "request {seq}");
            assert!(started.elapsed() < ROUND_TRIP_LIMIT);
        }
        let last = client.send(sample(u64::MAX)).unwrap().unwrap();
        let _ = client.receive(&last, ROUND_TRIP_LIMIT).unwrap();
        server.finish();
    }
    release(&domain);
}

/// A server on another thread wakes the client with a sample just before it answers, so the
/// client looks for the response while the server is sending it and letting go of the
/// request: every response must still arrive, none may be taken for a server gone away.
#[test]
fn a_response_sent_as_the_server_lets_go_is_received() {
    const REQUESTS: u64 = 3000;
    let domain = unique_domain("rr-race");
    std::thread::scope(|scope| {
        let server_domain = domain.clone();
        scope.spawn(move || {
            let mut rt = Runtime::in_domain("server", server_domain).unwrap();
            let server = rt.server::<EncoderSample, EncoderSample>(ECHO).unwrap();
            let nudge = rt.publisher::<EncoderSample>(PING).unwrap();
            let mut answered = 0;
            rt.run_on_data(&[&server], PEER_IDLE, |ctx| {
                if !ctx.woke_on_data() {
                    ctx.stop();
                }
                nudge.send(sample(answered))?;
                // A varying head start for the woken client, up to a few microseconds.
                let head_start = Instant::now();
                while head_start.elapsed() < Duration::from_nanos(answered % 16 * 300) {
                    std::hint::spin_loop();
                }
                answered += server.answer(|request| sample(request.seq + 1))?.sent as u64;
                if answered == REQUESTS {
                    ctx.stop();
                }
                Ok::<_, sabr_node::NodeError>(())
            })
            .unwrap();
        });
        let rt = Runtime::in_domain("client", domain.clone()).unwrap();
        let nudges = rt.subscriber::<EncoderSample>(PING).unwrap();
        let client = rt.client::<EncoderSample, EncoderSample>(ECHO).unwrap();
        let start = Instant::now();
        let mut seq = 0;
        while seq < REQUESTS {
            let Some(pending) = client.send(sample(seq)).unwrap() else {
                assert!(
                    start.elapsed() < Duration::from_secs(20),
                    "no server appeared"
                );
                std::thread::sleep(Duration::from_millis(1));
                continue;
            };
            let response = client.receive(&pending, ROUND_TRIP_LIMIT).unwrap();
            assert_eq!(response.map(|r| r.seq), Some(seq + 1), "request {seq}");
            nudges.drain(|_| {}).unwrap();
            seq += 1;
        }
    });
    release(&domain);
}
