//! The code generated from the full PPRZLINK reference `messages.xml` (all 367 messages,
//! 5 classes), compiled to prove the generator handles every real message, and tested
//! (round trips, malformed payloads) in `tests/`. Its generated `Set` must fill every role
//! of `pprz_messages::roles` (checked at compile time below).
//!
//! Not published. When the reference data is absent the crate is empty and its tests
//! print why they are skipped.
//!
//! ```
//! #[cfg(pprz_reference)]
//! assert_eq!(pprz_reference_check::MESSAGES.len(), 367);
//! ```

#![no_std]

#[cfg(pprz_reference)]
include!(concat!(env!("OUT_DIR"), "/reference.rs"));

/// The reference set fills both roles: the runtime's services and link report run on it.
#[cfg(pprz_reference)]
const _: () = {
    fn fills_every_role<
        S: pprz_messages::roles::ServiceSet + pprz_messages::roles::LinkReportSet,
    >() {
    }
    let _ = fills_every_role::<Set>;
};
