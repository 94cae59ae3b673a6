//! The example aircraft: one application shared by the host simulation (SITL), the STM32
//! board examples and the emulated Cortex-M4, so every one of them runs the same code.
//!
//! It simulates a rotorcraft flying a circle ([`vehicle`]), sends the periodic telemetry
//! of the default `telemetry.xml` through the downlink ([`telemetry`] builds each
//! message), answers the ground (PING, SETTING, GET_SETTING) through a datalink reader,
//! lets the ground switch the telemetry mode with SETTING, and can flood the link with
//! low-priority payload to show priority shedding.
//!
//! [`run_aircraft`] builds everything that is local to the application (telemetry modes,
//! scheduler, settings, services, datalink, reader) inside one future that never ends, so
//! the firmware needs no `static` but the arena and the downlink; it spawns it next to one
//! writer task per device:
//!
//! ```ignore
//! #[embassy_executor::task]
//! async fn aircraft(radio: Device<'static>, radio_rx: BufferedUartRx<'static>) {
//!     let Err(e) = pprz_example_app::run_aircraft(radio, radio_rx, Config::default()).await;
//!     panic!("the aircraft application cannot start: {e}");
//! }
//! ```

#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod telemetry;
pub mod vehicle;

use core::cell::{Cell, RefCell};
use core::convert::Infallible;
use core::fmt;
use pprz_telemetry::SendOptions;

use core::future::Future;

use embassy_futures::select::{Either, Either4, select, select4};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time::{Duration, Instant, Ticker};
use embedded_io_async::Read;
use pprz_default::messages::Set;
use pprz_default::messages::telemetry::values::RotorcraftStatusApMode as ApMode;
use pprz_default::messages::telemetry::{
    Alive, Attitude, AutopilotVersion, DatalinkReport, DlValue, Energy, GpsInt, ImuAccelRaw,
    ImuGyroRaw, ImuMagRaw, Ins, Payload, RotorcraftFp, RotorcraftStatus, Rssi, UartErrors,
};
use pprz_default::periodic::{PROCESSES, SCHEDULE, main};
use pprz_messages::MessageSet;
use pprz_messages::{Message, VarArray};
use pprz_telemetry::health::{Health, HealthConfig, LinkHealth};
use pprz_telemetry::reader::{Datalink, Inbox, Reader};
use pprz_telemetry::registry::{Received, RegistryFull};
use pprz_telemetry::scheduler::{Callback, ModeError, Modes, Scheduler, SchedulerFull};
use pprz_telemetry::services::{LinkReporter, Services};
use pprz_telemetry::settings::SettingsError;
use pprz_telemetry::{Device, Layered, LinkLayer, Plain, Relay, RelayStats, Sender};
use pprz_transports::PprzV2;

use crate::vehicle::{Mode, Vehicle};

/// The mutex of everything shared between tasks (a critical section on boards).
pub type M = CriticalSectionRawMutex;

/// Our aircraft id.
pub const AC_ID: u8 = 7;

/// What the application does besides the periodic telemetry.
#[derive(Debug, Clone, Copy, Default)]
pub struct Config {
    /// Low-priority payload bytes per second to send (0: none). 10x the link's byte rate
    /// saturates it tenfold.
    pub flood_bytes_per_s: u32,
    /// Called with every message the application submits to the downlink (periodic
    /// telemetry and payload, not the services' replies), just before it is submitted,
    /// whether the downlink then accepts it or not (`None`, the default: nothing is
    /// called and nothing is encoded for it). The simulation records submission times
    /// with it to measure how old messages are when they reach the ground. Only with the
    /// crate's `observer` feature (off on the boards: the observer's encoding costs about
    /// 2 KiB of flash).
    #[cfg(feature = "observer")]
    pub observer: Option<Observer>,
    /// The link health the application's reader drives and its failsafe watches (`None`,
    /// the default: one of its own, with the default timeouts: Lost after 5 s). Give one
    /// to read it from other tasks, or to choose the timeouts. The radio must be device 0
    /// of its downlink (the only ground link of a one-device health).
    pub health: Option<&'static LinkHealth<M>>,
}

/// An observer of submissions (see [`Config::observer`]): class id, message id, the
/// encoded message fields (the payload of a PPRZ frame) and the time of submission.
#[cfg(feature = "observer")]
pub type Observer = fn(class_id: u8, msg_id: u8, payload: &[u8], now: Instant);

