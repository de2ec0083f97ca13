//! The motor setpoint → rig hop, on a graph of the rig alone following setpoints (no autoplay,
//! no motion node): the bench publishes `MotorSetpoint`s on `sabr/motion/setpoints` and
//! watches the rig's counter register on `sabr/rig/counters`.
//!
//! The rig reads its setpoints once per tick of its counter clock (2 kHz) and stamps each
//! `CounterLatch` with the start of its tick; a setpoint applies from its `t_ns` on. The bench
//! stamps each setpoint with its publication time, so the rig applies it in the first tick
//! that starts at or after the publication and has received it, and its motors turn towards it
//! within that tick. [`SETPOINT_TO_RIG`] is that tick's `latch_t_ns` minus the setpoint's
//! `t_ns`: the transport plus the wait for the rig's next tick (up to 0.5 ms by design).
//!
//! Setpoints alternate between two targets either side of joint 1's power-up count
//! ([`AMPLITUDE_COUNTS`] away, never reached: the motor is rate limited), so the motor moves
//! towards the old target until the new one applies, then reverses: the first latch whose
//! count moved towards the new target comes from the applying tick. Each setpoint is published
//! [`GAP`] after the previous one was seen applied, at the arrival of a latch, plus a phase
//! slept (a Weyl sequence over [`PHASE_SPREAD`], two rig ticks), so the wait for the rig's
//! tick is sampled evenly: waiting on the latches alone would publish each setpoint right
//! after a tick started.

use super::cpu::measure_cpu_shares;
use super::graph::{GraphMeasured, LiveGraph, SETPOINTS_LAUNCH_FILE};
use super::hops::SETPOINT_TO_RIG;
use super::stats::Measurement;
use anyhow::{bail, Context};
use sabr_node::msgs::{services, CounterLatch, MotorSetpoint};
use sabr_node::{monotonic_ns, Domain, NodeRuntime, Publisher, Subscriber};
use std::path::Path;
use std::time::{Duration, Instant};

/// The joint whose motor is moved (joint 1).
const JOINT: usize = 0;

/// Distance of both targets from the power-up count, motor counts (0.13 rad of joint 1).
const AMPLITUDE_COUNTS: f64 = 400.0;

/// Least time between one setpoint seen applied and the next one.
const GAP: Duration = Duration::from_millis(2);

/// Spread of the extra delay before each setpoint: two ticks of the rig's 2 kHz clock.
const PHASE_SPREAD: Duration = Duration::from_millis(1);

/// Longest wait for the rig to apply one setpoint, or for its first counter latch.
const APPLY_TIMEOUT: Duration = Duration::from_millis(500);

/// What the setpoint part measures and how long it waits.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// Longest wait for the rig's readiness.
    pub ready_timeout: Duration,
    /// Window of the CPU use of the rig while it holds still.
    pub cpu_window: Duration,
    /// Setpoints recorded (after a tenth as many unrecorded).
    pub setpoints: u64,
}

impl Plan {
    /// Setpoints sent first and not recorded.
    fn warmup(&self) -> u64 {
        (self.setpoints / 10).max(10)
    }

    /// Longest the graph may need to run; the launcher stops it by itself after that.
    pub fn backstop(&self) -> Duration {
        let per_setpoint = GAP + PHASE_SPREAD + APPLY_TIMEOUT;
        self.ready_timeout
            + self.cpu_window
            + per_setpoint * (self.setpoints + self.warmup()) as u32
            + Duration::from_secs(120)
    }
}

/// Runs the rig alone in `domain` from a launch file written to `dir` (executable in
/// `bin_dir`), measures its CPU use while it holds still, then the setpoint → rig hop.
pub fn run(
    plan: &Plan,
    dir: &Path,
    bin_dir: &Path,
    domain: Domain,
) -> anyhow::Result<GraphMeasured> {
    let mut probe = Probe::open(&domain)?;
    let mut graph = LiveGraph::start(
        "setpoints",
        SETPOINTS_LAUNCH_FILE,
        dir,
        bin_dir,
        domain,
        plan.backstop(),
    )?;
    graph.wait_ready(&["rig"], plan.ready_timeout)?;

    let processes = graph.processes();
    let pids: Vec<u32> = processes.iter().map(|(_, pid)| *pid).collect();
    let shares = measure_cpu_shares(&pids, plan.cpu_window)?;
    graph.check_running()?;
    let idle = processes
        .iter()
        .zip(shares)
        .map(|((node, _), share)| {
            let label = match node.as_str() {
                "rig" => "setpoints/rig-holding".to_owned(),
                other => format!("setpoints/{other}"),
            };
            (label, share)
        })
        .collect();

    let hop = probe.setpoint_hops(&mut graph, plan)?;
    drop(probe);
    graph.stop()?;
    Ok(GraphMeasured {
        measurements: vec![hop],
        idle,
        notes: Vec::new(),
    })
}

/// The bench's node in the setpoint graph's domain.
struct Probe {
    rt: NodeRuntime,
    setpoints: Publisher<MotorSetpoint>,
    counters: Subscriber<CounterLatch>,
}

impl Probe {
    fn open(domain: &Domain) -> anyhow::Result<Self> {
        let rt = NodeRuntime::with_domain("bench", domain.clone())?;
        Ok(Self {
            setpoints: rt.publisher(services::MOTION_SETPOINTS)?,
            counters: rt.subscriber(services::RIG_COUNTERS)?,
            rt,
        })
    }

