//! Where and how a node runs: its CPU set (`cpus = [0]`) and scheduling policy
//! (`sched = "fifo:40"`, `"rr:20"`, `"other"`, `"idle"`), checked when the launch file is read, probed
//! before any node starts, and applied in the child between fork and exec.

use nix::sched::CpuSet;
use std::fmt;

/// A scheduling policy of Linux (`sched(7)`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sched {
    /// `SCHED_FIFO` at a real-time priority 1..=99: runs until it blocks or a higher one wakes.
    Fifo(u8),
    /// `SCHED_RR` at a real-time priority 1..=99: like FIFO, time-sliced among equals.
    RoundRobin(u8),
    /// `SCHED_OTHER`: the normal time-shared policy (priority 0).
    Other,
    /// `SCHED_IDLE`: runs only when nothing else on its CPU wants to (priority 0).
    Idle,
}

impl Sched {
    /// Parses `fifo:N`, `rr:N` (N in 1..=99), `other` or `idle`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let expected = "expected \"fifo:N\", \"rr:N\" (N a real-time priority 1..=99), \
                        \"other\" or \"idle\"";
        match text {
            "other" => return Ok(Sched::Other),
            "idle" => return Ok(Sched::Idle),
            _ => {}
        }
        let (policy, priority) = text
            .split_once(':')
            .ok_or_else(|| format!("bad sched {text:?}: {expected}"))?;
        let priority: u8 = priority
            .parse()
            .ok()
            .filter(|p| (1..=99).contains(p))
            .ok_or_else(|| format!("bad real-time priority in sched {text:?}: {expected}"))?;
        match policy {
            "fifo" => Ok(Sched::Fifo(priority)),
            "rr" => Ok(Sched::RoundRobin(priority)),
            _ => Err(format!(
                "unknown scheduling policy in sched {text:?}: {expected}"
            )),
        }
    }

    /// The real-time priority (0 for `other` and `idle`).
    pub fn priority(self) -> u8 {
        match self {
            Sched::Fifo(p) | Sched::RoundRobin(p) => p,
            Sched::Other | Sched::Idle => 0,
        }
    }

    fn policy(self) -> libc::c_int {
        match self {
            Sched::Fifo(_) => libc::SCHED_FIFO,
            Sched::RoundRobin(_) => libc::SCHED_RR,
            Sched::Other => libc::SCHED_OTHER,
            Sched::Idle => libc::SCHED_IDLE,
        }
    }
}

impl fmt::Display for Sched {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Sched::Fifo(p) => write!(f, "fifo:{p}"),
            Sched::RoundRobin(p) => write!(f, "rr:{p}"),
            Sched::Other => write!(f, "other"),
            Sched::Idle => write!(f, "idle"),
        }
    }
}

/// The placement of one node; the default leaves both to the system.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Placement {
    /// CPUs the node may run on (`sched_setaffinity`); `None`: any.
    pub cpus: Option<Vec<usize>>,
    /// Scheduling policy (`sched_setscheduler`); `None`: inherited from the launcher.
    pub sched: Option<Sched>,
}

/// CPUs the machine has online.
pub fn online_cpus() -> usize {
    std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .max(
            nix::unistd::sysconf(nix::unistd::SysconfVar::_NPROCESSORS_ONLN)
                .ok()
                .flatten()
                .map_or(1, |n| n.max(1) as usize),
        )
}

/// Checks a CPU list of a launch file against the machine.
pub fn check_cpus(cpus: &[usize]) -> Result<(), String> {
    let online = online_cpus();
    if cpus.is_empty() {
        return Err("cpus is empty: list at least one CPU, or leave cpus out".to_owned());
    }
    if let Some(cpu) = cpus.iter().find(|&&cpu| cpu >= online) {
        return Err(format!(
            "CPU {cpu} does not exist: this machine has CPUs 0..={}",
            online - 1
        ));
    }
    Ok(())
}

/// What the child applies between fork and exec, prepared without allocating.
#[derive(Clone, Copy)]
pub struct Prepared {
    cpus: Option<CpuSet>,
    sched: Option<Sched>,
}