/// Where the application's messages go: the downlink, and the observer if any.
#[derive(Clone, Copy)]
struct Out<'d> {
    downlink: Sender<'d>,
    #[cfg(feature = "observer")]
    observer: Option<Observer>,
}

impl<'d> Out<'d> {
    /// Sends through `downlink`, showing messages to the observer of `config`.
    fn new(downlink: Sender<'d>, config: &Config) -> Self {
        #[cfg(not(feature = "observer"))]
        let _ = config;
        Self {
            downlink,
            #[cfg(feature = "observer")]
            observer: config.observer,
        }
    }

    /// Sends `msg` to every device; a drop is counted by the downlink (per device,
    /// reason and priority level), so the result needs no handling here.
    fn send<Msg: Message>(&self, msg: &Msg) {
        self.observe(msg);
        let _ = self.downlink.send(msg);
    }

    /// Sends the state sample `msg` (attitude, position, status: one stream per message)
    /// to every device: a newer sample takes the place of one still waiting, so a
    /// saturated link carries the latest state. Counted as [`send`](Self::send) is.
    fn send_state<Msg: Message>(&self, msg: &Msg) {
        self.observe(msg);
        let _ = self.downlink.send_with(msg, SendOptions::new().latest());
    }

    /// Shows `msg` to the observer, if there is one.
    fn observe<Msg: Message>(&self, msg: &Msg) {
        #[cfg(feature = "observer")]
        if let Some(observer) = self.observer {
            observe(observer, msg);
        }
        #[cfg(not(feature = "observer"))]
        let _ = msg;
    }
}

/// Encodes `msg` for `observer` and calls it. Not inlined, so that the send path of a
/// firmware without an observer does not reserve the encoding buffer on its stack.
#[cfg(feature = "observer")]
#[inline(never)]
fn observe<Msg: Message>(observer: Observer, msg: &Msg) {
    let mut fields = [0u8; 256];
    if let Ok(len) = msg.encode(&mut fields) {
        observer(Msg::CLASS_ID, Msg::ID, &fields[..len], Instant::now());
    }
}

/// Runs the aircraft application forever: dynamics at 50 Hz, periodic telemetry to
/// every device of `radio`'s downlink, the datalink reader on `radio_rx` (replies go to
/// `radio`), and the payload flood of `config`.
///
/// # Errors
/// Returns at once if the application cannot start: a table too small for its entries,
/// or a periodic message missing from the schedule.
pub async fn run_aircraft<R: Read>(
    radio: Device<'_>,
    radio_rx: R,
    config: Config,
) -> Result<Infallible, SetupError> {
    run_with_layer(
        radio,
        radio_rx,
        RadioOnly,
        config,
        &Plain,
        core::future::pending(),
    )
    .await
}

/// [`run_aircraft`] for an aircraft that relays for others
/// ([`relay`](pprz_telemetry::relay)): a second device, `link`, leads to other aircraft
/// and is read from `link_rx`; forwarded frames go with the priority `messages` gives
/// their message, else `priority` (see [`Relay`]); frames for other aircraft (and broadcast frames) arriving
/// on either device are forwarded by the routes of the downlink
/// ([`Downlink::with_routes`](pprz_telemetry::Downlink::with_routes)). Its own telemetry
/// goes to the ground's route. Requests are answered on the device they came in on.
///
/// The relay lives inside this future; with `counters`, its counters (what it forwarded
/// and what it refused, per reason) are copied there after every frame it reads, for
/// the firmware's other tasks to report.
///
/// # Errors
/// As [`run_aircraft`].
#[allow(clippy::too_many_arguments)]
pub async fn run_relay_aircraft<R: Read>(
    radio: Device<'_>,
    radio_rx: R,
    link: Device<'_>,
    link_rx: R,
    priority: u8,
    messages: Option<&MessageSet<'_>>,
    counters: Option<&RelayCounters>,
    config: Config,
) -> Result<Infallible, SetupError> {
    run_with_layer(
        radio,
        radio_rx,
        RelayLink {
            link,
            rx: link_rx,
            priority,
            messages,
            counters,
        },
        config,
        &Plain,
        core::future::pending(),
    )
    .await
}

