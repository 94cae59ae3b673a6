//! The gateway on the bus: delivered messages published, commands and settings
//! queries from the bus checked, framed and sent on the links.
//!
//! A command is a put on `pprz/<ac_id>/uplink/<MESSAGE>` whose payload is the JSON
//! object of the message's fields ([`json::parse_message`]): a datalink message of
//! the `messages.xml`. An `ac_id` field may be left out (the key's aircraft is used);
//! given, it must be the key's. Each aircraft takes at most
//! [`uplink_rate`](Service::with_uplink_rate) commands a second (a burst of as many);
//! beyond, they are refused (below one a second, one command goes every `1/rate`
//! seconds). A command or a settings query whose payload is longer than
//! [`MAX_PAYLOAD`] is refused unread. Every refusal is counted by reason and published
//! on `pprz/gateway/<name>/refused` with the key and the reason.
//!
//! A settings query on `pprz/<ac_id>/settings/<name>` (a name of the settings files,
//! or an index) is answered with the setting's latest value from the aircraft's
//! DL_VALUEs; with a payload `{"value": V}` (a number in the setting's display unit, or
//! a label) the value is checked against the bounds, sent as a SETTING, and the answer
//! comes when a DL_VALUE reports it, or as an error after [`SETTING_TIMEOUT`] seconds.

use std::collections::BTreeMap;
use std::sync::Arc;

use serde_json::{Value, json};
use zenoh::Wait;
use zenoh::liveliness::LivelinessToken;
use zenoh::query::Query;

use super::{Arrival, Delivered, Gateway};
use crate::bus::{self, Bus, MAX_PAYLOAD, Request, keys};
use crate::cli::SettingArg;
use crate::device::Uplink;
use crate::json;
use crate::monitor::LinkState;
use crate::settings::SettingsTable;

/// Seconds a settings query waits for the DL_VALUE of the value it set.
pub const SETTING_TIMEOUT: f64 = 2.0;

/// Commands an aircraft takes per second by default.
pub const DEFAULT_UPLINK_RATE: f64 = 20.0;

/// Settings queries waiting for their DL_VALUE at most; further ones are refused.
pub const MAX_PENDING_SETTINGS: usize = 64;

/// Why a command was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Refusal {
    /// The key is not `pprz/<ac_id>/uplink/<MESSAGE>` with an id 0..=255.
    BadKey,
    /// The `messages.xml` has no such datalink message.
    UnknownMessage,
    /// The payload is not the message's JSON object ([`json::ParseError`]).
    BadFields,
    /// The `ac_id` field names another aircraft than the key.
    OtherAircraft,
    /// The aircraft's command rate was exceeded.
    Rate,
    /// No link can send to the aircraft, or the transport refused the frame.
    NoLink,
    /// The settings query named no setting, or a value out of bounds.
    BadSetting,
    /// More settings queries than [`MAX_PENDING_SETTINGS`] were waiting.
    TooManyQueries,
    /// The payload of the command or the settings query is longer than
    /// [`MAX_PAYLOAD`] bytes (dropped unread).
    TooLarge,
}

impl Refusal {
    /// Its name in the JSON counters.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::BadKey => "bad_key",
            Self::UnknownMessage => "unknown_message",
            Self::BadFields => "bad_fields",
            Self::OtherAircraft => "other_aircraft",
            Self::Rate => "rate",
            Self::NoLink => "no_link",
            Self::BadSetting => "bad_setting",
            Self::TooManyQueries => "too_many_queries",
            Self::TooLarge => "too_large",
        }
    }
}

/// A result, or why the request is refused (the reason, and a message for the client).
type Checked<T> = Result<T, (Refusal, String)>;

/// An aircraft's token bucket: `rate` tokens a second, at most `rate.max(1.0)` (a rate
/// below one lets one command go every `1/rate` seconds).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Bucket {
    tokens: f64,
    at: f64,
}

impl Bucket {
    /// A full bucket at `now`.
    fn full(now: f64, rate: f64) -> Self {
        Self {
            tokens: rate.max(1.0),
            at: now,
        }
    }

