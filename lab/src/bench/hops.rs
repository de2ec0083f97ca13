//! The live-graph hops and the transport goals, judged against the ping-pong baselines
//! measured in the same run.

use super::payload::{baseline_name, paced_name, Payload, Transport};
use super::stats::{format_ns, Measurement, Summary};
use std::fmt::Write as _;

/// Goal: an event-driven hop's p50 is at most this many times the raw futex round-trip p50
/// of its payload (placed as the shipped graph places that hop).
pub const FUTEX_P50_FACTOR: f64 = 2.0;

/// Goal: IK request → response p99 (ns).
pub const IK_ROUND_TRIP_P99_LIMIT_NS: u64 = 50_000;

/// Goal: one IK solve (ns), judged on the median batch of `compute/ik-glam` (the IK server's
/// solver).
pub const IK_SOLVE_LIMIT_NS: u64 = 2_000;

/// The rig's tick (ns): it applies the latest setpoint once per tick (2 kHz).
pub const RIG_PERIOD_NS: u64 = 500_000;

/// Goal: setpoint → rig p99 within one rig period plus this (ns).
pub const SETPOINT_SLACK_NS: u64 = 50_000;

/// Goal: synchronizer exposure-time matching error p99 (ns).
pub const MATCHING_ERROR_P99_LIMIT_NS: u64 = 500_000;

/// Goal: |mean signed matching error| (ns), the sync given the true tracker latency.
pub const MATCHING_ERROR_MEAN_LIMIT_NS: f64 = 100_000.0;

/// Goal: CPU use of an idle process, in cores.
pub const IDLE_CPU_LIMIT_CORES: f64 = 0.05;

/// What a hop is compared with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Baseline {
    /// An event-driven hop carrying this payload: the goals are p99 below the `uds` round-trip
    /// p99 and p50 within [`FUTEX_P50_FACTOR`] × the `futex` round-trip p50, both of this
    /// payload in the same run.
    PingPong(Payload),
    /// Paced by a timer or a time error: only the absolute limit applies.
    None,
}

/// A hop of the live graph and its goals.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HopSpec {
    /// Measurement name, `hop/<what>`.
    pub name: &'static str,
    /// What it is compared with.
    pub baseline: Baseline,
    /// Absolute p99 limit (ns), if there is one.
    pub p99_limit_ns: Option<u64>,
}

/// Encoder sample published by `encoders` → received by a second subscriber (the bench).
pub const ENCODER_TO_SUBSCRIBER: &str = "hop/encoder-sample-to-subscriber";
/// Tracker frame arrival (stamped by `tracker`) → its matched sample received from `sync`.
pub const TRACKER_FRAME_TO_MATCHED: &str = "hop/tracker-frame-to-matched";
/// [`TRACKER_FRAME_TO_MATCHED`] in parts, from the stamps a `MatchedSample` carries: the
/// tracker's work on the frame (`frame_sent_t_ns − arrival_t_ns`: parsing, the availability
/// estimate, converting).
pub const CHAIN_TRACKER_WORK: &str = "chain/tracker-work";
/// The frame's hop from the tracker's send to the sync's receipt (`frame_received_t_ns −
/// frame_sent_t_ns`).
pub const CHAIN_TRACKER_TO_SYNC: &str = "chain/tracker-to-sync";
/// The sync's work from the frame's receipt to its matched sample's send (`sent_t_ns −
/// frame_received_t_ns`: admitting, matching, building the sample).
pub const CHAIN_SYNC_WORK: &str = "chain/sync-work";
/// The matched sample's hop from the sync's send to the bench's receipt.
pub const CHAIN_SYNC_TO_SUBSCRIBER: &str = "chain/sync-to-subscriber";
/// [`CHAIN_TRACKER_WORK`] + [`CHAIN_SYNC_WORK`] of the same frame: the chain's work beyond
/// its two legs.
pub const CHAIN_WORK: &str = "chain/work";
/// IK request → response at the client.
pub const IK_ROUND_TRIP: &str = "hop/ik-round-trip";
/// [`IK_ROUND_TRIP`] minus the server's solve time of the same request (as its response
/// reports it): the round trip's transport part (the client's send and receive, the server's
/// receive and response, both wake-ups), judged against the same baselines. Not a goal of
/// its own; it tells the transport's share of a missed round-trip goal from the solver's.
pub const IK_TRANSPORT: &str = "hop/ik-transport";
/// The first request of each setpoint period of [`IK_ROUND_TRIP`]: the motion node sends its
/// IK requests in bursts, once per period, and the first of a burst finds the path (caches,
/// TLBs, the kernel's wake-up path) gone cold after a period of other work, where the rest
/// find it hot. Judged against the same baselines, not a goal of its own: it shows the cold
/// part of the round trip.
pub const IK_ROUND_TRIP_FIRST: &str = "hop/ik-round-trip-first";
/// The time the IK server reports having spent solving a request of [`IK_ROUND_TRIP`] (ns,
/// `IkResponse::solve_ns`): the solver as it runs in the live graph, between the other nodes.
pub const IK_SERVER_SOLVE: &str = "hop/ik-server-solve";
/// Motor setpoint published → the rig's tick that applies it.
pub const SETPOINT_TO_RIG: &str = "hop/setpoint-to-rig";
/// |sync's exposure time − the rig's true exposure time| of a tracker frame.
pub const MATCHING_ERROR: &str = "hop/matching-error";

