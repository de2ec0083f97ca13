//! Autoplay: the rig plays the simulator's session plan itself (homing, excitation, tip,
//! validation) in real time when no motion node drives it, announcing each phase as it ends.
//! Times are robot time (ns since power-up); the plan starts when [`Autoplay::start`] is
//! called and the robot holds its power-up pose until then.

use sabr_model::plan::{PhaseSpan, SessionPlan};
use sabr_model::Joints;
use sabr_node::{GraphObserver, NodeError};
use std::collections::BTreeSet;
use std::time::{Duration, Instant};

/// The session plan being played.
#[derive(Debug, Clone)]
pub struct Autoplay {
    plan: SessionPlan,
    start_ns: Option<i64>,
    announced: usize,
}

impl Autoplay {
    /// Autoplay of `plan`, not started.
    pub fn new(plan: SessionPlan) -> Self {
        Autoplay {
            plan,
            start_ns: None,
            announced: 0,
        }
    }

    /// Starts the plan at robot time `t_ns` (once; later calls change nothing).
    pub fn start(&mut self, t_ns: i64) {
        self.start_ns.get_or_insert(t_ns);
    }

    /// Robot time at which the plan started, if it did.
    pub fn start_ns(&self) -> Option<i64> {
        self.start_ns
    }

    fn plan_time(&self, t_ns: i64) -> i64 {
        self.start_ns.map_or(0, |start| t_ns - start)
    }

    /// Commanded paper joints (rad) at robot time `t_ns`: the plan's start pose (power-up)
    /// before the plan starts, its last pose after it ends.
    pub fn joints_at(&self, t_ns: i64) -> Joints {
        self.plan.joints_at(self.plan_time(t_ns))
    }

    /// Whether the tip sphere is on the needle at robot time `t_ns` (the tip phase).
    pub fn tip_attached(&self, t_ns: i64) -> bool {
        self.start_ns.is_some() && self.plan.tip_attached(self.plan_time(t_ns))
    }

    /// Phases that ended at or before robot time `t_ns` and were not returned before, in
    /// robot time.
    pub fn finished_phases(&mut self, t_ns: i64) -> Vec<PhaseSpan> {
        let Some(start) = self.start_ns else {
            return Vec::new();
        };
        let phases = self.plan.phases();
        let mut done = Vec::new();
        while let Some(phase) = phases.get(self.announced) {
            if phase.end_ns > t_ns - start {
                break;
            }
            done.push(PhaseSpan {
                name: phase.name,
                start_ns: start + phase.start_ns,
                end_ns: start + phase.end_ns,
            });
            self.announced += 1;
        }
        done
    }

    /// Robot time at which the plan ends, once started.
    pub fn end_ns(&self) -> Option<i64> {
        self.start_ns.map(|start| start + self.plan.end_ns())
    }
}

/// When autoplay may start: after the listed nodes announced readiness on the graph's
/// lifecycle service, then a delay.
pub struct StartGate {
    observer: Option<GraphObserver>,
    waiting_for: BTreeSet<String>,
    delay: Duration,
    open_since: Option<Instant>,
}

impl StartGate {
    /// A gate waiting for `nodes` (none: it opens at once) and then `delay`.
    pub fn new(
        domain: &sabr_node::Domain,
        nodes: &[String],
        delay: Duration,
    ) -> Result<Self, NodeError> {
        let observer = if nodes.is_empty() {
            None
        } else {
            Some(GraphObserver::new(domain)?)
        };
        Ok(StartGate {
            observer,
            waiting_for: nodes.iter().cloned().collect(),
            delay,
            open_since: nodes.is_empty().then(Instant::now),
        })
    }

    /// True once every awaited node was seen ready and the delay has passed since.
    pub fn is_open(&mut self) -> Result<bool, NodeError> {
        if let Some(observer) = &self.observer {
            let waiting = &mut self.waiting_for;
            observer.poll(|m| {
                if m.state == sabr_msgs::LifecycleState::Ready && waiting.remove(m.node.as_str()) {
                    tracing::info!(node = m.node.as_str(), "autoplay: node ready");
                }
            })?;
            if self.waiting_for.is_empty() {
                self.observer = None;
                self.open_since = Some(Instant::now());
            }
        }
        Ok(self
            .open_since
            .is_some_and(|since| since.elapsed() >= self.delay))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_sim::{Session, SimConfig};

    fn plan() -> SessionPlan {
        let mut config = SimConfig::new(3);
        config.duration_scale = 0.02;
        Session::new(&config).unwrap().plan().clone()
    }

    #[test]
    fn holds_the_power_up_pose_until_started() {
        let plan = plan();
        let mut autoplay = Autoplay::new(plan.clone());
        assert_eq!(autoplay.joints_at(5_000_000_000), plan.joints_at(0));
        assert!(autoplay.finished_phases(i64::MAX / 2).is_empty());
        assert!(!autoplay.tip_attached(i64::MAX / 2));
        assert_eq!(autoplay.end_ns(), None);
        autoplay.start(2_000_000_000);
        autoplay.start(9_000_000_000);
        assert_eq!(autoplay.start_ns(), Some(2_000_000_000));
        assert_eq!(
            autoplay.joints_at(3_500_000_000),
            plan.joints_at(1_500_000_000)
        );
        assert_eq!(autoplay.end_ns(), Some(2_000_000_000 + plan.end_ns()));
    }

    #[test]
    fn announces_each_phase_once_when_it_ends() {
        let plan = plan();
        let names: Vec<&str> = plan.phases().iter().map(|p| p.name).collect();
        assert_eq!(names, ["homing", "excitation", "tip", "validation"]);
        let start = 1_000_000_000;
        let mut autoplay = Autoplay::new(plan.clone());
        autoplay.start(start);
        let mut announced = Vec::new();
        let mut t = 0;
        while t <= start + plan.end_ns() {
            for phase in autoplay.finished_phases(t) {
                // Announced no earlier than its end, and within one 10 ms step of it.
                assert!(phase.end_ns <= t && t - phase.end_ns < 10_000_000);
                announced.push(phase);
            }
            t += 10_000_000;
        }
        for phase in autoplay.finished_phases(i64::MAX / 2) {
            announced.push(phase);
        }
        let expected: Vec<PhaseSpan> = plan
            .phases()
            .iter()
            .map(|p| PhaseSpan {
                name: p.name,
                start_ns: start + p.start_ns,
                end_ns: start + p.end_ns,
            })
            .collect();
        assert_eq!(announced, expected);
        assert!(autoplay.finished_phases(i64::MAX / 2).is_empty());
    }

    #[test]
    fn tip_sphere_is_attached_during_the_tip_phase_only() {
        let plan = plan();
        let tip = plan.phases().iter().find(|p| p.name == "tip").unwrap();
        let mut autoplay = Autoplay::new(plan.clone());
        autoplay.start(500);
        assert!(autoplay.tip_attached(500 + tip.start_ns + 1));
        assert!(!autoplay.tip_attached(500 + tip.start_ns - 1));
        assert!(!autoplay.tip_attached(500 + tip.end_ns + 1));
    }

    #[test]
    fn gate_without_nodes_opens_after_the_delay() {
        let domain = sabr_node::Domain::new("rig-gate-test").unwrap();
        let mut gate = StartGate::new(&domain, &[], Duration::from_millis(30)).unwrap();
        assert!(!gate.is_open().unwrap());
        std::thread::sleep(Duration::from_millis(40));
        assert!(gate.is_open().unwrap());
    }
}
