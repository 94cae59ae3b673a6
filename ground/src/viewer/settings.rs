//! Settings from the viewer: the Foxglove parameters `/ac/<id>/settings/<index>` read
//! and written from the Parameters panel become GET_SETTING and SETTING requests to the
//! aircraft, answered with the value its DL_VALUE reports.
//!
//! With the aircraft's settings files (a [`SettingsTable`]), the parameters are named
//! `/ac/<id>/settings/<name>` instead, `<name>` being the setting's name unique in the
//! table (its var, with its `.`: [`SettingsTable::unique_name`]), and their values are in
//! the setting's display unit (its `alt_unit`). A value set is checked as `--setting`
//! checks it: a number in the display unit, or a label as a string; outside the bounds,
//! NaN, an infinity or an unknown label is refused with an error status naming the
//! bounds, and nothing is sent.
//!
//! * Reading named parameters sends a GET_SETTING per parameter; the answer is the
//!   reported value. Reading all parameters answers at once with every value reported so
//!   far (DL_VALUEs, periodic ones included).
//! * Writing a parameter sends a SETTING; the answer is the value the aircraft then
//!   reports. When that is not the value set (as the wire type carries it), the aircraft
//!   did not apply it: the answer carries the aircraft's value, and a warning status
//!   says "not applied".
//! * Requests unanswered after [`ANSWER_TIMEOUT`] seconds are answered with what is known,
//!   and a warning status says so.
//! * A value that a SETTING cannot carry (not a finite number that fits a `float`, the
//!   rule of `--setting`: [`setting_value`]) is refused: nothing is sent, and the answer
//!   comes at once with what is known and an error status to the client. So is a
//!   setting the ground cannot send ([`Viewer::setting_not_sent`]: no secure session
//!   yet, or the uplink failed). Both are counted ([`ViewerCounts`]).
//! * A request to an aircraft the monitor does not track is sent, but does not make the
//!   monitor track it ([`SettingRequest::sent`]).
//!
//! Bounded: at most [`MAX_NAMES`] parameters per request, [`MAX_PENDING`] requests
//! waiting (further ones are answered at once with what is known and an error status,
//! and counted), and one value per aircraft and index.
//!
//! [`Viewer::setting_not_sent`]: super::Viewer::setting_not_sent
//! [`ViewerCounts`]: super::ViewerCounts

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

use foxglove::websocket::{
    AnyClient, GetParametersResponder, Parameter, ParameterHandler, ParameterValue,
    SetParametersResponder,
};
use pprz_messages::BaseType;

use crate::monitor::Monitor;
use crate::settings::{SettingsTable, quantize, setting_value};

/// Parameters per request, at most (further names are ignored).
pub const MAX_NAMES: usize = 32;

/// Requests waiting for the aircraft, at most.
pub const MAX_PENDING: usize = 64;

/// Seconds after which a request is answered with what is known.
pub const ANSWER_TIMEOUT: f64 = 3.0;

/// The parameter name of setting `index` of aircraft `ac_id`.
pub fn parameter_name(ac_id: u8, index: u8) -> String {
    format!("/ac/{ac_id}/settings/{index}")
}

/// The aircraft and setting index a parameter name names, if it is one.
pub fn parse_name(name: &str) -> Option<(u8, u8)> {
    let (ac, index) = split_name(name)?;
    if !digits(index) {
        return None;
    }
    Some((ac, index.parse().ok()?))
}

/// Whether `s` is a number of 1 to 3 digits.
fn digits(s: &str) -> bool {
    !s.is_empty() && s.len() <= 3 && s.bytes().all(|b| b.is_ascii_digit())
}

/// The aircraft and the rest of `/ac/<id>/settings/<rest>`.
fn split_name(name: &str) -> Option<(u8, &str)> {
    let rest = name.strip_prefix("/ac/")?;
    let (ac, rest) = rest.split_once("/settings/")?;
    if !digits(ac) {
        return None;
    }
    Some((ac.parse().ok()?, rest))
}

/// How parameters are named and valued: by index in the aircraft's units, or, with the
/// settings files' table, by name in the display units.
#[derive(Debug, Clone, Default)]
pub struct Naming(Option<Arc<SettingsTable>>);

impl Naming {
    /// Parameters named after `table` (or by index without one).
    pub fn new(table: Option<Arc<SettingsTable>>) -> Self {
        Self(table)
    }

    /// The table, if any.
    fn table(&self) -> Option<&SettingsTable> {
        self.0.as_deref()
    }

    /// The parameter of setting `index` of aircraft `ac_id`: `/ac/<id>/settings/<name>`
    /// with a table that has the index, else `/ac/<id>/settings/<index>`.
    pub fn name(&self, ac_id: u8, index: u8) -> String {
        match self.table().and_then(|t| t.unique_name(index)) {
            Some(name) => format!("/ac/{ac_id}/settings/{name}"),
            None => parameter_name(ac_id, index),
        }
    }

