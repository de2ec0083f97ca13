//! The doorbell transport: an iceoryx2 service variant for the graph whose events wake
//! through a futex, and one inbound doorbell per process.
//!
//! Publish-subscribe and request-response payloads travel exactly as with `ipc::Service`
//! (same shared memory, connections, storages); only the event concept differs
//! ([`futex::FutexEvent`]). On it:
//!
//! - every process ([`crate::NodeRuntime`]) listens on one event service, its doorbell
//!   `sabr/graph/doorbell/<node id>` ([`sabr_msgs::services::GRAPH_DOORBELLS`]);
//! - every inbound port (subscriber, server, client) gets an event id of that doorbell and
//!   carries it in its iceoryx2 port name (`doorbell-<id>`), so any producer can read it from
//!   the service's dynamic config;
//! - a producer (publisher, client sending a request, server sending a response) rings, after
//!   each send, the doorbell of every consumer port's node with that port's event id
//!   ([`Ringer`]), highest real-time priority of the consumer's process first (on one core
//!   the first consumer rung above the producer runs before the next is rung): the consumer
//!   ports come from the service's dynamic config (node id and port name; read again before
//!   the ring when their number changes, and after it every 20 ms), the doorbells from the
//!   node ids. A consumer that restarts is a new node with a new doorbell; a dead one
//!   disappears from the dynamic config when iceoryx2 cleans up after it, and its doorbell
//!   with it;
//! - the consumer sleeps on its doorbell with a relative timeout (deadlines and heartbeats
//!   keep working) and drains the ports whose ids rang.
//!
//! A futex has no file descriptor, so a doorbell cannot join an iceoryx2 `WaitSet`: that is
//! why there is one per process and everything inbound rings it.

mod bell;
mod futex;

pub use bell::CONSUMERS_REFRESH;
pub(crate) use bell::{Bell, Inbox, Ringer};

use core::fmt::Debug;
use iceoryx2::prelude::ZeroCopySend;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::{
    arc_sync_policy, bag, dynamic_storage, hash, monitoring, reactor, resizable_shared_memory,
    serialize, shared_memory, static_storage, zero_copy_connection,
};

/// The graph's iceoryx2 service variant on the doorbell transport: `ipc::Service` with a
/// futex event instead of a Unix-datagram-socket event. Every process of a domain must use
/// the same variant (their event services are not compatible).
#[derive(Debug, Clone)]
pub struct Doorbell {}

impl iceoryx2::service::Service for Doorbell {
    type StaticStorage = static_storage::recommended::Ipc;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::PersistentIpc<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    type Event = futex::FutexEvent;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
        arc_sync_policy::single_threaded::SingleThreaded<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<Doorbell> for Doorbell {}