/// The hops the benchmark measures, in the order printed.
pub const HOPS: [HopSpec; 7] = [
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
        name: IK_TRANSPORT,
        baseline: Baseline::PingPong(Payload::Ik),
        p99_limit_ns: None,
    },
    HopSpec {
        name: IK_ROUND_TRIP_FIRST,
        baseline: Baseline::PingPong(Payload::Ik),
        p99_limit_ns: None,
    },
    HopSpec {
        name: SETPOINT_TO_RIG,
        baseline: Baseline::None,
        p99_limit_ns: Some(RIG_PERIOD_NS + SETPOINT_SLACK_NS),
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

impl Outcome {
    /// Met if `met`, else missed.
    pub fn of(met: bool) -> Self {
        if met {
            Outcome::Met
        } else {
            Outcome::Missed
        }
    }
}

/// One goal and its outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct GoalCheck {
    /// The goal, e.g. `p99 < uds`.
    pub goal: String,
    /// The outcome.
    pub outcome: Outcome,
}

/// The printed verdict: `met`, `MISSED` or `unknown (why)`.
impl std::fmt::Display for Outcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Outcome::Met => f.write_str("met"),
            Outcome::Missed => f.write_str("MISSED"),
            Outcome::Unknown(why) => write!(f, "unknown ({why})"),
        }
    }
}

impl GoalCheck {
    /// `goal: met`, `goal: MISSED` or `goal: unknown (why)`.
    pub fn describe(&self) -> String {
        format!("{}: {}", self.goal, self.outcome)
    }
}

/// One row of the hop table.
#[derive(Debug, Clone, PartialEq)]
pub struct RatioRow {
    /// Hop name.
    pub hop: &'static str,
    /// The hop's p50 and p99 (ns), or why it was not measured.
    pub p50_p99_ns: Result<(u64, u64), String>,
    /// Hop p50 / `futex` round-trip p50 of the same payload.
    pub p50_vs_futex: Option<f64>,
    /// Hop p50 / `futex-paced` round-trip p50 of the same payload: against a floor that goes
    /// cold at the hop's rate (no goal; it shows how much of the first ratio a cold path
    /// explains).
    pub p50_vs_paced_futex: Option<f64>,
    /// Hop p99 / `uds` round-trip p99 of the same payload.
    pub p99_vs_uds: Option<f64>,
    /// The goals and their outcomes (empty when not measured).
    pub goals: Vec<GoalCheck>,
}

/// The summary of the baseline `transport/payload` in `measured`, or its name if absent.
fn baseline(
    measured: &[Measurement],
    transport: Transport,
    payload: Payload,
) -> Result<Summary, String> {
    summary_of(measured, baseline_name(transport, payload))
}

/// The summary of the measurement `name` in `measured`, or the name if absent or empty.
fn summary_of(measured: &[Measurement], name: String) -> Result<Summary, String> {
    measured
        .iter()
        .find(|m| m.name == name)
        .map(Measurement::summary)
        .filter(|summary| summary.count > 0)
        .ok_or(name)
}