/// [`run_aircraft`] on a secure radio: the reader opens every frame with `secure` (the
/// radio's writer must seal with the same [`SecureLink`](pprz_secure::link::SecureLink),
/// `run_writer_with(&mut port, tx, &SECURE)`, and the radio's device be configured with
/// `SecureLink::DEVICE`), the handshake runs as part of the application with `responder`
/// and `rng`, and `SECURE_LINK_STATUS` goes to the radio every second. Until a ground
/// completes the handshake, the radio carries nothing but the key exchange.
///
/// # Errors
/// As [`run_aircraft`].
#[cfg(feature = "secure")]
pub async fn run_secure_aircraft<R: Read, G: pprz_secure::rand_core::CryptoRng>(
    radio: Device<'_>,
    radio_rx: R,
    config: Config,
    secure: &pprz_secure::link::SecureLink<M>,
    mut responder: pprz_secure::Responder,
    mut rng: G,
) -> Result<Infallible, SetupError> {
    use pprz_default::messages::telemetry::SecureLinkStatus;
    let handshake = secure.run_responder(
        &mut responder,
        &mut rng,
        radio.sender(),
        pprz_telemetry::Targets::from(radio),
    );
    let status = async {
        let mut ticker = Ticker::every(Duration::from_secs(1));
        loop {
            ticker.next().await;
            let s = secure.status();
            // Refused before the session (counted), like all telemetry.
            let _ = radio.send_with(
                &SecureLinkStatus {
                    sts_stage: s.stage,
                    sts_error: s.error,
                    counter_err: s.counter_err,
                    decrypt_err: s.decrypt_err,
                    encrypt_err: s.encrypt_err,
                },
                SendOptions::new().latest(),
            );
        }
    };
    let extra = async {
        match embassy_futures::select::select(handshake, status).await {
            embassy_futures::select::Either::First(never)
            | embassy_futures::select::Either::Second(never) => never,
        }
    };
    run_with_layer(radio, radio_rx, RadioOnly, config, secure, extra).await
}

/// The readers of the application, given the radio's: the radio's alone, or with a
/// relay link's. A type per case, so a firmware that does not relay carries no relay
/// code.
trait Readers<'d> {
    /// Reads forever, the radio's frames delivered through `layer`.
    async fn run<'x, R: Read, L: LinkLayer + ?Sized, const N: usize>(
        self,
        radio: Reader<'d, R, PprzV2>,
        layer: &L,
        datalink: &Datalink<'x, M, N>,
    ) -> Infallible
    where
        'd: 'x;
}

/// The radio alone.
struct RadioOnly;

impl<'d> Readers<'d> for RadioOnly {
    async fn run<'x, R: Read, L: LinkLayer + ?Sized, const N: usize>(
        self,
        mut radio: Reader<'d, R, PprzV2>,
        layer: &L,
        datalink: &Datalink<'x, M, N>,
    ) -> Infallible
    where
        'd: 'x,
    {
        radio.run(&Layered::new(layer, datalink)).await
    }
}

/// The counters of the relay of [`run_relay_aircraft`], as it last copied them: a
/// snapshot of its [`RelayStats`] that other tasks read. `const`, so it can be a
/// `static`.
pub struct RelayCounters(Mutex<M, Cell<RelayStats>>);

impl RelayCounters {
    /// Zero counters.
    pub const fn new() -> Self {
        Self(Mutex::new(Cell::new(RelayStats::ZERO)))
    }

    /// The relay's counters after the last frame it read.
    pub fn get(&self) -> RelayStats {
        self.0.lock(Cell::get)
    }
}

impl Default for RelayCounters {
    fn default() -> Self {
        Self::new()
    }
}

/// The relay, copying its counters into `counters` after every frame it reads.
struct Counted<'a, 'r, I: ?Sized> {
    relay: &'a Relay<'r, M, I>,
    counters: Option<&'a RelayCounters>,
}

impl<'d, I: Inbox<'d> + ?Sized> Inbox<'d> for Counted<'_, '_, I> {
    fn deliver(&self, rx: &Received<'_, 'd>) {
        self.relay.deliver(rx);
        if let Some(c) = self.counters {
            c.0.lock(|s| s.set(self.relay.stats()));
        }
    }

    fn read_error(&self) {
        self.relay.read_error();
    }
}

/// The radio and a link to other aircraft, both delivering to a [`Relay`].
struct RelayLink<'l, 'm, R2> {
    link: Device<'l>,
    rx: R2,
    priority: u8,
    messages: Option<&'m MessageSet<'m>>,
    counters: Option<&'m RelayCounters>,
}

