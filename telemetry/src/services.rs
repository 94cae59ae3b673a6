//! Built-in datalink services the Paparazzi ground expects, and the link health report.
//!
//! * `PING` -> `PONG` (round-trip time measurement).
//! * `SETTING(index, ac_id, value)` -> apply through the [`Settings`] table, then
//!   acknowledge with `DL_VALUE(index, value read back)` at high priority.
//! * `GET_SETTING(index, ac_id)` -> `DL_VALUE(index, value)`.
//!
//! Replies go out on the link the request came in on (the downlink device whose index is
//! the reader's link). A request for another aircraft id or an unknown setting index
//! gets no reply and is counted ([`ServiceStats`]).
//!
//! ```
//! use core::sync::atomic::{AtomicU32, Ordering};
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_telemetry::services::{Services, Settings};
//! # use pprz_telemetry::{DeviceConfig, Downlink, FrameArena};
//! # use pprz_telemetry::pprz_transports::PprzV2;
//! # static ARENA: FrameArena<M, 2048> = FrameArena::new();
//! # let downlink: Downlink<'_, M, 1, 8> = Downlink::new(&ARENA, 7, [DeviceConfig::new(PprzV2::new().into())]);
//!
//! // An application setting stored as f32 bits in an atomic.
//! static GAIN: AtomicU32 = AtomicU32::new(0);
//! let get_gain = || f32::from_bits(GAIN.load(Ordering::Relaxed));
//! let set_gain = |v: f32| GAIN.store(v.to_bits(), Ordering::Relaxed);
//!
//! let mut settings: Settings<'_, 16> = Settings::new();
//! let index = settings.add("gain", &get_gain, &set_gain).unwrap();
//! assert_eq!(index, 0);
//! let services: Services<'_, '_, M, 1, 8, 16> = Services::new(&downlink, settings);
//! // Register with the datalink's registry: `services.subscribe(&mut registry)`.
//! # let mut registry: pprz_telemetry::registry::Registry<'_, 4> = pprz_telemetry::registry::Registry::new();
//! # services.subscribe(&mut registry).unwrap();
//! ```

use core::cell::RefCell;
use core::fmt;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::Instant;
use pprz_messages::Message;

use crate::downlink::{Downlink, Targets};
use crate::messages::datalink::{GetSetting, Ping, Setting};
use crate::messages::telemetry::{DatalinkReport, DlValue, Pong};
use crate::reader::UplinkStats;
use crate::registry::{Filter, Received, Registry, RegistryFull, Subscriber};
use crate::stats::DeviceStats;

/// One entry of the settings table: a name and typed access through `f32`, the type
/// `SETTING` and `DL_VALUE` carry.
#[derive(Clone, Copy)]
pub struct SettingEntry<'a> {
    /// Name, for display.
    pub name: &'a str,
    get: &'a (dyn Fn() -> f32 + Sync),
    set: &'a (dyn Fn(f32) + Sync),
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
/// registration, as the ground's settings file numbers them).
pub struct Settings<'a, const S: usize> {
    entries: heapless::Vec<SettingEntry<'a>, S>,
}

impl<'a, const S: usize> Settings<'a, S> {
    /// An empty table.
    pub const fn new() -> Self {
        Self {
            entries: heapless::Vec::new(),
        }
    }

    /// Registers a setting; returns its index.
    ///
    /// # Errors
    /// [`SettingsFull`] when the table holds `S` settings (or 256, the most an index
    /// byte can address).
    pub fn add(
        &mut self,
        name: &'a str,
        get: &'a (dyn Fn() -> f32 + Sync),
        set: &'a (dyn Fn(f32) + Sync),
    ) -> Result<u8, SettingsFull> {
        let index = u8::try_from(self.entries.len()).map_err(|_| SettingsFull { capacity: S })?;
        self.entries
            .push(SettingEntry { name, get, set })
            .map_err(|_| SettingsFull { capacity: S })?;
        Ok(index)
    }

    /// The entry at `index`.
    pub fn entry(&self, index: u8) -> Option<&SettingEntry<'a>> {
        self.entries.get(usize::from(index))
    }

    /// The value of setting `index`.
    pub fn get(&self, index: u8) -> Option<f32> {
        self.entry(index).map(|e| (e.get)())
    }

    /// Sets setting `index`, returning the value read back (what the ground is told).
    pub fn set(&self, index: u8, value: f32) -> Option<f32> {
        let e = self.entry(index)?;
        (e.set)(value);
        Some((e.get)())
    }

    /// Number of settings.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the table is empty.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

impl<const S: usize> Default for Settings<'_, S> {
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

