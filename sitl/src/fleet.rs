//! The fleet (`--fleet 2`): aircraft 8 flies beside aircraft 7, out of the ground's
//! reach, and 7 relays between its two radios. Here: the second aircraft's id and 7's
//! routes (each aircraft's own figures are in `figures.rs`).

use pprz_example_app::AC_ID;
use pprz_telemetry::{Routes, Targets};

/// The id of the fleet's second aircraft (`--fleet 2`), reachable only through
/// aircraft 7 ([`AC_ID`]).
pub const SECOND_AC_ID: u8 = 8;

/// Aircraft 7's routes with `--fleet 2`: aircraft 8 through its second radio, the ground
/// (and any other) through the first, broadcast on both.
static FLEET_ROUTES: [(u8, Targets); 1] = [(SECOND_AC_ID, Targets::only(1))];

/// Aircraft 7's routes: with a `fleet`, [`FLEET_ROUTES`]; alone, everything on the radio
/// (device 1 stays idle).
pub fn routes(fleet: bool) -> Routes<'static> {
    if fleet {
        Routes::new(&FLEET_ROUTES, Targets::only(0))
    } else {
        Routes::new(&[], Targets::only(0)).broadcast(Targets::only(0))
    }
}

/// The ids of the aircraft the ground PINGs and sets.
pub fn ids(fleet: u8) -> &'static [u8] {
    if fleet > 1 {
        &[AC_ID, SECOND_AC_ID]
    } else {
        &[AC_ID]
    }
}
