//! Opening iceoryx2 event ports by service name: shared by the runtime, the transports and the
//! doorbell's request-response, so none of them reaches up into another for it.

use crate::NodeError;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::{ipc, ServiceName};

/// A notifier on the event service named `service` (stock transport).
pub(crate) fn notifier_on(
    node: &Node<ipc::Service>,
    service: &str,
) -> Result<Notifier<ipc::Service>, NodeError> {
    node.service_builder(&service_name(service)?)
        .event()
        .open_or_create()
        .map_err(|e| NodeError::port(service, "open event service", e))?
        .notifier_builder()
        .create()
        .map_err(|e| NodeError::port(service, "create notifier", e))
}

/// A listener on the event service named `service` (stock transport).
pub(crate) fn listener_on(
    node: &Node<ipc::Service>,
    service: &str,
) -> Result<Listener<ipc::Service>, NodeError> {
    node.service_builder(&service_name(service)?)
        .event()
        .open_or_create()
        .map_err(|e| NodeError::port(service, "open event service", e))?
        .listener_builder()
        .create()
        .map_err(|e| NodeError::port(service, "create listener", e))
}

pub(crate) fn service_name(service: &str) -> Result<ServiceName, NodeError> {
    ServiceName::new(service).map_err(|e| NodeError::port(service, "parse service name", e))
}