    /// Takes a token at `now` (a clock going back is taken as still): whether there
    /// was one.
    fn take(&mut self, now: f64, rate: f64) -> bool {
        let elapsed = (now - self.at).max(0.0);
        self.tokens = (self.tokens + elapsed * rate).min(rate.max(1.0));
        self.at = self.at.max(now);
        if self.tokens < 1.0 {
            return false;
        }
        self.tokens -= 1.0;
        true
    }
}

/// A settings query waiting for its DL_VALUE.
struct Pending {
    query: Query,
    ac: u8,
    index: u8,
    value: f32,
    deadline: f64,
}

/// The gateway's counters.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ServiceStats {
    /// Messages delivered (published).
    pub delivered: u64,
    /// Commands sent (on one link or more).
    pub commands: u64,
    /// Frames written to links.
    pub frames_sent: u64,
    /// Frames a link failed to write.
    pub send_errors: u64,
    /// Refused commands and queries, by reason.
    pub refused: BTreeMap<Refusal, u64>,
    /// Settings queries answered.
    pub settings_answered: u64,
}

/// The gateway serving the bus (module doc).
pub struct Service {
    name: String,
    gateway: Gateway,
    bus: Bus,
    uplinks: Vec<Uplink>,
    table: Option<Arc<SettingsTable>>,
    rate: f64,
    buckets: BTreeMap<u8, Bucket>,
    pending: Vec<Pending>,
    stats: ServiceStats,
    /// The liveliness tokens of the live aircraft, and the gateway's own.
    alive: BTreeMap<u8, LivelinessToken>,
    _token: Option<LivelinessToken>,
}

impl Service {
    /// The gateway `name` (in the bus keys) with its links' uplinks (in link order),
    /// on `bus`.
    pub fn new(name: &str, gateway: Gateway, uplinks: Vec<Uplink>, bus: Bus) -> Self {
        let token = bus.token(&keys::gateway(name));
        Self {
            name: name.to_owned(),
            gateway,
            bus,
            uplinks,
            table: None,
            rate: DEFAULT_UPLINK_RATE,
            buckets: BTreeMap::new(),
            pending: Vec::new(),
            stats: ServiceStats::default(),
            alive: BTreeMap::new(),
            _token: token,
        }
    }

    /// The same service naming settings with `table`.
    pub fn with_settings(mut self, table: Arc<SettingsTable>) -> Self {
        self.table = Some(table);
        self
    }

    /// The same service taking at most `per_second` commands per aircraft.
    pub fn with_uplink_rate(mut self, per_second: f64) -> Self {
        self.rate = per_second;
        self
    }

    /// The gateway.
    pub fn gateway(&self) -> &Gateway {
        &self.gateway
    }

    /// The gateway, to feed a ground station's own requests through it.
    pub fn gateway_mut(&mut self) -> &mut Gateway {
        &mut self.gateway
    }

    /// The counters.
    pub fn stats(&self) -> &ServiceStats {
        &self.stats
    }

    /// The bus.
    pub fn bus(&self) -> &Bus {
        &self.bus
    }

    /// Bytes from link `link` at `now`: each message delivered is published.
    pub fn feed(&mut self, link: usize, now: f64, bytes: &[u8]) {
        self.arrive(link, now, Arrival::Bytes(bytes), |_| {});
    }

    /// Input of link `link` was dropped before the next bytes (its queue overflowed):
    /// counted by the link's monitor, the frame being assembled abandoned.
    pub fn input_gap(&mut self, link: usize, now: f64, dropped: crate::input::Drops) {
        if !dropped.is_empty() {
            self.arrive(link, now, Arrival::Gap(dropped), |_| {});
        }
    }

