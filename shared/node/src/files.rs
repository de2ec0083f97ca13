//! The files a domain keeps in `/dev/shm` and in the iceoryx2 root directory.

use crate::Domain;
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
