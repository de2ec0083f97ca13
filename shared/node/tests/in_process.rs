//! In-process checks of the runtime's ports, lifecycle and cleanup, each in its own domain.

use sabr_msgs::{services, EncoderSample, LifecycleState};
use sabr_node::{
    domain_files, release_domain, Domain, Exit, GraphObserver, NodeRuntime, Publisher, Subscriber,
};
use std::time::{Duration, Instant};

fn unique_domain(test: &str) -> Domain {
    Domain::new(&format!("t-{test}-{}", std::process::id())).unwrap()
}

/// Leaves the domain as found once every node of the test is gone.
fn release(domain: &Domain) {
    let left = release_domain(domain);
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// A publisher and a subscriber of the encoder samples, both ports of `rt`.
fn encoder_ports(rt: &NodeRuntime) -> (Publisher<EncoderSample>, Subscriber<EncoderSample>) {
    let publisher = rt.publisher(services::ENCODER_SAMPLES).unwrap();
    let subscriber = rt.subscriber(services::ENCODER_SAMPLES).unwrap();
    (publisher, subscriber)
}

#[test]
fn samples_flow_and_a_silent_publisher_times_out() {
    let domain = unique_domain("flow");
    let rt = NodeRuntime::with_domain("producer", domain.clone()).unwrap();
    let (publisher, subscriber) = encoder_ports(&rt);
    let sample = EncoderSample {
        seq: 7,
        t_ns: sabr_node::monotonic_ns(),
        counts: [1, -2, 3, -4, 5],
    };
    publisher.send(sample).unwrap();
    let received = subscriber.recv_timeout(Duration::from_secs(1)).unwrap();
    assert_eq!(received, Some(sample));

    let start = Instant::now();
    let nothing = subscriber.recv_timeout(Duration::from_millis(50)).unwrap();
    assert_eq!(nothing, None);
    assert!(start.elapsed() >= Duration::from_millis(50));
    drop((publisher, subscriber, rt));
    release(&domain);
}

/// The publisher keeps one sample loaned for its next message: a send must use or give back
/// every loan it holds. A lost loan would exhaust the loans iceoryx2 grants (a send fails) and
/// keep the service's shared memory alive after the ports are gone (`release` finds it).
#[test]
fn a_publisher_loaning_ahead_never_runs_out_of_samples() {
    let domain = unique_domain("loan-ahead");
    let rt = NodeRuntime::with_domain("producer", domain.clone()).unwrap();
    let publisher = rt
        .publisher::<EncoderSample>(services::ENCODER_SAMPLES)
        .unwrap();
    let slow = rt
        .subscriber::<EncoderSample>(services::ENCODER_SAMPLES)
        .unwrap();
    let keeping_up = rt
        .subscriber::<EncoderSample>(services::ENCODER_SAMPLES)
        .unwrap();
    let sample = |seq| EncoderSample {
        seq,
        t_ns: 0,
        counts: [0; 5],
    };
    const SENDS: u64 = 1_000;
    for seq in 0..SENDS {
        publisher
            .send(sample(seq))
            .unwrap_or_else(|e| panic!("send {seq}: {e}"));
        assert_eq!(keeping_up.try_recv().unwrap(), Some(sample(seq)));
    }
    // The slow subscriber read nothing: its buffer overflowed, keeping the newest samples.
    let mut kept = Vec::new();
    slow.drain(|received| kept.push(received.seq)).unwrap();
    assert!(!kept.is_empty());
    assert_eq!(kept.last(), Some(&(SENDS - 1)));
    assert!(
        kept.windows(2).all(|pair| pair[1] == pair[0] + 1),
        "{kept:?}"
    );
    drop((publisher, slow, keeping_up, rt));
    release(&domain);
}

/// Warming a publisher touches what its next send uses and nothing else: it sends nothing,
/// leaves what was sent alone, and keeps one loan however often it is warmed (a lost loan
/// would exhaust the loans iceoryx2 grants, and the next send would fail).
#[test]
fn a_warmed_publisher_sends_nothing_and_keeps_one_loan() {
    let domain = unique_domain("warm");
    let rt = NodeRuntime::with_domain("producer", domain.clone()).unwrap();
    let (publisher, subscriber) = encoder_ports(&rt);
    for _ in 0..1_000 {
        publisher.warm();
    }
    assert_eq!(subscriber.try_recv().unwrap(), None);
    let sample = EncoderSample {
        seq: 3,
        t_ns: 42,
        counts: [5, 4, 3, 2, 1],
    };
    publisher.send(sample).unwrap();
    publisher.warm();
    assert_eq!(subscriber.try_recv().unwrap(), Some(sample));
    assert_eq!(subscriber.try_recv().unwrap(), None);
    drop((publisher, subscriber, rt));
    release(&domain);
}

/// A pre-wake on transport `S` wakes a waiting subscriber as a send does, with nothing to
/// read; the next send is read on the next wake-up.
fn a_prewake_wakes_the_subscribers_without_a_message<S: sabr_node::Transport>(test: &str) {
    let domain = unique_domain(test);
    {
        let mut rt = NodeRuntime::<S>::in_domain("consumer", domain.clone()).unwrap();
        let publisher = rt.publisher::<EncoderSample>("sabr/test/slow").unwrap();
        let subscriber = rt.subscriber::<EncoderSample>("sabr/test/slow").unwrap();
        publisher.prewake().unwrap();
        // (tick, woke on data, the subscriber rang, samples read)
        let mut calls = Vec::new();
        // Idle calls come 10 s apart: without the rings, the first call would be an idle one
        // (woke on data false), 10 s late.
        rt.run_on_data(&[&subscriber], Duration::from_secs(10), |ctx| {
            let mut read = Vec::new();
            if ctx.woken_by(&subscriber) {
                subscriber.drain(|sample| read.push(sample.seq))?;
            }
            calls.push((
                ctx.tick(),
                ctx.woke_on_data(),
                ctx.woken_by(&subscriber),
                read,
            ));
            match ctx.tick() {
                0 => publisher.send(EncoderSample {
                    seq: 7,
                    ..Default::default()
                })?,
                _ => ctx.stop(),
            }
            Ok::<_, sabr_node::NodeError>(())
        })
        .unwrap();
        assert_eq!(calls, [(0, true, true, vec![]), (1, true, true, vec![7])]);
    }
    release(&domain);
}

#[test]
fn a_prewake_wakes_the_subscribers_without_a_message_on_the_doorbell() {
    a_prewake_wakes_the_subscribers_without_a_message::<sabr_node::Doorbell>("prewake-doorbell");
}

#[test]
fn a_prewake_wakes_the_subscribers_without_a_message_on_iceoryx2_events() {
    a_prewake_wakes_the_subscribers_without_a_message::<iceoryx2::prelude::ipc::Service>(
        "prewake-events",
    );
}

/// Publishers that go away leave their unread samples to the subscriber: it keeps their
/// connections (its expired-connection buffer) until it has read them, as many as can be
/// connected at once.
#[test]
fn samples_of_publishers_that_went_away_are_still_received() {
    let domain = unique_domain("departed");
    let rt = NodeRuntime::with_domain("consumer", domain.clone()).unwrap();
    let subscriber = rt
        .subscriber::<EncoderSample>(services::ENCODER_SAMPLES)
        .unwrap();
    let publishers: Vec<_> = (0..domain
        .iceoryx_config()
        .defaults
        .publish_subscribe
        .max_publishers)
        .map(|_| {
            rt.publisher::<EncoderSample>(services::ENCODER_SAMPLES)
                .unwrap()
        })
        .collect();
    // The subscriber connects to every publisher (nothing sent yet).
    assert_eq!(subscriber.try_recv().unwrap(), None);
    for (seq, publisher) in (0..).zip(&publishers) {
        let sample = EncoderSample {
            seq,
            t_ns: 0,
            counts: [0; 5],
        };
        publisher.send(sample).unwrap();
    }
    let sent = publishers.len() as u64;
    drop(publishers);
    let mut received = Vec::new();
    subscriber
        .drain(|sample| received.push(sample.seq))
        .unwrap();
    received.sort_unstable();
    assert_eq!(received, (0..sent).collect::<Vec<_>>());
    drop((subscriber, rt));
    release(&domain);
}

#[test]
fn run_on_data_wakes_on_samples_and_idles_without() {
    let domain = unique_domain("wake");
    let mut rt = NodeRuntime::with_domain("consumer", domain.clone()).unwrap();
    let publisher = rt
        .publisher::<EncoderSample>(services::ENCODER_SAMPLES)
        .unwrap();
    let subscriber = rt
        .subscriber::<EncoderSample>(services::ENCODER_SAMPLES)
        .unwrap();
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
                // The first call is an idle timeout; then send one sample per call.
                0..=2 => publisher.send(EncoderSample {
                    seq: ctx.tick(),
                    ..Default::default()
                })?,
                _ => ctx.stop(),
            }
            Ok::<_, sabr_node::NodeError>(())
        })
        .unwrap();
    assert_eq!(exit, Exit::Stopped);
    assert_eq!(seen, vec![0, 1, 2]);
    assert_eq!(idle_calls, 1);
    drop((publisher, subscriber, rt));
    release(&domain);
}