    /// The aircraft and setting index a parameter name names: by name with a table, by
    /// index without.
    pub fn parse(&self, name: &str) -> Option<(u8, u8)> {
        match self.table() {
            Some(t) => {
                let (ac, rest) = split_name(name)?;
                Some((ac, t.by_unique_name(rest)?))
            }
            None => parse_name(name),
        }
    }

    /// The parameter's value for the aircraft's `value` of setting `index`: in its
    /// display unit with a table.
    pub fn shown(&self, index: u8, value: f64) -> f64 {
        self.table().map_or(value, |t| t.to_display(index, value))
    }

    /// `gain (index 2)` with a table, else `2`.
    fn describe(&self, index: u8) -> String {
        match self.table().filter(|t| t.get(index).is_some()) {
            Some(t) => t.describe(index),
            None => index.to_string(),
        }
    }

    /// A value of setting `index` for a message: as the table shows it, or the number.
    fn value_text(&self, index: u8, value: f64) -> String {
        match self.table().filter(|t| t.get(index).is_some()) {
            Some(t) => t.show(index, value),
            None => value.to_string(),
        }
    }

    /// The aircraft's value for a parameter of setting `index` set to `value`: a number
    /// in the display unit (or a label, as a string) checked against the bounds with a
    /// table; any finite number that fits a float without.
    ///
    /// # Errors
    /// Why it is refused, for the client.
    pub fn set_value(&self, index: u8, value: Option<&ParameterValue>) -> Result<f64, String> {
        let Some(t) = self.table() else {
            return set_value(value);
        };
        let checked = match value {
            Some(ParameterValue::Float64(v)) => t.display_value(index, *v),
            Some(ParameterValue::Integer(v)) => t.display_value(index, *v as f64),
            Some(ParameterValue::Bool(b)) => t.display_value(index, f64::from(u8::from(*b))),
            Some(ParameterValue::String(label)) => t.value(index, label),
            _ => return Err("not a number".to_owned()),
        };
        checked.map(f64::from).map_err(|e| e.to_string())
    }
}

/// What the viewer asks of an aircraft: the ground sends it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SettingRequest {
    /// GET_SETTING `index` of `ac_id`.
    Get {
        /// The aircraft.
        ac_id: u8,
        /// The setting index.
        index: u8,
    },
    /// SETTING `index` of `ac_id` to `value`.
    Set {
        /// The aircraft.
        ac_id: u8,
        /// The setting index.
        index: u8,
        /// The value asked for.
        value: f64,
    },
}

impl SettingRequest {
    /// The aircraft it is for.
    pub fn ac_id(&self) -> u8 {
        match *self {
            Self::Get { ac_id, .. } | Self::Set { ac_id, .. } => ac_id,
        }
    }

    /// The uplink message to send (`GET_SETTING` or `SETTING`) and its field values, for
    /// [`uplink::frame`](crate::uplink::frame).
    pub fn message(&self) -> (&'static str, Vec<(&'static str, f64)>) {
        match *self {
            Self::Get { ac_id, index } => (
                "GET_SETTING",
                vec![("index", f64::from(index)), ("ac_id", f64::from(ac_id))],
            ),
            Self::Set {
                ac_id,
                index,
                value,
            } => (
                "SETTING",
                vec![
                    ("index", f64::from(index)),
                    ("ac_id", f64::from(ac_id)),
                    ("value", value),
                ],
            ),
        }
    }

    /// Tells `monitor` the request was sent at `now`, so that the aircraft's DL_VALUE
    /// is matched to it, if the monitor tracks the aircraft (it heard it, or the ground
    /// addresses it). A request from a viewer never makes the monitor track an aircraft:
    /// it must not take the place of one heard. The viewer matches the answer all the
    /// same.
    pub fn sent(&self, monitor: &mut Monitor, now: f64) {
        if monitor.aircraft_state(self.ac_id()).is_none() {
            return;
        }
        match *self {
            Self::Get { ac_id, index } => monitor.get_setting_sent(Some(ac_id), now, index),
            Self::Set {
                ac_id,
                index,
                value,
            } => monitor.setting_sent(Some(ac_id), now, index, value),
        }
    }
}

/// Where an answer goes: the values, and an error status, to the requesting client (a
/// Foxglove responder and its client; closures in tests).
pub(crate) struct Reply {
    values: Box<dyn FnOnce(Vec<Parameter>) + Send>,
    error: Box<dyn FnOnce(String) + Send>,
}

