//! The end of a run: the figures collected into a [`Summary`], printed after the last
//! view of the ground, and written as JSON with `--summary-json`.

use std::fs::File;
use std::io::Write as _;
use std::path::PathBuf;

use embassy_time::Instant;
use pprz_default::messages::MESSAGES;
use pprz_devices::sim::Direction;
use pprz_ground::monitor::Monitor;

use crate::merge::{AircraftDelivery, GatewayFigures, LinkFigures, Merge};
use pprz_telemetry::DeviceStats;
use pprz_telemetry::pprz_messages::priority;

use crate::aircraft::{Aircraft, SECURE};
use crate::bridge;
use crate::figures;
use crate::link;
use crate::options::{Args, FlowControl};
use crate::radio::RadioPlan;
use crate::record;
use crate::summary::{
    DeliveryFigures, DownlinkFigures, Level, Levels, MessageFigures, ModemFigures, PingFigures,
    RunConfig, SecureFigures, Summary,
};

/// The file of `--summary-json`, created before the run (a bad path fails before the
/// run, not after it).
pub struct JsonFile {
    path: PathBuf,
    file: File,
}

impl JsonFile {
    /// Creates the file of `--summary-json`, if given; fails with the message to print.
    pub fn create(args: &Args) -> Result<Option<Self>, String> {
        let Some(path) = &args.summary_json else {
            return Ok(None);
        };
        match File::create(path) {
            Ok(file) => Ok(Some(Self {
                path: path.clone(),
                file,
            })),
            Err(e) => Err(cannot_write(path, &e)),
        }
    }

    /// Writes `summary`; fails with the message to print.
    pub fn write(mut self, summary: &Summary) -> Result<(), String> {
        self.file
            .write_all(summary.json().as_bytes())
            .map_err(|e| cannot_write(&self.path, &e))
    }
}

/// The message of a summary file that cannot be written.
fn cannot_write(path: &std::path::Path, e: &std::io::Error) -> String {
    format!("cannot write the summary to {}: {e}", path.display())
}

/// Prints the end of the run: the ground's last view (live table), the summary, and the
/// ground station's own view of its PINGs and of the secure link. Returns the summary.
pub fn print(
    args: &Args,
    plan: &RadioPlan,
    aircraft: &Aircraft,
    merge: Option<&Merge>,
    now: f64,
) -> Summary {
    let monitor = merge.map(Merge::monitor);
    if let Some(m) = monitor
        && !args.lines
    {
        print!("\x1b[2J\x1b[H{}", m.render(now));
    }
    let mut summary = collect_summary(args, plan, aircraft);
    summary.gateway = merge.and_then(|m| gateway_figures(args, aircraft, m));
    print!("{}", summary.text());
    if let Some(line) = crate::persist::summary_line(args) {
        print!("{line}");
    }
    if let Some(m) = monitor {
        ground_lines(m, &summary);
    }
    summary
}

/// The ground station's lines of the summary: its PINGs per aircraft, and its end of the
/// secure link.
fn ground_lines(m: &Monitor, summary: &Summary) {
    let mut sent = 0;
    for ac in m.aircraft() {
        if let Some(pings) = m.aircraft_state(ac).map(|a| a.pings()) {
            sent += pings.sent_count();
            println!(
                "  ground station, aircraft {ac}: PINGs sent {}, answered {}, lost {}",
                pings.sent_count(),
                pings.answered(),
                pings.lost()
            );
        }
    }
    if let Some(line) = pings_not_up(
        sent,
        radio_pings(summary),
        bridge::uplink_datagrams_dropped(),
    ) {
        println!("{line}");
    }
    for line in m.secure_lines() {
        println!("  ground station {line}");
    }
}

/// The PINGs that went up the radio, to every aircraft.
fn radio_pings(summary: &Summary) -> u64 {
    match &summary.fleet {
        Some(fleet) => fleet.aircraft.iter().map(|a| a.ping.sent).sum(),
        None => summary.ping.sent,
    }
}

/// Why the ground sent `sent` PINGs (counted as it sends them on UDP) and `up` went up
/// the radio (counted at the radio's ground end), when the two differ: the radio's
/// ground end dropped `dropped` uplink datagrams (its UDP input full: the radio's uplink
/// carries less than a flood of PINGs), and the others were still on their way.
fn pings_not_up(sent: u64, up: u64, dropped: u64) -> Option<String> {
    let missing = sent.checked_sub(up).filter(|&n| n > 0)?;
    let dropped = dropped.min(missing);
    let waiting = missing - dropped;
    let mut line =
        format!("  of the {sent} PINGs the ground sent, {up} went up the radio: {missing} did not");
    if dropped > 0 {
        line.push_str(&format!(
            ", {dropped} dropped at the radio's ground end (its UDP input was full: the radio's uplink carries fewer)"
        ));
    }
    if waiting > 0 {
        line.push_str(&format!(", {waiting} still on their way at the end"));
    }
    Some(line)
}

