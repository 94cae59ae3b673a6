//! The aircraft: the example application on the Embassy std executor, its downlink and
//! radio device, and the tasks around them (the radio's writers, the XBee reader and
//! flood, aircraft 7 relaying for aircraft 8). [`start`] builds them from the options
//! and runs them on a thread of their own.

use std::convert::Infallible;

use embassy_executor::{Executor, Spawner};
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

use crate::bridge::ground_bridge;
use crate::fleet::{self, SECOND_AC_ID};
use crate::options::{Args, TransportArg};
use crate::persist::{self, SitlStore};
use crate::radio::{RADIO_RING, Radio, RadioPlan};
use crate::{clock, link, record};

/// Aircraft 7's downlink: device 0 its radio to the ground, device 1 its radio to
/// aircraft 8 (`--fleet 2`; unused otherwise).
pub type Dl = Downlink<'static, M, 2, 32>;
/// Aircraft 8's downlink: its radio to aircraft 7.
pub type Dl8 = Downlink<'static, M, 1, 32>;

/// The PAYLOAD fields the flood sends over XBee 802.15.4 (the application's 120-byte
/// flood frames exceed its 96 field bytes).
const XBEE_FLOOD_FIELDS: usize = 90;

/// Priority of the frames aircraft 7 forwards whose message it does not know.
const RELAY_PRIORITY: u8 = priority::LOW;

static ARENA: FrameArena<M, 8192> = FrameArena::new();
static ARENA_8: FrameArena<M, 8192> = FrameArena::new();
static DOWNLINK_8: StaticCell<Dl8> = StaticCell::new();
/// The radio between aircraft 7 and 8 (side A: 7, side B: 8).
static LINK_78: StaticCell<Radio> = StaticCell::new();
/// The downlink, built at start-up from the options (its device configuration is not
/// known at compile time).
static DOWNLINK: StaticCell<Dl> = StaticCell::new();
static RADIO: StaticCell<Radio> = StaticCell::new();
/// Aircraft 7's link health, with the timeout of `--lost-timeout`.
static HEALTH: StaticCell<LinkHealth<M>> = StaticCell::new();
/// Aircraft 8's (`--fleet 2`).
static HEALTH_8: StaticCell<LinkHealth<M>> = StaticCell::new();
static EXECUTOR: StaticCell<Executor> = StaticCell::new();
/// `--secure`: the radio's secure link (its writer seals, the application's reader
/// opens, the application runs its handshake).
pub static SECURE: SecureLink<M> = SecureLink::aircraft(AC_ID);
/// `--fleet 2`: aircraft 7's relay counters (what it forwarded and refused, per reason),
/// copied after every frame it reads.
pub static RELAY_COUNTERS: RelayCounters = RelayCounters::new();
/// XBee: the uplink messages, re-framed as PPRZ v2 for the application's reader.
static UPLINK_PIPE: Pipe<M, 1024> = Pipe::new();

/// The aircraft of the run, started: what the ground's viewer and the summary read.
#[derive(Clone, Copy)]
pub struct Aircraft {
    /// Aircraft 7's downlink.
    pub downlink: &'static Dl,
    /// Its radio device (device 0 of the downlink).
    pub radio_device: Device<'static>,
    /// Its radio to the ground.
    pub radio: &'static Radio,
    /// `--fleet 2`: the radio between 7 and 8, and 8's downlink.
    pub second: Option<(&'static Radio, &'static Dl8)>,
    /// Aircraft 7's link health (its application's reader drives it, its failsafe
    /// watches it).
    pub health: &'static LinkHealth<M>,
    /// `--fleet 2`: aircraft 8's.
    pub health_8: Option<&'static LinkHealth<M>>,
}

impl Aircraft {
    /// Each aircraft's id and link health, aircraft 7 first.
    pub fn healths(&self) -> Vec<(u8, &'static LinkHealth<M>)> {
        let mut all = vec![(AC_ID, self.health)];
        all.extend(self.health_8.map(|h| (SECOND_AC_ID, h)));
        all
    }
}

/// Aircraft 8 (`--fleet 2`) before it starts: its radio to 7, its downlink and the port
/// of its radio device.
struct Second {
    link: &'static Radio,
    downlink: &'static Dl8,
    port: Port<'static>,
    health: &'static LinkHealth<M>,
}