#[test]
fn observer_sees_lifecycle_and_a_clean_exit_leaves_no_files() {
    let domain = unique_domain("life");
    assert!(domain_files(&domain).is_empty(), "domain not fresh");
    {
        let observer = GraphObserver::new(&domain).unwrap();
        let mut rt = NodeRuntime::with_domain("worker", domain.clone()).unwrap();
        let mut states = Vec::new();
        let mut record = |m: sabr_msgs::Lifecycle| {
            assert_eq!(m.node.as_str(), "worker");
            assert_eq!(m.pid, std::process::id());
            states.push(m.state);
        };
        observer.poll(&mut record).unwrap();
        rt.ready();
        rt.finish_graph();
        observer.poll(&mut record).unwrap();
        drop(rt);
        observer.poll(&mut record).unwrap();
        assert_eq!(
            states,
            [
                LifecycleState::Starting,
                LifecycleState::Ready,
                LifecycleState::Done,
                LifecycleState::Stopping
            ]
        );
        assert!(
            !domain_files(&domain).is_empty(),
            "observer should own files"
        );
    }
    let left = release_domain(&domain);
    assert!(left.is_empty(), "left behind: {left:?}");
    assert!(domain_files(&domain).is_empty());
}

#[test]
fn a_domain_is_not_released_while_a_node_of_it_lives() {
    let domain = unique_domain("live");
    let rt = NodeRuntime::with_domain("alive", domain.clone()).unwrap();
    let left = release_domain(&domain);
    assert!(
        left.iter()
            .any(|file| file.to_string_lossy().ends_with(".global_mgmt")),
        "the node counter went while a node lives: {left:?}"
    );
    drop(rt);
    release(&domain);
}

