//! The one exit convention of the eight services, seen from outside: a service that cannot
//! start says why on its standard output (`<service>: FAILED: <causes>`, what the launcher
//! shows for a `console` node) and in its log, and exits with status 1 — also when nobody
//! reads its standard output any more, where a `println!` would have panicked (status 101).

use sabr_integration_tests::SERVICES;
use std::process::{Command, Output, Stdio};

/// A domain name the node runtime refuses, so that every service fails at its start, before
/// any iceoryx2 resource exists.
const BAD_DOMAIN: &str = "not a domain";

/// Runs `sabr-<service>` in [`BAD_DOMAIN`], its standard output given by `stdout`.
fn run_failing(service: &str, stdout: Stdio) -> Output {
    Command::new(sabr_integration_tests::bin(&format!("sabr-{service}")))
        .env(sabr_node::DOMAIN_ENV, BAD_DOMAIN)
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(Stdio::piped())
        .output()
        .unwrap()
}

#[test]
fn a_service_that_cannot_start_says_why_and_exits_with_status_1() {
    for service in SERVICES {
        let output = run_failing(service, Stdio::piped());
        let stdout = String::from_utf8_lossy(&output.stdout);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{service}: {stderr}");
        assert!(
            stdout.starts_with(&format!(
                "{service}: FAILED: invalid domain \"{BAD_DOMAIN}\""
            )),
            "{service} printed {stdout:?}"
        );
        assert!(stderr.contains("ERROR"), "{service} logged {stderr:?}");
    }
}

#[test]
fn a_service_whose_reader_left_still_exits_with_its_own_status() {
    for service in SERVICES {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let output = run_failing(service, writer.into());
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{service}: {stderr}");
        assert!(!stderr.contains("panicked"), "{service}: {stderr}");
        assert!(
            stderr.contains(&format!("invalid domain \"{BAD_DOMAIN}\"")),
            "{service} logged {stderr:?}"
        );
    }
}
