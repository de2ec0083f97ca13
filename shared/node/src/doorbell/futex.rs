//! The wake-up mechanism of the doorbell: one futex word in the listener's shared memory.
//!
//! iceoryx2's generic event ([`EventImpl`]) keeps the event ids (a counting bit set) and a
//! notification state in a shared-memory segment owned by the listener, and leaves the actual
//! sleeping and waking to a trigger. Its semaphore trigger waits with a timeout by polling,
//! its socket triggers cost several system calls per wake-up; this trigger is a futex with a
//! relative timeout (`FUTEX_WAIT` measures it on `CLOCK_MONOTONIC`):
//!
//! - the word is [`EMPTY`], [`RUNG`] (a notifier rang since the last wait) or [`SLEEPING`]
//!   (the one listener is, or is about to be, blocked in `FUTEX_WAIT`);
//! - ringing swaps in `RUNG` and makes the `FUTEX_WAKE` system call only if the listener
//!   sleeps, so a producer ringing a busy consumer makes no system call at all (and
//!   [`EventImpl`] skips the trigger entirely while a notification is still unread);
//! - waiting consumes `RUNG` without a system call, else announces `SLEEPING` and sleeps
//!   until woken, the timeout, or a signal.

// Implementing iceoryx2's trigger traits needs `unsafe fn` declarations (`remove`,
// `abandon_in_place`; both do nothing here) and one lifetime extension per side, explained
// at each `unsafe` block.
#![allow(unsafe_code)]

use core::mem::MaybeUninit;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicU32, Ordering};
use core::time::Duration;
use iceoryx2::prelude::{FileName, Path, ZeroCopySend};
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_lock_free::mpmc::counting_bit_set::RelocatableCountingBitSet;
use iceoryx2_cal::dynamic_storage::posix_shared_memory;
use iceoryx2_cal::event::common::EventImpl;
use iceoryx2_cal::event::trigger::{Configuration, HandlerInterface, State, WaiterInterface};
use iceoryx2_cal::event::{
    ListenerCreateError, ListenerWaitError, NotifierNotifyError, NotifierOpenError,
};
use iceoryx2_cal::named_concept::{NamedConceptPathHintRemoveError, NamedConceptRemoveError};
use rustix::io::Errno;
use rustix::thread::futex;

/// Nothing rang since the last wait.
const EMPTY: u32 = 0;
/// A notifier rang since the last wait.
const RUNG: u32 = 1;
/// The listener sleeps (or is about to) in `FUTEX_WAIT` on the word.
const SLEEPING: u32 = 2;

/// The futex word, placed by iceoryx2 in the listener's shared-memory segment.
#[derive(Debug, ZeroCopySend)]
#[repr(C)]
#[type_name("sabr.FutexWord.v1")]
pub struct FutexWord {
    state: iceoryx2_bb_concurrency::atomic::AtomicU32,
}

impl FutexWord {
    fn word(&self) -> &AtomicU32 {
        &self.state
    }
}

/// The event state: iceoryx2's counting bit set of event ids.
type Ids = RelocatableCountingBitSet;
/// The shared-memory segment of one listener: event ids, notification state, futex word.
type Storage = posix_shared_memory::Storage<State<Ids, FutexWord>>;

/// The iceoryx2 event concept of the doorbell service variant.
pub type FutexEvent = EventImpl<Ids, FutexWord, Storage, FutexRinger, FutexWaiter>;

/// The notifier side: rings the futex word.
#[derive(Debug)]
pub struct FutexRinger {
    word: &'static FutexWord,
}

/// The listener side: sleeps on the futex word.
#[derive(Debug)]
pub struct FutexWaiter {
    word: &'static FutexWord,
}

/// Extends the lifetime of the futex word in a listener's segment to that of the trigger.
///
/// # Safety
///
/// iceoryx2's `EventImpl` stores the trigger next to the `Storage` that maps the segment
/// (`Handle { handle, storage }`, `Waiter { waiter, storage }`) and never hands the trigger
/// out, so the mapping outlives every use of the reference; the reference never leaves the
/// trigger.
unsafe fn in_segment(word: &FutexWord) -> &'static FutexWord {
    // SAFETY: see the function's contract above.
    unsafe { &*(word as *const FutexWord) }
}

