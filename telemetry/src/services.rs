//! Built-in datalink services the Paparazzi ground expects, and the link health report.
//!
//! * `PING` -> `PONG` (round-trip time measurement).
//! * `SETTING(index, ac_id, value)` -> apply through the [`Settings`] table, then
//!   acknowledge with `DL_VALUE(index, value read back)`.
//! * `GET_SETTING(index, ac_id)` -> `DL_VALUE(index, value)`.
//!
//! The services work with any generated message set `S` that has these messages: `S`
//! implements [`ServiceSet`] (the generator implements it on the generated `Set` type when
//! PING, PONG, SETTING, GET_SETTING and DL_VALUE are present with Paparazzi's fields; a set
//! without them does not compile here). Replies go out on the device the request came in
//! on, at the reply message's priority (PONG and DL_VALUE are acknowledgements, high in the
//! default set). A request for another aircraft id or an unknown setting index gets no
//! reply and is counted ([`ServiceStats`]).
//!
//! ```
//! use core::sync::atomic::{AtomicU32, Ordering};
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_telemetry::reader::Datalink;
//! use pprz_telemetry::services::Services;
//! use pprz_default::messages::Set; // any generated set with the services' messages
//!
//! // An application setting stored as f32 bits in an atomic.
//! static GAIN: AtomicU32 = AtomicU32::new(0);
//! fn get_gain() -> f32 { f32::from_bits(GAIN.load(Ordering::Relaxed)) }
//! fn set_gain(v: f32) { GAIN.store(v.to_bits(), Ordering::Relaxed) }
//!
//! static SERVICES: Services<'static, Set, M, 16> = Services::new(7);
//! static DATALINK: Datalink<'static, M, 8> = Datalink::new(7);
//!
//! let index = SERVICES.settings().add("gain", &get_gain, &set_gain).unwrap();
//! assert_eq!(index, 0);
//! SERVICES.subscribe(DATALINK.registry()).unwrap(); // takes SUBSCRIPTIONS (3) entries
//! ```
//!
//! The one-link facade ([`Link`](crate::Link)) runs these services without a registry
//! entry.

use core::cell::RefCell;
use core::fmt;
use core::marker::PhantomData;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::Instant;
use pprz_messages::Message;
use pprz_messages::roles::{
    GetSettingRequest, LinkReport, Pong, ServiceSet, SettingRequest, SettingValue,
};

use crate::reader::{Handler, UplinkStats};
use crate::registry::{Filter, Received, Registry, RegistryFull, Subscriber};
use crate::scheduler::ModeSetting;
use crate::stats::DeviceStats;

/// How a setting is read and written.
#[derive(Clone, Copy)]
enum Access<'a> {
    /// Application closures or functions.
    Fns(&'a (dyn Fn() -> f32 + Sync), &'a (dyn Fn(f32) + Sync)),
    /// The active telemetry mode of a process.
    Mode(ModeSetting<'a>),
}

/// One entry of the settings table: a name and typed access through `f32`, the type
/// `SETTING` and `DL_VALUE` carry.
#[derive(Clone, Copy)]
pub struct SettingEntry<'a> {
    /// Name, for display.
    pub name: &'a str,
    access: Access<'a>,
}

impl SettingEntry<'_> {
    /// The current value.
    pub fn get(&self) -> f32 {
        match self.access {
            Access::Fns(get, _) => get(),
            Access::Mode(mode) => mode.get(),
        }
    }

    /// Sets the value and returns the value read back. A value the setting refuses
    /// leaves it unchanged: a non-finite one (NaN, infinities: never a setting's value,
    /// and `clamp` lets NaN through) for every setting, an unknown telemetry mode for a
    /// mode setting.
    pub fn set(&self, value: f32) -> f32 {
        if !value.is_finite() {
            return self.get();
        }
        match self.access {
            Access::Fns(_, set) => set(value),
            Access::Mode(mode) => {
                // Refused values leave the mode in force, which the read-back reports.
                let _ = mode.set(value);
            }
        }
        self.get()
    }
}