/// The rows of every hop in [`HOPS`]: each hop found (by name) in `measured` is judged
/// against the round trips found there too; the rest are "not measured" with
/// `missing_reason`.
pub fn ratio_rows(measured: &[Measurement], missing_reason: &str) -> Vec<RatioRow> {
    HOPS.iter()
        .map(|spec| match measured.iter().find(|m| m.name == spec.name) {
            None => RatioRow {
                hop: spec.name,
                p50_p99_ns: Err(missing_reason.to_owned()),
                p50_vs_futex: None,
                p50_vs_paced_futex: None,
                p99_vs_uds: None,
                goals: Vec::new(),
            },
            Some(hop) => measured_row(spec, hop, measured),
        })
        .collect()
}

fn measured_row(spec: &HopSpec, hop: &Measurement, measured: &[Measurement]) -> RatioRow {
    let summary = hop.summary();
    let (p50, p99) = (summary.p50, summary.p99);
    let mut goals = Vec::new();
    let (mut p50_vs_futex, mut p50_vs_paced_futex, mut p99_vs_uds) = (None, None, None);
    if let Baseline::PingPong(payload) = spec.baseline {
        let uds = baseline(measured, Transport::Uds, payload);
        p99_vs_uds = uds.as_ref().ok().map(|u| p99 as f64 / u.p99.max(1) as f64);
        goals.push(GoalCheck {
            goal: "p99 < uds p99".to_owned(),
            outcome: match p99_vs_uds {
                Some(ratio) => Outcome::of(ratio < 1.0),
                None => Outcome::Unknown(format!("{} not measured", uds.unwrap_err())),
            },
        });
        let futex = baseline(measured, Transport::Futex, payload);
        p50_vs_futex = futex
            .as_ref()
            .ok()
            .map(|f| p50 as f64 / f.p50.max(1) as f64);
        goals.push(GoalCheck {
            goal: format!("p50 ≤ {FUTEX_P50_FACTOR}× futex p50"),
            outcome: match p50_vs_futex {
                Some(ratio) => Outcome::of(ratio <= FUTEX_P50_FACTOR),
                None => Outcome::Unknown(format!("{} not measured", futex.unwrap_err())),
            },
        });
        p50_vs_paced_futex = summary_of(measured, paced_name(Transport::Futex, payload))
            .ok()
            .map(|f| p50 as f64 / f.p50.max(1) as f64);
    }
    if let Some(limit) = spec.p99_limit_ns {
        goals.push(GoalCheck {
            goal: format!("p99 ≤ {}", format_ns(limit)),
            outcome: Outcome::of(p99 <= limit),
        });
    }
    RatioRow {
        hop: spec.name,
        p50_p99_ns: Ok((p50, p99)),
        p50_vs_futex,
        p50_vs_paced_futex,
        p99_vs_uds,
        goals,
    }
}

/// The printed table of [`ratio_rows`].
pub fn ratio_table(rows: &[RatioRow]) -> String {
    let mut text = format!(
        "{:<33} {:>12} {:>12} {:>9} {:>8} {:>9}  goals\n",
        "hop", "p50", "p99", "p50/futex", "p99/uds", "p50/paced"
    );
    let ratio = |r: Option<f64>| r.map_or("-".to_owned(), |r| format!("{r:.2}"));
    for row in rows {
        match &row.p50_p99_ns {
            Err(reason) => {
                let _ = writeln!(text, "{:<33} not measured: {reason}", row.hop);
            }
            Ok((p50, p99)) => {
                let goals: Vec<String> = row.goals.iter().map(GoalCheck::describe).collect();
                let _ = writeln!(
                    text,
                    "{:<33} {:>12} {:>12} {:>9} {:>8} {:>9}  {}",
                    row.hop,
                    format_ns(*p50),
                    format_ns(*p99),
                    ratio(row.p50_vs_futex),
                    ratio(row.p99_vs_uds),
                    ratio(row.p50_vs_paced_futex),
                    goals.join("; ")
                );
            }
        }
    }
    text
}