impl Abandonable for FutexRinger {
    unsafe fn abandon_in_place(_this: NonNull<Self>) {}
}

impl Abandonable for FutexWaiter {
    unsafe fn abandon_in_place(_this: NonNull<Self>) {}
}

impl HandlerInterface<Ids, FutexWord, Storage> for FutexRinger {
    fn open(
        _name: &FileName,
        _config: &Configuration,
        mgmt: &FutexWord,
    ) -> Result<Self, NotifierOpenError> {
        // SAFETY: `mgmt` lies in the segment the notifier's `Handle` keeps mapped.
        Ok(Self {
            word: unsafe { in_segment(mgmt) },
        })
    }

    fn notify(&self) -> Result<(), NotifierNotifyError> {
        if self.word.word().swap(RUNG, Ordering::SeqCst) == SLEEPING {
            futex::wake(self.word.word(), futex::Flags::empty(), 1)
                .map_err(|_| NotifierNotifyError::InternalFailure)?;
        }
        Ok(())
    }
}

impl FutexWaiter {
    /// Consumes a ring without sleeping; true if there was one.
    fn take_ring(&self) -> bool {
        self.word.word().swap(EMPTY, Ordering::SeqCst) == RUNG
    }

    /// Sleeps until rung, `timeout` (`None`: forever) or a signal.
    fn sleep(&self, timeout: Option<Duration>) -> Result<(), ListenerWaitError> {
        let word = self.word.word();
        if self.take_ring() {
            return Ok(());
        }
        if word
            .compare_exchange(EMPTY, SLEEPING, Ordering::SeqCst, Ordering::SeqCst)
            .is_err()
        {
            // Rung between the two steps.
            self.take_ring();
            return Ok(());
        }
        let timespec = timeout.map(|t| futex::Timespec {
            tv_sec: t.as_secs().min(i64::MAX as u64) as i64,
            tv_nsec: i64::from(t.subsec_nanos()),
        });
        let result = futex::wait(word, futex::Flags::empty(), SLEEPING, timespec.as_ref());
        // Whatever woke us, leave the word empty: a ring that raced with the timeout or the
        // signal still has its event id set, which the caller drains next.
        word.store(EMPTY, Ordering::SeqCst);
        match result {
            // Woken, rung before we slept, spuriously woken, or timed out: the caller
            // looks at the event ids either way.
            Ok(()) | Err(Errno::AGAIN) | Err(Errno::TIMEDOUT) => Ok(()),
            Err(Errno::INTR) => Err(ListenerWaitError::InterruptSignal),
            Err(_) => Err(ListenerWaitError::InternalFailure),
        }
    }
}

impl WaiterInterface<Ids, FutexWord, Storage> for FutexWaiter {
    const IS_FILE_DESCRIPTOR_BASED: bool = false;

    unsafe fn remove(
        _name: &FileName,
        _config: &Configuration,
    ) -> Result<bool, NamedConceptRemoveError> {
        // The word lives in the segment, which iceoryx2 removes with the event.
        Ok(true)
    }

    fn remove_path_hint(_value: &Path) -> Result<(), NamedConceptPathHintRemoveError> {
        Ok(())
    }

    fn create(
        _name: &FileName,
        _config: &Configuration,
        mgmt: &mut MaybeUninit<FutexWord>,
    ) -> Result<Self, ListenerCreateError> {
        let word = mgmt.write(FutexWord {
            state: iceoryx2_bb_concurrency::atomic::AtomicU32::new(EMPTY),
        });
        // SAFETY: `mgmt` lies in the segment the listener's `Waiter` keeps mapped.
        Ok(Self {
            word: unsafe { in_segment(word) },
        })
    }

    fn try_wait(&self) -> Result<(), ListenerWaitError> {
        self.take_ring();
        Ok(())
    }

    fn timed_wait(&self, timeout: Duration) -> Result<(), ListenerWaitError> {
        self.sleep(Some(timeout))
    }

    fn blocking_wait(&self) -> Result<(), ListenerWaitError> {
        self.sleep(None)
    }

    fn empty_buffer(&self) -> Result<(), ListenerWaitError> {
        self.word.word().store(EMPTY, Ordering::SeqCst);
        Ok(())
    }
}