/// PING, SETTING and GET_SETTING handling; see the [module documentation](self).
///
/// `'s` is the lifetime of the services' borrows (downlink, settings), `'a` the
/// downlink's own (its arena).
pub struct Services<'s, 'a, M: RawMutex, const D: usize, const Q: usize, const S: usize> {
    downlink: &'s Downlink<'a, M, D, Q>,
    settings: Settings<'s, S>,
    stats: Mutex<M, RefCell<ServiceStats>>,
}

impl<'s, 'a, M: RawMutex, const D: usize, const Q: usize, const S: usize>
    Services<'s, 'a, M, D, Q, S>
{
    /// Services replying through `downlink`, for aircraft `downlink.ac_id()`.
    pub fn new(downlink: &'s Downlink<'a, M, D, Q>, settings: Settings<'s, S>) -> Self {
        Self {
            downlink,
            settings,
            stats: Mutex::new(RefCell::new(ServiceStats::default())),
        }
    }

    /// Subscribes the services to PING, SETTING and GET_SETTING.
    ///
    /// # Errors
    /// The registry has no room for the three subscriptions.
    pub fn subscribe<'r, const N: usize>(
        &'r self,
        registry: &mut Registry<'r, N>,
    ) -> Result<(), RegistryFull>
    where
        Self: Subscriber,
    {
        registry.subscribe(Filter::message::<Ping>(), self)?;
        registry.subscribe(Filter::message::<Setting>(), self)?;
        registry.subscribe(Filter::message::<GetSetting>(), self)
    }

    /// The settings table.
    pub fn settings(&self) -> &Settings<'s, S> {
        &self.settings
    }

    /// A snapshot of the counters.
    pub fn stats(&self) -> ServiceStats {
        self.stats.lock(|s| *s.borrow())
    }

    fn count(&self, f: impl FnOnce(&mut ServiceStats)) {
        self.stats.lock(|s| f(&mut s.borrow_mut()));
    }

    fn reply<Msg: Message>(&self, rx: &Received<'_>, msg: &Msg) {
        if self
            .downlink
            .send_to(msg, Targets::only(rx.link), Msg::PRIORITY)
            .is_err()
        {
            self.count(|s| s.replies_dropped = s.replies_dropped.wrapping_add(1));
        }
    }

    /// Sends `DL_VALUE(index, value)` if the request is for us and the index exists.
    fn value_reply(&self, rx: &Received<'_>, index: u8, ac_id: u8, value: Option<f32>) -> bool {
        if ac_id != self.downlink.ac_id() {
            self.count(|s| s.wrong_ac_id = s.wrong_ac_id.wrapping_add(1));
            return false;
        }
        match value {
            Some(value) => {
                self.reply(rx, &DlValue { index, value });
                true
            }
            None => {
                self.count(|s| s.unknown_index = s.unknown_index.wrapping_add(1));
                false
            }
        }
    }

    fn malformed(&self) {
        self.count(|s| s.malformed = s.malformed.wrapping_add(1));
    }
}

impl<M: RawMutex + Sync, const D: usize, const Q: usize, const S: usize> Subscriber
    for Services<'_, '_, M, D, Q, S>
{
    fn on_message(&self, rx: &Received<'_>) {
        match (rx.class_id(), rx.msg_id()) {
            (Ping::CLASS_ID, Ping::ID) => {
                if rx.decode::<Ping>().is_ok() {
                    self.reply(rx, &Pong);
                    self.count(|s| s.pings = s.pings.wrapping_add(1));
                } else {
                    self.malformed();
                }
            }
            (Setting::CLASS_ID, Setting::ID) => match rx.decode::<Setting>() {
                Ok(req) => {
                    // Applied only when the request is for us (and the index exists).
                    let value = (req.ac_id == self.downlink.ac_id())
                        .then(|| self.settings.set(req.index, req.value))
                        .flatten();
                    if self.value_reply(rx, req.index, req.ac_id, value) {
                        self.count(|s| s.settings = s.settings.wrapping_add(1));
                    }
                }
                Err(_) => self.malformed(),
            },
            (GetSetting::CLASS_ID, GetSetting::ID) => match rx.decode::<GetSetting>() {
                Ok(req) => {
                    let value = self.settings.get(req.index);
                    if self.value_reply(rx, req.index, req.ac_id, value) {
                        self.count(|s| s.get_settings = s.get_settings.wrapping_add(1));
                    }
                }
                Err(_) => self.malformed(),
            },
            _ => {}
        }
    }
}

/// Builds DATALINK_REPORT messages from the uplink and downlink counters; rates are
/// computed since the previous report.
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
    ) -> DatalinkReport {
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
        DatalinkReport {
            uplink_lost_time,
            uplink_nb_msgs: uplink.received as u16,
            downlink_nb_msgs: downlink.downlink_nb_msgs(),
            downlink_rate,
            uplink_rate,
            downlink_ovrn: downlink.downlink_ovrn(),
        }
    }
}