impl<'d, R2: Read> Readers<'d> for RelayLink<'d, '_, R2> {
    async fn run<'x, R: Read, L: LinkLayer + ?Sized, const N: usize>(
        self,
        mut radio: Reader<'d, R, PprzV2>,
        layer: &L,
        datalink: &Datalink<'x, M, N>,
    ) -> Infallible
    where
        'd: 'x,
    {
        let relay: Relay<'_, M, _> = match self.messages {
            Some(messages) => Relay::new(datalink, self.priority).with_messages(messages),
            None => Relay::new(datalink, self.priority),
        };
        // The link to other aircraft carries no layer (the secure link is per radio,
        // between one aircraft and the ground).
        let relay = Counted {
            relay: &relay,
            counters: self.counters,
        };
        let mut link = Reader::<R2, PprzV2>::new(self.rx, PprzV2::new(), self.link);
        match select(radio.run(&Layered::new(layer, &relay)), link.run(&relay)).await {
            Either::First(never) | Either::Second(never) => never,
        }
    }
}

/// The application, its reader delivering through `layer`, with `extra` (the secure
/// link's tasks) running beside it, and the readers of `readers`.
async fn run_with_layer<'d, R: Read, L: LinkLayer + ?Sized>(
    radio: Device<'d>,
    radio_rx: R,
    readers: impl Readers<'d>,
    config: Config,
    layer: &L,
    extra: impl Future<Output = Infallible>,
) -> Result<Infallible, SetupError> {
    let out = Out::new(radio.sender(), &config);
    let vehicle: Mutex<M, RefCell<Vehicle>> = Mutex::new(RefCell::new(Vehicle::new()));
    let v = || vehicle.lock(|v| *v.borrow());
    let boot = Instant::now();

    // Telemetry modes, which the ground switches through a setting.
    let modes: Modes<'_, PROCESSES> = Modes::new(&SCHEDULE);

    // Settings the ground can change (indices in registration order), and the services
    // answering PING / SETTING / GET_SETTING.
    let flood_on: Mutex<M, Cell<bool>> = Mutex::new(Cell::new(config.flood_bytes_per_s > 0));
    let gain: Mutex<M, Cell<f32>> = Mutex::new(Cell::new(1.0));
    let get_flood = || f32::from(u8::from(flood_on.lock(Cell::get)));
    let set_flood = |x: f32| flood_on.lock(|c| c.set(x >= 0.5));
    let get_gain = || gain.lock(Cell::get);
    // Out-of-range values are clamped (the services refuse NaN and infinities before a
    // setter sees them; the acknowledgement reports the gain in force).
    let set_gain = |x: f32| gain.lock(|c| c.set(x.clamp(0.0, 10.0)));
    // Our id is the downlink's (the example's `AC_ID` unless a fleet says otherwise).
    let ac_id = radio.sender().ac_id();
    let get_mode = || ap_mode_setting(v().mode);
    let set_mode = |x: f32| set_ap_mode(&vehicle, x);
    let own_health = LinkHealth::<M>::new(HealthConfig::new());
    let health = config.health.unwrap_or(&own_health);
    let services: Services<'_, Set, M, SETTINGS> = Services::new(ac_id);
    let datalink: Datalink<'_, M, { Services::<Set, M, SETTINGS>::SUBSCRIPTIONS }> =
        Datalink::with_health(ac_id, health);
    let settings = services.settings();
    settings.add_mode("telemetry_mode", modes.setting(main::PROCESS)?)?;
    settings.add("payload_flood", &get_flood, &set_flood)?;
    settings.add("gain", &get_gain, &set_gain)?;
    settings.add("ap_mode", &get_mode, &set_mode)?;
    services.subscribe(datalink.registry())?;

    // Periodic telemetry callbacks.
    let alive = || out.send_state(&telemetry::alive());
    let version = || out.send_state(&telemetry::version());
    let attitude = || out.send_state(&telemetry::attitude(&v()));
    let tow = || boot.elapsed().as_millis() as u32;
    let gps_int = || out.send_state(&telemetry::gps_int(&v(), tow()));
    let fp = || out.send_state(&telemetry::rotorcraft_fp(&v()));
    let ins = || out.send_state(&telemetry::ins(&v()));
    let energy = || out.send_state(&telemetry::energy(&v()));
    let status = || out.send_state(&telemetry::status(&v()));
    let gyro = || out.send_state(&telemetry::gyro(&v()));
    let accel = || out.send_state(&telemetry::accel(&v()));
    let mag = || out.send_state(&telemetry::mag());
    let uart_errors = || out.send_state(&UartErrors::default());
    let reporter = Mutex::<M, _>::new(RefCell::new(LinkReporter::new()));
    let report = || link_report(&out, &reporter, &datalink, radio, health);
    // Cycle through the settings, as the reference firmware's periodic DL_VALUE does
    // (one message type for several settings: not a single state stream, so `send`).
    let dl_value_index: Mutex<M, Cell<u8>> = Mutex::new(Cell::new(0));
    let dl_value = || {
        let count = settings.len().max(1) as u8;
        let index = dl_value_index.lock(|c| c.replace((c.get() + 1) % count));
        if let Some(value) = settings.get(index) {
            out.send(&DlValue { index, value });
        }
    };

    let scheduler: Scheduler<'_, M, PROCESSES, 16> = Scheduler::new(&modes);
    let periodic: [(&str, (u8, u8), Callback<'_>); 14] = [
        (Alive::NAME, id::<Alive>(), &alive),
        (AutopilotVersion::NAME, id::<AutopilotVersion>(), &version),
        (Attitude::NAME, id::<Attitude>(), &attitude),
        (GpsInt::NAME, id::<GpsInt>(), &gps_int),
        (RotorcraftFp::NAME, id::<RotorcraftFp>(), &fp),
        (Ins::NAME, id::<Ins>(), &ins),
        (Energy::NAME, id::<Energy>(), &energy),
        (RotorcraftStatus::NAME, id::<RotorcraftStatus>(), &status),
        (DlValue::NAME, id::<DlValue>(), &dl_value),
        (DatalinkReport::NAME, id::<DatalinkReport>(), &report),
        (UartErrors::NAME, id::<UartErrors>(), &uart_errors),
        (ImuGyroRaw::NAME, id::<ImuGyroRaw>(), &gyro),
        (ImuAccelRaw::NAME, id::<ImuAccelRaw>(), &accel),
        (ImuMagRaw::NAME, id::<ImuMagRaw>(), &mag),
    ];
    register(&scheduler, periodic)?;

    let reader = Reader::<R, PprzV2>::new(radio_rx, PprzV2::new(), radio);
    let readers = readers.run(reader, layer, &datalink);
    let flood = flood(&out, config.flood_bytes_per_s, &flood_on);
    let app = select4(scheduler.run(), readers, fly(&vehicle), flood);
    Ok(forever(app, select(extra, failsafe(health, &vehicle))).await)
}

/// Runs the application's tasks and the extra ones; none of them ends.
async fn forever<A, B, C, D>(
    app: impl Future<Output = Either4<A, B, C, D>>,
    extra: impl Future<Output = Either<Infallible, Infallible>>,
) -> Infallible
where
    A: Into<Infallible>,
    B: Into<Infallible>,
    C: Into<Infallible>,
    D: Into<Infallible>,
{
    match select(app, extra).await {
        Either::First(Either4::First(n)) => n.into(),
        Either::First(Either4::Second(n)) => n.into(),
        Either::First(Either4::Third(n)) => n.into(),
        Either::First(Either4::Fourth(n)) => n.into(),
        Either::Second(Either::First(n) | Either::Second(n)) => n,
    }
}

/// Sends DATALINK_REPORT from the datalink's and the radio's counters and, with a radio
/// that measures it (XBee), RSSI: the signal of the last uplink frame.
fn link_report<const N: usize>(
    out: &Out<'_>,
    reporter: &Mutex<M, RefCell<LinkReporter>>,
    datalink: &Datalink<'_, M, N>,
    radio: Device<'_>,
    health: &LinkHealth<M>,
) {
    let (up, down) = (datalink.stats(), radio.stats());
    let report = reporter.lock(|r| r.borrow_mut().report(Instant::now(), &up, &down));
    out.send_state(&DatalinkReport::from(report));
    if let Some(rssi) = health.rssi() {
        out.send_state(&Rssi { rssi, tx_power: 0 });
    }
}

/// The `ap_mode` setting's value: ROTORCRAFT_STATUS `ap_mode` numbering, NAV (13) or
/// HOME (2).
fn ap_mode_setting(mode: Mode) -> f32 {
    match mode {
        Mode::Nav => f32::from(ApMode::Nav.raw()),
        Mode::Home => f32::from(ApMode::Home.raw()),
    }
}

/// Sets the autopilot mode from the `ap_mode` setting; other values than NAV and HOME
/// leave it as it is (the acknowledgement says which is in force).
fn set_ap_mode(vehicle: &Mutex<M, RefCell<Vehicle>>, x: f32) {
    let mode = match x {
        x if x == ap_mode_setting(Mode::Nav) => Mode::Nav,
        x if x == ap_mode_setting(Mode::Home) => Mode::Home,
        _ => return,
    };
    vehicle.lock(|v| v.borrow_mut().mode = mode);
}

/// The settings table's size: telemetry mode, payload flood, gain, autopilot mode.
const SETTINGS: usize = 4;

/// The link-loss failsafe: once the ground has been heard, the vehicle flies home each
/// time the link becomes Lost, as Paparazzi's autopilot does after its
/// `DATALINK_LOST_TIME`. It stays in HOME until the ground sets the `ap_mode` setting
/// back to NAV (13).
async fn failsafe(health: &LinkHealth<M>, vehicle: &Mutex<M, RefCell<Vehicle>>) -> Infallible {
    // Not before the ground was heard once: a vehicle waiting for its ground on the
    // field does not take off for home.
    health.wait_for(Health::Up).await;
    let mut state = Health::Up;
    loop {
        state = health.changed(state).await;
        if state == Health::Lost {
            vehicle.lock(|v| v.borrow_mut().mode = Mode::Home);
        }
    }
}

/// Registers every periodic callback with `scheduler`; each must have a schedule.
fn register<'c, const P: usize, const K: usize>(
    scheduler: &Scheduler<'c, M, P, K>,
    periodic: [(&'static str, (u8, u8), Callback<'c>); 14],
) -> Result<(), SetupError> {
    for (name, id, callback) in periodic {
        if !scheduler.register(id, callback)?.is_scheduled() {
            return Err(SetupError::Unscheduled(name));
        }
    }
    Ok(())
}