impl fmt::Debug for SettingEntry<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SettingEntry")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

/// The settings table is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SettingsFull {
    /// Capacity of the table.
    pub capacity: usize,
}

impl fmt::Display for SettingsFull {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "settings table full ({} settings)", self.capacity)
    }
}

impl core::error::Error for SettingsFull {}

/// The settings the ground can read and write, by index (the index is the position of
/// registration, as the ground's settings file numbers them). Up to `N` (at most 256)
/// settings, added through `&self`, so the table can be a `static` or part of one.
pub struct Settings<'a, M: RawMutex, const N: usize> {
    inner: Mutex<M, RefCell<Table<'a, N>>>,
}

/// (A plain array: no drop glue, so a setting may borrow the structure holding it.)
struct Table<'a, const N: usize> {
    len: usize,
    entries: [Option<SettingEntry<'a>>; N],
}

impl<'a, M: RawMutex, const N: usize> Settings<'a, M, N> {
    /// An empty table.
    pub const fn new() -> Self {
        Self {
            inner: Mutex::new(RefCell::new(Table {
                len: 0,
                entries: [None; N],
            })),
        }
    }

    fn push(&self, entry: SettingEntry<'a>) -> Result<u8, SettingsFull> {
        self.inner.lock(|t| {
            let mut t = t.borrow_mut();
            let len = t.len;
            let index = u8::try_from(len).map_err(|_| SettingsFull { capacity: N })?;
            let slot = t.entries.get_mut(len).ok_or(SettingsFull { capacity: N })?;
            *slot = Some(entry);
            t.len = len + 1;
            Ok(index)
        })
    }

    /// Registers a setting read by `get` and written by `set` (closures or functions);
    /// returns its index.
    ///
    /// # Errors
    /// [`SettingsFull`] when the table holds `N` settings (or 256, the most an index
    /// byte can address).
    pub fn add(
        &self,
        name: &'a str,
        get: &'a (dyn Fn() -> f32 + Sync),
        set: &'a (dyn Fn(f32) + Sync),
    ) -> Result<u8, SettingsFull> {
        self.push(SettingEntry {
            name,
            access: Access::Fns(get, set),
        })
    }

    /// Registers the active telemetry mode of a process as a setting (see
    /// [`Modes::setting`](crate::scheduler::Modes::setting)), so the ground switches
    /// telemetry modes with SETTING; returns its index.
    ///
    /// # Errors
    /// [`SettingsFull`], as [`add`](Self::add).
    pub fn add_mode(&self, name: &'a str, mode: ModeSetting<'a>) -> Result<u8, SettingsFull> {
        self.push(SettingEntry {
            name,
            access: Access::Mode(mode),
        })
    }

    /// The entry at `index` (a copy: calling it holds no lock).
    pub fn entry(&self, index: u8) -> Option<SettingEntry<'a>> {
        self.inner.lock(|t| {
            let t = t.borrow();
            t.entries.get(..t.len)?.get(usize::from(index)).copied()?
        })
    }

    /// The value of setting `index`.
    pub fn get(&self, index: u8) -> Option<f32> {
        self.entry(index).map(|e| e.get())
    }

    /// Sets setting `index`, returning the value read back (what the ground is told);
    /// see [`SettingEntry::set`] for the values refused.
    pub fn set(&self, index: u8, value: f32) -> Option<f32> {
        self.entry(index).map(|e| e.set(value))
    }

    /// Number of settings.
    pub fn len(&self) -> usize {
        self.inner.lock(|t| t.borrow().len)
    }

    /// Whether the table is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl<M: RawMutex, const N: usize> Default for Settings<'_, M, N> {
    fn default() -> Self {
        Self::new()
    }
}

