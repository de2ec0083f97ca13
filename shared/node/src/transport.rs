//! How the processes of a graph wake each other: the [`Transport`] a [`crate::NodeRuntime`]
//! runs on.
//!
//! - `ipc::Service` (stock iceoryx2): every publish-subscribe service has a paired event
//!   service of the same name; each subscriber listens on its own, the loops wait on them in
//!   a `WaitSet` (the event is a Unix datagram socket).
//! - [`crate::Doorbell`]: one futex doorbell per process; producers ring their consumers'
//!   doorbells with the consumer port's event id (see [`crate::doorbell`]).

use crate::doorbell::{Bell, Doorbell, Inbox, Ringer};
use crate::events::{listener_on, notifier_on};
use crate::message::Message;
use crate::signals::note_termination_request;
use crate::NodeError;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::{
    ipc, CallbackProgression, PortFactory, PortName, WaitSetAttachmentId, WaitSetBuilder,
};
use iceoryx2::service::port_factory::publish_subscribe;
use iceoryx2::waitset::WaitSetRunResult;
use sealed::Waited;
use std::rc::Rc;
use std::time::Duration;

/// An iceoryx2 service variant a graph can run on (`ipc::Service` or [`crate::Doorbell`]).
/// Every process of a domain must use the same one.
pub trait Transport: sealed::Sealed {}

impl Transport for ipc::Service {}
impl Transport for Doorbell {}

/// An input of a main loop ([`crate::NodeRuntime::run_on_data`]): a subscriber of any message
/// type (or, on the doorbell transport, a server), for waiting on several at once.
pub trait Waitable<S: Transport = Doorbell> {
    /// How the input is woken: its event listener, or its event id of the doorbell.
    #[doc(hidden)]
    #[allow(private_interfaces)]
    fn wake_listener(&self) -> &S::Inbox;
    /// Takes the pending wake-ups after a wake (the data stays readable); true if there
    /// were any.
    #[doc(hidden)]
    fn take_ring(&self) -> bool {
        S::take_inbox(self.wake_listener())
    }
}

pub(crate) mod sealed {
    use super::*;

    /// What one wait of a main loop saw.
    #[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
    pub struct Waited {
        /// An input of the loop rang (its data may be read).
        pub data: bool,
    }

    /// The wake-up operations of a transport (not implementable outside this crate).
    pub trait Sealed:
        iceoryx2::service::Service + iceoryx2::service::internal::ServiceInternal<Self> + 'static
    {
        /// Per-process inbound state: nothing, or the process's doorbell.
        type Inbound: Clone;
        /// How a subscriber is woken: its own listener, or an event id of the doorbell.
        type Inbox;
        /// How a publisher wakes its subscribers: a notifier, or a doorbell ringer.
        type Wake;

        /// The process's inbound state, created once with the node.
        fn open_inbound(node: &Node<Self>) -> Result<Self::Inbound, NodeError>;

        /// The wake-up of a new subscriber of `service`.
        fn inbox(
            node: &Node<Self>,
            inbound: &Self::Inbound,
            service: &str,
        ) -> Result<Self::Inbox, NodeError>;

        /// The port name an inbound port must carry, if the transport needs one.
        fn port_name(inbox: &Self::Inbox) -> Option<&PortName>;

        /// The wake-up side of a new publisher of `service`.
        fn wake(node: &Rc<Node<Self>>, service: &str) -> Result<Self::Wake, NodeError>;

        /// Wakes the subscribers of `service` after a send.
        fn wake_subscribers<T: Message>(
            wake: &Self::Wake,
            service: &publish_subscribe::PortFactory<Self, T, ()>,
            name: &str,
        ) -> Result<(), NodeError>;

        /// Sleeps up to `timeout` for the inbox to be woken; `Err` on a signal.
        fn wait_inbox(inbox: &Self::Inbox, timeout: Duration) -> Result<(), ()>;

        /// Forgets pending wake-ups of the inbox; true if there were any.
        fn take_inbox(inbox: &Self::Inbox) -> bool;

        /// Calls `run` with a function that waits up to a timeout for any of `inputs`.
        fn with_waiter<R>(
            inbound: &Self::Inbound,
            inputs: &[&dyn Waitable<Self>],
            run: impl FnOnce(&mut dyn FnMut(Duration) -> Waited) -> R,
        ) -> Result<R, NodeError>
        where
            Self: Transport;
    }
}

impl sealed::Sealed for ipc::Service {
    type Inbound = ();
    type Inbox = Listener<ipc::Service>;
    type Wake = Notifier<ipc::Service>;

    fn open_inbound(_node: &Node<Self>) -> Result<(), NodeError> {
        Ok(())
    }

    fn inbox(node: &Node<Self>, _inbound: &(), service: &str) -> Result<Self::Inbox, NodeError> {
        listener_on(node, service)
    }

