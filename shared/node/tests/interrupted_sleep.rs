//! A signal that requests no stop — a SIGCONT, as a node gets when it is resumed after a
//! SIGSTOP — cuts a node's system calls short (iceoryx2's signal handler catches it), but must
//! neither stop the node nor shorten its sleep.

use nix::sys::pthread::{pthread_kill, pthread_self};
use nix::sys::signal::Signal;
use sabr_msgs::{services, EncoderSample};
use sabr_node::{release_domain, Domain, Exit, NodeRuntime, Subscriber};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A thread that sends the calling thread a SIGCONT every 20 ms, five times.
fn poke_this_thread() -> JoinHandle<()> {
    let target = pthread_self();
    std::thread::spawn(move || {
        for _ in 0..5 {
            std::thread::sleep(Duration::from_millis(20));
            pthread_kill(target, Signal::SIGCONT).unwrap();
        }
    })
}

fn release(domain: &Domain) {
    let left = release_domain(domain);
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn a_sleep_interrupted_by_a_signal_that_requests_no_stop_sleeps_on() {
    let domain = Domain::new(&format!("t-sigcont-{}", std::process::id())).unwrap();
    let mut rt = NodeRuntime::with_domain("sleeper", domain.clone()).unwrap();
    let poker = poke_this_thread();
    let sleep = Duration::from_millis(200);
    let start = Instant::now();
    assert!(rt.sleep(sleep), "a SIGCONT is no stop request");
    assert!(start.elapsed() >= sleep, "woke after {:?}", start.elapsed());
    poker.join().unwrap();
    assert!(rt.keep_running());
    assert!(!sabr_node::termination_requested());
    drop(rt);
    release(&domain);
}

#[test]
fn a_wait_for_data_interrupted_by_a_signal_that_requests_no_stop_waits_on() {
    let domain = Domain::new(&format!("t-sigcont-data-{}", std::process::id())).unwrap();
    let mut rt = NodeRuntime::with_domain("waiter", domain.clone()).unwrap();
    let subscriber: Subscriber<EncoderSample> = rt.subscriber(services::ENCODER_SAMPLES).unwrap();
    let poker = poke_this_thread();
    let start = Instant::now();
    let mut idle_calls = 0;
    let exit = rt
        .run_on_data(&[&subscriber], Duration::from_millis(50), |ctx| {
            idle_calls += 1;
            if start.elapsed() >= Duration::from_millis(200) {
                ctx.stop();
            }
            Ok::<_, std::convert::Infallible>(())
        })
        .unwrap();
    poker.join().unwrap();
    assert_eq!(exit, Exit::Stopped, "a SIGCONT is no stop request");
    assert!(
        (4..=6).contains(&idle_calls),
        "{idle_calls} idle calls in 200 ms"
    );
    assert!(!sabr_node::termination_requested());
    drop((subscriber, rt));
    release(&domain);
}
