//! How a node takes signals.
//!
//! - A signal that requests no stop — a SIGCONT, as a node gets when it is resumed after a
//!   SIGSTOP — cuts a node's system calls short (iceoryx2's signal handler catches it), but
//!   must neither stop the node nor shorten its sleep.
//! - A stop request (SIGINT) that arrives while a node works between two waits ends its loop,
//!   and stays visible to every later reader. iceoryx2 reads its signal flag when a wait
//!   begins, resets it and reports a termination request; the runtime must take that report
//!   as the stop, and keep it for [`sabr_node::termination_requested`], not look at the flag
//!   again and find it empty. A stop request is for the life of a process, so each of these
//!   tests runs in a process of its own: the test re-runs this binary with only itself
//!   selected.

use nix::sys::pthread::{pthread_kill, pthread_self};
use nix::sys::signal::{raise, Signal};
use sabr_msgs::{services, EncoderSample};
use sabr_node::iceoryx2::prelude::ipc;
use sabr_node::{
    release_domain, termination_requested, Domain, Exit, LoopCtx, NodeRuntime, Subscriber,
};
use std::convert::Infallible;
use std::process::Command;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Names the test a re-run process is for.
const CHILD_ENV: &str = "SABR_TEST_STOP_CHILD";
/// How many calls a loop gets before it stops itself, should the stop request be lost.
const FALLBACK_CALLS: u32 = 50;

/// Runs `body` in a new process of this test binary with only `test` selected.
fn in_own_process(test: &str, body: impl FnOnce()) {
    if std::env::var(CHILD_ENV).as_deref() == Ok(test) {
        body();
        return;
    }
    let output = Command::new(std::env::current_exe().unwrap())
        .args([test, "--exact", "--test-threads=1", "--nocapture"])
        .env(CHILD_ENV, test)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("1 passed"),
        "the test did not run: {stdout}"
    );
}

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

fn domain(test: &str) -> Domain {
    Domain::new(&format!("t-{test}-{}", std::process::id())).unwrap()
}

fn release(domain: &Domain) {
    let left = release_domain(domain);
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// A loop body that raises SIGINT in its first call and stops the loop itself in its
/// `FALLBACK_CALLS`-th, should the request be lost; counts its calls.
fn interrupt_first_call(
    calls: &mut u32,
) -> impl FnMut(&mut LoopCtx) -> Result<(), Infallible> + '_ {
    move |ctx| {
        *calls += 1;
        if *calls == 1 {
            raise(Signal::SIGINT).unwrap();
        }
        if *calls == FALLBACK_CALLS {
            ctx.stop();
        }
        Ok(())
    }
}

/// The loop ended at its next wait after the request, which every later reader still sees.
fn assert_stopped_by_the_request(exit: Exit, calls: u32) {
    assert_eq!(exit, Exit::Signal, "the stop request was lost");
    assert_eq!(calls, 1, "the loop worked on after the stop request");
    assert!(termination_requested(), "seen once, then forgotten");
}

#[test]
fn a_stop_requested_while_a_fixed_rate_loop_works_ends_it() {
    in_own_process(
        "a_stop_requested_while_a_fixed_rate_loop_works_ends_it",
        || {
            let domain = domain("stop-fixed");
            let mut rt = NodeRuntime::with_domain("worker", domain.clone()).unwrap();
            let mut calls = 0;
            let exit = rt
                .run_loop(Duration::from_millis(10), interrupt_first_call(&mut calls))
                .unwrap();
            assert_stopped_by_the_request(exit, calls);
            assert!(!rt.sleep(Duration::from_millis(10)));
            drop(rt);
            release(&domain);
        },
    );
}

#[test]
fn a_stop_requested_while_a_waitset_loop_works_ends_it() {
    in_own_process(
        "a_stop_requested_while_a_waitset_loop_works_ends_it",
        || {
            let domain = domain("stop-waitset");
            let mut rt = NodeRuntime::<ipc::Service>::in_domain("worker", domain.clone()).unwrap();
            let input = rt
                .subscriber::<EncoderSample>(services::ENCODER_SAMPLES)
                .unwrap();
            let mut calls = 0;
            let exit = rt
                .run_on_data(
                    &[&input],
                    Duration::from_millis(10),
                    interrupt_first_call(&mut calls),
                )
                .unwrap();
            assert_stopped_by_the_request(exit, calls);
            drop((input, rt));
            release(&domain);
        },
    );
}

#[test]
fn a_sleep_interrupted_by_a_signal_that_requests_no_stop_sleeps_on() {
    let domain = domain("sigcont");
    let mut rt = NodeRuntime::with_domain("sleeper", domain.clone()).unwrap();
    let poker = poke_this_thread();
    let sleep = Duration::from_millis(200);
    let start = Instant::now();
    assert!(rt.sleep(sleep), "a SIGCONT is no stop request");
    assert!(start.elapsed() >= sleep, "woke after {:?}", start.elapsed());
    poker.join().unwrap();
    assert!(rt.keep_running());
    assert!(!termination_requested());
    drop(rt);
    release(&domain);
}

#[test]
fn a_wait_for_data_interrupted_by_a_signal_that_requests_no_stop_waits_on() {
    let domain = domain("sigcont-data");
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
            Ok::<_, Infallible>(())
        })
        .unwrap();
    poker.join().unwrap();
    assert_eq!(exit, Exit::Stopped, "a SIGCONT is no stop request");
    assert!(
        (4..=6).contains(&idle_calls),
        "{idle_calls} idle calls in 200 ms"
    );
    assert!(!termination_requested());
    drop((subscriber, rt));
    release(&domain);
}
