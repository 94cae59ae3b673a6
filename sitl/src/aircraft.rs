//! The aircraft: the example application on the Embassy std executor, its downlink and
//! radio device, and the tasks around them (the radio's writers, the XBee reader and
//! flood, aircraft 7 relaying for aircraft 8). [`start`] builds them from the options
//! and runs them on a thread of their own.
//!
//! Aircraft 7 is built from statics, with what only one aircraft has (`--secure`,
//! `--settings-flash`, XBee, the relay's second radio). The fleet's other aircraft
//! (`--fleet N`) are built alike by [`wing`], on the heap and leaked (they live as long
//! as the run): each its radio, its frame arena, its downlink and its link health.
//!
//! With `--radios 2`, every aircraft has a second radio to the ground (device 1 of its
//! downlink, which routes its telemetry to both devices); what the ground sends up
//! either radio is merged, frame by frame, into the application's one reader
//! ([`uplink_merge`]), so a frame on either radio keeps its link health Up. The
//! application replies (PONG) on radio A.

use std::convert::Infallible;

use embassy_executor::{Executor, Spawner};
use embassy_sync::mutex::Mutex;
use embassy_sync::pipe::Pipe;
use embassy_time::{Duration, Instant, Ticker};
use embedded_io_async::Read;
use pprz_default::messages::MESSAGES;
use pprz_default::messages::telemetry::Payload;
use pprz_devices::host::HostDevice;
use pprz_devices::sim::{SimLink, SimRx, SimTx};
use pprz_example_app::{AC_ID, Config, M, RelayCounters, SetupError};
use pprz_messages::{Message, VarArray};
use pprz_secure::Responder;
use pprz_secure::link::SecureLink;
use pprz_secure::rand_core::{OsRng, TryRngCore};
use pprz_telemetry::health::LinkHealth;
use pprz_telemetry::pprz_messages::priority;
use pprz_telemetry::pprz_transports::{Decoder, Encoder, MAX_FRAME_LEN, PprzV2, XBee24};
use pprz_telemetry::{Device, Downlink, FrameArena, Port, Sender, run_writer, run_writer_with};
use static_cell::StaticCell;

use crate::bridge::{self, BridgeMode, GroundRadio};
use crate::fleet::{self, MAX_FLEET};
use crate::options::{Args, TransportArg};
use crate::persist::{self, SitlStore};
use crate::radio::{RADIO_RING, Radio, RadioPlan};
use crate::{clock, link, record};

/// Aircraft 7's downlink: device 0 its radio to the ground, device 1 its radio to
/// aircraft 8 (`--relay`; unused otherwise).
pub type Dl = Downlink<'static, M, 2, 32>;
/// The downlink of every other aircraft of the fleet: device 0 its radio to the ground,
/// device 1 its second radio (`--radios 2`; unused otherwise).
pub type WingDl = Downlink<'static, M, 2, 32>;

/// The uplink frames of an aircraft's two radios, merged for its application's reader.
type UplinkPipe = Pipe<M, 1024>;

/// Bytes of each aircraft's frame arena.
const ARENA_BYTES: usize = 8192;

/// The PAYLOAD fields the flood sends over XBee 802.15.4 (the application's 120-byte
/// flood frames exceed its 96 field bytes).
const XBEE_FLOOD_FIELDS: usize = 90;

/// Priority of the frames aircraft 7 forwards whose message it does not know.
const RELAY_PRIORITY: u8 = priority::LOW;

static ARENA: FrameArena<M, ARENA_BYTES> = FrameArena::new();
/// The downlink, built at start-up from the options (its device configuration is not
/// known at compile time).
static DOWNLINK: StaticCell<Dl> = StaticCell::new();
static RADIO: StaticCell<Radio> = StaticCell::new();
/// Aircraft 7's link health, with the timeout of `--lost-timeout`.
static HEALTH: StaticCell<LinkHealth<M>> = StaticCell::new();
static EXECUTOR: StaticCell<Executor> = StaticCell::new();
/// `--secure`: the radio's secure link (its writer seals, the application's reader
/// opens, the application runs its handshake).
pub static SECURE: SecureLink<M> = SecureLink::aircraft(AC_ID);
/// `--relay`: aircraft 7's relay counters (what it forwarded and refused, per reason),
/// copied after every frame it reads.
pub static RELAY_COUNTERS: RelayCounters = RelayCounters::new();
/// XBee: the uplink messages, re-framed as PPRZ v2 for the application's reader.
static UPLINK_PIPE: Pipe<M, 1024> = Pipe::new();

