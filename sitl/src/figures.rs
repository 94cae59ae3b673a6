//! Each aircraft's own figures, read from the downlinks and the run's record: per
//! priority level for the viewer's link statistics, and per aircraft and route for the
//! fleet's summary (`--fleet 2`).

use pprz_example_app::AC_ID;
use pprz_ground::viewer::LevelFigures;
use pprz_telemetry::DeviceStats;
use pprz_telemetry::pprz_messages::priority;

use crate::aircraft::{Dl, Dl8, RELAY_COUNTERS};
use crate::fleet::SECOND_AC_ID;
use crate::record;
use crate::summary::{
    AircraftFigures, AircraftLevel, FleetFigures, PingFigures, RelayFigures, RouteFigures,
};

/// The aircraft's own figures per priority level (what it submitted, sent and shed of
/// its own messages; frames it relays are the other aircraft's), for the viewer's link
/// statistics.
pub fn aircraft_levels(ac: u8, downlink: &Dl, second: Option<&Dl8>) -> Option<[LevelFigures; 3]> {
    let figures = |f: &dyn Fn(usize) -> (u32, u32, u32)| {
        [0, 1, 2].map(|i| {
            let (submitted, sent, shed) = f(i);
            LevelFigures {
                submitted: submitted.into(),
                sent: sent.into(),
                shed: shed.into(),
            }
        })
    };
    if ac == AC_ID {
        let s = downlink.stats(0)?;
        Some(figures(&|i| {
            let (all, relayed) = (s.levels[i], s.relayed.levels[i]);
            (
                all.submitted.saturating_sub(relayed.submitted),
                all.sent.saturating_sub(relayed.sent),
                all.lost.saturating_sub(relayed.lost),
            )
        }))
    } else if ac == SECOND_AC_ID {
        let s = second?.stats(0)?;
        Some(figures(&|i| {
            let l = s.levels[i];
            (l.submitted, l.sent, l.lost)
        }))
    } else {
        None
    }
}

/// `--fleet 2`: aircraft 7 (relay) and 8 per level, from their downlinks' statistics
/// (7's radio device counts 8's frames apart: `DeviceStats::relayed`) and the record of
/// what reached the ground.
pub fn fleet_figures(downlink_7: &Dl, downlink_8: &Dl8) -> FleetFigures {
    let radio_7 = downlink_7.stats(0).unwrap_or_default();
    let link_7 = downlink_7.stats(1).unwrap_or_default();
    let radio_8 = downlink_8.stats(0).unwrap_or_default();
    let record = record::lock();
    let received = |ac: u8, i: usize| record.aircraft.get(&ac).map_or(0, |a| a.received[i]);
    let ping = |ac: u8| {
        record
            .aircraft
            .get(&ac)
            .map_or_else(PingFigures::default, |a| PingFigures {
                sent: a.pings.sent_count(),
                answered: a.pings.answered(),
                lost: a.pings.lost(),
                rtt_p50_ms: a.rtt.percentile_ms(50.0),
                rtt_p99_ms: a.rtt.percentile_ms(99.0),
            })
    };
    let names = priority::LEVEL_NAMES;
    let own_7 = |i: usize| {
        let (all, relayed) = (radio_7.levels[i], radio_7.relayed.levels[i]);
        AircraftLevel {
            level: names[i],
            submitted: all.submitted - relayed.submitted,
            sent: all.sent - relayed.sent,
            shed: all.lost - relayed.lost,
            forwarded: 0,
            shed_by_relay: 0,
            received: received(AC_ID, i),
        }
    };
    let of_8 = |i: usize| {
        let (own, relayed) = (radio_8.levels[i], radio_7.relayed.levels[i]);
        AircraftLevel {
            level: names[i],
            submitted: own.submitted,
            sent: own.sent,
            shed: own.lost,
            forwarded: relayed.submitted,
            shed_by_relay: relayed.lost,
            received: received(SECOND_AC_ID, i),
        }
    };
    let route = |to: String, s: &DeviceStats| {
        let r = &s.relayed;
        RouteFigures {
            relay: AC_ID,
            to,
            forwarded: r.levels.map(|l| l.submitted),
            sent: r.sent,
            shed: r.levels.map(|l| l.lost),
            queue_full: r.dropped.queue_full,
            arena_full: r.dropped.arena_full,
            evicted: r.evicted.total(),
        }
    };
    FleetFigures {
        aircraft: vec![
            AircraftFigures {
                ac_id: AC_ID,
                relayed_by: None,
                levels: [own_7(0), own_7(1), own_7(2)],
                ping: ping(AC_ID),
            },
            AircraftFigures {
                ac_id: SECOND_AC_ID,
                relayed_by: Some(AC_ID),
                levels: [of_8(0), of_8(1), of_8(2)],
                ping: ping(SECOND_AC_ID),
            },
        ],
        routes: vec![
            route("ground".to_owned(), &radio_7),
            route(format!("aircraft {SECOND_AC_ID}"), &link_7),
        ],
        relay: relay_figures(),
    }
}

/// What aircraft 7's relay forwarded and refused, per reason.
fn relay_figures() -> RelayFigures {
    let r = RELAY_COUNTERS.get();
    RelayFigures {
        ac_id: AC_ID,
        forwarded: r.forwarded,
        broadcast: r.broadcast,
        refused: r.refused(),
        no_route: r.no_route,
        reverse_path: r.reverse_path,
        own_source: r.own_source,
        malformed: r.malformed,
    }
}