/// The figures of the run so far.
pub fn collect_summary(args: &Args, plan: &RadioPlan, aircraft: &Aircraft) -> Summary {
    let elapsed_us = Instant::now().as_micros();
    let fleet = (!aircraft.wings.is_empty()).then(|| figures::fleet_figures(aircraft));
    let stats = ground_devices(aircraft);
    // Copied out of the record before anything else is locked.
    let (received, ping, messages) = recorded();
    let level = |i: usize| {
        let s = stats.levels[i];
        let r = &received[i];
        Level {
            submitted: s.submitted,
            sent: s.sent,
            shed: s.lost,
            superseded: s.superseded,
            received: r.received,
            aged: r.aged,
            age_p50_ms: r.p50,
            age_p99_ms: r.p99,
            ambiguous: r.ambiguous,
        }
    };
    let delivery = plan.xbee().then(|| {
        let d = aircraft.radio_device.delivery_stats();
        DeliveryFigures {
            delivered: d.delivered,
            failed: d.failed,
            timeouts: d.timeouts,
            unexpected: d.unexpected,
        }
    });
    Summary {
        schema: 1,
        config: run_config(args, plan),
        simulated_s: elapsed_us as f64 / 1e6,
        levels: Levels {
            high: level(0),
            normal: level(1),
            low: level(2),
        },
        downlink: downlink_figures(&stats),
        modem: modem_figures(aircraft, elapsed_us),
        delivery,
        ping,
        messages,
        secure: plan.secure.then(secure_figures),
        fleet,
        link: link::figures(args, aircraft),
        gateway: None,
    }
}

/// The gateway's figures, when it merged the radios: per link, and per aircraft what
/// it sent and what was delivered.
fn gateway_figures(args: &Args, aircraft: &Aircraft, merge: &Merge) -> Option<GatewayFigures> {
    let gateway = merge.gateway_of()?;
    let links = gateway
        .links()
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let m = gateway.link_merge(i);
            let d = l.monitor().decoder_stats();
            LinkFigures {
                link: l.name().to_owned(),
                frames: d.frames.into(),
                checksum_errors: d.checksum_errors.into(),
                first: m.first,
                duplicates: m.duplicates,
                alone: m.alone,
                missed: m.missed,
            }
        })
        .collect();
    let ids: Vec<u8> = aircraft.healths().iter().map(|&(ac, _)| ac).collect();
    let each = ids
        .into_iter()
        .map(|ac| AircraftDelivery {
            ac_id: ac,
            sent: aircraft.ground_devices(ac).iter().map(|s| s.sent).collect(),
            aired: merge.aired(ac),
            delivered: merge.delivered(ac),
            fleet_frames: merge.monitor().aircraft_state(ac).map_or(0, |a| a.frames()),
        })
        .collect();
    let (lost_down, lost_up) = bridge::frames_lost();
    Some(GatewayFigures {
        radios: args.radios,
        frame_loss: args.frame_loss,
        lost_frames_down: lost_down,
        lost_frames_up: lost_up,
        dedup_window_s: gateway.dedup().window(),
        links,
        aircraft: each,
        bus: merge.bus_stats(),
    })
}

/// The radio devices to the ground, their statistics summed: aircraft 7's radio, and
/// each other aircraft's own radio (not the one relayed through 7, whose frames 7's
/// radio device counts).
fn ground_devices(aircraft: &Aircraft) -> DeviceStats {
    let mut all: DeviceStats = aircraft.downlink.stats(0).unwrap_or_default();
    for w in aircraft.wings.iter().filter(|w| !w.relayed) {
        let s = w.downlink.stats(0).unwrap_or_default();
        add_stats(&mut all, &s);
    }
    all
}

/// Adds the counters of `s` that the summary shows to `all`.
fn add_stats(all: &mut DeviceStats, s: &DeviceStats) {
    for (a, l) in all.levels.iter_mut().zip(s.levels) {
        a.submitted = a.submitted.saturating_add(l.submitted);
        a.sent = a.sent.saturating_add(l.sent);
        a.lost = a.lost.saturating_add(l.lost);
        a.superseded = a.superseded.saturating_add(l.superseded);
    }
    let (d, e) = (&mut all.dropped, &s.dropped);
    for (a, b) in [
        (&mut d.too_large, e.too_large),
        (&mut d.encode, e.encode),
        (&mut d.queue_full, e.queue_full),
        (&mut d.arena_full, e.arena_full),
        (&mut d.write_error, e.write_error),
        (&mut d.rate_limited, e.rate_limited),
        (&mut d.refused, e.refused),
        (&mut all.evicted.queue_full, s.evicted.queue_full),
        (&mut all.evicted.arena_full, s.evicted.arena_full),
        (&mut all.sent, s.sent),
        (&mut all.superseded, s.superseded),
    ] {
        *a = a.saturating_add(b);
    }
    all.queued = all.queued.saturating_add(s.queued);
}

