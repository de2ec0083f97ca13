//! The domain that isolates one running graph from every other, and the one iceoryx2 config.

use crate::NodeError;
use iceoryx2::config::Config;
use iceoryx2::prelude::{FileName, SemanticString};

/// Environment variable naming the domain of the graph (set by the launcher).
pub const DOMAIN_ENV: &str = "SABR_DOMAIN";
/// Domain used when [`DOMAIN_ENV`] is unset.
pub const DEFAULT_DOMAIN: &str = "sabr";
/// Longest accepted domain name, in bytes.
pub const MAX_DOMAIN_LEN: usize = 40;

/// A validated domain name: 1..=40 ASCII letters, digits or `-`.
///
/// Every iceoryx2 resource (shared memory, node and service files) of the domain is named with
/// the prefix [`Domain::file_prefix`], so graphs in different domains never see each other.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Domain(String);

impl Domain {
    /// Validates a domain name.
    pub fn new(name: &str) -> Result<Self, NodeError> {
        let reason = if name.is_empty() {
            Some("it is empty")
        } else if name.len() > MAX_DOMAIN_LEN {
            Some("it is longer than 40 bytes")
        } else if !name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-') {
            Some("only ASCII letters, digits and '-' are allowed")
        } else {
            None
        };
        match reason {
            Some(reason) => Err(NodeError::InvalidDomain {
                value: name.to_owned(),
                reason,
            }),
            None => Ok(Self(name.to_owned())),
        }
    }

    /// The domain from [`DOMAIN_ENV`], or [`DEFAULT_DOMAIN`] when it is unset.
    pub fn from_env() -> Result<Self, NodeError> {
        match std::env::var(DOMAIN_ENV) {
            Ok(name) => Self::new(&name),
            Err(std::env::VarError::NotPresent) => Self::new(DEFAULT_DOMAIN),
            Err(std::env::VarError::NotUnicode(_)) => Err(NodeError::InvalidDomain {
                value: format!("{:?}", std::env::var_os(DOMAIN_ENV)),
                reason: "it is not valid UTF-8",
            }),
        }
    }

    /// The domain name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Prefix of every iceoryx2 file of this domain (`<domain>_`), e.g. in `/dev/shm`.
    ///
    /// `_` cannot occur in a domain, so no domain's prefix is a prefix of another's.
    pub fn file_prefix(&self) -> String {
        format!("{}_", self.0)
    }

    /// The one iceoryx2 configuration every process of the domain uses.
    ///
    /// Built in code (no config file is read), so all processes agree: the domain prefix, dead
    /// node cleanup on node creation and service open, and port capacities sized for a 1 kHz
    /// stream read every few milliseconds by up to 16 subscribers.
    ///
    /// A receiving port (subscriber, client, server) keeps the connections of senders that went
    /// away with data still unread, up to its expired-connection buffer, and every receive that
    /// finds nothing scans all its connection slots, expired ones included. iceoryx2's default
    /// of 128 each made that scan the largest part of an empty receive. The buffers here hold at
    /// least as many departed senders as can be connected at once: twice the publishers of a
    /// subscriber and the servers of a client, the clients of a server (a sender that leaves
    /// beyond that is dropped with its unread data, logged by iceoryx2). Alternated quick
    /// benches on the development VM (2026-12-05): the IK round trip's transport part p50
    /// 8.7–9.5 µs against 9.1–10.6 µs with the defaults.
    pub fn iceoryx_config(&self) -> Config {
        let mut config = Config::default();
        // The prefix is at most 41 ASCII bytes, always a valid file name.
        if let Ok(prefix) = FileName::new(self.file_prefix().as_bytes()) {
            config.global.prefix = prefix;
        }
        config.global.node.cleanup_dead_nodes_on_creation = true;
        config.global.node.cleanup_dead_nodes_on_destruction = true;
        config.global.service.cleanup_dead_nodes_on_open = true;

        let pubsub = &mut config.defaults.publish_subscribe;
        pubsub.max_publishers = 4;
        pubsub.max_subscribers = 16;
        pubsub.max_nodes = 32;
        pubsub.subscriber_max_buffer_size = 256;
        pubsub.subscriber_max_borrowed_samples = 4;
        pubsub.publisher_max_loaned_samples = 4;
        pubsub.publisher_history_size = 1;
        pubsub.enable_safe_overflow = true;
        pubsub.subscriber_expired_connection_buffer = 2 * pubsub.max_publishers;

        let event = &mut config.defaults.event;
        event.max_listeners = 16;
        event.max_notifiers = 16;
        event.max_nodes = 32;

        let rr = &mut config.defaults.request_response;
        rr.max_clients = 16;
        rr.max_servers = 2;
        rr.max_nodes = 32;
        rr.client_expired_connection_buffer = 2 * rr.max_servers;
        rr.server_expired_connection_buffer = rr.max_clients;
        config
    }
}

impl std::fmt::Display for Domain {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_letters_digits_and_dashes() {
        let domain = Domain::new("test-42-abc").unwrap();
        assert_eq!(domain.file_prefix(), "test-42-abc_");
        let config = domain.iceoryx_config();
        assert_eq!(config.global.prefix.as_bytes(), b"test-42-abc_");
    }

    #[test]
    fn expired_connection_buffers_hold_every_sender_that_can_be_connected() {
        let config = Domain::new("test-buffers").unwrap().iceoryx_config();
        let pubsub = &config.defaults.publish_subscribe;
        assert!(pubsub.subscriber_expired_connection_buffer >= pubsub.max_publishers);
        // Below its max borrowed samples, iceoryx2 would replace the buffer size.
        assert!(
            pubsub.subscriber_expired_connection_buffer >= pubsub.subscriber_max_borrowed_samples
        );
        let rr = &config.defaults.request_response;
        assert!(rr.client_expired_connection_buffer >= rr.max_servers);
        assert!(rr.server_expired_connection_buffer >= rr.max_clients);
        // Far below iceoryx2's default (128), which every empty receive scanned.
        assert!(pubsub.subscriber_expired_connection_buffer <= 16);
        assert!(rr.client_expired_connection_buffer <= 16);
        assert!(rr.server_expired_connection_buffer <= 16);
    }

    #[test]
    fn rejects_empty_long_and_odd_names() {
        for bad in ["", "a_b", "a/b", "a b", &"x".repeat(MAX_DOMAIN_LEN + 1)] {
            let error = Domain::new(bad).unwrap_err();
            assert!(matches!(error, NodeError::InvalidDomain { .. }), "{bad:?}");
        }
    }
}