impl Reply {
    /// A reply made of `values` (the parameters answered) and `error` (an error status).
    pub(crate) fn new(
        values: impl FnOnce(Vec<Parameter>) + Send + 'static,
        error: impl FnOnce(String) + Send + 'static,
    ) -> Self {
        Self {
            values: Box::new(values),
            error: Box::new(error),
        }
    }

    /// Answers with `values`, after an error status made of `errors` if there are any
    /// (the status first: a client reading the answer has seen why).
    fn send(self, values: Vec<Parameter>, errors: &[String]) {
        if !errors.is_empty() {
            (self.error)(errors.join("; "));
        }
        (self.values)(values);
    }
}

/// A setting refused before anything is sent: its value is not one a SETTING carries.
pub(crate) struct Refused {
    ac_id: u8,
    index: u8,
    why: String,
}

/// A request from a viewer, as the handler passes it on.
pub(crate) enum Call {
    /// Read these settings (none: every known one).
    Get(Vec<(u8, u8)>, Reply),
    /// Write these settings; the `refused` ones are not sent.
    Set {
        values: Vec<(u8, u8, f64)>,
        refused: Vec<Refused>,
        reply: Reply,
    },
}

/// The SDK's parameter handler: passes requests to the ground's loop through a bounded
/// channel (never blocks the server).
pub(crate) struct Handler {
    tx: SyncSender<Call>,
    /// Requests answered here because the channel was full.
    busy: Arc<AtomicU64>,
    naming: Naming,
}

impl Handler {
    fn pass(&self, call: Call) {
        if let Err(TrySendError::Full(call) | TrySendError::Disconnected(call)) =
            self.tx.try_send(call)
        {
            // The ground is behind: nothing is known here, answer empty.
            self.busy.fetch_add(1, Ordering::Relaxed);
            let reply = match call {
                Call::Get(_, reply) | Call::Set { reply, .. } => reply,
            };
            reply.send(Vec::new(), &[BUSY.to_owned()]);
        }
    }
}

/// The error status of a request answered at once because too many are waiting.
const BUSY: &str = "settings not sent: too many requests are waiting for the aircraft";

/// The value of a parameter set from a viewer, if it is one a SETTING carries (the rule
/// of `--setting`: [`setting_value`]).
fn set_value(value: Option<&ParameterValue>) -> Result<f64, String> {
    let v = match value {
        Some(ParameterValue::Float64(v)) => *v,
        Some(ParameterValue::Integer(v)) => *v as f64,
        Some(ParameterValue::Bool(b)) => f64::from(u8::from(*b)),
        _ => return Err("not a number".to_owned()),
    };
    setting_value(v).map(|_| v).map_err(|e| e.to_string())
}

impl ParameterHandler for Handler {
    fn get(
        &self,
        _client: AnyClient,
        names: Vec<String>,
        _request_id: Option<String>,
        responder: GetParametersResponder,
    ) {
        let keys = names
            .iter()
            .filter_map(|n| self.naming.parse(n))
            .take(MAX_NAMES)
            .collect();
        let client = responder.client();
        let reply = Reply::new(move |p| responder.respond(p), move |e| client.send_error(e));
        self.pass(Call::Get(keys, reply));
    }

    fn set(
        &self,
        _client: AnyClient,
        parameters: Vec<Parameter>,
        _request_id: Option<String>,
        responder: SetParametersResponder,
    ) {
        let client = responder.client();
        let reply = Reply::new(move |p| responder.respond(p), move |e| client.send_error(e));
        self.pass(set_call(&self.naming, &parameters, reply));
    }
}

/// The call for setting `parameters` (those `naming` knows, the first [`MAX_NAMES`]):
/// the values a SETTING can carry (within the bounds, with a table), and the others
/// refused.
fn set_call(naming: &Naming, parameters: &[Parameter], reply: Reply) -> Call {
    let mut values = Vec::new();
    let mut refused = Vec::new();
    let ours = parameters
        .iter()
        .filter_map(|p| Some((naming.parse(&p.name)?, p.value.as_ref())));
    for ((ac_id, index), value) in ours.take(MAX_NAMES) {
        match naming.set_value(index, value) {
            Ok(v) => values.push((ac_id, index, v)),
            Err(why) => refused.push(Refused { ac_id, index, why }),
        }
    }
    Call::Set {
        values,
        refused,
        reply,
    }
}

/// One setting a request waits for.
struct Wait {
    ac_id: u8,
    index: u8,
    /// The value set (SETTING), none for GET_SETTING.
    requested: Option<f64>,
    /// The value reported since the request.
    reported: Option<f64>,
    /// Why it was not sent (refused, or no link to send it on).
    failed: Option<String>,
}

impl Wait {
    fn new(ac_id: u8, index: u8, requested: Option<f64>) -> Self {
        Self {
            ac_id,
            index,
            requested,
            reported: None,
            failed: None,
        }
    }