/// One aircraft of the fleet besides aircraft 7.
pub struct Wing {
    /// Its id.
    pub id: u8,
    /// Its radio: to the ground, or (`relayed`) to aircraft 7. Endpoint A is the
    /// aircraft.
    pub radio: &'static Radio,
    /// Its second radio to the ground (`--radios 2`). Endpoint A is the aircraft.
    pub radio_b: Option<&'static Radio>,
    /// Its downlink (device 0: the radio; device 1: the second radio).
    pub downlink: &'static WingDl,
    /// Its link health (its application's reader drives it, its failsafe watches it).
    pub health: &'static LinkHealth<M>,
    /// `--relay`: its radio joins it to aircraft 7, which relays, not to the ground.
    pub relayed: bool,
}

/// The aircraft of the run, started: what the ground's viewer and the summary read.
#[derive(Clone, Copy)]
pub struct Aircraft {
    /// Aircraft 7's downlink.
    pub downlink: &'static Dl,
    /// Its radio device (device 0 of the downlink).
    pub radio_device: Device<'static>,
    /// Its radio to the ground.
    pub radio: &'static Radio,
    /// Its second radio to the ground (`--radios 2`; device 1 of the downlink).
    pub radio_b: Option<&'static Radio>,
    /// Aircraft 7's link health (its application's reader drives it, its failsafe
    /// watches it).
    pub health: &'static LinkHealth<M>,
    /// The fleet's other aircraft, 8 first (none with `--fleet 1`).
    pub wings: &'static [Wing],
}

impl Aircraft {
    /// Each aircraft's id and link health, aircraft 7 first.
    pub fn healths(&self) -> Vec<(u8, &'static LinkHealth<M>)> {
        let mut all = vec![(AC_ID, self.health)];
        all.extend(self.wings.iter().map(|w| (w.id, w.health)));
        all
    }

    /// The radios to the ground: aircraft 7's, then every other aircraft's own (not
    /// one relayed through 7), on link 0; with `--radios 2` their second radios after,
    /// on link 1.
    pub fn ground_radios(&self) -> Vec<GroundRadio> {
        let own = |ac: u8, link: usize, radio: &'static Radio| GroundRadio {
            ac,
            link,
            seed_index: if link == 0 {
                ac - AC_ID
            } else {
                fleet::second_radio(ac - AC_ID)
            },
            radio,
        };
        let mut all = vec![own(AC_ID, 0, self.radio)];
        let reaching = || self.wings.iter().filter(|w| !w.relayed);
        all.extend(reaching().map(|w| own(w.id, 0, w.radio)));
        if let Some(b) = self.radio_b {
            all.push(own(AC_ID, 1, b));
        }
        all.extend(reaching().filter_map(|w| Some(own(w.id, 1, w.radio_b?))));
        all
    }

    /// The radio devices of aircraft `ac` to the ground, by link: its `DeviceStats`
    /// (device 0, and device 1 with `--radios 2`).
    pub fn ground_devices(&self, ac: u8) -> Vec<pprz_telemetry::DeviceStats> {
        let (stats, two): (&dyn Fn(usize) -> Option<pprz_telemetry::DeviceStats>, bool) =
            if ac == AC_ID {
                (&|i| self.downlink.stats(i), self.radio_b.is_some())
            } else if let Some(w) = self.wing(ac) {
                (&|i| w.downlink.stats(i), w.radio_b.is_some())
            } else {
                return Vec::new();
            };
        let links = if two { 2 } else { 1 };
        (0..links).filter_map(stats).collect()
    }

    /// `--relay`: the aircraft 7 relays for.
    pub fn relayed(&self) -> Option<&'static Wing> {
        self.wings.iter().find(|w| w.relayed)
    }

    /// The aircraft `id` of the fleet, if it is not 7.
    pub fn wing(&self, id: u8) -> Option<&'static Wing> {
        self.wings.iter().find(|w| w.id == id)
    }
}