    /// Publishes the setpoints one after the other and times each until the rig applied it.
    fn setpoint_hops(&mut self, graph: &mut LiveGraph, plan: &Plan) -> anyhow::Result<Measurement> {
        self.counters.drain(|_| {})?;
        let first = self
            .counters
            .recv_timeout(APPLY_TIMEOUT)?
            .with_context(|| format!("no counter latch from the rig within {APPLY_TIMEOUT:?}"))?;
        let base = first.counts;
        let mut watch = MotorWatch::new(first.counts[JOINT]);
        let mut hops = Measurement::new(SETPOINT_TO_RIG, "ns");
        let warmup = plan.warmup();
        for index in 0..warmup + plan.setpoints {
            // Waiting on the latches ends just after one arrived, i.e. at the start of a rig
            // tick; a plain sleep then sets the phase.
            self.follow_until(&mut watch, Instant::now() + GAP)?;
            std::thread::sleep(PHASE_SPREAD.mul_f64(weyl(index)));
            self.counters.drain(|latch| {
                watch.moved_towards(&latch, 0);
            })?;
            let towards = if index % 2 == 0 { 1 } else { -1 };
            let mut target_counts = base.map(|count| count as f64);
            target_counts[JOINT] += towards as f64 * AMPLITUDE_COUNTS;
            let t_ns = monotonic_ns();
            self.setpoints.send(MotorSetpoint {
                seq: index + 1,
                t_ns,
                target_counts,
            })?;
            let applied_ns = self.wait_applied(&mut watch, towards).with_context(|| {
                format!(
                    "setpoint {} (is the rig autoplaying, or is joint {} at a stop?)",
                    index + 1,
                    JOINT + 1
                )
            })?;
            if index >= warmup {
                let hop = u64::try_from(applied_ns - t_ns).map_err(|_| {
                    anyhow::anyhow!(
                        "setpoint {}: applied in a tick stamped {applied_ns} ns, before its \
                         time {t_ns} ns",
                        index + 1
                    )
                })?;
                hops.record(hop)?;
            }
            if index % 200 == 199 {
                graph.check_running()?;
                if !self.rt.keep_running() {
                    bail!("interrupted");
                }
            }
        }
        Ok(hops)
    }

    /// Follows the counter latches until `until`.
    fn follow_until(&self, watch: &mut MotorWatch, until: Instant) -> anyhow::Result<()> {
        loop {
            let now = Instant::now();
            if now >= until {
                return Ok(());
            }
            if let Some(latch) = self.counters.recv_timeout(until - now)? {
                watch.moved_towards(&latch, 0);
            }
        }
    }

    /// The `latch_t_ns` of the first latch whose count moved in direction `towards`.
    fn wait_applied(&self, watch: &mut MotorWatch, towards: i64) -> anyhow::Result<i64> {
        let started = Instant::now();
        loop {
            let left = APPLY_TIMEOUT.saturating_sub(started.elapsed());
            if left.is_zero() {
                bail!("the rig's motor did not turn towards it within {APPLY_TIMEOUT:?}");
            }
            if let Some(latch) = self.counters.recv_timeout(left)? {
                if watch.moved_towards(&latch, towards) {
                    return Ok(latch.latch_t_ns);
                }
            }
        }
    }
}

/// The count of the moved motor in successive counter latches.
#[derive(Debug)]
struct MotorWatch {
    previous: i64,
}

impl MotorWatch {
    fn new(count: i64) -> Self {
        Self { previous: count }
    }

    /// Takes the next latch; true if the count moved in direction `towards` (+1 or −1; 0:
    /// just follow) since the previous latch.
    fn moved_towards(&mut self, latch: &CounterLatch, towards: i64) -> bool {
        let count = latch.counts[JOINT];
        let moved = towards != 0 && (count - self.previous).signum() == towards;
        self.previous = count;
        moved
    }
}

/// The fractional part of `index` × the golden ratio: evenly spread over [0, 1).
fn weyl(index: u64) -> f64 {
    (index as f64 * 0.618_033_988_749_895).fract()
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_node::msgs::JOINTS;

    fn latch(count: i64) -> CounterLatch {
        let mut counts = [0; JOINTS];
        counts[JOINT] = count;
        CounterLatch {
            counts,
            ..CounterLatch::default()
        }
    }

    #[test]
    fn the_first_latch_moving_towards_the_new_target_is_found() {
        let mut watch = MotorWatch::new(100);
        // Moving down towards the old target, then reversing.
        let found: Vec<bool> = [92, 84, 84, 90, 98]
            .iter()
            .map(|&count| watch.moved_towards(&latch(count), 1))
            .collect();
        assert_eq!(found, [false, false, false, true, true]);
        // Following only never reports.
        assert!(!watch.moved_towards(&latch(200), 0));
        assert!(watch.moved_towards(&latch(150), -1));
    }

    #[test]
    fn phases_cover_the_spread_evenly() {
        let phases: Vec<f64> = (0..1000).map(weyl).collect();
        assert!(phases.iter().all(|p| (0.0..1.0).contains(p)));
        for decile in 0..10 {
            let low = f64::from(decile) / 10.0;
            let inside = phases
                .iter()
                .filter(|&&p| (low..low + 0.1).contains(&p))
                .count();
            assert!((95..=105).contains(&inside), "decile {decile}: {inside}");
        }
    }

    #[test]
    fn launch_file_runs_the_rig_without_autoplay() {
        let bin_dir = tempfile::tempdir().unwrap();
        std::fs::write(bin_dir.path().join("sabr-rig"), "").unwrap();
        let graph = sabr_launcher::spec::parse(
            Path::new("bench-setpoints.toml"),
            SETPOINTS_LAUNCH_FILE,
            bin_dir.path(),
        )
        .unwrap();
        assert_eq!(graph.nodes.len(), 1);
        assert_eq!(
            graph.nodes[0].args,
            ["--seed", &super::super::compute::SESSION_SEED.to_string()]
        );
    }
}