/// The doorbell round trip of each payload against the Unix-socket round trip of the same
/// payload and placement: below it at p50 and at p99.
pub fn transport_checks(measured: &[Measurement]) -> Vec<(Payload, Vec<GoalCheck>)> {
    Payload::ALL
        .iter()
        .filter_map(|&payload| {
            let doorbell = baseline(measured, Transport::Doorbell, payload).ok()?;
            let uds = baseline(measured, Transport::Uds, payload).ok()?;
            let check = |name: &str, ours: u64, theirs: u64| GoalCheck {
                goal: format!("{name} {} < uds {}", format_ns(ours), format_ns(theirs)),
                outcome: Outcome::of(ours < theirs),
            };
            Some((
                payload,
                vec![
                    check("p50", doorbell.p50, uds.p50),
                    check("p99", doorbell.p99, uds.p99),
                ],
            ))
        })
        .collect()
}

/// The floor under each payload's hop at the graph's rate: the bare `futex` round trip paced
/// as the graph sends that payload (`futex-paced/<payload>`), judged by the goals of the
/// payload's event-driven hop — p99 below the `uds` round-trip p99, p50 within
/// [`FUTEX_P50_FACTOR`] × the back-to-back `futex` round-trip p50. The floor wakes two
/// processes in turn, carries nothing, and runs nothing in between: both are cold at that
/// rate. A goal it misses is out of reach of a transport whose path goes cold between
/// messages, not of a hop whose processes run in between (the sync wakes at 1 kHz for the
/// encoder samples) or warm their path before a message (`sabr_node::Publisher::warm`):
/// tracker frame → matched, two wake-ups with a frame, a match and a matched sample, has
/// gone below it since its senders warm.
pub fn floor_checks(measured: &[Measurement]) -> Vec<(Payload, Vec<GoalCheck>)> {
    Payload::ALL
        .iter()
        .filter_map(|&payload| {
            let floor = summary_of(measured, paced_name(Transport::Futex, payload)).ok()?;
            let uds = baseline(measured, Transport::Uds, payload).ok()?;
            let futex = baseline(measured, Transport::Futex, payload).ok()?;
            let goals = vec![
                GoalCheck {
                    goal: format!(
                        "p99 {} < uds p99 {}",
                        format_ns(floor.p99),
                        format_ns(uds.p99)
                    ),
                    outcome: Outcome::of(floor.p99 < uds.p99),
                },
                GoalCheck {
                    goal: format!(
                        "p50 {} ≤ {FUTEX_P50_FACTOR}× futex p50 {}",
                        format_ns(floor.p50),
                        format_ns(futex.p50)
                    ),
                    outcome: Outcome::of(floor.p50 as f64 <= FUTEX_P50_FACTOR * futex.p50 as f64),
                },
            ];
            Some((payload, goals))
        })
        .collect()
}

/// An event-driven hop with a p50 goal, the one-way doorbell hops its message crosses, and
/// the work it does beyond them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HopPath {
    /// Measurement name of the hop (one of [`HOPS`]).
    pub hop: &'static str,
    /// The payload whose baselines judge it.
    pub payload: Payload,
    /// One-way doorbell hops between the hop's start and its end: 1 for a message to a
    /// subscriber, 2 for a request and its answer (the doorbell round trip of the payload
    /// carries the same two messages).
    pub legs: u32,
    /// What the hop does beyond its legs.
    pub work: &'static str,
    /// The measurement of that work, if the bench takes one.
    pub work_measured: Option<&'static str>,
}

/// The hops judged by [`FUTEX_P50_FACTOR`] and what their paths are made of.
pub const HOP_PATHS: [HopPath; 3] = [
    HopPath {
        hop: ENCODER_TO_SUBSCRIBER,
        payload: Payload::EncoderSample,
        legs: 1,
        work: "none: stamped right before the send",
        work_measured: None,
    },
    HopPath {
        hop: TRACKER_FRAME_TO_MATCHED,
        payload: Payload::TrackerFrame,
        legs: 2,
        work: "the tracker's work after the BX reply arrives and the sync's match",
        work_measured: Some(CHAIN_WORK),
    },
    HopPath {
        hop: IK_ROUND_TRIP,
        payload: Payload::Ik,
        legs: 2,
        work: "the server's solve",
        work_measured: Some(IK_SERVER_SOLVE),
    },
];