/// Builds the aircraft the options describe, starts the clock and runs the aircraft on
/// a thread of their own; `udp` is the UDP side of the radios' ground ends, `responder`
/// the aircraft's end of `--secure`. Fails (with the message) before anything runs.
pub fn start(
    args: &Args,
    plan: &RadioPlan,
    responder: Option<Responder>,
    store: Option<&'static mut SitlStore>,
    udp: Vec<HostDevice>,
) -> Result<Aircraft, String> {
    let radio: &'static Radio = RADIO.init(SimLink::new(plan.sim_config(args.flow_control, 0)));
    link::cut(radio, &args.outage)?;
    let radio_b = second_radio(args, plan, 0)?;
    let health: &'static LinkHealth<M> = HEALTH.init(link::health(args));
    let downlink: &'static Dl = DOWNLINK.init(
        Downlink::new(&ARENA, AC_ID, [plan.device_config(), plan.device_config()])
            .with_routes(fleet::routes(args.relay, plan.radios)),
    );
    let [radio_port, link_port] = downlink.ports().map_err(|e| e.to_string())?;
    let radio_device = radio_port.device();
    let mut wings = Vec::with_capacity(usize::from(args.fleet));
    let mut wing_ports = Vec::with_capacity(usize::from(args.fleet));
    for index in 1..args.fleet {
        let (w, port) = wing(args, plan, index)?;
        wings.push(w);
        wing_ports.push(port);
    }
    let aircraft = Aircraft {
        downlink,
        radio_device,
        radio,
        radio_b,
        health,
        wings: Box::leak(wings.into_boxed_slice()),
    };
    let tasks = Tasks {
        radio_port,
        link_port,
        radio,
        aircraft,
        wing_ports,
        config: config(plan, health),
        responder,
        store,
        xbee: plan.xbee(),
        flood: plan.flood_bytes_per_s,
        udp,
        loss: (plan.frame_loss, plan.seed),
    };
    clock::pace(args.speed);
    std::thread::spawn(move || {
        let executor = EXECUTOR.init(Executor::new());
        executor.run(|spawner| tasks.spawn(spawner))
    });
    Ok(aircraft)
}

/// With `--radios 2`, the second radio to the ground of the fleet's aircraft number
/// `index`, cut by the outages like the first.
fn second_radio(
    args: &Args,
    plan: &RadioPlan,
    index: u8,
) -> Result<Option<&'static Radio>, String> {
    if plan.radios < 2 {
        return Ok(None);
    }
    let config = plan.sim_config(args.flow_control, fleet::second_radio(index));
    let radio: &'static Radio = Box::leak(Box::new(SimLink::new(config)));
    link::cut(radio, &args.outage)?;
    Ok(Some(radio))
}

/// The application's configuration: the flood (over XBee, [`xbee_flood`] sends it
/// instead), the record of what it submits and its link `health`.
fn config(plan: &RadioPlan, health: &'static LinkHealth<M>) -> Config {
    Config {
        flood_bytes_per_s: if plan.xbee() {
            0 // the flood task sends frames that fit XBee 802.15.4
        } else {
            plan.flood_bytes_per_s
        },
        observer: Some(record::submitted),
        health: Some(health),
    }
}

/// The fleet's aircraft number `index` (1: aircraft 8, ...), before it starts, with the
/// port of its radio device: its radio (radio number `index`, the same as aircraft 7's,
/// its errors seeded apart, cut by the outages when it reaches the ground), its frame
/// arena, downlink and link health. With `--relay`, aircraft 8's radio joins it to 7.
fn wing(args: &Args, plan: &RadioPlan, index: u8) -> Result<(Wing, [Port<'static>; 2]), String> {
    let relayed = args.relay && index == 1;
    let radio: &'static Radio = Box::leak(Box::new(SimLink::new(
        plan.sim_config(args.flow_control, index),
    )));
    if !relayed {
        link::cut(radio, &args.outage)?;
    }
    let arena: &'static FrameArena<M, ARENA_BYTES> = Box::leak(Box::new(FrameArena::new()));
    let id = fleet::id(index);
    let radio_b = second_radio(args, plan, index)?;
    let downlink: &'static WingDl = Box::leak(Box::new(
        Downlink::new(arena, id, [plan.device_config(), plan.device_config()])
            .with_routes(fleet::routes(false, plan.radios)),
    ));
    let ports = downlink.ports().map_err(|e| e.to_string())?;
    let health: &'static LinkHealth<M> = Box::leak(Box::new(link::health(args)));
    let wing = Wing {
        id,
        radio,
        radio_b,
        downlink,
        health,
        relayed,
    };
    Ok((wing, ports))
}

