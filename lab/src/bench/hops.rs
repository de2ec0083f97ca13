//! The live-graph hops and their summary as ratios to the ping-pong baselines
//! measured in the same run.

use super::payload::{baseline_name, Payload, Transport};
use super::stats::{format_ns, Measurement};
use std::fmt::Write as _;

/// Goal: a hop's p99 is at most this many times the `iox2-event` round-trip p99.
pub const BLOCKING_P99_FACTOR: f64 = 2.0;

/// Goal: IK request → response p99 (ns).
pub const IK_ROUND_TRIP_P99_LIMIT_NS: u64 = 50_000;

/// Goal: one IK solve (ns), judged on the median batch of `compute/ik-glam` (the IK server's
/// solver).
pub const IK_SOLVE_LIMIT_NS: u64 = 2_000;

/// Goal: synchronizer exposure-time matching error p99 (ns).
pub const MATCHING_ERROR_P99_LIMIT_NS: u64 = 500_000;

/// Goal: CPU use of an idle process, in cores.
pub const IDLE_CPU_LIMIT_CORES: f64 = 0.05;

/// What a hop's p99 is compared with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Baseline {
    /// The `iox2-event` and `uds` round trips of this payload in the same run: the goal is
    /// p99 ≤ [`BLOCKING_P99_FACTOR`] × the `iox2-event` p99 and below the `uds` p99.
    PingPong(Payload),
    /// Not a transport latency (a time error): only the absolute limit applies.
    None,
}

/// A hop of the live graph and its goals.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HopSpec {
    /// Measurement name, `hop/<what>`.
    pub name: &'static str,
    /// What it is compared with.
    pub baseline: Baseline,
    /// Absolute p99 limit (ns), if the issue sets one.
    pub p99_limit_ns: Option<u64>,
}

/// Encoder sample published by `encoders` → received by a second subscriber (the bench).
pub const ENCODER_TO_SUBSCRIBER: &str = "hop/encoder-sample-to-subscriber";
/// Tracker frame arrival (stamped by `tracker`) → its matched sample received from `sync`.
pub const TRACKER_FRAME_TO_MATCHED: &str = "hop/tracker-frame-to-matched";
/// IK request → response at the client.
pub const IK_ROUND_TRIP: &str = "hop/ik-round-trip";
/// Motor setpoint published → the rig's tick that applies it.
pub const SETPOINT_TO_RIG: &str = "hop/setpoint-to-rig";
/// |sync's exposure time − the rig's true exposure time| of a tracker frame.
pub const MATCHING_ERROR: &str = "hop/matching-error";

/// The hops the benchmark measures, in the order printed.
pub const HOPS: [HopSpec; 5] = [
    HopSpec {
        name: ENCODER_TO_SUBSCRIBER,
        baseline: Baseline::PingPong(Payload::EncoderSample),
        p99_limit_ns: None,
    },
    HopSpec {
        name: TRACKER_FRAME_TO_MATCHED,
        baseline: Baseline::PingPong(Payload::TrackerFrame),
        p99_limit_ns: None,
    },
    HopSpec {
        name: IK_ROUND_TRIP,
        baseline: Baseline::PingPong(Payload::Ik),
        p99_limit_ns: Some(IK_ROUND_TRIP_P99_LIMIT_NS),
    },
    HopSpec {
        name: SETPOINT_TO_RIG,
        baseline: Baseline::PingPong(Payload::MotorSetpoint),
        p99_limit_ns: None,
    },
    HopSpec {
        name: MATCHING_ERROR,
        baseline: Baseline::None,
        p99_limit_ns: Some(MATCHING_ERROR_P99_LIMIT_NS),
    },
];

/// Whether one goal was met.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Met.
    Met,
    /// Not met.
    Missed,
    /// Cannot be judged; the reason.
    Unknown(String),
}

/// One goal of a hop and its outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct GoalCheck {
    /// The goal, e.g. `p99 ≤ 2× iox2-event`.
    pub goal: String,
    /// The outcome.
    pub outcome: Outcome,
}