/// What the p50 goal of a hop leaves for its own work once its legs are paid at the hot
/// doorbell's price.
#[derive(Debug, Clone, PartialEq)]
pub struct WorkBudget {
    /// The hop's path.
    pub path: HopPath,
    /// Its legs at the doorbell's back-to-back price (ns): the `doorbell` round-trip p50 of
    /// its payload × legs / 2.
    pub legs_ns: u64,
    /// The `futex` round-trip p50 of its payload (ns).
    pub futex_p50_ns: u64,
    /// [`FUTEX_P50_FACTOR`] × the futex p50 − the legs (ns); negative when the legs alone
    /// exceed the goal.
    pub left_ns: i64,
    /// The p50 of [`HopPath::work_measured`] (ns), where measured.
    pub work_p50_ns: Option<u64>,
}

/// For each of [`HOP_PATHS`] whose payload has both back-to-back baselines in `measured`:
/// how much of its p50 goal is left for its work when its legs run as fast as the doorbell
/// ping-pong, everything hot. Work that takes longer than that puts the goal out of reach
/// whatever the transport's placement or warmth: the hop's legs are never faster than the
/// same messages back to back.
pub fn work_budgets(measured: &[Measurement]) -> Vec<WorkBudget> {
    HOP_PATHS
        .iter()
        .filter_map(|path| {
            let doorbell = baseline(measured, Transport::Doorbell, path.payload).ok()?;
            let futex = baseline(measured, Transport::Futex, path.payload).ok()?;
            let legs_ns = doorbell.p50 * u64::from(path.legs) / 2;
            let goal_ns = (FUTEX_P50_FACTOR * futex.p50 as f64).round() as i64;
            Some(WorkBudget {
                path: *path,
                legs_ns,
                futex_p50_ns: futex.p50,
                left_ns: goal_ns - legs_ns as i64,
                work_p50_ns: path
                    .work_measured
                    .and_then(|name| summary_of(measured, name.to_owned()).ok())
                    .map(|work| work.p50),
            })
        })
        .collect()
}

/// The printed table of [`work_budgets`], a line per hop.
pub fn budget_table(budgets: &[WorkBudget]) -> String {
    let mut text = String::new();
    for budget in budgets {
        let path = &budget.path;
        let left = if budget.left_ns >= 0 {
            format_ns(budget.left_ns as u64)
        } else {
            format!("nothing (−{})", format_ns(budget.left_ns.unsigned_abs()))
        };
        let work = match budget.work_p50_ns {
            Some(p50) => {
                let fits = if i64::try_from(p50).is_ok_and(|p50| p50 <= budget.left_ns) {
                    "within it"
                } else {
                    "more than that"
                };
                format!("{}, p50 {}: {fits}", path.work, format_ns(p50))
            }
            None => path.work.to_owned(),
        };
        let _ = writeln!(
            text,
            "  {:<33} {} leg{} {} ({:.2}× futex p50 {}): leaves {left} for its work ({work})",
            path.hop,
            path.legs,
            if path.legs == 1 { "" } else { "s" },
            format_ns(budget.legs_ns),
            budget.legs_ns as f64 / budget.futex_p50_ns.max(1) as f64,
            format_ns(budget.futex_p50_ns),
        );
    }
    text
}

/// The printed table of [`floor_checks`]; empty without the paced and back-to-back baselines.
pub fn floor_table(checks: &[(Payload, Vec<GoalCheck>)]) -> String {
    goal_table(checks, 33, |payload| paced_name(Transport::Futex, payload))
}

/// The printed table of [`transport_checks`]; empty without both baselines.
pub fn transport_table(checks: &[(Payload, Vec<GoalCheck>)]) -> String {
    goal_table(checks, 29, |payload| {
        baseline_name(Transport::Doorbell, payload)
    })
}