    /// Answered, or never to be.
    fn done(&self) -> bool {
        self.reported.is_some() || self.failed.is_some()
    }

    /// The request to send for it.
    fn request(&self) -> SettingRequest {
        let (ac_id, index) = (self.ac_id, self.index);
        match self.requested {
            Some(value) => SettingRequest::Set {
                ac_id,
                index,
                value,
            },
            None => SettingRequest::Get { ac_id, index },
        }
    }
}

/// A request waiting for its answers.
struct Pending {
    waits: Vec<Wait>,
    reply: Reply,
    deadline: f64,
}

/// A status for the viewer's clients.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Warning(pub String);

/// Settings requested from the viewers and not sent, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct NotSent {
    /// Values refused: not a finite number that fits a float (or not a number), or with
    /// the settings files outside the bounds or an unknown label.
    pub(crate) refused: u64,
    /// Settings the ground could not send (no secure session yet, or the uplink failed).
    pub(crate) unsent: u64,
    /// Requests answered at once because [`MAX_PENDING`] were waiting (or the channel
    /// from the server was full).
    pub(crate) busy: u64,
}

/// The ground's side of the viewer's settings.
pub(crate) struct Settings {
    rx: Receiver<Call>,
    naming: Naming,
    known: BTreeMap<(u8, u8), f64>,
    pending: Vec<Pending>,
    counts: NotSent,
    /// Requests the handler answered because the channel was full.
    handler_busy: Arc<AtomicU64>,
}

impl Settings {
    /// The settings, named by `naming`, and the handler to give the server.
    pub(crate) fn new(naming: Naming) -> (Self, Handler) {
        let (tx, rx) = sync_channel(MAX_PENDING);
        let busy = Arc::new(AtomicU64::new(0));
        let settings = Self {
            rx,
            naming: naming.clone(),
            known: BTreeMap::new(),
            pending: Vec::new(),
            counts: NotSent::default(),
            handler_busy: busy.clone(),
        };
        (settings, Handler { tx, busy, naming })
    }

    /// What was not sent so far.
    pub(crate) fn not_sent_counts(&self) -> NotSent {
        let mut c = self.counts;
        c.busy += self.handler_busy.load(Ordering::Relaxed);
        c
    }

    /// Answers `p`: each setting with the value reported, else the value known; an
    /// error status names the settings not sent.
    fn answer(&self, p: Pending) {
        let mut values = Vec::new();
        let mut errors = Vec::new();
        for w in &p.waits {
            let v = w
                .reported
                .or_else(|| self.known.get(&(w.ac_id, w.index)).copied());
            values.extend(v.map(|v| self.parameter(w.ac_id, w.index, v)));
            if let Some(e) = &w.failed
                && !errors.contains(e)
            {
                errors.push(e.clone());
            }
        }
        p.reply.send(values, &errors);
    }

    /// The parameter of setting `index` of `ac_id` with the aircraft's `value`.
    fn parameter(&self, ac_id: u8, index: u8, value: f64) -> Parameter {
        Parameter::float64(
            self.naming.name(ac_id, index),
            self.naming.shown(index, value),
        )
    }

    /// Takes the requests the viewers made since the last call: returns what to send to
    /// the aircraft, and answers the requests that need no aircraft, whose values are
    /// all refused, or that are too many.
    pub(crate) fn poll(&mut self, now: f64) -> Vec<SettingRequest> {
        let mut out = Vec::new();
        while let Ok(call) = self.rx.try_recv() {
            let (waits, reply) = match call {
                Call::Get(keys, reply) if keys.is_empty() => {
                    let all = self
                        .known
                        .iter()
                        .map(|(&(ac, i), &v)| self.parameter(ac, i, v))
                        .collect();
                    reply.send(all, &[]);
                    continue;
                }
                Call::Get(keys, reply) => (
                    keys.into_iter()
                        .map(|(ac_id, index)| Wait::new(ac_id, index, None))
                        .collect::<Vec<_>>(),
                    reply,
                ),
                Call::Set {
                    values,
                    refused,
                    reply,
                } => {
                    self.counts.refused += refused.len() as u64;
                    let refused = refused.into_iter().map(|r| Wait {
                        failed: Some(format!(
                            "{} refused: {}",
                            self.naming.name(r.ac_id, r.index),
                            r.why
                        )),
                        ..Wait::new(r.ac_id, r.index, None)
                    });
                    let waits = values
                        .into_iter()
                        .map(|(ac_id, index, v)| Wait::new(ac_id, index, Some(v)));
                    (waits.chain(refused).collect(), reply)
                }
            };
            let pending = Pending {
                waits,
                reply,
                deadline: now + ANSWER_TIMEOUT,
            };
            let to_send = pending.waits.iter().filter(|w| w.failed.is_none()).count();
            if to_send == 0 {
                self.answer(pending);
            } else if self.pending.len() >= MAX_PENDING {
                self.counts.busy += 1;
                let mut pending = pending;
                for w in pending.waits.iter_mut().filter(|w| w.failed.is_none()) {
                    w.failed = Some(BUSY.to_owned());
                }
                self.answer(pending);
            } else {
                out.extend(
                    pending
                        .waits
                        .iter()
                        .filter(|w| w.failed.is_none())
                        .map(Wait::request),
                );
                self.pending.push(pending);
            }
        }
        out
    }