impl Placement {
    /// True when the node is left to the system.
    pub fn is_default(&self) -> bool {
        self.cpus.is_none() && self.sched.is_none()
    }

    /// The placement of a process started without one: the normal policy (`SCHED_OTHER`) on
    /// the CPUs of this process's main thread. A child inherits the placement of the thread
    /// that starts it; a child started from a placed thread (a real-time measuring thread,
    /// say) is given this one instead, so that neither it nor the nodes it starts without a
    /// placement of their own run at that thread's priority or on its CPUs.
    pub fn unplaced() -> Result<Self, String> {
        let main_thread = nix::unistd::Pid::this();
        let set = nix::sched::sched_getaffinity(main_thread)
            .map_err(|e| format!("cannot read the CPUs of this process: {e}"))?;
        let cpus = (0..CpuSet::count())
            .filter(|&cpu| set.is_set(cpu).unwrap_or(false))
            .collect();
        Ok(Self {
            cpus: Some(cpus),
            sched: Some(Sched::Other),
        })
    }

    /// The CPU set and policy in the form the child applies.
    pub fn prepare(&self) -> Result<Prepared, String> {
        let cpus = match &self.cpus {
            None => None,
            Some(list) => {
                let mut set = CpuSet::new();
                for &cpu in list {
                    set.set(cpu)
                        .map_err(|e| format!("CPU {cpu} cannot be placed in a CPU set: {e}"))?;
                }
                Some(set)
            }
        };
        Ok(Prepared {
            cpus,
            sched: self.sched,
        })
    }

    /// Tries the placement on a short-lived thread of the launcher (affinity and policy are
    /// per thread on Linux), so a graph that cannot be placed is refused before any node
    /// starts. The error says what failed and how to allow it.
    pub fn probe(&self) -> Result<(), String> {
        let prepared = self.prepare()?;
        let sched = self.sched;
        let result = std::thread::spawn(move || prepared.apply())
            .join()
            .map_err(|_| "the placement probe thread panicked".to_owned())?;
        result.map_err(|error| match (error, sched) {
            (nix::errno::Errno::EPERM, Some(sched @ (Sched::Fifo(_) | Sched::RoundRobin(_)))) => {
                format!(
                "sched = \"{sched}\" is not allowed here ({error}): real-time scheduling needs \
                 CAP_SYS_NICE (run the launcher as root, or `setcap cap_sys_nice+ep` on it) or \
                 a real-time priority limit of at least {p} (`ulimit -r {p}`, or `@group - \
                 rtprio {p}` in /etc/security/limits.conf), and a cgroup with a real-time \
                 budget (cpu.rt_runtime_us > 0)",
                p = sched.priority()
            )
            }
            (error, _) => format!("cannot apply the placement ({error}): {self}"),
        })
    }
}

impl Prepared {
    /// Applies the placement to the calling thread (in the child before exec: the process).
    /// Only makes the system calls `sched_setaffinity` and `sched_setscheduler`, so it is
    /// async-signal-safe.
    pub fn apply(&self) -> Result<(), nix::errno::Errno> {
        if let Some(cpus) = &self.cpus {
            nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), cpus)?;
        }
        if let Some(sched) = self.sched {
            set_scheduler(sched)?;
        }
        Ok(())
    }

    /// Makes the child of `command` apply this placement between fork and exec.
    #[allow(unsafe_code)]
    pub fn apply_in_child(self, command: &mut std::process::Command) {
        use std::os::unix::process::CommandExt;
        // SAFETY: the closure runs in the child between fork and exec; `apply` only makes
        // the async-signal-safe system calls sched_setaffinity and sched_setscheduler and
        // does not allocate.
        unsafe {
            command.pre_exec(move || Ok(self.apply()?));
        }
    }

    /// Applies the placement to the running process `pid` (its main thread), e.g. the peer
    /// of a measurement started without one.
    pub fn apply_to(&self, pid: u32) -> Result<(), nix::errno::Errno> {
        let pid = i32::try_from(pid).map_err(|_| nix::errno::Errno::ESRCH)?;
        if let Some(cpus) = &self.cpus {
            nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(pid), cpus)?;
        }
        if let Some(sched) = self.sched {
            set_scheduler_of(pid, sched)?;
        }
        Ok(())
    }
}