/// One row of the summary table.
#[derive(Debug, Clone, PartialEq)]
pub struct RatioRow {
    /// Hop name.
    pub hop: &'static str,
    /// The hop's p99 (ns), or why it was not measured.
    pub p99_ns: Result<u64, String>,
    /// Hop p99 / `iox2-event` round-trip p99 of the same payload.
    pub vs_blocking: Option<f64>,
    /// Hop p99 / `uds` round-trip p99 of the same payload.
    pub vs_uds: Option<f64>,
    /// The goals and their outcomes (empty when not measured).
    pub goals: Vec<GoalCheck>,
}

/// The summary rows of every hop in [`HOPS`]: each hop found (by name) in `measured` is
/// compared with the matching round trips found there too; the rest are "not measured" with
/// `missing_reason`.
pub fn ratio_rows(measured: &[Measurement], missing_reason: &str) -> Vec<RatioRow> {
    HOPS.iter()
        .map(|spec| match measured.iter().find(|m| m.name == spec.name) {
            None => RatioRow {
                hop: spec.name,
                p99_ns: Err(missing_reason.to_owned()),
                vs_blocking: None,
                vs_uds: None,
                goals: Vec::new(),
            },
            Some(hop) => measured_row(spec, hop, measured),
        })
        .collect()
}

fn measured_row(spec: &HopSpec, hop: &Measurement, baselines: &[Measurement]) -> RatioRow {
    let p99 = hop.summary().p99;
    let mut goals = Vec::new();
    let (mut vs_blocking, mut vs_uds) = (None, None);
    if let Baseline::PingPong(payload) = spec.baseline {
        let baseline_p99 = |transport| {
            let name = baseline_name(transport, payload);
            baselines
                .iter()
                .find(|m| m.name == name)
                .map(|m| m.summary().p99)
                .filter(|&p99| p99 > 0)
                .ok_or(name)
        };
        let blocking = baseline_p99(Transport::IoxEvent);
        vs_blocking = blocking.as_ref().ok().map(|&b| p99 as f64 / b as f64);
        goals.push(GoalCheck {
            goal: format!("≤ {BLOCKING_P99_FACTOR}× iox2-event"),
            outcome: match (&blocking, vs_blocking) {
                (Ok(_), Some(ratio)) if ratio <= BLOCKING_P99_FACTOR => Outcome::Met,
                (Ok(_), _) => Outcome::Missed,
                (Err(name), _) => Outcome::Unknown(format!("{name} not measured")),
            },
        });
        let uds = baseline_p99(Transport::Uds);
        vs_uds = uds.as_ref().ok().map(|&u| p99 as f64 / u as f64);
        goals.push(GoalCheck {
            goal: "< uds".to_owned(),
            outcome: match (&uds, vs_uds) {
                (Ok(_), Some(ratio)) if ratio < 1.0 => Outcome::Met,
                (Ok(_), _) => Outcome::Missed,
                (Err(name), _) => Outcome::Unknown(format!("{name} not measured")),
            },
        });
    }
    if let Some(limit) = spec.p99_limit_ns {
        goals.push(GoalCheck {
            goal: format!("≤ {}", format_ns(limit)),
            outcome: if p99 <= limit {
                Outcome::Met
            } else {
                Outcome::Missed
            },
        });
    }
    RatioRow {
        hop: spec.name,
        p99_ns: Ok(p99),
        vs_blocking,
        vs_uds,
        goals,
    }
}