/// Builds the aircraft the options describe, starts the clock and runs the aircraft on
/// a thread of their own; `udp` is the UDP side of the radio's ground end, `responder`
/// the aircraft's end of `--secure`. Fails (with the message) before anything runs.
pub fn start(
    args: &Args,
    plan: &RadioPlan,
    responder: Option<Responder>,
    store: Option<&'static mut SitlStore>,
    udp: HostDevice,
) -> Result<Aircraft, String> {
    let radio: &'static Radio = RADIO.init(SimLink::new(plan.sim_config(args.flow_control)));
    link::cut(radio, &args.outage)?;
    let health: &'static LinkHealth<M> = HEALTH.init(link::health(args));
    let fleet = args.fleet > 1;
    let downlink: &'static Dl = DOWNLINK.init(
        Downlink::new(&ARENA, AC_ID, [plan.device_config(), plan.device_config()])
            .with_routes(fleet::routes(fleet)),
    );
    let [radio_port, link_port] = downlink.ports().map_err(|e| e.to_string())?;
    let radio_device = radio_port.device();
    let second = if fleet {
        Some(second_aircraft(args, plan)?)
    } else {
        None
    };
    let aircraft = Aircraft {
        downlink,
        radio_device,
        radio,
        second: second.as_ref().map(|s| (s.link, s.downlink)),
        health,
        health_8: second.as_ref().map(|s| s.health),
    };
    let tasks = Tasks {
        radio_port,
        link_port,
        radio,
        second,
        config: config(plan, health),
        responder,
        store,
        xbee: plan.xbee(),
        flood: plan.flood_bytes_per_s,
        udp,
    };
    clock::pace(args.speed);
    std::thread::spawn(move || {
        let executor = EXECUTOR.init(Executor::new());
        executor.run(|spawner| tasks.spawn(spawner))
    });
    Ok(aircraft)
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

/// `--fleet 2`: aircraft 8 and its radio to 7.
fn second_aircraft(args: &Args, plan: &RadioPlan) -> Result<Second, String> {
    let link: &'static Radio = LINK_78.init(SimLink::new(plan.sim_config(args.flow_control)));
    let downlink: &'static Dl8 = DOWNLINK_8.init(Downlink::new(
        &ARENA_8,
        SECOND_AC_ID,
        [plan.device_config()],
    ));
    let [port] = downlink.ports().map_err(|e| e.to_string())?;
    Ok(Second {
        link,
        downlink,
        port,
        health: HEALTH_8.init(link::health(args)),
    })
}

/// Everything the executor's tasks take, moved to its thread.
struct Tasks {
    radio_port: Port<'static>,
    link_port: Port<'static>,
    radio: &'static Radio,
    second: Option<Second>,
    config: Config,
    responder: Option<Responder>,
    /// `--settings-flash`: aircraft 7's store (one aircraft only).
    store: Option<&'static mut SitlStore>,
    xbee: bool,
    flood: u32,
    udp: HostDevice,
}

impl Tasks {
    /// Spawns the aircraft's tasks and the radio's ground end.
    fn spawn(self, spawner: Spawner) {
        let (air, ground) = self.radio.endpoints();
        let (air_rx, air_tx) = air.split();
        let radio_device = self.radio_port.device();
        let secure = self.responder.is_some();
        let config = self.config;
        let layer = secure.then_some(&SECURE);
        if let Some(health) = config.health {
            spawner.spawn(link::watch(AC_ID, health).unwrap());
        }
        spawner.spawn(radio_writer(self.radio_port, air_tx, layer).unwrap());
        if let Some(second) = self.second {
            let (side_7, side_8) = second.link.endpoints();
            let (rx_7, tx_7) = side_7.split();
            let (rx_8, tx_8) = side_8.split();
            let link_device = self.link_port.device();
            let device_8 = second.port.device();
            let config_8 = Config {
                observer: Some(record::submitted_by_second),
                health: Some(second.health),
                ..config
            };
            spawner.spawn(link::watch(SECOND_AC_ID, second.health).unwrap());
            spawner.spawn(radio_writer(self.link_port, tx_7, None).unwrap());
            spawner.spawn(radio_writer(second.port, tx_8, None).unwrap());
            spawner.spawn(relay_aircraft(radio_device, air_rx, link_device, rx_7, config).unwrap());
            spawner.spawn(aircraft(device_8, rx_8, config_8, None).unwrap());
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
            spawner.spawn(aircraft(radio_device, air_rx, config, self.store).unwrap());
        }
        spawner.spawn(ground_bridge(ground, self.udp, self.xbee, secure).unwrap());
    }
}

/// A radio device's writer (sealing every frame with `secure`, if given).
#[embassy_executor::task(pool_size = 3)]
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

/// Aircraft 7 relaying for aircraft 8 (`--fleet 2`): its radio to the ground and its
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

/// The application reading its uplink from the radio (PPRZ v2), with its settings in
/// `store`, if given.
#[embassy_executor::task(pool_size = 2)]
async fn aircraft(
    radio: Device<'static>,
    rx: SimRx<'static, M, RADIO_RING>,
    config: Config,
    store: Option<&'static mut SitlStore>,
) {
    let Err(e) = run_aircraft(radio, rx, config, store).await;
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