/// `sched_setscheduler(0, policy, priority)` on the calling thread.
fn set_scheduler(sched: Sched) -> Result<(), nix::errno::Errno> {
    set_scheduler_of(0, sched)
}

/// `sched_setscheduler(pid, policy, priority)`; pid 0 is the calling thread.
#[allow(unsafe_code)]
fn set_scheduler_of(pid: i32, sched: Sched) -> Result<(), nix::errno::Errno> {
    let param = libc::sched_param {
        sched_priority: libc::c_int::from(sched.priority()),
    };
    // SAFETY: `param` is a valid sched_param for the duration of the call.
    let result = unsafe { libc::sched_setscheduler(pid, sched.policy(), &param) };
    if result == 0 {
        Ok(())
    } else {
        Err(nix::errno::Errno::last())
    }
}

impl fmt::Display for Placement {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.cpus {
            Some(cpus) => write!(f, "cpus = {cpus:?}")?,
            None => write!(f, "any CPU")?,
        }
        match self.sched {
            Some(sched) => write!(f, ", sched = \"{sched}\""),
            None => write!(f, ", inherited policy"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_policies_and_priorities() {
        assert_eq!(Sched::parse("fifo:40"), Ok(Sched::Fifo(40)));
        assert_eq!(Sched::parse("rr:1"), Ok(Sched::RoundRobin(1)));
        assert_eq!(Sched::parse("other"), Ok(Sched::Other));
        assert_eq!(Sched::parse("idle"), Ok(Sched::Idle));
        for bad in [
            "fifo", "fifo:0", "fifo:100", "rr:-3", "idle:5", "FIFO:40", "",
        ] {
            assert!(Sched::parse(bad).is_err(), "{bad:?}");
        }
        assert_eq!(Sched::Fifo(40).to_string(), "fifo:40");
        assert_eq!(Sched::Idle.to_string(), "idle");
    }

    #[test]
    fn cpus_must_exist() {
        assert_eq!(check_cpus(&[0]), Ok(()));
        let error = check_cpus(&[4096]).unwrap_err();
        assert!(error.contains("CPU 4096 does not exist"), "{error}");
        assert!(check_cpus(&[]).is_err());
    }

    #[test]
    fn a_child_started_from_a_placed_thread_runs_unplaced() {
        let unplaced = Placement::unplaced().unwrap();
        let cpus = unplaced.cpus.clone().unwrap();
        assert!(!cpus.is_empty() && cpus.iter().all(|&cpu| cpu < online_cpus()));
        assert_eq!(unplaced.sched, Some(Sched::Other));
        // A thread confined to one CPU starts a child: the child reports every CPU of the
        // process, not the thread's one.
        let only_first = Placement {
            cpus: Some(vec![cpus[0]]),
            sched: None,
        };
        let prepared = unplaced.prepare().unwrap();
        let allowed = std::thread::spawn(move || {
            only_first.prepare().unwrap().apply().unwrap();
            let mut command = std::process::Command::new("sh");
            command.args(["-c", "grep Cpus_allowed_list /proc/self/status"]);
            prepared.apply_in_child(&mut command);
            command.output().unwrap()
        })
        .join()
        .unwrap();
        assert!(allowed.status.success(), "{allowed:?}");
        let child = String::from_utf8(allowed.stdout).unwrap();
        // (`/proc/self` is the process: its main thread.)
        let process = std::fs::read_to_string("/proc/self/status").unwrap();
        let process = process
            .lines()
            .find(|line| line.starts_with("Cpus_allowed_list"))
            .unwrap();
        assert_eq!(child.trim(), process.trim());
    }

    #[test]
    fn the_default_placement_always_applies() {
        Placement::default().probe().unwrap();
        let on_cpu_zero = Placement {
            cpus: Some(vec![0]),
            sched: Some(Sched::Other),
        };
        on_cpu_zero.probe().unwrap();
    }
}
