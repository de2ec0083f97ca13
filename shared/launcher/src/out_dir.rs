//! The output directory of a measuring command (`sabr bench`, `sabr soak`).

use anyhow::{bail, Context};
use std::path::PathBuf;

/// Creates `out`, or `runs/<kind>-<unix time>` when none is given, and returns its absolute
/// path. An existing directory must be empty: nothing already there is overwritten.
pub fn create_out_dir(out: Option<PathBuf>, kind: &str) -> anyhow::Result<PathBuf> {
    let dir = match out {
        Some(dir) => dir,
        None => {
            let seconds = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs());
            PathBuf::from("runs").join(format!("{kind}-{seconds}"))
        }
    };
    if dir.exists() {
        let mut entries = std::fs::read_dir(&dir)
            .with_context(|| format!("cannot read the output directory {}", dir.display()))?;
        if entries.next().is_some() {
            bail!(
                "{} is not empty: choose a new output directory",
                dir.display()
            );
        }
    }
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    dir.canonicalize()
        .with_context(|| format!("cannot resolve {}", dir.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn creates_an_absolute_empty_directory_and_refuses_a_used_one() {
        let parent = tempfile::tempdir().unwrap();
        let dir = create_out_dir(Some(parent.path().join("a/b")), "bench").unwrap();
        assert!(dir.is_absolute() && dir.is_dir(), "{}", dir.display());
        std::fs::write(dir.join("bench.csv"), "x").unwrap();
        let error = create_out_dir(Some(dir.clone()), "bench").unwrap_err();
        assert!(error.to_string().contains("is not empty"), "{error:#}");
        assert_eq!(std::fs::read_to_string(dir.join("bench.csv")).unwrap(), "x");
    }
}