/// One indented line per payload: its `label`, padded to `width`, then its goals and their
/// outcomes.
fn goal_table(
    checks: &[(Payload, Vec<GoalCheck>)],
    width: usize,
    label: impl Fn(Payload) -> String,
) -> String {
    let mut text = String::new();
    for (payload, goals) in checks {
        let goals: Vec<String> = goals.iter().map(GoalCheck::describe).collect();
        let _ = writeln!(text, "  {:<width$} {}", label(*payload), goals.join("; "));
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

    fn hop(index: usize, value: u64) -> Measurement {
        constant(HOPS[index].name, value)
    }

    #[test]
    fn event_driven_hops_are_judged_against_uds_p99_and_futex_p50() {
        let measured = [
            constant("uds/encoder-sample", 1500),
            constant("futex/encoder-sample", 1000),
            constant("futex/tracker-frame", 100),
            hop(0, 1800),
            hop(1, 400),
        ];
        let rows = ratio_rows(&measured, "no graph");
        assert_eq!(rows.len(), HOPS.len());

        assert_eq!(rows[0].p50_p99_ns, Ok((1800, 1800)));
        assert_eq!(rows[0].p99_vs_uds, Some(1.2));
        assert_eq!(rows[0].p50_vs_futex, Some(1.8));
        assert_eq!(rows[0].goals[0].outcome, Outcome::Missed);
        assert_eq!(rows[0].goals[1].outcome, Outcome::Met);

        assert_eq!(
            rows[1].goals[0].outcome,
            Outcome::Unknown("uds/tracker-frame not measured".into())
        );
        assert_eq!(rows[1].p50_vs_futex, Some(4.0));
        assert_eq!(rows[1].goals[1].outcome, Outcome::Missed);

        assert_eq!(rows[2].p50_p99_ns, Err("no graph".into()));
        assert!(rows[2].goals.is_empty());
    }

    #[test]
    fn absolute_limits_apply_with_and_without_baseline() {
        let measured = [
            hop(2, 60_000),
            hop(3, 40_000),
            constant("uds/ik", 50_000),
            hop(4, 45_000),
            hop(5, 540_000),
            hop(6, 400_000),
        ];
        let rows = ratio_rows(&measured, "-");
        let ik = &rows[2];
        assert_eq!(ik.goals.len(), 3);
        assert_eq!(ik.goals[0].outcome, Outcome::Missed);
        assert_eq!(ik.goals[2].goal, "p99 ≤ 50.000 µs");
        assert_eq!(ik.goals[2].outcome, Outcome::Missed);
        let transport = &rows[3];
        assert_eq!(transport.hop, IK_TRANSPORT);
        assert_eq!(transport.goals.len(), 2, "no absolute limit of its own");
        assert_eq!(transport.goals[0].outcome, Outcome::Met);
        let first = &rows[4];
        assert_eq!(first.hop, IK_ROUND_TRIP_FIRST);
        assert_eq!(first.goals.len(), 2, "no absolute limit of its own");
        assert_eq!(first.goals[0].outcome, Outcome::Met);
        let setpoint = &rows[5];
        assert_eq!(setpoint.goals.len(), 1);
        assert_eq!(setpoint.goals[0].goal, "p99 ≤ 550.000 µs");
        assert_eq!(setpoint.goals[0].outcome, Outcome::Met);
        let matching = &rows[6];
        assert_eq!(matching.p99_vs_uds, None);
        assert_eq!(matching.goals.len(), 1);
        assert_eq!(matching.goals[0].outcome, Outcome::Met);
    }

    #[test]
    fn table_shows_ratios_and_reasons() {
        let measured = [
            constant("futex/encoder-sample", 1000),
            constant("futex-paced/encoder-sample", 750),
            constant("uds/encoder-sample", 3000),
            hop(0, 1500),
        ];
        let rows = ratio_rows(&measured, "graph not running");
        assert_eq!(rows[0].p50_vs_paced_futex, Some(2.0));
        assert_eq!(rows[1].p50_vs_paced_futex, None);
        let table = ratio_table(&rows);
        let lines: Vec<&str> = table.lines().collect();
        assert!(
            lines[1].starts_with("hop/encoder-sample-to-subscriber"),
            "{table}"
        );
        assert!(
            lines[1].contains(" 1.50 ")
                && lines[1].contains(" 0.50 ")
                && lines[1].contains(" 2.00 "),
            "{table}"
        );
        assert!(
            lines[1].contains("p99 < uds p99: met; p50 ≤ 2× futex p50: met"),
            "{table}"
        );
        assert!(
            lines[2].ends_with("not measured: graph not running"),
            "{table}"
        );
    }

    #[test]
    fn the_paced_floor_is_judged_by_its_payloads_hop_goals() {
        let measured = [
            constant("futex-paced/tracker-frame", 9_000),
            constant("futex/tracker-frame", 3_000),
            constant("uds/tracker-frame", 8_000),
            constant("futex-paced/ik", 4_000),
            constant("futex/ik", 3_000),
            constant("uds/ik", 6_000),
            constant("futex-paced/encoder-sample", 4_000),
            constant("futex/encoder-sample", 3_000),
        ];
        let checks = floor_checks(&measured);
        let payloads: Vec<Payload> = checks.iter().map(|(payload, _)| *payload).collect();
        assert_eq!(
            payloads,
            [Payload::TrackerFrame, Payload::Ik],
            "encoder-sample has no uds baseline"
        );
        let outcomes = |index: usize| -> Vec<Outcome> {
            checks[index].1.iter().map(|g| g.outcome.clone()).collect()
        };
        assert_eq!(outcomes(0), [Outcome::Missed, Outcome::Missed]);
        assert_eq!(outcomes(1), [Outcome::Met, Outcome::Met]);
        let table = floor_table(&checks);
        assert!(
            table.contains("futex-paced/tracker-frame")
                && table.contains("p50 9.007 µs ≤ 2× futex p50 3.001 µs: MISSED"),
            "{table}"
        );
    }

    #[test]
    fn the_work_budget_is_the_goal_less_the_legs_at_the_doorbells_price() {
        let measured = [
            constant("doorbell/encoder-sample", 4_000),
            constant("futex/encoder-sample", 3_000),
            constant("doorbell/tracker-frame", 5_000),
            constant("futex/tracker-frame", 2_000),
            constant("doorbell/ik", 4_000),
            constant("futex/ik", 2_500),
            constant(IK_SERVER_SOLVE, 700),
            constant(CHAIN_WORK, 900),
        ];
        let budgets = work_budgets(&measured);
        assert_eq!(budgets.len(), 3);
        // The histograms keep 3 significant digits: 4000 ns is stored as 4001, 3000 as 3001.
        let encoder = &budgets[0];
        assert_eq!(encoder.path.hop, ENCODER_TO_SUBSCRIBER);
        assert_eq!(encoder.legs_ns, 2_000, "one leg: half the round trip");
        assert_eq!(encoder.left_ns, 2 * 3_001 - 2_000);
        assert_eq!(encoder.work_p50_ns, None);
        let tracker = &budgets[1];
        assert_eq!(tracker.legs_ns, 5_003);
        assert_eq!(
            tracker.left_ns,
            2 * 2_000 - 5_003,
            "the legs alone exceed the goal"
        );
        let ik = &budgets[2];
        assert_eq!(ik.left_ns, 2 * 2_501 - 4_001);
        assert_eq!(ik.work_p50_ns, Some(700));
        let table = budget_table(&budgets);
        let lines: Vec<&str> = table.lines().collect();
        assert!(
            lines[0].contains("1 leg 2.000 µs (0.67× futex p50 3.001 µs): leaves 4.002 µs"),
            "{table}"
        );
        assert!(
            lines[1].contains("leaves nothing (−1.003 µs)")
                && lines[1].ends_with("match, p50 900 ns: more than that)"),
            "{table}"
        );
        assert!(
            lines[2].ends_with("(the server's solve, p50 700 ns: within it)"),
            "{table}"
        );
        assert!(
            work_budgets(&measured[..2]).len() == 1,
            "only the encoder's baselines"
        );
    }

    #[test]
    fn the_doorbell_must_beat_uds_at_p50_and_p99_per_payload() {
        let measured = [
            constant("doorbell/ik", 5_000),
            constant("uds/ik", 6_000),
            constant("doorbell/encoder-sample", 7_000),
            constant("uds/encoder-sample", 6_000),
            constant("doorbell/tracker-frame", 5_000),
        ];
        let checks = transport_checks(&measured);
        // The histograms keep 3 significant digits: 5000 ns is stored as 5003.
        assert_eq!(checks.len(), 2, "tracker-frame has no uds baseline");
        let (payload, goals) = &checks[0];
        assert_eq!(*payload, Payload::EncoderSample);
        assert!(goals.iter().all(|g| g.outcome == Outcome::Missed));
        let (payload, goals) = &checks[1];
        assert_eq!(*payload, Payload::Ik);
        assert!(goals.iter().all(|g| g.outcome == Outcome::Met));
        let table = transport_table(&checks);
        assert!(
            table.contains("doorbell/ik") && table.contains("p99 5.003 µs < uds 6.003 µs: met"),
            "{table}"
        );
    }
}
