//! Request-response on the doorbell transport: a client rings the servers' doorbells with
//! each request and sleeps on its own doorbell for the answer; a server rings the doorbell of
//! the client each response goes to.

use crate::doorbell::{Doorbell, Inbox, Ringer};
use crate::events::service_name;
use crate::message::Message;
use crate::signals::termination_requested;
use crate::transport::Waitable;
use crate::{NodeError, NodeRuntime};
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::prelude::{CallbackProgression, PortFactory};
use iceoryx2::service::port_factory::request_response;
use std::time::{Duration, Instant};

/// The port factory of a request-response service on the doorbell transport.
type Factory<Req, Resp> = request_response::PortFactory<Doorbell, Req, (), Resp, ()>;

/// A request sent by a [`DoorbellClient`], waiting for its response.
pub type Pending<Req, Resp> = PendingResponse<Doorbell, Req, (), Resp, ()>;

impl NodeRuntime<Doorbell> {
    /// A client of a request-response service (e.g. `services::IK_SOLVE`).
    pub fn client<Req: Message, Resp: Message>(
        &self,
        service: &str,
    ) -> Result<DoorbellClient<Req, Resp>, NodeError> {
        let inbox = self.inbound().allocate()?;
        let factory = self.request_response::<Req, Resp>(service)?;
        let port = factory
            .client_builder()
            .name(inbox.port_name())
            .create()
            .map_err(|e| NodeError::port(service, "create client", e))?;
        Ok(DoorbellClient {
            port,
            inbox,
            servers: Ringer::new(self.shared_node(), service),
            factory,
            service: service.to_owned(),
        })
    }

    /// The server of a request-response service; an input of
    /// [`NodeRuntime::run_on_data`] (woken by every request).
    pub fn server<Req: Message, Resp: Message>(
        &self,
        service: &str,
    ) -> Result<DoorbellServer<Req, Resp>, NodeError> {
        let inbox = self.inbound().allocate()?;
        let factory = self.request_response::<Req, Resp>(service)?;
        let port = factory
            .server_builder()
            .name(inbox.port_name())
            .create()
            .map_err(|e| NodeError::port(service, "create server", e))?;
        Ok(DoorbellServer {
            port,
            inbox,
            clients: Ringer::new(self.shared_node(), service),
            factory,
            service: service.to_owned(),
        })
    }

    fn request_response<Req: Message, Resp: Message>(
        &self,
        service: &str,
    ) -> Result<Factory<Req, Resp>, NodeError> {
        self.node()
            .service_builder(&service_name(service)?)
            .request_response::<Req, Resp>()
            .open_or_create()
            .map_err(|e| NodeError::port(service, "open service", e))
    }
}

/// A client of a request-response service on the doorbell transport.
pub struct DoorbellClient<Req: Message, Resp: Message> {
    port: iceoryx2::port::client::Client<Doorbell, Req, (), Resp, ()>,
    inbox: Inbox,
    servers: Ringer,
    factory: Factory<Req, Resp>,
    service: String,
}

impl<Req: Message, Resp: Message> DoorbellClient<Req, Resp> {
    /// Sends `request` and rings every server's doorbell; `Ok(None)` if no server is
    /// connected (the request is dropped).
    pub fn send(&self, request: Req) -> Result<Option<Pending<Req, Resp>>, NodeError> {
        let pending = self
            .port
            .send_copy(request)
            .map_err(|e| NodeError::port(&self.service, "send a request", e))?;
        if pending.number_of_server_connections() == 0 {
            return Ok(None);
        }
        let config = self.factory.dynamic_config();
        self.servers
            .ring(config.number_of_servers(), None, |visit| {
                config.list_servers(|server| {
                    visit(
                        server.node_id,
                        &server.server_name,
                        server.server_id.value(),
                    );
                    CallbackProgression::Continue
                })
            })?;
        Ok(Some(pending))
    }

    /// The response to `pending`, sleeping on the doorbell up to `timeout` for it; `None`
    /// on timeout, on a termination signal, or when the server went away without answering.
    pub fn receive(
        &self,
        pending: &Pending<Req, Resp>,
        timeout: Duration,
    ) -> Result<Option<Resp>, NodeError> {
        let receive = || -> Result<Option<Resp>, NodeError> {
            let response = pending
                .receive()
                .map_err(|e| NodeError::port(&self.service, "receive a response", e))?;
            Ok(response.map(|response| *response.payload()))
        };
        let start = Instant::now();
        loop {
            if let Some(response) = receive()? {
                return Ok(Some(response));
            }
            let left = timeout.saturating_sub(start.elapsed());
            if left.is_zero() || !pending.is_connected() {
                // A server on another core may have answered and let go of the request
                // between the receive above and this check: look once more. (The receive
                // comes first because it also connects to a server that appeared since.)
                return receive();
            }
            if self.inbox.wait(left).is_err() && termination_requested() {
                // A stop request: let the caller look at it. (Another signal, a SIGCONT after
                // a SIGSTOP say, only cut the wait short.)
                return Ok(None);
            }
        }
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

/// How many requests one [`DoorbellServer::answer`] call answered.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Answered {
    /// Responses sent.
    pub sent: usize,
    /// Responses that could not be sent (the client left); each is logged.
    pub undelivered: usize,
}

/// The server of a request-response service on the doorbell transport.
pub struct DoorbellServer<Req: Message, Resp: Message> {
    port: iceoryx2::port::server::Server<Doorbell, Req, (), Resp, ()>,
    inbox: Inbox,
    clients: Ringer,
    factory: Factory<Req, Resp>,
    service: String,
}

impl<Req: Message, Resp: Message> DoorbellServer<Req, Resp> {
    /// Answers every waiting request with `answer(request)`, ringing each response's client.
    pub fn answer(&self, mut answer: impl FnMut(&Req) -> Resp) -> Result<Answered, NodeError> {
        let mut answered = Answered::default();
        while let Some(request) = self
            .port
            .receive()
            .map_err(|e| NodeError::port(&self.service, "receive a request", e))?
        {
            let response = answer(request.payload());
            if let Err(error) = request.send_copy(response) {
                answered.undelivered += 1;
                tracing::warn!(?error, service = %self.service, "cannot send a response");
                continue;
            }
            answered.sent += 1;
            let config = self.factory.dynamic_config();
            let origin = request.origin().value();
            self.clients
                .ring(config.number_of_clients(), Some(origin), |visit| {
                    config.list_clients(|client| {
                        visit(
                            client.node_id,
                            &client.client_name,
                            client.client_id.value(),
                        );
                        CallbackProgression::Continue
                    })
                })?;
        }
        Ok(answered)
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

impl<Req: Message, Resp: Message> Waitable<Doorbell> for DoorbellServer<Req, Resp> {
    fn wake_listener(&self) -> &Inbox {
        &self.inbox
    }
}