/// What the services did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ServiceStats {
    /// PINGs answered.
    pub pings: u32,
    /// SETTINGs applied and acknowledged.
    pub settings: u32,
    /// SETTINGs with a non-finite value (NaN, infinities): not applied, acknowledged with
    /// the value in force.
    pub non_finite: u32,
    /// GET_SETTINGs answered.
    pub get_settings: u32,
    /// Requests for another aircraft id (no action).
    pub wrong_ac_id: u32,
    /// Requests for a setting index not in the table (no action).
    pub unknown_index: u32,
    /// Requests whose payload did not decode.
    pub malformed: u32,
    /// Replies the downlink dropped (counted there too, by reason).
    pub replies_dropped: u32,
}

/// PING, SETTING and GET_SETTING handling for message set `S`, with a settings table of
/// `N` entries; see the [module documentation](self).
pub struct Services<'a, S, M: RawMutex, const N: usize> {
    ac_id: u8,
    settings: Settings<'a, M, N>,
    stats: Mutex<M, RefCell<ServiceStats>>,
    set: PhantomData<fn() -> S>,
}

impl<'a, S, M: RawMutex, const N: usize> Services<'a, S, M, N> {
    /// Registry entries [`subscribe`](Self::subscribe) takes: PING, SETTING and
    /// GET_SETTING.
    pub const SUBSCRIPTIONS: usize = 3;

    /// Services for aircraft `ac_id`, with an empty settings table.
    pub const fn new(ac_id: u8) -> Self {
        Self {
            ac_id,
            settings: Settings::new(),
            stats: Mutex::new(RefCell::new(ServiceStats {
                pings: 0,
                settings: 0,
                non_finite: 0,
                get_settings: 0,
                wrong_ac_id: 0,
                unknown_index: 0,
                malformed: 0,
                replies_dropped: 0,
            })),
            set: PhantomData,
        }
    }

    /// The settings table (add settings here at start-up).
    pub fn settings(&self) -> &Settings<'a, M, N> {
        &self.settings
    }

    /// A snapshot of the counters.
    pub fn stats(&self) -> ServiceStats {
        self.stats.lock(|s| *s.borrow())
    }

    fn count(&self, f: impl FnOnce(&mut ServiceStats)) {
        self.stats.lock(|s| f(&mut s.borrow_mut()));
    }

    fn reply<Msg: Message>(&self, rx: &Received<'_, '_>, msg: &Msg) {
        if rx.reply(msg).is_err() {
            self.count(|s| s.replies_dropped = s.replies_dropped.wrapping_add(1));
        }
    }

    fn malformed(&self) {
        self.count(|s| s.malformed = s.malformed.wrapping_add(1));
    }
}

impl<'a, S: ServiceSet, M: RawMutex + Sync, const N: usize> Services<'a, S, M, N> {
    /// Subscribes the services to PING, SETTING and GET_SETTING in `registry`
    /// ([`SUBSCRIPTIONS`](Self::SUBSCRIPTIONS) entries).
    ///
    /// # Errors
    /// The registry has no room for the three subscriptions.
    pub fn subscribe<R: RawMutex, const C: usize>(
        &'a self,
        registry: &Registry<'a, R, C>,
    ) -> Result<(), RegistryFull> {
        registry.subscribe(Filter::message::<S::Ping>(), self)?;
        registry.subscribe(Filter::message::<S::Setting>(), self)?;
        registry.subscribe(Filter::message::<S::GetSetting>(), self)
    }

    /// Sends `DL_VALUE(index, value)` if the request is for us and the index exists.
    fn value_reply(&self, rx: &Received<'_, '_>, index: u8, ac_id: u8, value: Option<f32>) -> bool {
        if ac_id != self.ac_id {
            self.count(|s| s.wrong_ac_id = s.wrong_ac_id.wrapping_add(1));
            return false;
        }
        match value {
            Some(value) => {
                self.reply(rx, &S::DlValue::new(index, value));
                true
            }
            None => {
                self.count(|s| s.unknown_index = s.unknown_index.wrapping_add(1));
                false
            }
        }
    }
}