    /// What arrived on link `link` at `now`; each message delivered is published, then
    /// given to `deliver` (for a ground station that runs the service in its own loop).
    pub fn arrive(
        &mut self,
        link: usize,
        now: f64,
        arrival: Arrival<'_>,
        mut deliver: impl FnMut(&Delivered<'_>),
    ) {
        let Self {
            gateway,
            bus,
            stats,
            ..
        } = self;
        gateway.arrive(link, now, arrival, |d| {
            stats.delivered += 1;
            publish(bus, d);
            deliver(d);
        });
        if !self.pending.is_empty() {
            self.answer_settings(now);
        }
    }

    /// Handles the requests waiting (at most `max`).
    pub fn serve_requests(&mut self, now: f64, max: usize) {
        for _ in 0..max {
            let Some(request) = self.bus.next_request() else {
                return;
            };
            match request {
                Request::Command { key, payload } => {
                    if let Err((reason, why)) = self.command(now, &key, &payload) {
                        self.refuse(&key, reason, &why);
                    }
                }
                Request::Setting(query) => self.setting_query(now, query),
                Request::TooLarge { key, len } => {
                    self.refuse(&key, Refusal::TooLarge, &bus::too_large_message(len));
                }
            }
        }
    }

    /// One command: checked, framed and sent.
    fn command(&mut self, now: f64, key: &str, payload: &[u8]) -> Checked<()> {
        check_length(payload)?;
        let (ac, name) = keys::parse_uplink(key).ok_or((
            Refusal::BadKey,
            "not pprz/<ac_id>/uplink/<MESSAGE>".to_owned(),
        ))?;
        let set = self.gateway.fleet().set();
        let desc = set.find_by_name("datalink", &name).ok_or_else(|| {
            (
                Refusal::UnknownMessage,
                format!("no datalink message {}", crate::escape::token(&name)),
            )
        })?;
        let text = std::str::from_utf8(payload).map_err(|_| {
            (
                Refusal::BadFields,
                "the payload is not UTF-8 text".to_owned(),
            )
        })?;
        let mut value: Value =
            serde_json::from_str(text).map_err(|e| (Refusal::BadFields, e.to_string()))?;
        if desc.fields.iter().any(|f| f.name == "ac_id")
            && let Some(obj) = value.as_object_mut()
        {
            match obj.get("ac_id") {
                None => {
                    obj.insert("ac_id".into(), Value::from(ac));
                }
                Some(v) if v.as_f64() == Some(f64::from(ac)) => {}
                Some(v) => {
                    return Err((
                        Refusal::OtherAircraft,
                        format!(
                            "ac_id {} in the fields, {ac} in the key",
                            crate::escape::token(&v.to_string())
                        ),
                    ));
                }
            }
        }
        let bytes =
            json::parse_message(desc, &value).map_err(|e| (Refusal::BadFields, e.to_string()))?;
        self.take_token(now, ac)?;
        self.send(now, ac, desc, &bytes)
    }

    /// Frames and writes a message for `ac` on the links its route takes.
    fn send(
        &mut self,
        now: f64,
        ac: u8,
        desc: &pprz_messages::MessageDescriptor<'_>,
        payload: &[u8],
    ) -> Checked<()> {
        let frames = self
            .gateway
            .uplink(now, ac, desc, payload)
            .map_err(|e| (Refusal::NoLink, e.to_string()))?;
        self.stats.commands += 1;
        for (link, frame) in frames {
            match self.uplinks.get_mut(link).map(|u| u.send(&frame)) {
                Some(Ok(())) => self.stats.frames_sent += 1,
                _ => self.stats.send_errors += 1,
            }
        }
        Ok(())
    }

    /// Takes a command token of aircraft `ac`.
    fn take_token(&mut self, now: f64, ac: u8) -> Checked<()> {
        let rate = self.rate;
        let b = self
            .buckets
            .entry(ac)
            .or_insert_with(|| Bucket::full(now, rate));
        if !b.take(now, rate) {
            return Err((
                Refusal::Rate,
                format!("more than {rate} commands a second for aircraft {ac}"),
            ));
        }
        Ok(())
    }

    /// Counts and publishes a refusal.
    fn refuse(&mut self, key: &str, reason: Refusal, why: &str) {
        *self.stats.refused.entry(reason).or_insert(0) += 1;
        let body = json!({
            "key": crate::escape::token(key),
            "reason": reason.as_str(),
            "message": why,
            "count": self.stats.refused[&reason],
        });
        let key = keys::refused(&self.name);
        self.bus.put(&key, body.to_string(), None);
    }

    /// A settings query: read, or set and wait for the DL_VALUE.
    fn setting_query(&mut self, now: f64, query: Query) {
        let key = query.key_expr().as_str().to_owned();
        // (The bus refused longer payloads before queueing the query; the set below is
        // checked again before it is parsed.)
        let payload = query.payload().map(|p| p.to_bytes().into_owned());
        let sets = payload.as_ref().is_some_and(|p| !p.is_empty());
        if sets && self.pending.len() >= MAX_PENDING_SETTINGS {
            let why = format!("more than {MAX_PENDING_SETTINGS} settings queries waiting");
            let _ = query.reply_err(why.clone()).wait();
            self.refuse(&key, Refusal::TooManyQueries, &why);
            return;
        }
        match self.setting_request(now, &key, payload.as_deref()) {
            Ok(Some((ac, index, value))) => {
                self.pending.push(Pending {
                    query,
                    ac,
                    index,
                    value,
                    deadline: now + SETTING_TIMEOUT,
                });
            }
            Ok(None) => {
                let answer =
                    keys::parse_setting(&key).and_then(|(ac, name)| self.setting_json(ac, &name));
                self.stats.settings_answered += 1;
                let _ = query
                    .reply(
                        query.key_expr().clone(),
                        answer.unwrap_or_default().to_string(),
                    )
                    .wait();
            }
            Err((reason, why)) => {
                let _ = query.reply_err(why.clone()).wait();
                self.refuse(&key, reason, &why);
            }
        }
    }

    /// A settings query checked: `None` to read, or the setting sent: `(ac, index,
    /// value)`.
    fn setting_request(
        &mut self,
        now: f64,
        key: &str,
        payload: Option<&[u8]>,
    ) -> Checked<Option<(u8, u8, f32)>> {
        let bad = |why: String| (Refusal::BadSetting, why);
        let (ac, name) = keys::parse_setting(key).ok_or((
            Refusal::BadKey,
            "not pprz/<ac_id>/settings/<name>".to_owned(),
        ))?;
        let table = self.table.clone();
        let index = match &table {
            Some(t) => t.resolve(&name).map_err(|e| bad(e.to_string()))?,
            None => name
                .parse::<u8>()
                .map_err(|_| bad("a name needs the settings files (--settings)".into()))?,
        };
        let Some(payload) = payload.filter(|p| !p.is_empty()) else {
            return Ok(None);
        };
        check_length(payload)?;
        let v: Value = serde_json::from_slice(payload).map_err(|e| bad(e.to_string()))?;
        let text = match v.get("value") {
            Some(Value::Number(n)) => n.to_string(),
            Some(Value::String(s)) => s.clone(),
            _ => return Err(bad("give {\"value\": a number or a label}".into())),
        };
        let arg = SettingArg {
            name: index.to_string(),
            value: text,
        };
        let resolved = arg.resolve(table.as_deref()).map_err(bad)?;
        let set = self.gateway.fleet().set();
        let desc = set.find_by_name("datalink", "SETTING").ok_or((
            Refusal::UnknownMessage,
            "the messages.xml has no SETTING".to_owned(),
        ))?;
        let fields = json!({"index": resolved.index, "ac_id": ac, "value": resolved.value});
        let bytes =
            json::parse_message(desc, &fields).map_err(|e| (Refusal::BadFields, e.to_string()))?;
        self.take_token(now, ac)?;
        self.send(now, ac, desc, &bytes)?;
        Ok(Some((ac, resolved.index, resolved.value)))
    }

    /// The JSON answer for setting `name` of aircraft `ac`.
    fn setting_json(&self, ac: u8, name: &str) -> Option<Value> {
        let index = match &self.table {
            Some(t) => t.resolve(name).ok()?,
            None => name.parse().ok()?,
        };
        let value = self
            .gateway
            .fleet()
            .aircraft_state(ac)
            .and_then(|a| a.setting_values().get(&index).copied())
            .filter(|v| v.is_finite());
        let def = self.table.as_ref().and_then(|t| t.get(index));
        Some(json!({
            "ac_id": ac,
            "index": index,
            "name": self.table.as_ref().and_then(|t| t.unique_name(index)),
            "value": value,
            "min": def.map(|d| d.min),
            "max": def.map(|d| d.max),
        }))
    }

    /// Answers the settings queries whose DL_VALUE came, and those that waited too long.
    fn answer_settings(&mut self, now: f64) {
        let mut i = 0;
        while i < self.pending.len() {
            let p = &self.pending[i];
            let value = self
                .gateway
                .fleet()
                .aircraft_state(p.ac)
                .and_then(|a| a.setting_values().get(&p.index).copied());
            let applied = value.is_some_and(|v| {
                (v as f32 - p.value).abs() <= f32::EPSILON * p.value.abs().max(1.0)
            });
            if !applied && now < p.deadline {
                i += 1;
                continue;
            }
            let p = self.pending.swap_remove(i);
            self.stats.settings_answered += 1;
            if applied {
                let name = self
                    .table
                    .as_ref()
                    .and_then(|t| t.unique_name(p.index))
                    .map(str::to_owned);
                let answer =
                    self.setting_json(p.ac, name.as_deref().unwrap_or(&p.index.to_string()));
                let _ = p
                    .query
                    .reply(
                        p.query.key_expr().clone(),
                        answer.unwrap_or_default().to_string(),
                    )
                    .wait();
            } else {
                let why = format!(
                    "no DL_VALUE of {} from aircraft {} within {SETTING_TIMEOUT} s (value in force: {})",
                    p.value,
                    p.ac,
                    value.map_or("unknown".to_owned(), |v| v.to_string())
                );
                let _ = p.query.reply_err(why).wait();
            }
        }
    }

    /// Once a second or so: closes merging windows, answers late settings queries,
    /// publishes the link figures of each aircraft and link, and the counters.
    pub fn tick(&mut self, now: f64) {
        self.gateway.tick(now);
        self.answer_settings(now);
        let fleet = self.gateway.fleet();
        for ac in fleet.aircraft() {
            let Some(state) = fleet.aircraft_state(ac).filter(|a| a.frames() > 0) else {
                continue;
            };
            let quality = fleet.link_quality(ac, now);
            let live = quality.as_ref().is_some_and(|q| q.state == LinkState::Live);
            if !live {
                self.alive.remove(&ac);
            } else if !self.alive.contains_key(&ac)
                && let Some(t) = self.bus.token(&keys::alive(ac))
            {
                self.alive.insert(ac, t);
            }
            let mut body = crate::viewer::link_json(state, quality.as_ref(), None, None);
            body["links"] = self
                .gateway
                .routes()
                .links_of(now, ac)
                .iter()
                .map(|&(l, since)| json!({"link": self.gateway.links()[l].name(), "since_heard_s": since}))
                .collect();
            self.bus.put(&keys::link(ac), body.to_string(), None);
        }
        for (i, l) in self.gateway.links().iter().enumerate() {
            let m = self.gateway.link_merge(i);
            let d = l.monitor().decoder_stats();
            let body = json!({
                "link": l.name(),
                "can_send": l.can_send(),
                "bytes": l.monitor().bytes(),
                "frames": d.frames,
                "checksum_errors": d.checksum_errors,
                "first": m.first,
                "duplicates": m.duplicates,
                "alone": m.alone,
                "missed": m.missed,
            });
            let key = keys::gateway_link(&self.name, l.name());
            self.bus.put(&key, body.to_string(), None);
        }
        let body = self.stats_json();
        self.bus
            .put(&keys::stats(&self.name), body.to_string(), None);
    }

    /// The counters as JSON (published on `pprz/gateway/<name>/stats`).
    pub fn stats_json(&self) -> Value {
        let refused: serde_json::Map<String, Value> = self
            .stats
            .refused
            .iter()
            .map(|(r, n)| (r.as_str().to_owned(), Value::from(*n)))
            .collect();
        let links: Vec<Value> = (0..self.gateway.links().len())
            .map(|i| {
                let m = self.gateway.link_merge(i);
                json!({"link": self.gateway.links()[i].name(), "first": m.first, "duplicates": m.duplicates, "alone": m.alone, "missed": m.missed})
            })
            .collect();
        json!({
            "delivered": self.stats.delivered,
            "commands": self.stats.commands,
            "frames_sent": self.stats.frames_sent,
            "send_errors": self.stats.send_errors,
            "refused": refused,
            "flooded": self.bus.flooded(),
            "put_errors": self.bus.put_errors(),
            "settings_answered": self.stats.settings_answered,
            "dedup_window_s": self.gateway.dedup().window(),
            "remembered": self.gateway.dedup().len(),
            "evicted": self.gateway.dedup().evicted(),
            "links": links,
        })
    }
}

/// Refuses a payload longer than [`MAX_PAYLOAD`] (before it is read).
fn check_length(payload: &[u8]) -> Checked<()> {
    if payload.len() > MAX_PAYLOAD {
        return Err((Refusal::TooLarge, bus::too_large_message(payload.len())));
    }
    Ok(())
}

/// Publishes a delivered message: its JSON on its key (when the set decodes it), its
/// PPRZ v2 frame on the aircraft's frame key.
fn publish(bus: &mut Bus, d: &Delivered<'_>) {
    let m = d.message;
    if let Some(desc) = m.message.filter(|_| m.valid)
        && let Ok(body) = json::message(desc, m.payload)
    {
        let key = keys::message(m.source, desc.class_name, desc.name);
        bus.put(&key, body, Some(d.received.to_vec()));
    }
    bus.put(&keys::frame(m.source), m.raw.to_vec(), None);
}

#[cfg(test)]
mod tests {
    use super::Bucket;

