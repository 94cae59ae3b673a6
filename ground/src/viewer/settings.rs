//! Settings from the viewer: the Foxglove parameters `/ac/<id>/settings/<index>` read
//! and written from the Parameters panel become GET_SETTING and SETTING requests to the
//! aircraft, answered with the value its DL_VALUE reports.
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
//!
//! Bounded: at most [`MAX_NAMES`] parameters per request, [`MAX_PENDING`] requests
//! waiting (further ones are answered at once with what is known, and counted), and one
//! value per aircraft and index.

use std::collections::BTreeMap;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

use foxglove::websocket::{
    AnyClient, GetParametersResponder, Parameter, ParameterHandler, ParameterValue,
    SetParametersResponder,
};
use pprz_messages::BaseType;

use crate::monitor::Monitor;
use crate::settings::quantize;

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
    let rest = name.strip_prefix("/ac/")?;
    let (ac, index) = rest.split_once("/settings/")?;
    let digits = |s: &str| !s.is_empty() && s.len() <= 3 && s.bytes().all(|b| b.is_ascii_digit());
    if !digits(ac) || !digits(index) {
        return None;
    }
    Some((ac.parse().ok()?, index.parse().ok()?))
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
    /// is matched to it.
    pub fn sent(&self, monitor: &mut Monitor, now: f64) {
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

/// Where an answer goes (a Foxglove responder; a closure in tests).
pub(crate) type Respond = Box<dyn FnOnce(Vec<Parameter>) + Send>;

/// A request from a viewer, as the handler passes it on.
pub(crate) enum Call {
    /// Read these settings (none: every known one).
    Get(Vec<(u8, u8)>, Respond),
    /// Write these settings.
    Set(Vec<(u8, u8, f64)>, Respond),
}

/// The SDK's parameter handler: passes requests to the ground's loop through a bounded
/// channel (never blocks the server).
pub(crate) struct Handler {
    tx: SyncSender<Call>,
}

impl Handler {
    fn pass(&self, call: Call) {
        if let Err(TrySendError::Full(call) | TrySendError::Disconnected(call)) =
            self.tx.try_send(call)
        {
            // The ground is behind: nothing is known here, answer empty.
            match call {
                Call::Get(_, respond) | Call::Set(_, respond) => respond(Vec::new()),
            }
        }
    }
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
            .filter_map(|n| parse_name(n))
            .take(MAX_NAMES)
            .collect();
        self.pass(Call::Get(keys, Box::new(move |p| responder.respond(p))));
    }

    fn set(
        &self,
        _client: AnyClient,
        parameters: Vec<Parameter>,
        _request_id: Option<String>,
        responder: SetParametersResponder,
    ) {
        let values = parameters
            .iter()
            .filter_map(|p| {
                let (ac, index) = parse_name(&p.name)?;
                let value = match p.value.as_ref()? {
                    ParameterValue::Float64(v) => *v,
                    ParameterValue::Integer(v) => *v as f64,
                    ParameterValue::Bool(b) => f64::from(u8::from(*b)),
                    _ => return None,
                };
                value.is_finite().then_some((ac, index, value))
            })
            .take(MAX_NAMES)
            .collect();
        self.pass(Call::Set(values, Box::new(move |p| responder.respond(p))));
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
}

/// A request waiting for its answers.
struct Pending {
    waits: Vec<Wait>,
    respond: Respond,
    deadline: f64,
}

/// A status for the viewer's clients.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Warning(pub String);

/// The ground's side of the viewer's settings.
pub(crate) struct Settings {
    rx: Receiver<Call>,
    known: BTreeMap<(u8, u8), f64>,
    pending: Vec<Pending>,
    /// Requests answered at once because [`MAX_PENDING`] were waiting.
    pub(crate) refused: u64,
}

impl Settings {
    /// The settings and the handler to give the server.
    pub(crate) fn new() -> (Self, Handler) {
        let (tx, rx) = sync_channel(MAX_PENDING);
        let settings = Self {
            rx,
            known: BTreeMap::new(),
            pending: Vec::new(),
            refused: 0,
        };
        (settings, Handler { tx })
    }

    /// The value known for a setting, as a parameter.
    fn parameter(&self, ac_id: u8, index: u8) -> Option<Parameter> {
        let v = self.known.get(&(ac_id, index))?;
        Some(Parameter::float64(parameter_name(ac_id, index), *v))
    }

    /// Takes the requests the viewers made since the last call: returns what to send to
    /// the aircraft, and answers the requests that need no aircraft or are too many.
    pub(crate) fn poll(&mut self, now: f64) -> Vec<SettingRequest> {
        let mut out = Vec::new();
        while let Ok(call) = self.rx.try_recv() {
            let (waits, respond) = match call {
                Call::Get(keys, respond) if keys.is_empty() => {
                    let all = self
                        .known
                        .iter()
                        .map(|(&(ac, i), &v)| Parameter::float64(parameter_name(ac, i), v))
                        .collect();
                    respond(all);
                    continue;
                }
                Call::Get(keys, respond) => (
                    keys.into_iter()
                        .map(|(ac_id, index)| Wait {
                            ac_id,
                            index,
                            requested: None,
                            reported: None,
                        })
                        .collect::<Vec<_>>(),
                    respond,
                ),
                Call::Set(values, respond) => (
                    values
                        .into_iter()
                        .map(|(ac_id, index, v)| Wait {
                            ac_id,
                            index,
                            requested: Some(v),
                            reported: None,
                        })
                        .collect(),
                    respond,
                ),
            };
            if waits.is_empty() || self.pending.len() >= MAX_PENDING {
                if !waits.is_empty() {
                    self.refused += 1;
                }
                let known = waits
                    .iter()
                    .filter_map(|w| self.parameter(w.ac_id, w.index))
                    .collect();
                respond(known);
                continue;
            }
            for w in &waits {
                out.push(match w.requested {
                    Some(value) => SettingRequest::Set {
                        ac_id: w.ac_id,
                        index: w.index,
                        value,
                    },
                    None => SettingRequest::Get {
                        ac_id: w.ac_id,
                        index: w.index,
                    },
                });
            }
            self.pending.push(Pending {
                waits,
                respond,
                deadline: now + ANSWER_TIMEOUT,
            });
        }
        out
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
                .filter(|w| w.ac_id == ac_id && w.index == index && w.reported.is_none())
            {
                w.reported = Some(value);
                if let Some(requested) = w.requested {
                    let wire = quantize(base, requested);
                    if !(wire == value || (wire.is_nan() && value.is_nan())) {
                        warnings.push(Warning(format!(
                            "setting {index} of aircraft {ac_id} not applied: asked {requested}, the aircraft reports {value}"
                        )));
                    }
                }
            }
        }
        self.answer_complete();
        (
            Parameter::float64(parameter_name(ac_id, index), value),
            warnings,
        )
    }

    /// Answers the requests whose settings all reported.
    fn answer_complete(&mut self) {
        let (done, waiting): (Vec<_>, Vec<_>) = std::mem::take(&mut self.pending)
            .into_iter()
            .partition(|p| p.waits.iter().all(|w| w.reported.is_some()));
        self.pending = waiting;
        for p in done {
            let values = p
                .waits
                .iter()
                .filter_map(|w| {
                    Some(Parameter::float64(
                        parameter_name(w.ac_id, w.index),
                        w.reported?,
                    ))
                })
                .collect();
            (p.respond)(values);
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
            let mut values = Vec::new();
            for w in &p.waits {
                match w.reported {
                    Some(v) => values.push(Parameter::float64(parameter_name(w.ac_id, w.index), v)),
                    None => {
                        warnings.push(Warning(format!(
                            "setting {} of aircraft {}: no answer in {ANSWER_TIMEOUT} s",
                            w.index, w.ac_id
                        )));
                        values.extend(self.parameter(w.ac_id, w.index));
                    }
                }
            }
            (p.respond)(values);
        }
        warnings
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    type Answers = Arc<Mutex<Vec<Vec<(String, f64)>>>>;

    fn respond(answers: &Answers) -> Respond {
        let answers = answers.clone();
        Box::new(move |params: Vec<Parameter>| {
            let values = params
                .into_iter()
                .map(|p| match p.value {
                    Some(ParameterValue::Float64(v)) => (p.name, v),
                    other => panic!("{other:?}"),
                })
                .collect();
            answers.lock().unwrap().push(values);
        })
    }

    fn settings() -> (Settings, SyncSender<Call>) {
        let (s, handler) = Settings::new();
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
        tx.try_send(Call::Set(vec![(7, 2, 2.5)], respond(&answers)))
            .unwrap();
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
        assert!(answers.lock().unwrap().is_empty());
        let (p, warnings) = s.dl_value(7, 2, 2.5, BaseType::F32);
        assert!(warnings.is_empty());
        assert_eq!(p.name, "/ac/7/settings/2");
        assert_eq!(
            *answers.lock().unwrap(),
            [vec![("/ac/7/settings/2".to_owned(), 2.5)]]
        );
    }

    #[test]
    fn a_setting_not_applied_is_answered_with_the_aircraft_value_and_a_warning() {
        let (mut s, tx) = settings();
        let answers = Answers::default();
        tx.try_send(Call::Set(vec![(7, 2, 0.1)], respond(&answers)))
            .unwrap();
        s.poll(0.0);
        // 0.1 as a float reads back as f32 0.1: applied.
        let (_, w) = s.dl_value(7, 2, f64::from(0.1f32), BaseType::F32);
        assert!(w.is_empty());
        tx.try_send(Call::Set(vec![(7, 2, 3.0)], respond(&answers)))
            .unwrap();
        s.poll(1.0);
        let (_, w) = s.dl_value(7, 2, 1.0, BaseType::F32);
        assert_eq!(w.len(), 1);
        assert!(w[0].0.contains("not applied"), "{w:?}");
        assert_eq!(
            answers.lock().unwrap()[1],
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
            answers.lock().unwrap()[0],
            [("/ac/7/settings/1".to_owned(), 4.0)]
        );
        tx.try_send(Call::Get(Vec::new(), respond(&answers)))
            .unwrap();
        assert!(s.poll(14.0).is_empty());
        assert_eq!(
            answers.lock().unwrap()[1],
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
        assert_eq!(s.refused, 1);
        assert_eq!(answers.lock().unwrap().len(), 1);
        // The channel itself is bounded: the handler answers empty when it is full.
        let (_s, handler) = Settings::new();
        for _ in 0..MAX_PENDING {
            handler.pass(Call::Get(vec![(7, 1)], respond(&answers)));
        }
        handler.pass(Call::Get(vec![(7, 1)], respond(&answers)));
        assert_eq!(answers.lock().unwrap().len(), 2);
    }
}
