//! Routes: which devices of a [`Downlink`](crate::Downlink) a frame goes out on.
//!
//! [`Targets`] is a set of device indices. [`Routes`] is the aircraft's static route
//! table: destination id -> devices, a default route (normally to the ground) and the
//! devices a broadcast goes out on. A send without an explicit device set follows the
//! route of its destination ([`SendOptions::to`](crate::SendOptions::to)); the
//! [relay](crate::relay) forwards other aircraft's frames on the same table.
//!
//! ```
//! use pprz_telemetry::{Routes, Targets};
//! use pprz_telemetry::pprz_transports::{BROADCAST_ID, GROUND_ID};
//!
//! // Device 0 is the radio to the ground, device 1 the radio to aircraft 8.
//! static TABLE: [(u8, Targets); 1] = [(8, Targets::only(1))];
//! const ROUTES: Routes<'static> = Routes::new(&TABLE, Targets::only(0));
//! assert_eq!(ROUTES.to(8), Targets::only(1));
//! assert_eq!(ROUTES.to(GROUND_ID), Targets::only(0));
//! assert_eq!(ROUTES.to(BROADCAST_ID), Targets::ALL);
//! ```

use pprz_transports::{BROADCAST_ID, GROUND_ID};

/// A set of device indices (bit `i` = device `i`, up to 32 devices).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Targets(u32);

impl Targets {
    /// Every device.
    pub const ALL: Targets = Targets(u32::MAX);
    /// No device.
    pub const NONE: Targets = Targets(0);

    /// Only device `index` (no device if `index >= 32`).
    pub const fn only(index: usize) -> Self {
        Self::NONE.with(index)
    }

    /// This set plus device `index`.
    pub const fn with(self, index: usize) -> Self {
        if index < 32 {
            Targets(self.0 | (1 << index))
        } else {
            self
        }
    }

    /// Whether device `index` is in the set.
    pub const fn contains(&self, index: usize) -> bool {
        index < 32 && self.0 & (1 << index) != 0
    }

    /// A set from raw bits (bit `i` = device `i`).
    pub const fn from_bits(bits: u32) -> Self {
        Targets(bits)
    }

    /// The raw bit set.
    pub const fn bits(&self) -> u32 {
        self.0
    }
}

/// The route table of an aircraft: which devices lead to which destination. `const`, so
/// it can be given to a `static` [`Downlink`](crate::Downlink); see the
/// [module documentation](self).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Routes<'r> {
    table: &'r [(u8, Targets)],
    default: Targets,
    broadcast: Targets,
}

impl Routes<'static> {
    /// No table: every device leads to every destination, broadcast included (one radio,
    /// or a radio and a log).
    pub const DIRECT: Self = Self {
        table: &[],
        default: Targets::ALL,
        broadcast: Targets::ALL,
    };
}

impl<'r> Routes<'r> {
    /// `table` gives the devices leading to each listed destination (the first entry for
    /// a destination counts), `default` those leading to any other (the way to the
    /// ground, unless the table lists [`GROUND_ID`]); broadcast goes out on every device.
    pub const fn new(table: &'r [(u8, Targets)], default: Targets) -> Self {
        Self {
            table,
            default,
            broadcast: Targets::ALL,
        }
    }

    /// With broadcast frames going out on `targets` only.
    pub const fn broadcast(mut self, targets: Targets) -> Self {
        self.broadcast = targets;
        self
    }

    /// The devices leading to `destination`.
    pub fn to(&self, destination: u8) -> Targets {
        if destination == BROADCAST_ID {
            return self.broadcast;
        }
        self.table
            .iter()
            .find(|(id, _)| *id == destination)
            .map_or(self.default, |(_, targets)| *targets)
    }

    /// The devices leading to the ground.
    pub fn to_ground(&self) -> Targets {
        self.to(GROUND_ID)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets() {
        let t = Targets::only(1).with(3);
        assert!(t.contains(1) && t.contains(3) && !t.contains(0));
        assert_eq!(Targets::only(40), Targets::NONE);
        assert!(Targets::ALL.contains(31));
    }
}
