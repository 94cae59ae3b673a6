//! A mutex for Cortex-M3/M4/M7/M33 firmware that never masks the interrupts above a
//! priority ceiling (feature `basepri`).
//!
//! [`LinkMutex`](crate::LinkMutex), a critical section, masks every interrupt while the
//! link holds a lock: a motor or sensor interrupt waits behind it (on the send path of a
//! Cortex-M4 only the writer's wake-up, about 20 instructions; on a core without
//! compare-and-swap every bit operation of the queue and the arena, a few instructions
//! each; settings, registry and health locks elsewhere). [`BasepriRawMutex`] raises the processor's `BASEPRI` to a ceiling
//! instead (`msr BASEPRI_MAX`), the method RTIC uses: only interrupts at the ceiling's
//! priority or below wait, those above it (numerically lower priority values) run at once,
//! so the link never delays them. It is the third choice beside `LinkMutex` (senders
//! anywhere, everything masked briefly) and `ThreadModeRawMutex` (thread-mode senders
//! only, nothing masked):
//!
//! | mutex | who may send | what a lock delays |
//! |---|---|---|
//! | `LinkMutex` | any task of any executor, any interrupt handler | every interrupt |
//! | `BasepriRawMutex<C>` | thread mode and handlers at `C::PRIORITY` or below | handlers at `C::PRIORITY` or below |
//! | `ThreadModeRawMutex` | thread mode only (tasks of a thread-mode executor) | nothing |
//!
//! The ceiling is a type implementing [`Ceiling`]. Implementing it is `unsafe`: the
//! firmware promises that no code above the ceiling uses the link or its arena (sends,
//! releases a frame, reads statistics), which is what makes the mutex exclusive. A lock
//! taken above the ceiling anyway panics: each lock reads the active exception's priority
//! (nothing to read in thread mode) before raising `BASEPRI`.
//!
//! ```ignore
//! use pprz_default::messages::Set;
//! use pprz_telemetry::mutex::{BasepriRawMutex, Ceiling};
//! use pprz_telemetry::{FrameArena, Link};
//!
//! /// The link's senders: thread mode and the UART interrupt, at priority 0xC0
//! /// (embassy-stm32's `Priority::P12` on a 4-bit NVIC). Motor and IMU interrupts run
//! /// at 0x40 and are never masked by the link.
//! struct LinkCeiling;
//! // SAFETY: nothing at a priority above 0xC0 uses LINK or ARENA.
//! unsafe impl Ceiling for LinkCeiling {
//!     const PRIORITY: u8 = 0xC0;
//! }
//! type M = BasepriRawMutex<LinkCeiling>;
//! static ARENA: FrameArena<M, 4096> = FrameArena::new();
//! static LINK: Link<'static, Set, 32, 16, 8, M> = Link::new(&ARENA, 7);
//! ```
//!
//! Limits: one core (like `cortex-m`'s `critical-section-single-core`); privileged code
//! (an unprivileged `msr BASEPRI` is ignored); ARMv7-M and ARMv8-M mainline only (the
//! Cortex-M0/M0+/M23 have no `BASEPRI`: the crate does not build for them with this
//! feature). On a Cortex-M7 r0p1, enable `cortex-m`'s `cm7-r0p1` feature (its erratum
//! workaround for `BASEPRI_MAX`). `bash bench/m4/run.sh` measures the downlink with it.

// The crate denies `unsafe_code`; this module needs it for the `RawMutex` contract, the
// write that restores `BASEPRI`, and reads of the System Control Space. Each is justified.
#![allow(unsafe_code)]

use core::marker::PhantomData;

use cortex_m::register::{basepri, basepri_max};
use embassy_sync::blocking_mutex::raw::RawMutex;

/// The priority ceiling of a [`BasepriRawMutex`].
///
/// # Safety
///
/// No code running at a priority above `PRIORITY` (a numerically lower priority value,
/// or NMI and HardFault) may lock a mutex with this ceiling: it must not send on, read
/// or release anything of a link or arena that uses the mutex. Only one core may use it.
pub unsafe trait Ceiling: 'static {
    /// The value written to `BASEPRI` while a lock is held, as the NVIC priority
    /// registers hold it (the implemented bits at the top: 0xC0 is priority 12 of 16 on a
    /// 4-bit NVIC). Interrupts of this value or above (less urgent) wait. At least 0x20
    /// (a compile-time error otherwise): every ARMv7-M and ARMv8-M core implements the
    /// top three priority bits, so such a value always masks; a smaller one could read
    /// back as zero on a core with fewer bits (0x10 on a 3-bit NVIC) and mask nothing.
    const PRIORITY: u8;
}

