//! The fleet (`--fleet N`): aircraft 7 to 7 + N - 1, each on a radio of its own to the
//! ground; or, with `--relay` and two aircraft, aircraft 8 out of the ground's reach and
//! 7 relaying between its two radios. Here: the fleet's ids, the radios' seeds and 7's
//! routes (the aircraft are built in `aircraft.rs`, their figures are in `figures.rs`).

use pprz_devices::rng::SplitMix64;
use pprz_example_app::AC_ID;
use pprz_telemetry::{Routes, Targets};

/// Most aircraft in a fleet: as many as the ground's monitor tracks.
pub const MAX_FLEET: u8 = pprz_ground::monitor::MAX_AIRCRAFT as u8;

/// The id of the fleet's second aircraft, the one aircraft 7 relays for with `--relay`.
pub const SECOND_AC_ID: u8 = AC_ID + 1;

/// Aircraft 7's routes with `--relay`: aircraft 8 through its second radio, the ground
/// (and any other) through the first, broadcast on both.
static RELAY_ROUTES: [(u8, Targets); 1] = [(SECOND_AC_ID, Targets::only(1))];

/// An aircraft's routes: aircraft 7 relaying (`--relay`), [`RELAY_ROUTES`]; otherwise
/// everything on its radio to the ground (device 0), and with `radios` 2 on its second
/// radio too (device 1, idle with one radio).
pub fn routes(relay: bool, radios: u8) -> Routes<'static> {
    if relay {
        return Routes::new(&RELAY_ROUTES, Targets::only(0));
    }
    let ground = if radios > 1 {
        Targets::only(0).with(1)
    } else {
        Targets::only(0)
    };
    Routes::new(&[], ground).broadcast(ground)
}

/// The id of the fleet's aircraft number `index` (0: aircraft 7).
pub fn id(index: u8) -> u8 {
    AC_ID + index
}

/// The ids of a fleet of `size` aircraft, the ones the ground PINGs and sets.
pub fn ids(size: u8) -> Vec<u8> {
    (0..size).map(id).collect()
}

/// The seed of radio number `index` (0: aircraft 7's radio to the ground; then each
/// other aircraft's), derived from `--seed`: the same for the same options, and far
/// apart from the other radios' so their errors are independent.
pub fn radio_seed(seed: u64, index: u8) -> u64 {
    // One SplitMix64 step from a start that differs per radio by the generator's own
    // increment: the outputs of consecutive starts are uncorrelated.
    let start = seed.wrapping_add(u64::from(index).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    SplitMix64::new(start).next_u64()
}

/// The seed index of the second radio (`--radios 2`) of the fleet's aircraft number
/// `index`: after every first radio, so every radio of the run has its own.
pub fn second_radio(index: u8) -> u8 {
    MAX_FLEET + index
}

/// The seed of the frame losses (`--frame-loss`) of radio number `radio` in one
/// direction: apart from its bit errors' seed and from the other direction's.
pub fn loss_seed(seed: u64, radio: u8, up: bool) -> u64 {
    let salt: u64 = if up {
        0x5550_4C49_4E4B_0001
    } else {
        0x444F_574E_4C4B_0002
    };
    radio_seed(seed ^ salt, radio)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_run_from_7_and_seeds_differ_per_radio() {
        assert_eq!(ids(1), [7]);
        assert_eq!(ids(3), [7, 8, 9]);
        assert_eq!(ids(MAX_FLEET).last(), Some(&38));
        let seeds: Vec<u64> = (0..MAX_FLEET).map(|i| radio_seed(7, i)).collect();
        let mut distinct = seeds.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), seeds.len());
        // Reproducible, and another --seed gives other seeds.
        assert_eq!(radio_seed(7, 3), seeds[3]);
        assert_ne!(radio_seed(8, 3), seeds[3]);
        // The second radios and the losses have seeds of their own.
        assert!(!seeds.contains(&radio_seed(7, second_radio(0))));
        assert_ne!(loss_seed(7, 0, true), loss_seed(7, 0, false));
        assert!(!seeds.contains(&loss_seed(7, 0, false)));
    }
}