/// Everything the executor's tasks take, moved to its thread.
struct Tasks {
    radio_port: Port<'static>,
    link_port: Port<'static>,
    radio: &'static Radio,
    aircraft: Aircraft,
    /// The ports of the other aircraft's radio devices, in the order of `aircraft.wings`.
    wing_ports: Vec<[Port<'static>; 2]>,
    config: Config,
    responder: Option<Responder>,
    /// `--settings-flash`: aircraft 7's store (one aircraft only).
    store: Option<&'static mut SitlStore>,
    xbee: bool,
    flood: u32,
    /// The UDP side of each link's radios (link 0, and link 1 with `--radios 2`).
    udp: Vec<HostDevice>,
    /// `--frame-loss` and `--seed`, for the radios' ground ends.
    loss: (f64, u64),
}

impl Tasks {
    /// Spawns the aircraft's tasks and the radios' ground ends.
    fn spawn(self, spawner: Spawner) {
        let (air, _) = self.radio.endpoints();
        let (air_rx, air_tx) = air.split();
        let radio_device = self.radio_port.device();
        let secure = self.responder.is_some();
        let config = self.config;
        let layer = secure.then_some(&SECURE);
        if let Some(health) = config.health {
            spawner.spawn(link::watch(AC_ID, health).unwrap());
        }
        spawner.spawn(radio_writer(self.radio_port, air_tx, layer).unwrap());
        for (wing, ports) in self.aircraft.wings.iter().zip(self.wing_ports) {
            spawn_wing(spawner, wing, ports, config);
        }
        if let Some(b) = self.aircraft.radio_b {
            let (air_b, _) = b.endpoints();
            let (rx_b, tx_b) = air_b.split();
            spawner.spawn(radio_writer(self.link_port, tx_b, None).unwrap());
            let pipe = spawn_merge(spawner, air_rx, rx_b);
            spawner.spawn(aircraft_merged(AC_ID, radio_device, pipe, config, self.store).unwrap());
        } else if let Some(wing) = self.aircraft.relayed() {
            // Aircraft 7 at the other end of 8's radio (endpoint B).
            let (_, side_7) = wing.radio.endpoints();
            let (rx_7, tx_7) = side_7.split();
            let link_device = self.link_port.device();
            spawner.spawn(radio_writer(self.link_port, tx_7, None).unwrap());
            spawner.spawn(relay_aircraft(radio_device, air_rx, link_device, rx_7, config).unwrap());
        } else if let Some(responder) = self.responder {
            let task = secure_aircraft(radio_device, air_rx, config, responder, self.store);
            spawner.spawn(task.unwrap());
        } else if self.xbee {
            spawner.spawn(xbee_reader(air_rx, radio_device).unwrap());
            spawner.spawn(aircraft_piped(radio_device, config, self.store).unwrap());
            if self.flood > 0 {
                spawner.spawn(xbee_flood(radio_device.sender(), self.flood).unwrap());
            }
        } else {
            let task = aircraft(AC_ID, radio_device, air_rx, config, self.store);
            spawner.spawn(task.unwrap());
        }
        let mode = BridgeMode {
            xbee: self.xbee,
            secure,
            frame_loss: self.loss.0,
            seed: self.loss.1,
        };
        bridge::spawn(spawner, &self.aircraft.ground_radios(), self.udp, mode);
    }
}

/// Spawns the tasks of one of the fleet's other aircraft: its link health's record,
/// its radio devices' writers and its application (with aircraft 7's `config` but its
/// own health).
fn spawn_wing(spawner: Spawner, wing: &'static Wing, ports: [Port<'static>; 2], config: Config) {
    let [port, port_b] = ports;
    let (air, _) = wing.radio.endpoints();
    let (rx, tx) = air.split();
    let device = port.device();
    let config = Config {
        health: Some(wing.health),
        ..config
    };
    spawner.spawn(link::watch(wing.id, wing.health).unwrap());
    spawner.spawn(radio_writer(port, tx, None).unwrap());
    match wing.radio_b {
        Some(b) => {
            let (air_b, _) = b.endpoints();
            let (rx_b, tx_b) = air_b.split();
            spawner.spawn(radio_writer(port_b, tx_b, None).unwrap());
            let pipe = spawn_merge(spawner, rx, rx_b);
            spawner.spawn(aircraft_merged(wing.id, device, pipe, config, None).unwrap());
        }
        None => spawner.spawn(aircraft(wing.id, device, rx, config, None).unwrap()),
    }
}

