//! Read-modify-write on `AtomicU32` for every core the crate supports: the core's own
//! instructions where it has them (compare-and-swap, or load/store-exclusive), and a
//! short lock of the caller's mutex where it has not (ARMv6-M, RV32IMC): loads and stores
//! are atomic on every target, so the lock only has to keep other writers out.
//!
//! The queue and the counters are written with these, so that on the cores with
//! compare-and-swap no lock of the send path masks interrupts for them.

use core::sync::atomic::AtomicU32;
use core::sync::atomic::Ordering;
#[cfg(not(target_has_atomic = "32"))]
use core::sync::atomic::Ordering::SeqCst;
#[cfg(target_has_atomic = "32")]
use core::sync::atomic::Ordering::{Acquire, Relaxed};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;

/// The lock used in place of read-modify-write instructions on cores without them
/// (never taken on the others: a zero-sized field for the usual mutexes).
pub(crate) type Fallback<M> = Mutex<M, ()>;

/// Adds `v` (wrapping) to a counter, returning the previous value; no ordering with other
/// memory.
#[inline]
pub(crate) fn add<M: RawMutex>(_lock: &Fallback<M>, a: &AtomicU32, v: u32) -> u32 {
    #[cfg(target_has_atomic = "32")]
    return a.fetch_add(v, Relaxed);
    #[cfg(not(target_has_atomic = "32"))]
    locked(_lock, a, |old| Some(old.wrapping_add(v))).unwrap_or_else(|old| old)
}

/// `a |= v` with `order`, returning the previous value.
#[inline]
pub(crate) fn or<M: RawMutex>(_lock: &Fallback<M>, a: &AtomicU32, v: u32, order: Ordering) -> u32 {
    #[cfg(target_has_atomic = "32")]
    return a.fetch_or(v, order);
    #[cfg(not(target_has_atomic = "32"))]
    let _ = order;
    #[cfg(not(target_has_atomic = "32"))]
    locked(_lock, a, |old| Some(old | v)).unwrap_or_else(|old| old)
}

/// `a &= v` with `order`, returning the previous value.
#[inline]
pub(crate) fn and<M: RawMutex>(_lock: &Fallback<M>, a: &AtomicU32, v: u32, order: Ordering) -> u32 {
    #[cfg(target_has_atomic = "32")]
    return a.fetch_and(v, order);
    #[cfg(not(target_has_atomic = "32"))]
    let _ = order;
    #[cfg(not(target_has_atomic = "32"))]
    locked(_lock, a, |old| Some(old & v)).unwrap_or_else(|old| old)
}

/// Replaces the value `v` of `a` with `f(v)` unless `f` returns `None`, atomically, with
/// `order` (a failed update acquires if `order` does); returns the value `f` saw last,
/// `Ok` if it was replaced.
#[inline]
pub(crate) fn update<M: RawMutex>(
    _lock: &Fallback<M>,
    a: &AtomicU32,
    order: Ordering,
    f: impl FnMut(u32) -> Option<u32>,
) -> Result<u32, u32> {
    #[cfg(target_has_atomic = "32")]
    {
        let failure = match order {
            Ordering::Acquire | Ordering::AcqRel | Ordering::SeqCst => Acquire,
            _ => Relaxed,
        };
        #[allow(deprecated)] // `try_update` on newer toolchains; the same operation
        return a.fetch_update(order, failure, f);
    }
    #[cfg(not(target_has_atomic = "32"))]
    let _ = order;
    #[cfg(not(target_has_atomic = "32"))]
    locked(_lock, a, f)
}

/// The fallback of every operation above: a load and, unless `f` returns `None`, a store
/// of `f`'s value, under the lock; the value seen, `Ok` if it was replaced.
#[cfg(not(target_has_atomic = "32"))]
fn locked<M: RawMutex>(
    lock: &Fallback<M>,
    a: &AtomicU32,
    mut f: impl FnMut(u32) -> Option<u32>,
) -> Result<u32, u32> {
    lock.lock(|()| {
        let old = a.load(SeqCst);
        match f(old) {
            Some(new) => {
                a.store(new, SeqCst);
                Ok(old)
            }
            None => Err(old),
        }
    })
}