    /// Whether each command at `times` goes, at `rate` a second.
    fn goes(rate: f64, times: &[f64]) -> Vec<bool> {
        let mut b = Bucket::full(times[0], rate);
        times.iter().map(|&t| b.take(t, rate)).collect()
    }

    #[test]
    fn below_one_a_second_one_command_goes_every_one_over_rate_seconds() {
        let times = [
            0.0, 0.1, 1.0, 1.9, 2.0, 2.5, 3.5, 4.0, 100.0, 100.0, 101.0, 102.0,
        ];
        let expect = [
            true, false, false, false, true, false, false, true, true, false, false, true,
        ];
        assert_eq!(goes(0.5, &times), expect);
        // The slowest rate the command line takes.
        assert_eq!(
            goes(0.1, &[0.0, 5.0, 10.0, 15.0, 20.0]),
            [true, false, true, false, true]
        );
    }

    #[test]
    fn at_one_a_second_and_above_the_burst_is_the_rate() {
        assert_eq!(goes(1.0, &[0.0, 0.0, 0.5, 1.0]), [true, false, false, true]);
        let burst = goes(20.0, &[0.0; 21]);
        assert_eq!(burst.iter().filter(|&&g| g).count(), 20);
        assert!(!burst[20]);
        // A twentieth of a second later, one more.
        let mut b = Bucket::full(0.0, 20.0);
        for _ in 0..20 {
            assert!(b.take(0.0, 20.0));
        }
        assert!(b.take(0.05, 20.0));
        assert!(!b.take(0.05, 20.0));
    }

    #[test]
    fn a_clock_going_back_gives_no_tokens() {
        let mut b = Bucket::full(10.0, 0.5);
        assert!(b.take(10.0, 0.5));
        assert!(!b.take(5.0, 0.5));
        assert!(!b.take(11.0, 0.5));
        assert!(b.take(12.0, 0.5));
    }
}