/// The printed summary table of [`ratio_rows`].
pub fn ratio_table(rows: &[RatioRow]) -> String {
    let mut text = format!(
        "{:<33} {:>12} {:>14} {:>8}  goals (p99)\n",
        "hop", "p99", "×iox2-event", "×uds"
    );
    let ratio = |r: Option<f64>| r.map_or("-".to_owned(), |r| format!("{r:.2}"));
    for row in rows {
        match &row.p99_ns {
            Err(reason) => {
                let _ = writeln!(text, "{:<33} not measured: {reason}", row.hop);
            }
            Ok(p99) => {
                let goals: Vec<String> = row
                    .goals
                    .iter()
                    .map(|check| match &check.outcome {
                        Outcome::Met => format!("{}: met", check.goal),
                        Outcome::Missed => format!("{}: MISSED", check.goal),
                        Outcome::Unknown(why) => format!("{}: unknown ({why})", check.goal),
                    })
                    .collect();
                let _ = writeln!(
                    text,
                    "{:<33} {:>12} {:>14} {:>8}  {}",
                    row.hop,
                    format_ns(*p99),
                    ratio(row.vs_blocking),
                    ratio(row.vs_uds),
                    goals.join("; ")
                );
            }
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(name: &str, value: u64) -> Measurement {
        let mut m = Measurement::new(name, "ns");
        for _ in 0..100 {
            m.record(value).unwrap();
        }
        m
    }

    fn hop(index: usize, p99: u64) -> Measurement {
        constant(HOPS[index].name, p99)
    }

    #[test]
    fn ratios_divide_the_hop_p99_by_the_matching_baselines() {
        let measured = [
            constant("iox2-event/encoder-sample", 1000),
            constant("uds/encoder-sample", 1500),
            constant("iox2-event/tracker-frame", 100),
            hop(0, 1800),
            hop(1, 400),
        ];
        let rows = ratio_rows(&measured, "no graph");
        assert_eq!(rows.len(), HOPS.len());

        assert_eq!(rows[0].p99_ns, Ok(1800));
        assert_eq!(rows[0].vs_blocking, Some(1.8));
        assert_eq!(rows[0].vs_uds, Some(1.2));
        assert_eq!(rows[0].goals[0].outcome, Outcome::Met);
        assert_eq!(rows[0].goals[1].outcome, Outcome::Missed);

        assert_eq!(rows[1].vs_blocking, Some(4.0));
        assert_eq!(rows[1].goals[0].outcome, Outcome::Missed);
        assert_eq!(
            rows[1].goals[1].outcome,
            Outcome::Unknown("uds/tracker-frame not measured".into())
        );

        assert_eq!(rows[2].p99_ns, Err("no graph".into()));
        assert!(rows[2].goals.is_empty());
    }

    #[test]
    fn absolute_limits_apply_with_and_without_baseline() {
        let measured = [
            hop(2, 60_000),
            constant("iox2-event/ik", 40_000),
            constant("uds/ik", 90_000),
            hop(4, 400_000),
        ];
        let rows = ratio_rows(&measured, "-");
        let ik = &rows[2];
        // Above 2048 ns the histogram keeps 3 significant digits.
        let ratio = ik.vs_blocking.unwrap();
        assert!((ratio - 1.5).abs() < 1e-3, "{ratio}");
        assert_eq!(ik.goals.len(), 3);
        assert_eq!(ik.goals[2].goal, "≤ 50.000 µs");
        assert_eq!(ik.goals[2].outcome, Outcome::Missed);
        let matching = &rows[4];
        assert_eq!(matching.vs_blocking, None);
        assert_eq!(matching.goals.len(), 1);
        assert_eq!(matching.goals[0].outcome, Outcome::Met);
    }

    #[test]
    fn table_shows_ratios_and_reasons() {
        let measured = [
            constant("iox2-event/encoder-sample", 1000),
            constant("uds/encoder-sample", 3000),
            hop(0, 1500),
        ];
        let table = ratio_table(&ratio_rows(&measured, "graph not running"));
        let lines: Vec<&str> = table.lines().collect();
        assert!(
            lines[1].starts_with("hop/encoder-sample-to-subscriber"),
            "{table}"
        );
        assert!(
            lines[1].contains(" 1.50 ") && lines[1].contains(" 0.50 "),
            "{table}"
        );
        assert!(
            lines[1].contains("≤ 2× iox2-event: met; < uds: met"),
            "{table}"
        );
        assert!(
            lines[2].ends_with("not measured: graph not running"),
            "{table}"
        );
    }
}
