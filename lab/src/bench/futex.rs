//! The floor under every wake-up: a raw futex ping-pong between two processes, nothing but
//! two counters in one shared-memory segment and the `FUTEX_WAKE`/`FUTEX_WAIT` system calls.
//!
//! The segment is an iceoryx2 dynamic storage (`/dev/shm`), created by the measuring side and
//! removed with it; the peer opens it by name. Each side bumps its own counter and wakes the
//! other, then sleeps until the other's counter moves: a wake-up that races with the sleep is
//! never lost, because `FUTEX_WAIT` returns at once when the counter is no longer the value it
//! was told to sleep on.

use anyhow::{bail, Context};
use iceoryx2::prelude::{FileName, SemanticString, ZeroCopySend};
use iceoryx2_bb_concurrency::atomic::AtomicU32;
use iceoryx2_bb_posix::file::AccessMode;
use iceoryx2_cal::dynamic_storage::posix_shared_memory::Storage;
use iceoryx2_cal::dynamic_storage::{DynamicStorage, DynamicStorageBuilder};
use iceoryx2_cal::named_concept::NamedConceptBuilder;
use rustix::io::Errno;
use rustix::thread::futex;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// The two futex words of a ping-pong: how many pings and pongs were sent.
#[derive(Debug, ZeroCopySend)]
#[repr(C)]
#[type_name("sabr.FutexPingPong.v1")]
pub struct Counters {
    pings: AtomicU32,
    pongs: AtomicU32,
}

/// Which side of the ping-pong a process is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Sends pings, waits for pongs (the measuring side, owner of the segment).
    Ping,
    /// Waits for pings, answers with pongs.
    Pong,
}

/// One end of a futex ping-pong.
pub struct FutexEnd {
    storage: Storage<Counters>,
    side: Side,
    sent: u32,
}

impl FutexEnd {
    /// Creates the segment `name` (the ping side owns and removes it).
    pub fn create(name: &str) -> anyhow::Result<Self> {
        let storage =
            <Storage<Counters> as DynamicStorage<Counters>>::Builder::new(&file_name(name)?)
                .has_ownership(true)
                .initializer(|value, _| {
                    value.write(Counters {
                        pings: AtomicU32::new(0),
                        pongs: AtomicU32::new(0),
                    });
                    true
                })
                .create()
                .map_err(|e| anyhow::anyhow!("cannot create the futex segment {name}: {e:?}"))?;
        Ok(Self {
            storage,
            side: Side::Ping,
            sent: 0,
        })
    }

    /// Opens the segment `name` created by the ping side, waiting up to `timeout` for it.
    pub fn open(name: &str, timeout: Duration) -> anyhow::Result<Self> {
        let storage =
            <Storage<Counters> as DynamicStorage<Counters>>::Builder::new(&file_name(name)?)
                .timeout(timeout)
                .open(AccessMode::ReadWrite)
                .map_err(|e| anyhow::anyhow!("cannot open the futex segment {name}: {e:?}"))?;
        Ok(Self {
            storage,
            side: Side::Pong,
            sent: 0,
        })
    }

    fn words(&self) -> (&AtomicU32, &AtomicU32) {
        let counters = self.storage.get();
        match self.side {
            Side::Ping => (&counters.pings, &counters.pongs),
            Side::Pong => (&counters.pongs, &counters.pings),
        }
    }

    /// Sends one message: bumps this side's counter and wakes the other side.
    pub fn send(&mut self) -> anyhow::Result<()> {
        self.sent = self.sent.wrapping_add(1);
        let (own, _) = self.words();
        own.store(self.sent, Ordering::SeqCst);
        futex::wake(own, futex::Flags::empty(), 1).context("FUTEX_WAKE")?;
        Ok(())
    }

    /// Sleeps until the other side sent as many messages as this side (the answer to the
    /// last send, or the next ping), or `deadline` passes (an error: the peer hung or died).
    pub fn receive(&self, expected: u32, deadline: Instant) -> anyhow::Result<()> {
        let (_, other) = self.words();
        loop {
            let seen = other.load(Ordering::SeqCst);
            if seen == expected {
                return Ok(());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                bail!("no message {expected} from the peer (it sent {seen}) before the deadline");
            }
            let timeout = futex::Timespec {
                tv_sec: left.as_secs() as i64,
                tv_nsec: i64::from(left.subsec_nanos()),
            };
            match futex::wait(other, futex::Flags::empty(), seen, Some(&timeout)) {
                Ok(()) | Err(Errno::AGAIN | Errno::INTR | Errno::TIMEDOUT) => {}
                Err(error) => return Err(error).context("FUTEX_WAIT"),
            }
        }
    }

    /// Messages this side sent so far.
    pub fn sent(&self) -> u32 {
        self.sent
    }
}

fn file_name(name: &str) -> anyhow::Result<FileName> {
    FileName::new(name.as_bytes())
        .map_err(|e| anyhow::anyhow!("bad futex segment name {name:?}: {e:?}"))
}