    /// `request` (one of [`poll`](Self::poll)'s) was not sent, because of `why`: counted,
    /// and its request answered (with what is known, and an error status naming `why`)
    /// as soon as nothing else of it is waiting.
    pub(crate) fn not_sent(&mut self, request: &SettingRequest, why: &str) {
        self.counts.unsent += 1;
        let (ac_id, index, requested) = match *request {
            SettingRequest::Get { ac_id, index } => (ac_id, index, None),
            SettingRequest::Set {
                ac_id,
                index,
                value,
            } => (ac_id, index, Some(value.to_bits())),
        };
        // The newest request first: the one just polled.
        let wait = self.pending.iter_mut().rev().find_map(|p| {
            p.waits.iter_mut().find(|w| {
                (w.ac_id, w.index, w.requested.map(f64::to_bits)) == (ac_id, index, requested)
                    && !w.done()
            })
        });
        if let Some(w) = wait {
            w.failed = Some(format!(
                "{} not sent: {why}",
                self.naming.name(ac_id, index)
            ));
        }
        self.answer_complete();
    }

    /// A DL_VALUE from `ac_id`: setting `index` is `value` (a `base` field on the wire).
    /// Returns the parameter to publish, and warnings for settings not applied.
    pub(crate) fn dl_value(
        &mut self,
        ac_id: u8,
        index: u8,
        value: f64,
        base: BaseType,
    ) -> (Parameter, Vec<Warning>) {
        self.known.insert((ac_id, index), value);
        let mut warnings = Vec::new();
        for p in &mut self.pending {
            for w in p
                .waits
                .iter_mut()
                .filter(|w| w.ac_id == ac_id && w.index == index && !w.done())
            {
                w.reported = Some(value);
                if let Some(requested) = w.requested {
                    let wire = quantize(base, requested);
                    if !(wire == value || (wire.is_nan() && value.is_nan())) {
                        warnings.push(Warning(format!(
                            "setting {} of aircraft {ac_id} not applied: asked {}, the aircraft reports {}",
                            self.naming.describe(index),
                            self.naming.value_text(index, requested),
                            self.naming.value_text(index, value)
                        )));
                    }
                }
            }
        }
        self.answer_complete();
        (self.parameter(ac_id, index, value), warnings)
    }

    /// Answers the requests whose settings all reported (or failed).
    fn answer_complete(&mut self) {
        let (done, waiting): (Vec<_>, Vec<_>) = std::mem::take(&mut self.pending)
            .into_iter()
            .partition(|p| p.waits.iter().all(Wait::done));
        self.pending = waiting;
        for p in done {
            self.answer(p);
        }
    }

