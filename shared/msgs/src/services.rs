//! Every iceoryx2 service name of the graph, in one place (`sabr/<producer>/<topic>`).
//!
//! Names are relative to the domain: the domain (env `SABR_DOMAIN`) is applied through the
//! iceoryx2 config prefix by `sabr-node`, so the same names are used in every domain.

/// Publish-subscribe [`crate::EncoderSample`] from `encoders` (1 kHz).
pub const ENCODER_SAMPLES: &str = "sabr/encoders/samples";
/// Publish-subscribe [`crate::TrackerFrame`] from `tracker` (20 Hz).
pub const TRACKER_FRAMES: &str = "sabr/tracker/frames";
/// Publish-subscribe [`crate::MatchedSample`] from `sync` (one per tracker frame).
pub const SYNC_MATCHED: &str = "sabr/sync/matched";
/// Publish-subscribe [`crate::MotorSetpoint`] from `motion` to the rig/motor drive (1 kHz).
pub const MOTION_SETPOINTS: &str = "sabr/motion/setpoints";
/// Publish-subscribe [`crate::MotionStatus`] from `motion`.
pub const MOTION_STATUS: &str = "sabr/motion/status";
/// Publish-subscribe [`crate::PhaseMark`] from `motion`, one per finished phase.
pub const MOTION_PHASES: &str = "sabr/motion/phases";
/// Request-response [`crate::IkRequest`] → [`crate::IkResponse`] served by `ik`.
pub const IK_SOLVE: &str = "sabr/ik/solve";
/// Publish-subscribe [`crate::ParameterSetAnnouncement`] from `calibrator`.
pub const CALIBRATOR_PARAMETERS: &str = "sabr/calibrator/parameters";
/// Publish-subscribe [`crate::RigTruth`] from the simulated rig (tests and benchmarks only).
pub const RIG_TRUTH: &str = "sabr/rig/truth";
/// Publish-subscribe [`crate::CounterLatch`] from the rig: the quadrature counter register
/// (≥ 1 kHz) that `encoders` samples.
pub const RIG_COUNTERS: &str = "sabr/rig/counters";
/// Publish-subscribe [`crate::PhaseMark`] from the rig when it plays the session plan itself
/// (`sabr-rig --autoplay`, no `motion` node), one per finished phase.
pub const RIG_PHASES: &str = "sabr/rig/phases";
/// Publish-subscribe [`crate::Lifecycle`] from every node to the launcher: readiness,
/// heartbeats, stopping, done.
pub const GRAPH_LIFECYCLE: &str = "sabr/graph/lifecycle";

/// Prefix of the event service that is one process's doorbell in a graph on the doorbell
/// transport (`sabr_node::Doorbell`): `<prefix>/<iceoryx2 node id in hex>`. Every producer
/// rings the doorbells of its consumers' nodes; each process waits on its own.
pub const GRAPH_DOORBELLS: &str = "sabr/graph/doorbell";

/// Publish-subscribe [`crate::EncoderSample`] used as a plain counter by the launcher's test
/// node (`sabr-test-node`); no production node uses it.
pub const TEST_COUNTER: &str = "sabr/test/counter";

/// Tracker frames a publisher keeps for late-joining subscribers: 10 s at 20 Hz, so a
/// restarted `sync` fits the tracker clock from the frames it missed instead of waiting for
/// new ones. Subscribers ask for it explicitly (`NodeRuntime::subscriber_with_history`).
pub const TRACKER_FRAMES_HISTORY: usize = 200;

/// How many past samples the publishers of a publish-subscribe service keep for subscribers
/// that connect later. Every process opens a service with this same value, so whichever opens
/// it first creates it right. One sample (the latest) unless a service needs more.
pub fn history_size(service: &str) -> usize {
    match service {
        TRACKER_FRAMES => TRACKER_FRAMES_HISTORY,
        _ => 1,
    }
}

/// All publish-subscribe and request-response services above, for listings and checks.
pub const ALL: [&str; 13] = [
    ENCODER_SAMPLES,
    TRACKER_FRAMES,
    SYNC_MATCHED,
    MOTION_SETPOINTS,
    MOTION_STATUS,
    MOTION_PHASES,
    IK_SOLVE,
    CALIBRATOR_PARAMETERS,
    RIG_TRUTH,
    RIG_COUNTERS,
    RIG_PHASES,
    GRAPH_LIFECYCLE,
    TEST_COUNTER,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_follow_the_scheme() {
        let mut seen = std::collections::HashSet::new();
        for name in ALL {
            assert!(seen.insert(name), "duplicate service name {name}");
            let parts: Vec<&str> = name.split('/').collect();
            assert_eq!(parts.len(), 3, "{name} is not sabr/<producer>/<topic>");
            assert_eq!(parts[0], "sabr");
            assert!(parts[1..].iter().all(|p| !p.is_empty()), "{name}");
        }
    }

    #[test]
    fn only_the_tracker_frames_keep_a_long_history() {
        for name in ALL {
            let expected = if name == TRACKER_FRAMES {
                TRACKER_FRAMES_HISTORY
            } else {
                1
            };
            assert_eq!(history_size(name), expected, "{name}");
        }
    }
}
