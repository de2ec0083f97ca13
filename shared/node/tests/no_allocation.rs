//! The doorbell transport adds no heap allocation to a send (publish, then ring the
//! subscriber's doorbell) beyond what iceoryx2's own `send_copy` makes, but for the re-read of
//! the consumer ports at most once per [`CONSUMERS_REFRESH`], and none to a receive: a
//! real-time loop's send does not wait on the allocator for our sake.

// A counting global allocator is an `unsafe impl GlobalAlloc` around the system one.
#![allow(unsafe_code)]

use sabr_msgs::EncoderSample;
use sabr_node::doorbell::CONSUMERS_REFRESH;
use sabr_node::iceoryx2::prelude::{ipc, NodeBuilder, ServiceName};
use sabr_node::{release_domain, Domain, Doorbell, NodeRuntime};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// The system allocator, counting allocations.
struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

/// Sends measured after the warm-up that connects the ports.
const SENDS: u64 = 5_000;

fn sample(seq: u64) -> EncoderSample {
    EncoderSample {
        seq,
        t_ns: 0,
        counts: [0; 5],
    }
}

/// Allocations made by `f`.
fn allocations(f: impl FnOnce()) -> u64 {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    f();
    ALLOCATIONS.load(Ordering::Relaxed) - before
}

/// The allocations of each of [`SENDS`] sends after a warm-up, with the time it started, and
/// the allocations of all their receives.
fn count(
    mut send: impl FnMut(u64),
    mut receive: impl FnMut() -> u64,
) -> (Vec<(u64, Instant)>, u64) {
    for seq in 0..10 {
        send(seq);
        receive();
    }
    let (mut sends, mut in_receives, mut received) = (Vec::with_capacity(SENDS as usize), 0, 0);
    for seq in 0..SENDS {
        let started = Instant::now();
        sends.push((allocations(|| send(seq)), started));
        in_receives += allocations(|| received += receive());
    }
    assert_eq!(received, SENDS);
    (sends, in_receives)
}

#[test]
fn the_doorbell_allocates_beyond_iceoryx2_only_to_reread_its_consumers() {
    let domain = Domain::new(&format!("d-noalloc-{}", std::process::id())).unwrap();
    {
        let node = NodeBuilder::new()
            .config(&domain.iceoryx_config())
            .create::<ipc::Service>()
            .unwrap();
        let service = node
            .service_builder(&ServiceName::new("sabr/test/plain").unwrap())
            .publish_subscribe::<EncoderSample>()
            .open_or_create()
            .unwrap();
        let publisher = service.publisher_builder().create().unwrap();
        let subscriber = service.subscriber_builder().create().unwrap();
        let (plain_sends, _) = count(
            |seq| {
                publisher.send_copy(sample(seq)).unwrap();
            },
            || {
                let mut received = 0;
                while subscriber.receive().unwrap().is_some() {
                    received += 1;
                }
                received
            },
        );

        let producer = NodeRuntime::<Doorbell>::in_domain("producer", domain.clone()).unwrap();
        let consumer = NodeRuntime::<Doorbell>::in_domain("consumer", domain.clone()).unwrap();
        let publisher = producer
            .publisher::<EncoderSample>("sabr/test/rung")
            .unwrap();
        let subscriber = consumer
            .subscriber::<EncoderSample>("sabr/test/rung")
            .unwrap();
        let (sends, receives) = count(
            |seq| publisher.send(sample(seq)).unwrap(),
            || {
                let mut received = 0;
                subscriber.drain(|_| received += 1).unwrap();
                received
            },
        );
        let most_per_send = plain_sends.iter().map(|(n, _)| *n).max().unwrap();
        // A send that allocated more than iceoryx2's most is one that re-read the consumer
        // ports: at most one per refresh period (less a margin for the time between a send's
        // start and its ring's clock reading).
        let rereads: Vec<&(u64, Instant)> =
            sends.iter().filter(|(n, _)| *n > most_per_send).collect();
        for pair in rereads.windows(2) {
            let apart = pair[1].1 - pair[0].1;
            assert!(
                apart >= CONSUMERS_REFRESH - Duration::from_millis(1),
                "doorbell sends allocated beyond iceoryx2's send_copy {apart:?} apart"
            );
        }
        assert!(
            rereads.len() < sends.len() / 100,
            "{} of {SENDS} sends allocated more than iceoryx2's",
            rereads.len()
        );
        // Every other allocation is iceoryx2's own, send for send.
        let total = |sends: &[(u64, Instant)]| sends.iter().map(|(n, _)| n).sum::<u64>();
        let reread_extra: u64 = rereads.iter().map(|(n, _)| n - most_per_send).sum();
        assert_eq!(
            total(&sends) - reread_extra,
            total(&plain_sends),
            "allocations in {SENDS} doorbell sends, re-reads aside, against iceoryx2's own \
             send_copy"
        );
        assert_eq!(receives, 0, "allocations in {SENDS} doorbell receives");
    }
    release_domain(&domain);
}
