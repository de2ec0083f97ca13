//! Building a graph's executables before launching it, when `sabr` runs from a cargo build of
//! this workspace.
//!
//! `cargo run --release -- launch FILE` builds only the `sabr` package; the service binaries a
//! launch file names are other packages of the workspace. So when the executables' directory is
//! a cargo output directory (`target/<profile>/`, marked by cargo's `.cargo-lock`) and the
//! workspace `sabr` was built from is still there, the launcher runs
//! `cargo build --profile <profile> --workspace --bin <exec>...` into that same target directory:
//! always under `cargo run` of this package (cargo only rebuilds what is stale), otherwise only
//! when an executable is missing. Anywhere else (an installed `sabr`, `--bin-dir`) nothing is
//! built and a missing executable stays the launch file's "not found" error.

use anyhow::Context;
use sabr_node::errln;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The directory of the `sabr` command's package in the workspace.
const SABR_PACKAGE_DIR: &str = "launch";

/// The workspace this launcher was compiled in: the nearest directory above its package whose
/// `Cargo.toml` declares the `[workspace]`.
fn workspace_root() -> Option<PathBuf> {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .skip(1)
        .find(|dir| {
            std::fs::read_to_string(dir.join("Cargo.toml"))
                .is_ok_and(|manifest| manifest.lines().any(|l| l.trim() == "[workspace]"))
        })
        .map(Path::to_path_buf)
}

/// True when cargo itself started this process as the `sabr` package of `root` (`cargo run`):
/// cargo sets `CARGO_MANIFEST_DIR` to the running package's directory. Other packages' tests
/// that start a launcher see their own directory there.
fn started_by_cargo_run(root: &Path) -> bool {
    std::env::var_os("CARGO_MANIFEST_DIR")
        .is_some_and(|dir| Path::new(&dir) == root.join(SABR_PACKAGE_DIR))
}

/// The bare executable names (no `/`) of the `[[node]]` entries of a launch file; nothing when
/// the file does not parse (loading it reports that, with line and column).
fn bare_executables(file: &Path) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(file) else {
        return Vec::new();
    };
    let Ok(table) = text.parse::<toml::Table>() else {
        return Vec::new();
    };
    let mut names: Vec<String> = table
        .get("node")
        .and_then(toml::Value::as_array)
        .into_iter()
        .flatten()
        .filter_map(|node| node.get("exec")?.as_str())
        .filter(|exec| !exec.is_empty() && !exec.contains('/'))
        .map(str::to_owned)
        .collect();
    names.sort();
    names.dedup();
    names
}

/// The cargo profile whose output directory is `bin_dir` (`target/release` → `release`,
/// `target/debug` → `dev`), when `bin_dir` is one.
fn cargo_profile(bin_dir: &Path) -> Option<String> {
    if !bin_dir.join(".cargo-lock").is_file() {
        return None;
    }
    match bin_dir.file_name()?.to_str()? {
        "debug" => Some("dev".to_owned()),
        name => Some(name.to_owned()),
    }
}

/// Builds the executables that launch file `file` names into `bin_dir` when `sabr` runs from a
/// cargo build of its workspace (see the module documentation); says what it runs on stderr.
/// Does nothing otherwise. A failed build is an error naming the command.
pub fn build_graph_executables(file: &Path, bin_dir: &Path) -> anyhow::Result<()> {
    let (Some(profile), Some(root)) = (cargo_profile(bin_dir), workspace_root()) else {
        return Ok(());
    };
    let executables = bare_executables(file);
    let missing: Vec<&str> = executables
        .iter()
        .filter(|exec| !bin_dir.join(exec).is_file())
        .map(String::as_str)
        .collect();
    if executables.is_empty() || (missing.is_empty() && !started_by_cargo_run(&root)) {
        return Ok(());
    }
    let target_dir = bin_dir
        .parent()
        .context("the executables' directory has no parent")?;
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut command = Command::new(&cargo);
    command
        .arg("build")
        .arg("--profile")
        .arg(&profile)
        .arg("--workspace")
        .arg("--manifest-path")
        .arg(root.join("Cargo.toml"))
        .arg("--target-dir")
        .arg(target_dir);
    for exec in &executables {
        command.arg("--bin").arg(exec);
    }
    let shown = format!(
        "cargo build --profile {profile} --workspace {}",
        executables
            .iter()
            .map(|e| format!("--bin {e}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    if missing.is_empty() {
        errln!("sabr launch: bringing the graph's executables up to date: {shown}");
    } else {
        errln!(
            "sabr launch: building the graph's executables ({} not built yet): {shown}",
            missing.join(", ")
        );
    }
    let status = match command.status() {
        Ok(status) => status,
        Err(error) => {
            errln!(
                "sabr launch: cannot run {} ({error}); launching with what is built",
                Path::new(&cargo).display()
            );
            return Ok(());
        }
    };
    anyhow::ensure!(
        status.success(),
        "building the graph's executables failed ({shown}: {status})"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_cargo_output_directories_have_a_profile() {
        let dir = tempfile::tempdir().unwrap();
        let release = dir.path().join("release");
        std::fs::create_dir(&release).unwrap();
        assert_eq!(cargo_profile(&release), None, "no .cargo-lock: not cargo's");
        std::fs::write(release.join(".cargo-lock"), "").unwrap();
        assert_eq!(cargo_profile(&release).as_deref(), Some("release"));
        let debug = dir.path().join("debug");
        std::fs::create_dir(&debug).unwrap();
        std::fs::write(debug.join(".cargo-lock"), "").unwrap();
        assert_eq!(cargo_profile(&debug).as_deref(), Some("dev"));
    }

    #[test]
    fn bare_executables_of_a_launch_file() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("graph.toml");
        std::fs::write(
            &file,
            "[[node]]\nname = \"a\"\nexec = \"sabr-rig\"\n\
             [[node]]\nname = \"b\"\nexec = \"./local-tool\"\n\
             [[node]]\nname = \"c\"\nexec = \"sabr-rig\"\n\
             [[node]]\nname = \"d\"\nexec = \"sabr-sync\"\n",
        )
        .unwrap();
        assert_eq!(bare_executables(&file), ["sabr-rig", "sabr-sync"]);
        std::fs::write(&file, "[[node]\n").unwrap();
        assert!(
            bare_executables(&file).is_empty(),
            "bad TOML: loading says why"
        );
    }

    #[test]
    fn the_workspace_is_found_above_the_launcher_and_holds_the_sabr_package() {
        let root = workspace_root().expect("the workspace of this source tree");
        assert!(root.join(SABR_PACKAGE_DIR).join("Cargo.toml").is_file());
        let manifest = std::fs::read_to_string(root.join(SABR_PACKAGE_DIR).join("Cargo.toml"));
        assert!(
            manifest.unwrap().contains("name = \"sabr\""),
            "{} is not the sabr package",
            root.join(SABR_PACKAGE_DIR).display()
        );
    }

    #[test]
    fn nothing_is_built_outside_a_cargo_output_directory() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("graph.toml");
        std::fs::write(&file, "[[node]]\nname = \"a\"\nexec = \"no-such-binary\"\n").unwrap();
        build_graph_executables(&file, dir.path()).unwrap();
        assert!(!dir.path().join("no-such-binary").exists());
    }
}
