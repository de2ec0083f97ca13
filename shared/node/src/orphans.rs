//! A repair of what iceoryx2 0.10's dead-node cleanup can leave behind.
//!
//! Cleaning up a killed node that had notifiers open on other nodes' event services (the
//! doorbell transport's producers hold one per consumer) makes iceoryx2 send a "dead node"
//! signal to each of those services through a short-lived helper node. That helper node can be
//! left half removed: its details file is gone, its monitor files, one service tag and a port tag remain,
//! and the service's dynamic configuration still counts it as an owner. `Node::list` reports it
//! dead for ever, and iceoryx2 cannot finish the job itself: for a node without details it
//! cleans up with the process's global configuration instead of the domain's and finds
//! nothing. This module finishes it with the domain's configuration: deregisters the node from
//! each service its tags name (which also removes the tags, and the service if it has no owner
//! left), then removes its remaining files (port tags, monitor files).

use crate::files::domain_files;
use crate::transport::Transport;
use crate::Domain;
use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::prelude::CallbackProgression;
use std::path::PathBuf;

/// Repairs every half-removed dead node of `domain` (dead, without details); returns how many.
pub(crate) fn remove_orphaned_nodes<S: Transport>(domain: &Domain) -> usize {
    let config = domain.iceoryx_config();
    let mut orphans = Vec::new();
    let listed = Node::<S>::list(&config, |state| {
        if let NodeState::Dead(view) = &state {
            if view.details().is_none() {
                orphans.push(*view.id());
            }
        }
        CallbackProgression::Continue
    });
    if listed.is_err() || orphans.is_empty() {
        return 0;
    }
    let mut services = Vec::new();
    let listed = S::list(&config, |details| {
        services.push(*details.static_details.service_hash());
        CallbackProgression::Continue
    });
    if listed.is_err() {
        return 0;
    }
    let files = domain_files(domain);
    let mut repaired = 0;
    for id in orphans {
        let id_text = id.value().to_string();
        let own: Vec<&PathBuf> = files
            .iter()
            .filter(|f| f.to_string_lossy().contains(&id_text))
            .collect();
        for tag in own
            .iter()
            .filter(|f| f.to_string_lossy().ends_with(".service_tag"))
        {
            let name = tag.file_name().map(|n| n.to_string_lossy().into_owned());
            let Some(hash) = services.iter().find(|hash| {
                name.as_deref()
                    .is_some_and(|n| n.contains(&hash.to_string()))
            }) else {
                // The service is gone: only the tag is left.
                let _ = std::fs::remove_file(tag);
                continue;
            };
            if let Err(error) = S::__internal_remove_node_from_service(&id, hash, &config) {
                tracing::debug!(node = %id_text, ?error, "cannot deregister a half-removed node");
            }
        }
        // What deregistering left: port tags of ports no service knew, the monitor files.
        let left: Vec<PathBuf> = domain_files(domain)
            .into_iter()
            .filter(|f| f.to_string_lossy().contains(&id_text))
            .collect();
        for file in &left {
            let _ = std::fs::remove_file(file);
        }
        if let Some(dir) = own
            .iter()
            .chain(left.iter().collect::<Vec<_>>().iter())
            .filter_map(|f| f.parent())
            .find(|dir| dir.ends_with(&id_text))
        {
            // Fails harmlessly while the directory still holds another domain's files.
            let _ = std::fs::remove_dir(dir);
        }
        tracing::info!(node = %id_text, "finished removing a half-removed dead node");
        repaired += 1;
    }
    repaired
}