/// Spawns the merge of an aircraft's two radios' uplinks ([`uplink_merge`]); returns
/// the pipe its application reads.
fn spawn_merge(
    spawner: Spawner,
    rx_a: SimRx<'static, M, RADIO_RING>,
    rx_b: SimRx<'static, M, RADIO_RING>,
) -> &'static UplinkPipe {
    let pipe: &'static UplinkPipe = Box::leak(Box::new(Pipe::new()));
    let lock: &'static Mutex<M, ()> = Box::leak(Box::new(Mutex::new(())));
    spawner.spawn(uplink_merge(rx_a, pipe, lock).unwrap());
    spawner.spawn(uplink_merge(rx_b, pipe, lock).unwrap());
    pipe
}

/// One radio's uplink into the aircraft's merged reader (`--radios 2`): each valid
/// PPRZ v2 frame whole, one radio at a time (`lock`), so the frames of the two radios
/// never mix. A damaged frame stops here.
#[embassy_executor::task(pool_size = 2 * MAX_FLEET as usize)]
async fn uplink_merge(
    mut rx: SimRx<'static, M, RADIO_RING>,
    pipe: &'static UplinkPipe,
    lock: &'static Mutex<M, ()>,
) {
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut buf = [0u8; 256];
    let mut frames = Vec::new();
    loop {
        let Ok(n) = rx.read(&mut buf).await;
        let mut input = &buf[..n];
        frames.clear();
        while let Some(f) = decoder.feed(&mut input) {
            frames.extend_from_slice(f.raw());
        }
        if !frames.is_empty() {
            let _guard = lock.lock().await;
            pipe.write_all(&frames).await;
        }
    }
}

/// Aircraft `ac`'s application reading the merged uplink of its two radios, with its
/// settings in `store`, if given.
#[embassy_executor::task(pool_size = MAX_FLEET as usize)]
async fn aircraft_merged(
    ac: u8,
    radio: Device<'static>,
    rx: &'static UplinkPipe,
    config: Config,
    store: Option<&'static mut SitlStore>,
) {
    let Err(e) = record::as_aircraft(ac, run_aircraft(radio, rx, config, store)).await;
    panic!("the aircraft application cannot start: {e}");
}

/// A radio device's writer (sealing every frame with `secure`, if given): one per
/// aircraft, and aircraft 7's second with `--relay`.
#[embassy_executor::task(pool_size = 2 * MAX_FLEET as usize)]
async fn radio_writer(
    mut port: Port<'static>,
    tx: SimTx<'static, M, RADIO_RING>,
    secure: Option<&'static SecureLink<M>>,
) {
    match secure {
        Some(layer) => run_writer_with(&mut port, tx, layer).await,
        None => run_writer(&mut port, tx).await,
    }
}

/// The application on a secure radio (PPRZ v2), with its handshake (and its settings
/// in `store`, if given).
#[embassy_executor::task]
async fn secure_aircraft(
    radio: Device<'static>,
    rx: SimRx<'static, M, RADIO_RING>,
    config: Config,
    responder: Responder,
    store: Option<&'static mut SitlStore>,
) {
    let rng = OsRng.unwrap_err();
    let Err(e) = match store {
        Some(store) => {
            pprz_example_app::run_secure_aircraft_with_store(
                radio,
                rx,
                config,
                &SECURE,
                responder,
                rng,
                store,
                &persist::CONTROL,
            )
            .await
        }
        None => {
            pprz_example_app::run_secure_aircraft(radio, rx, config, &SECURE, responder, rng).await
        }
    };
    panic!("the aircraft application cannot start: {e}");
}