    /// Answers the requests older than [`ANSWER_TIMEOUT`] at `now` with what is known;
    /// returns a warning per setting without an answer.
    pub(crate) fn expire(&mut self, now: f64) -> Vec<Warning> {
        let (late, waiting): (Vec<_>, Vec<_>) = std::mem::take(&mut self.pending)
            .into_iter()
            .partition(|p| now >= p.deadline);
        self.pending = waiting;
        let mut warnings = Vec::new();
        for p in late {
            for w in p.waits.iter().filter(|w| !w.done()) {
                warnings.push(Warning(format!(
                    "setting {} of aircraft {}: no answer in {ANSWER_TIMEOUT} s",
                    self.naming.describe(w.index),
                    w.ac_id
                )));
            }
            self.answer(p);
        }
        warnings
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// The values of each answer: (name, value).
    type Values = Vec<Vec<(String, f64)>>;

    /// The answers a client got: the values of each, and the error statuses.
    #[derive(Default, Clone)]
    struct Answers {
        values: Arc<Mutex<Values>>,
        errors: Arc<Mutex<Vec<String>>>,
    }

    fn respond(answers: &Answers) -> Reply {
        let (values, errors) = (answers.values.clone(), answers.errors.clone());
        Reply::new(
            move |params: Vec<Parameter>| {
                let v = params
                    .into_iter()
                    .map(|p| match p.value {
                        Some(ParameterValue::Float64(v)) => (p.name, v),
                        other => panic!("{other:?}"),
                    })
                    .collect();
                values.lock().unwrap().push(v);
            },
            move |e| errors.lock().unwrap().push(e),
        )
    }

    fn set(values: Vec<(u8, u8, f64)>, answers: &Answers) -> Call {
        Call::Set {
            values,
            refused: Vec::new(),
            reply: respond(answers),
        }
    }

    fn settings() -> (Settings, SyncSender<Call>) {
        let (s, handler) = Settings::new(Naming::default());
        (s, handler.tx)
    }

    #[test]
    fn names() {
        assert_eq!(parse_name("/ac/7/settings/2"), Some((7, 2)));
        assert_eq!(parameter_name(7, 2), "/ac/7/settings/2");
        for bad in [
            "/ac/256/settings/2",
            "/ac/7/settings/",
            "/ac//settings/1",
            "/ac/7/settings/+1",
            "/ac/7/settings/1/x",
            "ac/7/settings/1",
            "/ac/0007/settings/1",
        ] {
            assert_eq!(parse_name(bad), None, "{bad}");
        }
    }

    #[test]
    fn a_setting_is_answered_with_the_reported_value() {
        let (mut s, tx) = settings();
        let answers = Answers::default();
        tx.try_send(set(vec![(7, 2, 2.5)], &answers)).unwrap();
        let sent = s.poll(0.0);
        assert_eq!(
            sent,
            [SettingRequest::Set {
                ac_id: 7,
                index: 2,
                value: 2.5
            }]
        );
        // Another aircraft's or index's value answers nothing.
        s.dl_value(8, 2, 2.5, BaseType::F32);
        s.dl_value(7, 3, 2.5, BaseType::F32);
        assert!(answers.values.lock().unwrap().is_empty());
        let (p, warnings) = s.dl_value(7, 2, 2.5, BaseType::F32);
        assert!(warnings.is_empty());
        assert_eq!(p.name, "/ac/7/settings/2");
        assert_eq!(
            *answers.values.lock().unwrap(),
            [vec![("/ac/7/settings/2".to_owned(), 2.5)]]
        );
    }

    #[test]
    fn a_setting_not_applied_is_answered_with_the_aircraft_value_and_a_warning() {
        let (mut s, tx) = settings();
        let answers = Answers::default();
        tx.try_send(set(vec![(7, 2, 0.1)], &answers)).unwrap();
        s.poll(0.0);
        // 0.1 as a float reads back as f32 0.1: applied.
        let (_, w) = s.dl_value(7, 2, f64::from(0.1f32), BaseType::F32);
        assert!(w.is_empty());
        tx.try_send(set(vec![(7, 2, 3.0)], &answers)).unwrap();
        s.poll(1.0);
        let (_, w) = s.dl_value(7, 2, 1.0, BaseType::F32);
        assert_eq!(w.len(), 1);
        assert!(w[0].0.contains("not applied"), "{w:?}");
        assert_eq!(
            answers.values.lock().unwrap()[1],
            [("/ac/7/settings/2".to_owned(), 1.0)]
        );
    }

    #[test]
    fn reads_time_out_with_what_is_known_and_all_known_values_come_at_once() {
        let (mut s, tx) = settings();
        let answers = Answers::default();
        s.dl_value(7, 1, 4.0, BaseType::F32);
        tx.try_send(Call::Get(vec![(7, 1), (7, 9)], respond(&answers)))
            .unwrap();
        assert_eq!(s.poll(10.0).len(), 2);
        assert!(s.expire(12.9).is_empty());
        let w = s.expire(13.0);
        assert_eq!(w.len(), 2);
        assert_eq!(
            answers.values.lock().unwrap()[0],
            [("/ac/7/settings/1".to_owned(), 4.0)]
        );
        tx.try_send(Call::Get(Vec::new(), respond(&answers)))
            .unwrap();
        assert!(s.poll(14.0).is_empty());
        assert_eq!(
            answers.values.lock().unwrap()[1],
            [("/ac/7/settings/1".to_owned(), 4.0)]
        );
    }

    #[test]
    fn too_many_waiting_requests_are_answered_at_once() {
        let (mut s, tx) = settings();
        let answers = Answers::default();
        for _ in 0..MAX_PENDING {
            tx.try_send(Call::Get(vec![(7, 1)], respond(&answers)))
                .unwrap();
        }
        assert_eq!(s.poll(0.0).len(), MAX_PENDING);
        tx.try_send(Call::Get(vec![(7, 1)], respond(&answers)))
            .unwrap();
        assert!(s.poll(0.0).is_empty());
        assert_eq!(s.not_sent_counts().busy, 1);
        assert_eq!(answers.values.lock().unwrap().len(), 1);
        assert_eq!(*answers.errors.lock().unwrap(), [BUSY]);
        // The channel itself is bounded: the handler answers empty when it is full.
        let (s2, handler) = Settings::new(Naming::default());
        for _ in 0..MAX_PENDING {
            handler.pass(Call::Get(vec![(7, 1)], respond(&answers)));
        }
        handler.pass(Call::Get(vec![(7, 1)], respond(&answers)));
        assert_eq!(answers.values.lock().unwrap().len(), 2);
        assert_eq!(
            answers.errors.lock().unwrap().len(),
            2,
            "an error status each"
        );
        assert_eq!(s2.not_sent_counts().busy, 1);
    }

    /// Issue: a viewer parameter set to 1e300 or -1e39 went out as SETTING value=+inf /
    /// -inf. Refused as `--setting` refuses it, answered with an error status, counted.
    #[test]
    fn a_value_that_does_not_fit_a_float_is_refused_with_an_error_status() {
        let (mut s, tx) = settings();
        let answers = Answers::default();
        s.dl_value(7, 3, 4.0, BaseType::F32);
        let bad = [
            Parameter::float64("/ac/7/settings/2", 1e300),
            Parameter::float64("/ac/7/settings/3", -1e39),
            Parameter::string("/ac/7/settings/4", "x"),
        ];
        tx.try_send(set_call(&Naming::default(), &bad, respond(&answers)))
            .unwrap();
        assert_eq!(s.poll(0.0), [], "nothing is sent");
        assert_eq!(s.not_sent_counts().refused, 3);
        // Answered at once: the value known, and why.
        assert_eq!(
            *answers.values.lock().unwrap(),
            [vec![("/ac/7/settings/3".to_owned(), 4.0)]]
        );
        let errors = answers.errors.lock().unwrap().clone();
        assert_eq!(errors.len(), 1, "{errors:?}");
        assert!(
            errors[0].contains(
                "/ac/7/settings/2 refused: 1e300 is not a finite number that fits a float"
            ),
            "{errors:?}"
        );
        assert!(
            errors[0].contains("-1e39 is not a finite number"),
            "{errors:?}"
        );
        assert!(errors[0].contains("/ac/7/settings/4 refused: not a number"));
        // With a value that fits: that one is sent, the other refused.
        let mixed = [
            Parameter::float64("/ac/7/settings/2", 2.5),
            Parameter::float64("/ac/7/settings/5", f64::from(f32::MAX) * 2.0),
        ];
        tx.try_send(set_call(&Naming::default(), &mixed, respond(&answers)))
            .unwrap();
        assert_eq!(
            s.poll(1.0),
            [SettingRequest::Set {
                ac_id: 7,
                index: 2,
                value: 2.5
            }]
        );
        s.dl_value(7, 2, 2.5, BaseType::F32);
        assert_eq!(
            answers.values.lock().unwrap()[1],
            [("/ac/7/settings/2".to_owned(), 2.5)]
        );
        assert_eq!(answers.errors.lock().unwrap().len(), 2);
        assert_eq!(s.not_sent_counts().refused, 4);
    }

    /// Issue: a SETTING requested before the secure session was neither sent nor
    /// counted nor answered as not sent (only "no answer" 3 s later).
    #[test]
    fn a_request_not_sent_is_answered_at_once_with_an_error_status_and_counted() {
        let (mut s, tx) = settings();
        let answers = Answers::default();
        tx.try_send(set(vec![(7, 2, 1.5), (7, 3, 0.5)], &answers))
            .unwrap();
        tx.try_send(Call::Get(vec![(7, 2)], respond(&answers)))
            .unwrap();
        let sent = s.poll(0.0);
        assert_eq!(sent.len(), 3);
        s.not_sent(&sent[0], "no secure session yet");
        assert!(answers.values.lock().unwrap().is_empty(), "one still waits");
        s.not_sent(&sent[1], "no secure session yet");
        s.not_sent(&sent[2], "no secure session yet");
        assert_eq!(answers.values.lock().unwrap().len(), 2, "both answered");
        let errors = answers.errors.lock().unwrap().clone();
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(
            errors[0].contains("/ac/7/settings/2 not sent: no secure session yet")
                && errors[0].contains("/ac/7/settings/3 not sent"),
            "{errors:?}"
        );
        assert_eq!(s.not_sent_counts().unsent, 3);
        // Nothing left to time out.
        assert!(s.expire(100.0).is_empty());
    }

    fn named() -> Naming {
        let table = SettingsTable::parse(&[(
            "s.xml",
            r#"<settings><dl_settings>
              <dl_setting var="gain" min="0" max="10"/>
              <dl_setting var="ins.roll_neutral" shortname="roll" min="-15" max="15" unit="rad" alt_unit="deg"/>
              <dl_setting var="ap_mode" min="0" max="19" values="KILL|FAILSAFE|HOME|RATE_DIRECT|ATTITUDE_DIRECT|RATE_RC_CLIMB|ATTITUDE_RC_CLIMB|ATTITUDE_CLIMB|RATE_Z_HOLD|ATTITUDE_Z_HOLD|HOVER_DIRECT|HOVER_CLIMB|HOVER_Z_HOLD|NAV"/>
              <dl_setting var="gain" min="0" max="5"/>
            </dl_settings></settings>"#,
        )])
        .unwrap();
        Naming::new(Some(Arc::new(table)))
    }

    #[test]
    fn parameters_are_named_after_the_settings_files() {
        let n = named();
        assert_eq!(n.name(7, 0), "/ac/7/settings/gain");
        assert_eq!(n.name(7, 1), "/ac/7/settings/ins.roll_neutral");
        assert_eq!(n.name(8, 3), "/ac/8/settings/gain@3", "unique per aircraft");
        assert_eq!(
            n.name(7, 9),
            "/ac/7/settings/9",
            "beyond the files: the index"
        );
        assert_eq!(n.parse("/ac/7/settings/ins.roll_neutral"), Some((7, 1)));
        assert_eq!(n.parse("/ac/7/settings/gain@3"), Some((7, 3)));
        assert_eq!(n.parse("/ac/7/settings/roll"), None, "the unique name only");
        assert_eq!(n.parse("/ac/7/settings/1"), None, "names, not indices");
        assert_eq!(n.parse("/ac/300/settings/gain"), None);
        // Without files: by index, as before.
        let plain = Naming::default();
        assert_eq!(plain.name(7, 1), "/ac/7/settings/1");
        assert_eq!(plain.parse("/ac/7/settings/1"), Some((7, 1)));
        assert_eq!(plain.parse("/ac/7/settings/gain"), None);
    }

    /// A named parameter is set in its display unit or by label, checked against the
    /// bounds (refused with a clear status, nothing sent), and published in its display
    /// unit.
    #[test]
    fn named_parameters_are_bound_checked_and_in_display_units() {
        let (mut s, handler) = Settings::new(named());
        let answers = Answers::default();
        let params = [
            Parameter::float64("/ac/7/settings/ins.roll_neutral", 10.0),
            Parameter::string("/ac/7/settings/ap_mode", "NAV"),
            Parameter::float64("/ac/7/settings/gain", 12.0),
            Parameter::float64("/ac/7/settings/gain@3", f64::NAN),
            Parameter::string("/ac/7/settings/ap_mode", "WARP"),
        ];
        handler
            .tx
            .try_send(set_call(&handler.naming, &params, respond(&answers)))
            .unwrap();
        let roll = (10.0f64 / (180.0 / std::f64::consts::PI)) as f32;
        assert_eq!(
            s.poll(0.0),
            [
                SettingRequest::Set {
                    ac_id: 7,
                    index: 1,
                    value: f64::from(roll)
                },
                SettingRequest::Set {
                    ac_id: 7,
                    index: 2,
                    value: 13.0
                },
            ]
        );
        assert_eq!(s.not_sent_counts().refused, 3);
        let (p, warnings) = s.dl_value(7, 1, f64::from(roll), BaseType::F32);
        assert!(warnings.is_empty());
        assert_eq!(p.name, "/ac/7/settings/ins.roll_neutral");
        assert_eq!(p.value, Some(ParameterValue::Float64(10.0)));
        let (_, warnings) = s.dl_value(7, 2, 2.0, BaseType::F32);
        assert_eq!(
            warnings,
            [Warning(
                "setting ap_mode (index 2) of aircraft 7 not applied: asked NAV (13), the aircraft reports HOME (2)".to_owned()
            )]
        );
        let errors = answers.errors.lock().unwrap().clone();
        assert_eq!(errors.len(), 1, "{errors:?}");
        for expected in [
            "/ac/7/settings/gain refused: setting gain (index 0): 12 is outside its bounds [0, 10]",
            "/ac/7/settings/gain@3 refused: setting gain (index 3): NaN is not a finite number (bounds [0, 5])",
            "/ac/7/settings/ap_mode refused: setting ap_mode (index 2): `WARP` is neither a number nor a label",
        ] {
            assert!(errors[0].contains(expected), "{expected}\n{errors:?}");
        }
        assert_eq!(
            answers.values.lock().unwrap()[0],
            [
                ("/ac/7/settings/ins.roll_neutral".to_owned(), 10.0),
                ("/ac/7/settings/ap_mode".to_owned(), 2.0),
                // The refused label: answered with the value known.
                ("/ac/7/settings/ap_mode".to_owned(), 2.0)
            ]
        );
    }
}