/// A loop with two inputs, on transport `S`: a call woken by one input's sample reports that
/// input as rung and the other not; an idle call reports both (the body then looks at all).
fn run_on_data_tells_which_inputs_rang<S: sabr_node::Transport>(test: &str) {
    let domain = unique_domain(test);
    {
        let mut rt = NodeRuntime::<S>::in_domain("consumer", domain.clone()).unwrap();
        let to_a = rt.publisher::<EncoderSample>("sabr/test/a").unwrap();
        let to_b = rt.publisher::<EncoderSample>("sabr/test/b").unwrap();
        let from_a = rt.subscriber::<EncoderSample>("sabr/test/a").unwrap();
        let from_b = rt.subscriber::<EncoderSample>("sabr/test/b").unwrap();
        let sample = |seq| EncoderSample {
            seq,
            ..Default::default()
        };
        // (tick, woke on data, a rang, b rang)
        let mut calls = Vec::new();
        rt.run_on_data(&[&from_a, &from_b], Duration::from_millis(20), |ctx| {
            let (a, b) = (ctx.woken_by(&from_a), ctx.woken_by(&from_b));
            calls.push((ctx.tick(), ctx.woke_on_data(), a, b));
            // Read only what rang (and everything on the idle call), as a node does.
            if a {
                from_a.drain(|_| {})?;
            }
            if b {
                from_b.drain(|_| {})?;
            }
            match ctx.tick() {
                0 => to_a.send(sample(1))?,
                1 => to_b.send(sample(2))?,
                _ => ctx.stop(),
            }
            Ok::<_, sabr_node::NodeError>(())
        })
        .unwrap();
        assert_eq!(
            calls,
            [
                (0, false, true, true),
                (1, true, true, false),
                (2, true, false, true)
            ]
        );
        // Nothing was left unread.
        assert_eq!(from_a.try_recv().unwrap(), None);
        assert_eq!(from_b.try_recv().unwrap(), None);
    }
    release(&domain);
}

#[test]
fn run_on_data_tells_which_inputs_rang_on_the_doorbell() {
    run_on_data_tells_which_inputs_rang::<sabr_node::Doorbell>("rang-doorbell");
}

#[test]
fn run_on_data_tells_which_inputs_rang_on_iceoryx2_events() {
    run_on_data_tells_which_inputs_rang::<sabr_node::iceoryx2::prelude::ipc::Service>("rang-ipc");
}

/// With a loop phase, the periodic loop's calls fall that long after each multiple of its
/// period on `CLOCK_MONOTONIC`, whenever the loop starts. (A call can come late on a busy
/// machine, never early: the median offset from the phase is well inside the period.)
#[test]
fn run_loop_keeps_the_phase_it_is_given() {
    let domain = unique_domain("phase");
    let mut rt = NodeRuntime::with_domain("periodic", domain.clone()).unwrap();
    let period_ns = 20_000_000;
    let phase_ns = 7_000_000;
    rt.set_loop_phase(Some(Duration::from_nanos(phase_ns)));
    let mut offsets = Vec::new();
    let exit = rt
        .run_loop(Duration::from_nanos(period_ns), |ctx| {
            let now = sabr_node::monotonic_ns();
            offsets.push((now - phase_ns as i64).rem_euclid(period_ns as i64));
            if ctx.tick() == 10 {
                ctx.stop();
            }
            Ok::<_, std::convert::Infallible>(())
        })
        .unwrap();
    assert_eq!(exit, Exit::Stopped);
    offsets.sort_unstable();
    let median = offsets[offsets.len() / 2];
    assert!(
        median < period_ns as i64 / 4,
        "calls {median} ns after the phase (period {period_ns} ns): {offsets:?}"
    );
    drop(rt);
    release(&domain);
}

#[test]
fn a_loop_phase_from_the_launcher_is_whole_microseconds_below_one_second() {
    assert_eq!(
        sabr_node::parse_loop_phase("300").unwrap(),
        Duration::from_micros(300)
    );
    assert_eq!(
        sabr_node::parse_loop_phase("999999").unwrap(),
        Duration::from_micros(999_999)
    );
    for bad in ["1000000", "-5", "2.5", "", "soon"] {
        let error = sabr_node::parse_loop_phase(bad).unwrap_err().to_string();
        assert!(
            error.contains("SABR_LOOP_PHASE_US") && error.contains(&format!("{bad:?}")),
            "{error}"
        );
    }
}
