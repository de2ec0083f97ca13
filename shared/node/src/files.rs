//! The files a domain keeps in `/dev/shm` and in the iceoryx2 root directory.

use crate::Domain;
use iceoryx2::node::Node;
use iceoryx2::prelude::ipc;
use std::path::PathBuf;

/// Every file of `domain` in `/dev/shm` and in the iceoryx2 root directory (sorted): after a
/// clean shutdown of the whole domain this is empty.
pub fn domain_files(domain: &Domain) -> Vec<PathBuf> {
    let prefix = domain.file_prefix();
    let config = domain.iceoryx_config();
    let root = PathBuf::from(config.global.root_path().to_string());
    let mut found = Vec::new();
    let mut stack = vec![PathBuf::from("/dev/shm"), root];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(path);
            } else if entry.file_name().to_string_lossy().starts_with(&prefix) {
                found.push(path);
            }
        }
    }
    found.sort();
    found
}

/// Removes what iceoryx2 keeps of `domain` once no node of it exists (alive or dead): the
/// per-domain node-counter segment `…global_mgmt`, which iceoryx2 never removes by itself.
/// Returns the files of the domain still left, which should be none.
///
/// Only the owner of the domain (the launcher, after its graph stopped) may call this: a node
/// starting at the same moment would lose its node counter.
pub fn release_domain(domain: &Domain) -> Vec<PathBuf> {
    let config = domain.iceoryx_config();
    let mut nodes = 0usize;
    let listed = Node::<ipc::Service>::list(&config, |_| {
        nodes += 1;
        iceoryx2::prelude::CallbackProgression::Continue
    });
    if listed.is_ok() && nodes == 0 {
        for file in domain_files(domain) {
            if file.to_string_lossy().ends_with(".global_mgmt") {
                if let Err(error) = std::fs::remove_file(&file) {
                    tracing::warn!(file = %file.display(), %error, "cannot remove");
                }
            }
        }
    }
    domain_files(domain)
}
