//! Typed publish-subscribe ports that wake waiting subscribers through a paired event.

use crate::NodeError;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::{ipc, ZeroCopySend};
use std::fmt::Debug;
use std::time::{Duration, Instant};

/// What a message type must be to travel through the graph: every `sabr_msgs` type is one.
pub trait Message: Debug + ZeroCopySend + Copy + 'static {}
impl<T: Debug + ZeroCopySend + Copy + 'static> Message for T {}

/// The raw iceoryx2 client of a request-response service.
pub type Client<Req, Resp> = iceoryx2::port::client::Client<ipc::Service, Req, (), Resp, ()>;
/// The raw iceoryx2 server of a request-response service.
pub type Server<Req, Resp> = iceoryx2::port::server::Server<ipc::Service, Req, (), Resp, ()>;

/// Publishes `T` on a service and wakes every [`Subscriber`] of it that is waiting.
pub struct Publisher<T: Message> {
    port: iceoryx2::port::publisher::Publisher<ipc::Service, T, ()>,
    notifier: Notifier<ipc::Service>,
    service: String,
}

impl<T: Message> Publisher<T> {
    pub(crate) fn new(
        port: iceoryx2::port::publisher::Publisher<ipc::Service, T, ()>,
        notifier: Notifier<ipc::Service>,
        service: &str,
    ) -> Self {
        Self {
            port,
            notifier,
            service: service.to_owned(),
        }
    }

    /// Sends one sample to all subscribers and wakes them.
    pub fn send(&self, value: T) -> Result<(), NodeError> {
        self.port
            .send_copy(value)
            .map_err(|e| NodeError::port(&self.service, "send", e))?;
        self.notifier
            .notify()
            .map_err(|e| NodeError::port(&self.service, "notify", e))?;
        Ok(())
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

/// Receives `T` from a service; can block until data arrives, with a timeout.
pub struct Subscriber<T: Message> {
    port: iceoryx2::port::subscriber::Subscriber<ipc::Service, T, ()>,
    listener: Listener<ipc::Service>,
    service: String,
}

impl<T: Message> Subscriber<T> {
    pub(crate) fn new(
        port: iceoryx2::port::subscriber::Subscriber<ipc::Service, T, ()>,
        listener: Listener<ipc::Service>,
        service: &str,
    ) -> Self {
        Self {
            port,
            listener,
            service: service.to_owned(),
        }
    }

    /// The oldest unread sample, or `None` if there is none (never blocks).
    pub fn try_recv(&self) -> Result<Option<T>, NodeError> {
        let sample = self
            .port
            .receive()
            .map_err(|e| NodeError::port(&self.service, "receive", e))?;
        Ok(sample.map(|s| *s.payload()))
    }

    /// Hands every unread sample, oldest first, to `f`; returns how many there were.
    pub fn drain(&self, mut f: impl FnMut(T)) -> Result<usize, NodeError> {
        let mut count = 0;
        while let Some(value) = self.try_recv()? {
            f(value);
            count += 1;
        }
        Ok(count)
    }

    /// The newest unread sample, dropping older unread ones.
    pub fn latest(&self) -> Result<Option<T>, NodeError> {
        let mut newest = None;
        self.drain(|value| newest = Some(value))?;
        Ok(newest)
    }

    /// The oldest unread sample, blocking up to `timeout` for one to arrive.
    ///
    /// Returns `None` on timeout and early on a termination signal (check
    /// [`crate::NodeRuntime::keep_running`]), so a dead publisher never blocks the caller forever.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<T>, NodeError> {
        let start = Instant::now();
        loop {
            if let Some(value) = self.try_recv()? {
                return Ok(Some(value));
            }
            let left = timeout.saturating_sub(start.elapsed());
            if left.is_zero() {
                return Ok(None);
            }
            match self.listener.timed_wait(|_| {}, left) {
                Ok(_) => {}
                // Interrupted by a signal: let the caller look at the stop request.
                Err(_) => return self.try_recv(),
            }
        }
    }

    /// Clears pending wake-ups (the data stays readable).
    pub(crate) fn clear_wakeups(&self) {
        // A failed wake-up drain only costs one spurious wake-up later.
        let _ = self.listener.try_wait(|_| {});
    }

    pub(crate) fn listener(&self) -> &Listener<ipc::Service> {
        &self.listener
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

/// A subscriber of any message type, for waiting on several at once
/// ([`crate::NodeRuntime::run_on_data`]).
pub trait Waitable {
    /// The event listener that fires when data arrives.
    #[doc(hidden)]
    fn wake_listener(&self) -> &Listener<ipc::Service>;
    /// Clears pending wake-ups after a wake.
    #[doc(hidden)]
    fn clear(&self);
}

impl<T: Message> Waitable for Subscriber<T> {
    fn wake_listener(&self) -> &Listener<ipc::Service> {
        self.listener()
    }

    fn clear(&self) {
        self.clear_wakeups();
    }
}