/// The vehicle's dynamics, stepped every 20 ms.
async fn fly(vehicle: &Mutex<M, RefCell<Vehicle>>) -> Infallible {
    let mut ticker = Ticker::every(Duration::from_millis(20));
    loop {
        ticker.next().await;
        vehicle.lock(|v| v.borrow_mut().step(0.02));
    }
}

/// PAYLOAD frames of 120 bytes of fields at `bytes_per_s` (none if 0), while `on`.
async fn flood(out: &Out<'_>, bytes_per_s: u32, on: &Mutex<M, Cell<bool>>) -> Infallible {
    let bytes = [0xA5u8; 120];
    let per_frame = bytes.len() as u32 + 1 + 8;
    let rate = bytes_per_s.max(1);
    let period_us = (u64::from(per_frame) * 1_000_000 / u64::from(rate)).max(100);
    let mut ticker = Ticker::every(Duration::from_micros(period_us));
    loop {
        ticker.next().await;
        if bytes_per_s > 0 && on.lock(Cell::get) {
            let payload = Payload {
                values: VarArray::new(&bytes),
            };
            out.send(&payload);
        }
    }
}

/// Class and message id of `T`.
const fn id<T: Message>() -> (u8, u8) {
    (T::CLASS_ID, T::ID)
}

/// Why the application could not start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SetupError {
    /// The settings table is too small.
    Settings(SettingsError),
    /// The subscriber registry is too small.
    Registry(RegistryFull),
    /// The scheduler has too few callback slots.
    Scheduler(SchedulerFull),
    /// The schedule has no telemetry process for the mode setting.
    Mode(ModeError),
    /// A message the application sends periodically is in no mode of the schedule.
    Unscheduled(&'static str),
}

impl fmt::Display for SetupError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Settings(e) => e.fmt(f),
            Self::Registry(e) => e.fmt(f),
            Self::Scheduler(e) => e.fmt(f),
            Self::Mode(e) => write!(f, "telemetry mode setting: {e}"),
            Self::Unscheduled(name) => write!(f, "{name} is in no mode of telemetry.xml"),
        }
    }
}

impl core::error::Error for SetupError {}

impl From<SettingsError> for SetupError {
    fn from(e: SettingsError) -> Self {
        Self::Settings(e)
    }
}

impl From<RegistryFull> for SetupError {
    fn from(e: RegistryFull) -> Self {
        Self::Registry(e)
    }
}

impl From<SchedulerFull> for SetupError {
    fn from(e: SchedulerFull) -> Self {
        Self::Scheduler(e)
    }
}

impl From<ModeError> for SetupError {
    fn from(e: ModeError) -> Self {
        Self::Mode(e)
    }
}
