//! A stop request (SIGINT) that arrives while a node works between two waits ends its loop,
//! and stays visible to every later reader.
//!
//! iceoryx2 reads its signal flag when a wait begins, resets it and reports a termination
//! request; the runtime must take that report as the stop, and keep it for
//! [`sabr_node::termination_requested`], not look at the flag again and find it empty.
//!
//! A stop request is for the life of a process, so each test runs in a process of its own:
//! the test re-runs this binary with only itself selected.

use nix::sys::signal::{raise, Signal};
use sabr_msgs::{services, EncoderSample};
use sabr_node::iceoryx2::prelude::ipc;
use sabr_node::{release_domain, termination_requested, Domain, Exit, LoopCtx, NodeRuntime};
use std::convert::Infallible;
use std::process::Command;
use std::time::Duration;

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