impl<'d, S: ServiceSet, M: RawMutex + Sync, const N: usize> Handler<'d> for Services<'_, S, M, N> {
    fn handle(&self, rx: &Received<'_, 'd>) -> bool {
        let id = (rx.class_id(), rx.msg_id());
        if id == (S::Ping::CLASS_ID, S::Ping::ID) {
            if rx.decode::<S::Ping>().is_ok() {
                self.reply(rx, &S::Pong::pong());
                self.count(|s| s.pings = s.pings.wrapping_add(1));
            } else {
                self.malformed();
            }
        } else if id == (S::Setting::CLASS_ID, S::Setting::ID) {
            match rx.decode::<S::Setting>() {
                Ok(req) => {
                    // Applied only when the request is for us (and the index exists).
                    let value = (req.ac_id() == self.ac_id)
                        .then(|| self.settings.set(req.index(), req.value()))
                        .flatten();
                    if self.value_reply(rx, req.index(), req.ac_id(), value) {
                        if req.value().is_finite() {
                            self.count(|s| s.settings = s.settings.wrapping_add(1));
                        } else {
                            self.count(|s| s.non_finite = s.non_finite.wrapping_add(1));
                        }
                    }
                }
                Err(_) => self.malformed(),
            }
        } else if id == (S::GetSetting::CLASS_ID, S::GetSetting::ID) {
            match rx.decode::<S::GetSetting>() {
                Ok(req) => {
                    let value = self.settings.get(req.index());
                    if self.value_reply(rx, req.index(), req.ac_id(), value) {
                        self.count(|s| s.get_settings = s.get_settings.wrapping_add(1));
                    }
                }
                Err(_) => self.malformed(),
            }
        } else {
            return false;
        }
        true
    }
}

impl<'d, S: ServiceSet, M: RawMutex + Sync, const N: usize> Subscriber<'d>
    for Services<'_, S, M, N>
{
    fn on_message(&self, rx: &Received<'_, 'd>) {
        self.handle(rx);
    }
}

/// Builds DATALINK_REPORT contents from the uplink and downlink counters; rates are
/// computed since the previous report. Convert the [`LinkReport`] into the set's message
/// with `.into()` (the generated `DatalinkReport` implements `From<LinkReport>`).
#[derive(Debug, Clone, Copy, Default)]
pub struct LinkReporter {
    previous: Option<(Instant, UplinkStats, DeviceStats)>,
}

impl LinkReporter {
    /// A reporter with no previous report (the first report has zero rates).
    pub const fn new() -> Self {
        Self { previous: None }
    }

    /// The report at `now` for the uplink counters and one downlink device's counters.
    pub fn report(
        &mut self,
        now: Instant,
        uplink: &UplinkStats,
        downlink: &DeviceStats,
    ) -> LinkReport {
        let uplink_lost_time = match uplink.last_received {
            Some(t) => {
                u16::try_from(now.saturating_duration_since(t).as_secs()).unwrap_or(u16::MAX)
            }
            None => u16::MAX,
        };
        let (downlink_rate, uplink_rate) = match &self.previous {
            Some((then, up, down)) => {
                let ms = now.saturating_duration_since(*then).as_millis();
                let ms32 = u32::try_from(ms).unwrap_or(u32::MAX);
                let msgs = u64::from(uplink.received.wrapping_sub(up.received));
                let uplink_rate = (msgs * 1000)
                    .checked_div(ms)
                    .map_or(0, |r| u16::try_from(r).unwrap_or(u16::MAX));
                (downlink.downlink_rate(down, ms32), uplink_rate)
            }
            None => (0, 0),
        };
        self.previous = Some((now, *uplink, *downlink));
        LinkReport {
            uplink_lost_time,
            uplink_nb_msgs: uplink.received as u16,
            downlink_nb_msgs: downlink.downlink_nb_msgs(),
            downlink_rate,
            uplink_rate,
            downlink_ovrn: downlink.downlink_ovrn(),
        }
    }
}
