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
use crate::settings::{Refusal, Settings};
use crate::stats::DeviceStats;

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
    /// SETTINGs outside the setting's bounds: not applied, acknowledged with the value in
    /// force.
    pub out_of_bounds: u32,
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
                out_of_bounds: 0,
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
                    let outcome = (req.ac_id() == self.ac_id)
                        .then(|| self.settings.try_set(req.index(), req.value()));
                    let value = match outcome {
                        Some(Ok(v) | Err(Refusal::NonFinite(v) | Refusal::OutOfBounds(v))) => {
                            Some(v)
                        }
                        Some(Err(Refusal::UnknownIndex)) | None => None,
                    };
                    if self.value_reply(rx, req.index(), req.ac_id(), value) {
                        self.count(|s| match outcome {
                            Some(Err(Refusal::NonFinite(_))) => {
                                s.non_finite = s.non_finite.wrapping_add(1);
                            }
                            Some(Err(Refusal::OutOfBounds(_))) => {
                                s.out_of_bounds = s.out_of_bounds.wrapping_add(1);
                            }
                            _ => s.settings = s.settings.wrapping_add(1),
                        });
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
