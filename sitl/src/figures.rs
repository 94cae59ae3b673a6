//! Each aircraft's own figures, read from the downlinks and the run's record: per
//! priority level for the viewer's link statistics, and per aircraft and route for the
//! fleet's summary (`--fleet N`).

use pprz_example_app::AC_ID;
use pprz_ground::viewer::LevelFigures;
use pprz_telemetry::DeviceStats;
use pprz_telemetry::pprz_messages::priority;

use crate::aircraft::{Aircraft, RELAY_COUNTERS, Wing};
use crate::record::{self, Record};
use crate::summary::{
    AircraftFigures, AircraftLevel, FleetFigures, PingFigures, RelayFigures, RouteFigures,
};

/// The aircraft's own figures per priority level (what it submitted, sent and shed of
/// its own messages; frames it relays are the other aircraft's), for the viewer's link
/// statistics.
pub fn aircraft_levels(ac: u8, aircraft: &Aircraft) -> Option<[LevelFigures; 3]> {
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
        let s = aircraft.downlink.stats(0)?;
        Some(figures(&|i| {
            let (all, relayed) = (s.levels[i], s.relayed.levels[i]);
            (
                all.submitted.saturating_sub(relayed.submitted),
                all.sent.saturating_sub(relayed.sent),
                all.lost.saturating_sub(relayed.lost),
            )
        }))
    } else {
        let s = aircraft.wing(ac)?.downlink.stats(0)?;
        Some(figures(&|i| {
            let l = s.levels[i];
            (l.submitted, l.sent, l.lost)
        }))
    }
}

/// The PINGs to aircraft `ac`, from the record.
fn ping(record: &Record, ac: u8) -> PingFigures {
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
}

/// A fleet (`--fleet 2` or more): each aircraft per level, from its downlink's
/// statistics and the record of what reached the ground; with `--relay`, what aircraft
/// 7 forwarded for 8 (7's radio device counts 8's frames apart: `DeviceStats::relayed`),
/// its routes and its relay's decisions.
pub fn fleet_figures(aircraft: &Aircraft) -> FleetFigures {
    let radio_7 = aircraft.downlink.stats(0).unwrap_or_default();
    let link_7 = aircraft.downlink.stats(1).unwrap_or_default();
    let wings: Vec<(&Wing, DeviceStats)> = aircraft
        .wings
        .iter()
        .map(|w| (w, w.downlink.stats(0).unwrap_or_default()))
        .collect();
    let record = record::lock();
    let received = |ac: u8, i: usize| record.aircraft.get(&ac).map_or(0, |a| a.received[i]);
    let names = priority::LEVEL_NAMES;
    let own_7 = |i: usize| {
        let (all, relayed) = (radio_7.levels[i], radio_7.relayed.levels[i]);
        AircraftLevel {
            level: names[i],
            submitted: all.submitted.saturating_sub(relayed.submitted),
            sent: all.sent.saturating_sub(relayed.sent),
            shed: all.lost.saturating_sub(relayed.lost),
            forwarded: 0,
            shed_by_relay: 0,
            received: received(AC_ID, i),
        }
    };
    let mut each = vec![AircraftFigures {
        ac_id: AC_ID,
        relayed_by: None,
        levels: [own_7(0), own_7(1), own_7(2)],
        ping: ping(&record, AC_ID),
    }];
    for (w, stats) in &wings {
        let of_wing = |i: usize| {
            let own = stats.levels[i];
            // Only the relayed aircraft's frames are relayed by 7.
            let relayed = if w.relayed {
                radio_7.relayed.levels[i]
            } else {
                Default::default()
            };
            AircraftLevel {
                level: names[i],
                submitted: own.submitted,
                sent: own.sent,
                shed: own.lost,
                forwarded: relayed.submitted,
                shed_by_relay: relayed.lost,
                received: received(w.id, i),
            }
        };
        each.push(AircraftFigures {
            ac_id: w.id,
            relayed_by: w.relayed.then_some(AC_ID),
            levels: [of_wing(0), of_wing(1), of_wing(2)],
            ping: ping(&record, w.id),
        });
    }
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
    let relayed = aircraft.relayed();
    FleetFigures {
        aircraft: each,
        routes: relayed
            .map(|w| {
                vec![
                    route("ground".to_owned(), &radio_7),
                    route(format!("aircraft {}", w.id), &link_7),
                ]
            })
            .unwrap_or_default(),
        relay: relayed.map(|_| relay_figures()),
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
        broadcast_source: r.broadcast_source,
        malformed: r.malformed,
    }
}