/// Aircraft 7 relaying for aircraft 8 (`--relay`): its radio to the ground and its
/// radio to 8, both read by one relaying datalink.
#[embassy_executor::task]
async fn relay_aircraft(
    radio: Device<'static>,
    rx: SimRx<'static, M, RADIO_RING>,
    link: Device<'static>,
    link_rx: SimRx<'static, M, RADIO_RING>,
    config: Config,
) {
    let Err(e) = pprz_example_app::run_relay_aircraft(
        radio,
        rx,
        link,
        link_rx,
        RELAY_PRIORITY,
        Some(&MESSAGES),
        Some(&RELAY_COUNTERS),
        config,
    )
    .await;
    panic!("the aircraft application cannot start: {e}");
}

/// Aircraft `ac`'s application reading its uplink from the radio (PPRZ v2), with its
/// settings in `store`, if given.
#[embassy_executor::task(pool_size = MAX_FLEET as usize)]
async fn aircraft(
    ac: u8,
    radio: Device<'static>,
    rx: SimRx<'static, M, RADIO_RING>,
    config: Config,
    store: Option<&'static mut SitlStore>,
) {
    let Err(e) = record::as_aircraft(ac, run_aircraft(radio, rx, config, store)).await;
    panic!("the aircraft application cannot start: {e}");
}

/// The application reading its uplink from [`UPLINK_PIPE`] (XBee), with its settings in
/// `store`, if given.
#[embassy_executor::task]
async fn aircraft_piped(
    radio: Device<'static>,
    config: Config,
    store: Option<&'static mut SitlStore>,
) {
    let Err(e) = run_aircraft(radio, &UPLINK_PIPE, config, store).await;
    panic!("the aircraft application cannot start: {e}");
}

/// The application, with its settings in `store` if given.
async fn run_aircraft<R: Read>(
    radio: Device<'static>,
    rx: R,
    config: Config,
    store: Option<&'static mut SitlStore>,
) -> Result<Infallible, SetupError> {
    match store {
        Some(store) => {
            pprz_example_app::run_aircraft_with_store(radio, rx, config, store, &persist::CONTROL)
                .await
        }
        None => pprz_example_app::run_aircraft(radio, rx, config).await,
    }
}

/// The aircraft's XBee API reader: transmit statuses go to the radio device's writer
/// (its delivery window), received frames go on to the application's reader as PPRZ v2
/// (the example application reads PPRZ v2).
#[embassy_executor::task]
async fn xbee_reader(mut rx: SimRx<'static, M, RADIO_RING>, radio: Device<'static>) {
    let mut decoder: Decoder<XBee24> = Decoder::new(XBee24::new());
    let v2 = PprzV2::new();
    let mut buf = [0u8; 64];
    let mut frame = [0u8; MAX_FRAME_LEN];
    loop {
        let Ok(n) = rx.read(&mut buf).await;
        let mut input = &buf[..n];
        loop {
            // `feed` returns `None` once the chunk is used up.
            let encoded = decoder
                .feed(&mut input)
                .map(|f| v2.encode(&f.tx_meta(), f.payload(), &mut frame));
            while let Some(status) = decoder.take_tx_status() {
                radio.tx_status(&status);
            }
            match encoded {
                Some(Ok(len)) => UPLINK_PIPE.write_all(&frame[..len]).await,
                Some(Err(_)) => {}
                None => break,
            }
        }
    }
}

/// The payload flood over XBee: PAYLOAD frames that fit 802.15.4, `bytes_per_s` API
/// bytes per second, recorded as the application's submissions are.
#[embassy_executor::task]
async fn xbee_flood(downlink: Sender<'static>, bytes_per_s: u32) {
    let fields = [0xA5u8; XBEE_FLOOD_FIELDS];
    let payload = Payload {
        values: VarArray::new(&fields),
    };
    let transport = TransportArg::Xbee.any();
    let frame_len = transport
        .frame_len(payload.encoded_len())
        .unwrap_or(MAX_FRAME_LEN);
    let period_us = (frame_len as u64 * 1_000_000 / u64::from(bytes_per_s.max(1))).max(100);
    let mut encoded = [0u8; MAX_FRAME_LEN];
    let len = payload.encode(&mut encoded).unwrap_or(0);
    let mut ticker = Ticker::every(Duration::from_micros(period_us));
    loop {
        ticker.next().await;
        record::submitted(
            Payload::CLASS_ID,
            Payload::ID,
            &encoded[..len],
            Instant::now(),
        );
        let _ = downlink.send(&payload);
    }
}