/// A `RawMutex` that raises `BASEPRI` to `C::PRIORITY` while it is held; see the
/// [module documentation](self).
pub struct BasepriRawMutex<C: Ceiling> {
    // `fn() -> C`: the mutex holds no `C`, and is `Send` and `Sync` whatever `C` is.
    ceiling: PhantomData<fn() -> C>,
}

impl<C: Ceiling> BasepriRawMutex<C> {
    /// A new mutex (also [`RawMutex::INIT`]).
    pub const fn new() -> Self {
        let () = Self::VALID;
        Self {
            ceiling: PhantomData,
        }
    }

    const VALID: () = assert!(
        C::PRIORITY >= 0x20,
        "Ceiling::PRIORITY must be at least 0x20: a core may implement only the top three \
         priority bits, and a BASEPRI without them masks nothing"
    );
}

impl<C: Ceiling> Default for BasepriRawMutex<C> {
    fn default() -> Self {
        Self::new()
    }
}

// SAFETY: while `lock` runs `f`, BASEPRI is at least as restrictive as `C::PRIORITY`, so no
// exception of priority `C::PRIORITY` or lower can start on this core; every other locker
// runs at such a priority (thread mode included), by the `Ceiling` contract, which
// `check_ceiling` also enforces with a panic. So no second `f` can run until this one
// returns. Nested locks restore BASEPRI in reverse order.
unsafe impl<C: Ceiling> RawMutex for BasepriRawMutex<C> {
    const INIT: Self = Self::new();

    #[inline]
    fn lock<R>(&self, f: impl FnOnce() -> R) -> R {
        check_ceiling(C::PRIORITY);
        let saved = basepri::read();
        // Raises only (BASEPRI_MAX never lowers a more restrictive value); a compiler
        // barrier, so `f`'s memory accesses stay after it.
        basepri_max::write(C::PRIORITY);
        let result = f();
        // SAFETY: writes back the value read on entry, after `f`: it lowers BASEPRI only
        // to what it was when this lock was taken (0 in thread mode outside any lock), so
        // it cannot end an enclosing critical section early. A compiler barrier.
        unsafe { basepri::write(saved) };
        result
    }
}

/// Address of the Interrupt Control and State Register (VECTACTIVE in bits 0..9).
const ICSR: usize = 0xE000_ED04;
/// System Handler Priority Registers, one byte per exception from number 4.
const SHPR: usize = 0xE000_ED18;
/// NVIC Interrupt Priority Registers, one byte per interrupt.
const NVIC_IPR: usize = 0xE000_E400;

/// Panics if the active exception's priority is above `ceiling`.
#[inline]
fn check_ceiling(ceiling: u8) {
    // SAFETY: ICSR is an architecturally defined, always-implemented 32-bit register of the
    // System Control Space on ARMv7-M and ARMv8-M; reading it has no side effect.
    let active = unsafe { core::ptr::read_volatile(ICSR as *const u32) } & 0x1FF;
    if active == 0 {
        return; // thread mode: the lowest priority there is
    }
    let register = match active {
        4..=15 => SHPR + active as usize - 4,
        16.. => NVIC_IPR + active as usize - 16,
        // NMI and HardFault: above every configurable priority.
        _ => panic!("BasepriRawMutex locked by NMI or HardFault"),
    };
    // SAFETY: SHPR bytes for exceptions 4..=15 and NVIC_IPR bytes for interrupts 0..=495
    // are architecturally defined byte-readable registers of the System Control Space (an
    // interrupt the device lacks reads as zero); reading them has no side effect.
    let priority = unsafe { core::ptr::read_volatile(register as *const u8) };
    assert!(
        priority >= ceiling,
        "BasepriRawMutex locked by an exception above its ceiling"
    );
}