/// What reached the ground at one priority level, from the record.
struct Received {
    received: u64,
    aged: u64,
    p50: Option<f64>,
    p99: Option<f64>,
    ambiguous: u64,
}

/// From the record: what reached the ground per level, the PINGs through the radio and
/// the figures of each message type.
fn recorded() -> ([Received; 3], PingFigures, Vec<MessageFigures>) {
    let record = record::lock();
    let level = |i: usize| {
        let r = &record.levels[i];
        Received {
            received: r.received,
            aged: r.ages.count(),
            p50: r.ages.percentile_ms(50.0),
            p99: r.ages.percentile_ms(99.0),
            ambiguous: r.ambiguous,
        }
    };
    let messages = record
        .types
        .iter()
        .filter_map(|(&(class, id), t)| {
            let desc = MESSAGES.find(class, id)?;
            Some(MessageFigures {
                class: desc.class_name,
                name: desc.name,
                level: priority::LEVEL_NAMES[priority::level(desc.priority)],
                submitted: t.submitted,
                received: t.received,
                max_gap_ms: (t.received > 1).then(|| t.max_gap_us as f64 / 1000.0),
            })
        })
        .collect::<Vec<_>>();
    let ping = PingFigures {
        sent: record.pings.sent_count(),
        answered: record.pings.answered(),
        lost: record.pings.lost(),
        rtt_p50_ms: record.rtt.percentile_ms(50.0),
        rtt_p99_ms: record.rtt.percentile_ms(99.0),
    };
    ([level(0), level(1), level(2)], ping, messages)
}

/// The options of the run and the radio they describe.
fn run_config(args: &Args, plan: &RadioPlan) -> RunConfig {
    RunConfig {
        transport: plan.transport.name(),
        baud: args.baud,
        serial_rate_bytes_per_s: plan.serial_rate,
        air_rate_bytes_per_s: plan.air_rate,
        modem_buffer_bytes: plan.modem_buffer,
        flow_control: match args.flow_control {
            FlowControl::Cts => "cts",
            FlowControl::None => "none",
        },
        pacing: plan.pacing.is_some(),
        pacing_budget_bytes: plan.pacing.map(|p| p.modem_budget),
        in_modem: plan.window.map(|w| w.in_modem),
        overload: args.overload,
        flood_bytes_per_s: plan.flood_bytes_per_s,
        speed: args.speed,
        duration_s: args.duration,
    }
}

/// The radio device's totals in the downlink.
fn downlink_figures(stats: &DeviceStats) -> DownlinkFigures {
    DownlinkFigures {
        sent: stats.sent,
        dropped: stats.dropped.total(),
        queue_full: stats.dropped.queue_full,
        arena_full: stats.dropped.arena_full,
        too_large: stats.dropped.too_large,
        rate_limited: stats.dropped.rate_limited,
        refused: stats.dropped.refused,
        evicted: stats.evicted.total(),
        superseded: stats.superseded,
        queued: stats.queued,
    }
}

/// The radio modems to the ground (aircraft to ground), `elapsed_us` into the run: the
/// losses summed, the busy times averaged.
fn modem_figures(aircraft: &Aircraft, elapsed_us: u64) -> ModemFigures {
    let radios = aircraft.ground_radios();
    let fraction = |busy_us: u64| {
        if elapsed_us == 0 {
            0.0
        } else {
            busy_us as f64 / elapsed_us as f64 / radios.len() as f64
        }
    };
    let mut m = ModemFigures::default();
    let (mut uart_us, mut air_us) = (0u64, 0u64);
    for r in &radios {
        let sim = r.radio.stats(Direction::AToB);
        m.dropped_bytes = m.dropped_bytes.saturating_add(sim.dropped_bytes);
        m.frames_dropped = m.frames_dropped.saturating_add(sim.frames_dropped);
        m.overrun_bytes = m.overrun_bytes.saturating_add(sim.overrun_bytes);
        uart_us = uart_us.saturating_add(sim.serial_busy_us);
        air_us = air_us.saturating_add(sim.air_busy_us);
    }
    m.uart_busy = fraction(uart_us);
    m.air_busy = fraction(air_us);
    m
}

/// The aircraft's end of the secure link.
fn secure_figures() -> SecureFigures {
    let k = SECURE.stats().secure;
    SecureFigures {
        session: k.session,
        handshakes_started: k.handshake.started,
        handshakes_completed: k.handshake.completed,
        handshakes_refused: k.handshake.refused(),
        encrypted: k.channel.encrypted,
        decrypted: k.channel.decrypted,
        rejected: k.channel.rejected(),
        counter_space_left: k.counter_space_left,
    }
}