    fn port_name(_inbox: &Self::Inbox) -> Option<&PortName> {
        None
    }

    fn wake(node: &Rc<Node<Self>>, service: &str) -> Result<Self::Wake, NodeError> {
        notifier_on(node, service)
    }

    fn wake_subscribers<T: Message>(
        wake: &Self::Wake,
        _service: &publish_subscribe::PortFactory<Self, T, ()>,
        name: &str,
    ) -> Result<(), NodeError> {
        wake.notify()
            .map(drop)
            .map_err(|e| NodeError::port(name, "notify", e))
    }

    fn wait_inbox(inbox: &Self::Inbox, timeout: Duration) -> Result<(), ()> {
        inbox.timed_wait(|_| {}, timeout).map(drop).map_err(drop)
    }

    fn take_inbox(inbox: &Self::Inbox) -> bool {
        let mut rang = false;
        // A failed drain counts as a ring (the input is read) and costs one spurious wake-up
        // later.
        let drained = inbox.try_wait(|_| rang = true);
        rang || drained.is_err()
    }

    fn with_waiter<R>(
        _inbound: &(),
        inputs: &[&dyn Waitable<Self>],
        run: impl FnOnce(&mut dyn FnMut(Duration) -> Waited) -> R,
    ) -> Result<R, NodeError> {
        let waitset = WaitSetBuilder::new()
            .create::<ipc::Service>()
            .map_err(|e| NodeError::port("(waitset)", "create a WaitSet", e))?;
        let mut guards = Vec::with_capacity(inputs.len());
        for input in inputs {
            let guard = waitset
                .attach_notification(input.wake_listener())
                .map_err(|e| NodeError::port("(waitset)", "wait on an input", e))?;
            guards.push(guard);
        }
        let ids: Vec<WaitSetAttachmentId<ipc::Service>> =
            guards.iter().map(WaitSetAttachmentId::from_guard).collect();
        let mut wait = |timeout: Duration| {
            let mut waited = Waited::default();
            let result = waitset.wait_and_process_once_with_timeout(
                |id| {
                    waited.data |= ids.contains(&id);
                    CallbackProgression::Continue
                },
                timeout,
            );
            // A termination request or an interrupt returns like a timeout (the loop looks
            // at the stop request itself); a termination request the waitset read is kept.
            match result {
                Ok(WaitSetRunResult::TerminationRequest) => note_termination_request(),
                Ok(_) => {}
                Err(error) => tracing::warn!(?error, "WaitSet wait failed"),
            }
            waited
        };
        Ok(run(&mut wait))
    }
}

impl sealed::Sealed for Doorbell {
    type Inbound = Rc<Bell>;
    type Inbox = Inbox;
    type Wake = Ringer;

    fn open_inbound(node: &Node<Self>) -> Result<Rc<Bell>, NodeError> {
        Bell::open(node)
    }

    fn inbox(_node: &Node<Self>, bell: &Rc<Bell>, _service: &str) -> Result<Inbox, NodeError> {
        bell.allocate()
    }

    fn port_name(inbox: &Inbox) -> Option<&PortName> {
        Some(inbox.port_name())
    }

    fn wake(node: &Rc<Node<Self>>, service: &str) -> Result<Ringer, NodeError> {
        Ok(Ringer::new(node, service))
    }

    fn wake_subscribers<T: Message>(
        wake: &Ringer,
        service: &publish_subscribe::PortFactory<Self, T, ()>,
        _name: &str,
    ) -> Result<(), NodeError> {
        let config = service.dynamic_config();
        wake.ring(config.number_of_subscribers(), None, |visit| {
            config.list_subscribers(|details| {
                visit(
                    details.node_id,
                    &details.subscriber_name,
                    details.subscriber_id.value(),
                );
                CallbackProgression::Continue
            })
        })
        .map(drop)
    }

    fn wait_inbox(inbox: &Inbox, timeout: Duration) -> Result<(), ()> {
        inbox.wait(timeout).map(drop).map_err(drop)
    }

    fn take_inbox(inbox: &Inbox) -> bool {
        inbox.take()
    }

    fn with_waiter<R>(
        bell: &Rc<Bell>,
        inputs: &[&dyn Waitable<Self>],
        run: impl FnOnce(&mut dyn FnMut(Duration) -> Waited) -> R,
    ) -> Result<R, NodeError> {
        let wanted = inputs
            .iter()
            .fold(0, |mask, input| mask | input.wake_listener().mask());
        let mut wait = |timeout: Duration| {
            // An interrupted wait returns like a timeout (the loop looks at the stop request
            // itself).
            let _interrupted = bell.wait_for(wanted, timeout);
            Waited {
                data: bell.any_pending(wanted),
            }
        };
        Ok(run(&mut wait))
    }
}
