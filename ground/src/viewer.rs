//! Telemetry for viewers: decoded messages served live over the Foxglove WebSocket
//! protocol (Foxglove, Lichtblick) and recorded to MCAP files, with the official
//! `foxglove` SDK.
//!
//! # Topics
//!
//! * `/ac/<id>/<class>/<MESSAGE>`: every message an aircraft sends, JSON-encoded, with a
//!   JSON Schema generated from the `messages.xml` in use ([`json`](mod@crate::json)).
//! * `/ac/<id>/location`: `foxglove.LocationFix` from GPS_INT (`lat`, `lon`, `hmsl`, the
//!   accuracy `pacc` as covariance) or GPS (UTM, northern hemisphere), so the Map panel
//!   shows the track. Messages without a fix (`fix`/`mode` below 2D) are not placed.
//! * `/ac/<id>/link`: link statistics ([`LINK_SCHEMA`]): frames, unknown and malformed
//!   messages, per priority level the messages received (and, when the ground knows the
//!   aircraft's side, as the SITL does, submitted, sent and shed), PINGs and their round
//!   trip, the fields of the latest DATALINK_REPORT, and the link quality the monitor
//!   keeps ([`Monitor::link_quality`]): live or stale, seconds since heard, the
//!   aircraft's uplink silence, its RSSI and the ground modem's, the downlink loss
//!   estimate and the autopilot mode. Published by [`Viewer::link_stats`].
//!
//! Settings: with [`Viewer::serve`]'s `settings` on, the Parameters panel reads and
//! writes the aircraft's settings ([`settings`]).
//!
//! Times are the reception time, or the PPRZLOG time stamps when the input is a PPRZLOG
//! file ([`Viewer::message`] takes the time).
//!
//! # Bounds
//!
//! At most [`MAX_AIRCRAFT`] aircraft get topics (frames from further source ids are
//! counted in [`ViewerCounts::untracked`]); each has at most one topic per message of the
//! set. At most [`Viewer::max_clients`] WebSocket clients are served at once, and each
//! message from a client is at most [`MAX_CLIENT_MESSAGE`] bytes: the viewer listens
//! itself and relays each client to the SDK's server, which has neither bound
//! ([`ViewerCounts::clients_refused`], [`ViewerCounts::clients_closed`] count the
//! clients turned away). Each WebSocket client has a queue of [`CLIENT_BACKLOG`] messages in the SDK: a
//! client that reads too slowly or vanishes loses the oldest messages of its own queue
//! and never holds up decoding (logging to the server never waits). The recording is
//! written as it goes, in chunks of [`CHUNK_SIZE`] bytes; [`Viewer::flush`] closes the
//! current chunk (the monitor calls it every second), so a file cut short (power loss,
//! `kill -9`) is readable up to its last chunk; [`Viewer::finish`] writes the index and
//! summary. A write error is kept ([`Viewer::error`]) and ends the run.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::net::{Ipv4Addr, SocketAddr};
use std::sync::{Arc, Mutex, PoisonError};

use foxglove::{
    ChannelBuilder, Context, McapWriteOptions, McapWriterHandle, PartialMetadata, RawChannel,
    Schema, WebSocketServer, WebSocketServerHandle,
};
use pprz_messages::dynamic::{self, Value};
use pprz_messages::{MessageDescriptor, priority};

use crate::json;
use crate::monitor::{Aircraft, Decoded, LinkQuality, LinkState, MAX_AIRCRAFT, Monitor};
use crate::settings::SettingsTable;

mod gate;
pub mod settings;

pub use gate::{
    DEFAULT_MAX_CLIENTS, HANDSHAKE_TIMEOUT, MAX_CLIENT_MESSAGE, MAX_MAX_CLIENTS, MAX_REQUEST_HEAD,
};
use settings::Settings;
pub use settings::{Naming, SettingRequest};

/// Messages each WebSocket client may have queued in the SDK before the oldest ones are
/// dropped.
pub const CLIENT_BACKLOG: usize = 4096;

/// Size of an MCAP chunk, in bytes (uncompressed: the SDK is built without compressors).
pub const CHUNK_SIZE: u64 = 256 * 1024;

/// The JSON Schema of the link-statistics topic (`pprz.LinkStats`).
pub const LINK_SCHEMA: &str = r#"{
 "$schema": "https://json-schema.org/draft/2020-12/schema",
 "title": "pprz.LinkStats",
 "description": "Link statistics of one aircraft as the ground sees them",
 "type": "object",
 "properties": {
  "frames": {"type": "integer", "description": "frames received from the aircraft"},
  "unknown": {"type": "integer", "description": "messages the set does not know"},
  "malformed": {"type": "integer", "description": "known messages whose payload did not match"},
  "levels": {"type": "array", "items": {"type": "object", "properties": {
    "level": {"type": "string", "description": "priority level: high, normal or low"},
    "received": {"type": "integer", "description": "messages received"},
    "submitted": {"type": ["integer", "null"], "description": "messages the aircraft submitted (known by the SITL only)"},
    "sent": {"type": ["integer", "null"], "description": "messages the aircraft sent (known by the SITL only)"},
    "shed": {"type": ["integer", "null"], "description": "messages the aircraft shed (known by the SITL only)"}},
    "required": ["level", "received", "submitted", "sent", "shed"]}},
  "ping_rtt_ms": {"type": ["number", "null"], "description": "latest PING round trip, ms"},
  "pings_sent": {"type": "integer"},
  "pings_answered": {"type": "integer"},
  "pings_lost": {"type": "integer"},
  "datalink_report": {"type": ["object", "null"], "description": "fields of the latest DATALINK_REPORT"},
  "state": {"type": "string", "enum": ["live", "stale"], "description": "stale: no frame from the aircraft for the stale time (pprz-monitor --stale-after, 5 s by default)"},
  "since_heard_s": {"type": "number", "minimum": 0, "description": "seconds since the latest frame from the aircraft"},
  "uplink_lost_time": {"type": ["number", "null"], "description": "the aircraft's view of the uplink: seconds since it last received from the ground (DATALINK_REPORT)"},
  "rssi_dbm": {"type": ["number", "null"], "maximum": 0, "description": "signal strength the aircraft's radio reports (RSSI message), dBm"},
  "tx_power_db": {"type": ["number", "null"], "description": "transmit power of the aircraft's radio (RSSI message), dB"},
  "ground_rssi_dbm": {"type": ["number", "null"], "maximum": 0, "description": "signal strength the ground's XBee modem measured on the latest frame, dBm (null with other transports)"},
  "ground_rssi_mean_dbm": {"type": ["number", "null"], "maximum": 0, "description": "smoothed mean of the ground's XBee RSSI, dBm"},
  "loss_rate": {"type": ["number", "null"], "minimum": 0, "maximum": 1, "description": "downlink loss estimated over the latest DATALINK_REPORT period: 1 - frames received / messages the aircraft sent"},
  "loss_overall": {"type": ["number", "null"], "minimum": 0, "maximum": 1, "description": "downlink loss over every report period estimated"},
  "ap_mode": {"type": ["string", "null"], "description": "autopilot mode (ap_mode of ROTORCRAFT_STATUS or PPRZ_MODE), its label from the messages.xml"}
 },
 "required": ["frames", "unknown", "malformed", "levels", "ping_rtt_ms", "datalink_report", "state", "since_heard_s", "uplink_lost_time", "rssi_dbm", "tx_power_db", "ground_rssi_dbm", "ground_rssi_mean_dbm", "loss_rate", "loss_overall", "ap_mode"]
}"#;

/// The JSON Schema of `foxglove.LocationFix` in JSON encoding.
const LOCATION_SCHEMA: &str = r#"{
 "$schema": "https://json-schema.org/draft/2020-12/schema",
 "title": "foxglove.LocationFix",
 "description": "A navigation satellite fix",
 "type": "object",
 "properties": {
  "timestamp": {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0}}},
  "frame_id": {"type": "string"},
  "latitude": {"type": "number", "description": "degrees"},
  "longitude": {"type": "number", "description": "degrees"},
  "altitude": {"type": "number", "description": "meters"},
  "position_covariance": {"type": "array", "items": {"type": "number"}, "minItems": 9, "maxItems": 9},
  "position_covariance_type": {"type": "integer", "minimum": 0, "maximum": 3}
 },
 "required": ["timestamp", "frame_id", "latitude", "longitude", "altitude", "position_covariance", "position_covariance_type"]
}"#;

/// What went wrong with a viewer output.
#[derive(Debug)]
pub enum ViewerError {
    /// The WebSocket server could not start.
    Serve(String),
    /// The recording could not be created or written.
    Record(String),
}

impl std::fmt::Display for ViewerError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Serve(e) => write!(f, "cannot serve Foxglove: {e}"),
            Self::Record(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for ViewerError {}

/// The aircraft's own figures of one priority level, when the ground knows them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LevelFigures {
    /// Messages submitted for sending.
    pub submitted: u64,
    /// Messages sent.
    pub sent: u64,
    /// Messages shed (dropped under overload, by any reason).
    pub shed: u64,
}

/// What the viewer published and left out.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ViewerCounts {
    /// Messages published on a message topic.
    pub messages: u64,
    /// Location fixes published.
    pub locations: u64,
    /// Link-statistics messages published.
    pub link: u64,
    /// Messages of aircraft beyond [`MAX_AIRCRAFT`]: not published.
    pub untracked: u64,
    /// Unknown or malformed messages: no topic, not published.
    pub undecodable: u64,
    /// Topics created.
    pub topics: u64,
    /// WebSocket clients refused: the most allowed were connected.
    pub clients_refused: u64,
    /// WebSocket clients closed: a message over [`MAX_CLIENT_MESSAGE`] bytes, or an
    /// HTTP request over [`MAX_REQUEST_HEAD`] bytes or not complete within
    /// [`HANDSHAKE_TIMEOUT`].
    pub clients_closed: u64,
    /// Settings set from a viewer to a value a SETTING cannot carry (not a finite
    /// number that fits a `float`) or, with the settings files, outside the setting's
    /// bounds or an unknown label: refused, not sent.
    pub settings_refused: u64,
    /// Settings requested from a viewer that the ground could not send (no secure
    /// session yet, or the uplink failed).
    pub settings_unsent: u64,
    /// Settings requests from a viewer answered at once, unsent, because too many were
    /// waiting for the aircraft.
    pub settings_busy: u64,
}

impl std::fmt::Display for ViewerCounts {
    /// The end-of-run line: `foxglove: published ...; not published: ...`, and the
    /// settings from viewers not sent, if any.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "foxglove: published {} messages, {} locations, {} link statistics on {} topics; not published: {} unknown or malformed, {} from untracked aircraft; clients refused {} (too many), closed {} (request too long or too slow)",
            self.messages,
            self.locations,
            self.link,
            self.topics,
            self.undecodable,
            self.untracked,
            self.clients_refused,
            self.clients_closed
        )?;
        let (r, u, b) = (
            self.settings_refused,
            self.settings_unsent,
            self.settings_busy,
        );
        if r + u + b > 0 {
            write!(
                f,
                "; settings from viewers not sent: {r} refused (not a float, or outside the bounds), {u} with no link to send them, {b} with too many waiting"
            )?;
        }
        Ok(())
    }
}

/// Now, in nanoseconds since the Unix epoch (the time of live messages).
pub fn unix_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// A writer that keeps its first error where the viewer can see it: the SDK's MCAP sink
/// reports a failed write only to its log.
struct Watched<W> {
    inner: W,
    error: Arc<Mutex<Option<String>>>,
}

impl<W> Watched<W> {
    fn note<T>(&self, r: std::io::Result<T>) -> std::io::Result<T> {
        if let Err(e) = &r {
            let mut slot = self.error.lock().unwrap_or_else(PoisonError::into_inner);
            slot.get_or_insert_with(|| e.to_string());
        }
        r
    }
}

impl<W: Write> Write for Watched<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let r = self.inner.write(buf);
        self.note(r)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        let r = self.inner.flush();
        self.note(r)
    }
}

impl<W: Seek> Seek for Watched<W> {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        let r = self.inner.seek(pos);
        self.note(r)
    }
}

/// The MCAP file being written.
type McapFile = BufWriter<Watched<File>>;

/// An MCAP recording in progress.
struct Recording {
    handle: McapWriterHandle<McapFile>,
    error: Arc<Mutex<Option<String>>>,
    path: String,
}

impl Recording {
    /// The first error of the file itself, if any.
    fn first_error(&self) -> Option<String> {
        self.error
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Writes the index and summary, flushes and syncs the file.
    ///
    /// # Errors
    /// The file's first error (a full disk, say) rather than what the SDK says after
    /// it ("attempted another write after a write method failed"), else the error of
    /// the close.
    fn close(self) -> Result<(), ViewerError> {
        let Self {
            handle,
            error,
            path,
        } = self;
        let fail = |e: &dyn std::fmt::Display| {
            ViewerError::Record(format!("recording to {path} failed: {e}"))
        };
        let closed = handle
            .close()
            .map_err(|e| e.to_string())
            .and_then(|mut file| {
                file.flush().map_err(|e| e.to_string())?;
                let watched = file.into_inner().map_err(|e| e.error().to_string())?;
                watched.inner.sync_all().map_err(|e| e.to_string())
            });
        let first = error.lock().unwrap_or_else(PoisonError::into_inner).clone();
        match (first, closed) {
            (Some(first), _) => Err(fail(&first)),
            (None, Err(e)) => Err(fail(&e)),
            (None, Ok(())) => Ok(()),
        }
    }
}

/// The topics of one aircraft besides its messages.
struct AircraftTopics {
    location: Arc<RawChannel>,
    link: Arc<RawChannel>,
    /// The JSON of the latest DATALINK_REPORT.
    report: Option<String>,
}

/// Decoded telemetry published to viewers: a Foxglove WebSocket server, an MCAP
/// recording, or both (one SDK context: same topics and schemas in both).
pub struct Viewer {
    context: Arc<Context>,
    topics: HashMap<(u8, u8, u8), Arc<RawChannel>>,
    schemas: HashMap<(u8, u8), Schema>,
    aircraft: BTreeMap<u8, AircraftTopics>,
    server: Option<WebSocketServerHandle>,
    gate: Option<gate::Gate>,
    max_clients: usize,
    settings: Option<Settings>,
    /// The settings files' table: parameters and DL_VALUEs named after it.
    table: Option<Arc<SettingsTable>>,
    recording: Option<Recording>,
    counts: ViewerCounts,
}

impl Default for Viewer {
    fn default() -> Self {
        Self::new()
    }
}

impl Viewer {
    /// A viewer with no output yet ([`serve`](Self::serve), [`record`](Self::record)).
    pub fn new() -> Self {
        Self {
            context: Context::new(),
            topics: HashMap::new(),
            schemas: HashMap::new(),
            aircraft: BTreeMap::new(),
            server: None,
            gate: None,
            max_clients: DEFAULT_MAX_CLIENTS,
            settings: None,
            table: None,
            recording: None,
            counts: ViewerCounts::default(),
        }
    }

    /// Names the settings after `table` (the aircraft's settings files), for the next
    /// [`serve`](Self::serve): parameters `/ac/<id>/settings/<name>` in display units,
    /// checked against the bounds when set ([`settings`]), and a `setting` key with the
    /// name in the JSON of DL_VALUE (live and recorded).
    #[must_use]
    pub fn settings_table(mut self, table: Arc<SettingsTable>) -> Self {
        self.table = Some(table);
        self
    }

    /// At most `n` WebSocket clients at once ([`DEFAULT_MAX_CLIENTS`] unless set; at
    /// least 1, at most [`MAX_MAX_CLIENTS`]), for the next [`serve`](Self::serve).
    #[must_use]
    pub fn max_clients(mut self, n: usize) -> Self {
        self.max_clients = n.clamp(1, MAX_MAX_CLIENTS);
        self
    }

    /// Serves the topics over the Foxglove WebSocket protocol at `addr` (port 0: any free
    /// port); returns the address it listens on. With `settings`, clients can read and
    /// write the aircraft's settings as parameters: the ground takes the requests with
    /// [`setting_requests`](Self::setting_requests) and sends them.
    ///
    /// The viewer listens at `addr` itself and relays each client to the SDK's server
    /// (on a loopback port of its own): at most [`max_clients`](Self::max_clients) at
    /// once, each message from a client at most [`MAX_CLIENT_MESSAGE`] bytes. A program
    /// on the same machine can reach the SDK's port directly, past these bounds (the SDK
    /// has no setting to authenticate the relay): the bounds protect against clients on
    /// the network, not against the machine's own users.
    ///
    /// # Errors
    /// The server could not bind or start.
    pub fn serve(
        &mut self,
        addr: SocketAddr,
        name: &str,
        settings: bool,
    ) -> Result<SocketAddr, ViewerError> {
        let fail = |e: &dyn std::fmt::Display| ViewerError::Serve(format!("{addr}: {e}"));
        let listener = std::net::TcpListener::bind(addr).map_err(|e| fail(&e))?;
        let bound = listener.local_addr().map_err(|e| fail(&e))?;
        let mut server = WebSocketServer::new()
            .context(&self.context)
            .name(name)
            .bind(Ipv4Addr::LOCALHOST.to_string(), 0)
            .message_backlog_size(CLIENT_BACKLOG);
        if settings {
            let (state, handler) = Settings::new(Naming::new(self.table.clone()));
            server = server.parameter_handler(Arc::new(handler));
            self.settings = Some(state);
        }
        let handle = server.start_blocking().map_err(|e| fail(&e))?;
        let upstream = SocketAddr::new(Ipv4Addr::LOCALHOST.into(), handle.port());
        self.server = Some(handle);
        let gate = gate::Gate::start(listener, upstream, self.max_clients).map_err(|e| fail(&e))?;
        self.gate = Some(gate);
        Ok(bound)
    }

    /// Records the topics to `file` (an MCAP file; `path` names it in errors).
    ///
    /// # Errors
    /// The MCAP header could not be written.
    pub fn record(&mut self, file: File, path: &str) -> Result<(), ViewerError> {
        let error = Arc::new(Mutex::new(None));
        let writer = BufWriter::new(Watched {
            inner: file,
            error: error.clone(),
        });
        let options = McapWriteOptions::new()
            .chunk_size(Some(CHUNK_SIZE))
            .compression(None)
            .library(format!("pprz-ground {}", env!("CARGO_PKG_VERSION")));
        let handle = foxglove::McapWriter::with_options(options)
            .context(&self.context)
            .create(writer)
            .map_err(|e| ViewerError::Record(format!("recording to {path} failed: {e}")))?;
        self.recording = Some(Recording {
            handle,
            error,
            path: path.to_owned(),
        });
        Ok(())
    }

    /// The settings requests the viewers made since the last call (GET_SETTING and
    /// SETTING to send to the aircraft, in order), at `now` (seconds, the monitor's
    /// time); requests unanswered for [`settings::ANSWER_TIMEOUT`] seconds are answered
    /// with what is known.
    pub fn setting_requests(&mut self, now: f64) -> Vec<SettingRequest> {
        let Some(s) = self.settings.as_mut() else {
            return Vec::new();
        };
        let requests = s.poll(now);
        let warnings = s.expire(now);
        self.warn(warnings);
        requests
    }

    /// Tells the viewers that `request` (one of [`setting_requests`](Self::setting_requests)'s)
    /// was not sent, because of `why` (no secure session yet, the uplink failed): the
    /// client that asked gets its answer (what is known) and an error status naming `why`
    /// as soon as nothing else of its request is waiting; counted in
    /// [`ViewerCounts::settings_unsent`].
    pub fn setting_not_sent(&mut self, request: &SettingRequest, why: &str) {
        if let Some(s) = self.settings.as_mut() {
            s.not_sent(request, why);
        }
    }

    /// Sends warnings to every client.
    fn warn(&self, warnings: Vec<settings::Warning>) {
        if let Some(server) = &self.server {
            for w in warnings {
                server.publish_status(foxglove::websocket::Status::warning(w.0));
            }
        }
    }

    /// What was published so far, the clients turned away and the settings from
    /// viewers not sent.
    pub fn counts(&self) -> ViewerCounts {
        let mut c = self.counts;
        if let Some(g) = &self.gate {
            let g = g.counts();
            c.clients_refused = g.refused;
            c.clients_closed = g.closed;
        }
        if let Some(s) = &self.settings {
            let n = s.not_sent_counts();
            c.settings_refused = n.refused;
            c.settings_unsent = n.unsent;
            c.settings_busy = n.busy;
        }
        c
    }

    /// WebSocket clients connected now.
    pub fn clients(&self) -> usize {
        self.server
            .as_ref()
            .map_or(0, WebSocketServerHandle::client_count)
    }

    /// The first error of the recording, if any: the run must end.
    pub fn error(&self) -> Option<String> {
        let r = self.recording.as_ref()?;
        let e = r.first_error()?;
        Some(format!("recording to {} failed: {e}", r.path))
    }

    /// The topics of aircraft `ac_id`, created while fewer than [`MAX_AIRCRAFT`] have
    /// topics.
    fn aircraft(&mut self, ac_id: u8) -> Option<&mut AircraftTopics> {
        if !self.aircraft.contains_key(&ac_id) {
            if self.aircraft.len() >= MAX_AIRCRAFT {
                return None;
            }
            let location = self.channel(
                format!("/ac/{ac_id}/location"),
                Schema::new(
                    "foxglove.LocationFix",
                    "jsonschema",
                    LOCATION_SCHEMA.as_bytes(),
                ),
            )?;
            let link = self.channel(
                format!("/ac/{ac_id}/link"),
                Schema::new("pprz.LinkStats", "jsonschema", LINK_SCHEMA.as_bytes()),
            )?;
            let topics = AircraftTopics {
                location,
                link,
                report: None,
            };
            self.aircraft.insert(ac_id, topics);
        }
        self.aircraft.get_mut(&ac_id)
    }

    /// A JSON topic of the context.
    fn channel(&mut self, topic: String, schema: Schema) -> Option<Arc<RawChannel>> {
        let channel = ChannelBuilder::new(topic)
            .context(&self.context)
            .message_encoding("json")
            .schema(schema)
            .build_raw()
            .ok()?;
        self.counts.topics += 1;
        Some(channel)
    }

    /// Publishes a decoded message received at `time_ns` (nanoseconds: since the Unix
    /// epoch, or since the start of a replayed log).
    pub fn message(&mut self, time_ns: u64, d: &Decoded<'_>) {
        let Some(desc) = d.message.filter(|_| d.valid) else {
            self.counts.undecodable += 1;
            return;
        };
        let Ok(mut body) = json::message(desc, d.payload) else {
            self.counts.undecodable += 1;
            return;
        };
        let named = self.table.is_some() && is_dl_value(desc);
        if named {
            name_dl_value(&mut body, desc, d.payload, self.table.as_deref());
        }
        if self.aircraft(d.source).is_none() {
            self.counts.untracked += 1;
            return;
        }
        let key = (d.source, desc.class_id, desc.id);
        let channel = match self.topics.get(&key) {
            Some(c) => c.clone(),
            None => {
                let schema = self
                    .schemas
                    .entry((desc.class_id, desc.id))
                    .or_insert_with(|| {
                        let mut schema = json::schema(desc);
                        if named {
                            schema = with_setting_key(&schema);
                        }
                        Schema::new(json::schema_name(desc), "jsonschema", schema.into_bytes())
                    })
                    .clone();
                let Some(c) = self.channel(json::topic(d.source, desc), schema) else {
                    self.counts.undecodable += 1;
                    return;
                };
                self.topics.insert(key, c.clone());
                c
            }
        };
        channel.log_with_meta(body.as_bytes(), PartialMetadata::with_log_time(time_ns));
        self.counts.messages += 1;
        if desc.name == "DATALINK_REPORT"
            && let Some(a) = self.aircraft.get_mut(&d.source)
        {
            a.report = Some(body);
        }
        if desc.name == "DL_VALUE" {
            self.dl_value(desc, d);
        }
        if let Some(fix) = location(desc, d.payload)
            && let Some(a) = self.aircraft.get(&d.source)
        {
            let text = fix.json(d.source, time_ns);
            a.location
                .log_with_meta(text.as_bytes(), PartialMetadata::with_log_time(time_ns));
            self.counts.locations += 1;
        }
    }

    /// A DL_VALUE: answers the viewers' settings requests, publishes the value.
    fn dl_value(&mut self, desc: &MessageDescriptor<'_>, d: &Decoded<'_>) {
        let Some(s) = self.settings.as_mut() else {
            return;
        };
        let mut index = None;
        let mut value = None;
        for (f, v) in dynamic::fields(desc, d.payload).filter_map(Result::ok) {
            match f.name {
                "index" => index = v.as_i64().and_then(|i| u8::try_from(i).ok()),
                "value" if !matches!(v, Value::Array(_) | Value::Text(_)) => {
                    value = v.as_f64().map(|x| (x, f.ty.base()));
                }
                _ => {}
            }
        }
        let (Some(index), Some((value, base))) = (index, value) else {
            return;
        };
        let (parameter, warnings) = s.dl_value(d.source, index, value, base);
        if let Some(server) = &self.server {
            server.publish_parameter_values(vec![parameter]);
        }
        self.warn(warnings);
    }

    /// Publishes the link statistics of every aircraft the monitor tracks and heard at
    /// `time_ns` (an aircraft only addressed takes no place among the
    /// [`MAX_AIRCRAFT`] with topics), with its [`Monitor::link_quality`] at `now` (the
    /// monitor's time, in seconds); `aircraft_side` gives, when known, the aircraft's
    /// own figures per priority level (high, normal, low).
    pub fn link_stats(
        &mut self,
        time_ns: u64,
        monitor: &Monitor,
        now: f64,
        aircraft_side: impl Fn(u8) -> Option<[LevelFigures; 3]>,
    ) {
        for ac_id in monitor.aircraft() {
            let Some(state) = monitor.aircraft_state(ac_id).filter(|a| a.frames() > 0) else {
                continue;
            };
            let quality = monitor.link_quality(ac_id, now);
            let side = aircraft_side(ac_id);
            let Some(topics) = self.aircraft(ac_id) else {
                continue;
            };
            let report = topics
                .report
                .as_deref()
                .and_then(|r| serde_json::from_str::<serde_json::Value>(r).ok());
            let text = link_json(state, quality.as_ref(), side, report).to_string();
            topics
                .link
                .log_with_meta(text.as_bytes(), PartialMetadata::with_log_time(time_ns));
            self.counts.link += 1;
        }
    }

    /// Closes the recording's current chunk and writes it out (a file cut short later
    /// is readable up to here).
    ///
    /// # Errors
    /// The recording failed (now or earlier).
    pub fn flush(&mut self) -> Result<(), ViewerError> {
        let Some(r) = &self.recording else {
            return Ok(());
        };
        let flushed = r.handle.flush();
        // The file's own error first: after it, the SDK only says that a write failed
        // before.
        if let Some(e) = self.error() {
            return Err(ViewerError::Record(e));
        }
        flushed.map_err(|e| ViewerError::Record(format!("recording to {} failed: {e}", r.path)))
    }

    /// Stops the server (without waiting for its clients) and finalises the recording
    /// (index and summary).
    ///
    /// # Errors
    /// The recording failed (now or earlier).
    pub fn finish(mut self) -> Result<ViewerCounts, ViewerError> {
        self.gate = None;
        if let Some(server) = self.server.take() {
            // Not waiting for the clients' connections to close: a client that stopped
            // reading would hold the end of the run forever.
            server.stop().detach_all();
        }
        if let Some(r) = self.recording.take() {
            r.close()?;
        }
        Ok(self.counts)
    }
}

/// Whether `desc` is Paparazzi's DL_VALUE (telemetry).
fn is_dl_value(desc: &MessageDescriptor<'_>) -> bool {
    desc.name == "DL_VALUE" && desc.class_name == "telemetry"
}

/// The key of a DL_VALUE's JSON that names its setting (with the settings files).
pub const SETTING_KEY: &str = "setting";

/// Adds the name of the setting (its name unique in `table`) to `body`, the JSON of a
/// DL_VALUE, when the table has its index.
fn name_dl_value(
    body: &mut String,
    desc: &MessageDescriptor<'_>,
    payload: &[u8],
    table: Option<&SettingsTable>,
) {
    let index = dynamic::fields(desc, payload)
        .filter_map(Result::ok)
        .find(|(f, _)| f.name == "index")
        .and_then(|(_, v)| v.as_i64())
        .and_then(|i| u8::try_from(i).ok());
    let Some(name) = index.and_then(|i| table?.unique_name(i)) else {
        return;
    };
    if body.ends_with('}') && body.len() > 2 {
        body.pop();
        body.push_str(&format!(
            ",{}:{}}}",
            serde_json::Value::from(SETTING_KEY),
            serde_json::Value::from(name)
        ));
    }
}

/// The JSON Schema `schema` of DL_VALUE with the key [`SETTING_KEY`] described.
fn with_setting_key(schema: &str) -> String {
    let Ok(mut value) = serde_json::from_str::<serde_json::Value>(schema) else {
        return schema.to_owned();
    };
    if let Some(props) = value
        .get_mut("properties")
        .and_then(serde_json::Value::as_object_mut)
    {
        props.insert(
            SETTING_KEY.to_owned(),
            serde_json::json!({
                "type": "string",
                "description": "the setting's name in the settings files (its var; var@index for a repeated var); absent for an index the files do not have"
            }),
        );
    }
    value.to_string()
}

/// The link statistics of one aircraft ([`LINK_SCHEMA`]): its `state` in the
/// monitor, its link `quality` (`None` before it is heard: then stale, as long as it has
/// never been heard), the aircraft's own figures per level when known, and the JSON of
/// its latest DATALINK_REPORT.
pub(crate) fn link_json(
    state: &Aircraft,
    quality: Option<&LinkQuality>,
    side: Option<[LevelFigures; 3]>,
    report: Option<serde_json::Value>,
) -> serde_json::Value {
    let mut received = [0u64; 3];
    for (p, n) in state.per_priority() {
        received[priority::level(p.0)] += n;
    }
    let levels: Vec<serde_json::Value> = (0..3)
        .map(|i| {
            let s = side.map(|s| s[i]);
            serde_json::json!({
                "level": priority::LEVEL_NAMES[i],
                "received": received[i],
                "submitted": s.map(|s| s.submitted),
                "sent": s.map(|s| s.sent),
                "shed": s.map(|s| s.shed),
            })
        })
        .collect();
    let pings = state.pings();
    // Only finite numbers: JSON has no NaN.
    let finite = |v: Option<f64>| v.filter(|x| x.is_finite());
    let q = quality;
    serde_json::json!({
        "frames": state.frames(),
        "unknown": state.unknown(),
        "malformed": state.malformed(),
        "levels": levels,
        "ping_rtt_ms": finite(state.last_rtt().map(|s| s * 1000.0)),
        "pings_sent": pings.sent_count(),
        "pings_answered": pings.answered(),
        "pings_lost": pings.lost(),
        "datalink_report": report,
        "state": q.map_or(LinkState::Stale, |q| q.state).as_str(),
        "since_heard_s": finite(q.map(|q| q.since_heard)).unwrap_or(0.0),
        "uplink_lost_time": finite(q.and_then(|q| q.uplink_lost_time)),
        "rssi_dbm": q.and_then(|q| q.rssi_dbm),
        "tx_power_db": q.and_then(|q| q.tx_power_db),
        "ground_rssi_dbm": q.and_then(|q| q.ground_rssi_dbm),
        "ground_rssi_mean_dbm": finite(q.and_then(|q| q.ground_rssi_mean_dbm)),
        "loss_rate": finite(q.and_then(|q| q.loss_rate)),
        "loss_overall": finite(q.and_then(|q| q.loss_overall)),
        "ap_mode": q.and_then(|q| q.ap_mode.clone()),
    })
}

/// A position fix.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Fix {
    latitude: f64,
    longitude: f64,
    altitude: f64,
    /// Horizontal and vertical accuracy (1 sigma), metres.
    accuracy: Option<f64>,
}

impl Fix {
    fn json(&self, ac_id: u8, time_ns: u64) -> String {
        let (cov, kind) = match self.accuracy {
            Some(a) => {
                let v = a * a;
                ([v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v], 2)
            }
            None => ([0.0; 9], 0),
        };
        serde_json::json!({
            "timestamp": {"sec": time_ns / 1_000_000_000, "nsec": time_ns % 1_000_000_000},
            "frame_id": format!("ac{ac_id}"),
            "latitude": self.latitude,
            "longitude": self.longitude,
            "altitude": self.altitude,
            "position_covariance": cov,
            "position_covariance_type": kind,
        })
        .to_string()
    }
}

/// The numeric scalar fields of a payload, by name.
fn numbers<'a>(desc: &'a MessageDescriptor<'a>, payload: &[u8]) -> HashMap<&'a str, f64> {
    dynamic::fields(desc, payload)
        .filter_map(Result::ok)
        .filter(|(_, v)| !matches!(v, Value::Array(_) | Value::Text(_)))
        .filter_map(|(f, v)| Some((f.name, v.as_f64()?)))
        .collect()
}

/// The position in GPS_INT (`lat`/`lon` in 1e7 degrees, `hmsl` or `alt` in mm) or GPS
/// (UTM in cm, `alt` in mm), if the message is one with a fix.
fn location(desc: &MessageDescriptor<'_>, payload: &[u8]) -> Option<Fix> {
    if desc.name != "GPS_INT" && desc.name != "GPS" {
        return None;
    }
    let n = numbers(desc, payload);
    let fix = n.get("fix").or_else(|| n.get("mode")).copied();
    if fix.is_some_and(|f| f < 2.0) {
        return None;
    }
    let fix = if desc.name == "GPS_INT" {
        Fix {
            latitude: n.get("lat")? * 1e-7,
            longitude: n.get("lon")? * 1e-7,
            altitude: n.get("hmsl").or_else(|| n.get("alt"))? / 1000.0,
            accuracy: n.get("pacc").map(|cm| cm / 100.0),
        }
    } else {
        let zone = *n.get("utm_zone")?;
        let (latitude, longitude) = utm_to_wgs84(
            zone,
            n.get("utm_east")? / 100.0,
            n.get("utm_north")? / 100.0,
        )?;
        Fix {
            latitude,
            longitude,
            altitude: n.get("alt")? / 1000.0,
            accuracy: None,
        }
    };
    let valid = fix.latitude.abs() <= 90.0
        && fix.longitude.abs() <= 180.0
        && fix.altitude.is_finite()
        && !(fix.latitude == 0.0 && fix.longitude == 0.0);
    valid.then_some(fix)
}

/// UTM (northern hemisphere, WGS84) to latitude and longitude in degrees; `None` for a
/// zone outside 1..=60.
fn utm_to_wgs84(zone: f64, east: f64, north: f64) -> Option<(f64, f64)> {
    if !(1.0..=60.0).contains(&zone) || !east.is_finite() || !north.is_finite() {
        return None;
    }
    let a = 6_378_137.0f64;
    let f = 1.0 / 298.257_223_563;
    let k0 = 0.9996;
    let e2 = f * (2.0 - f);
    let ep2 = e2 / (1.0 - e2);
    let x = east - 500_000.0;
    let m = north / k0;
    let mu = m / (a * (1.0 - e2 / 4.0 - 3.0 * e2 * e2 / 64.0 - 5.0 * e2 * e2 * e2 / 256.0));
    let e1 = (1.0 - (1.0 - e2).sqrt()) / (1.0 + (1.0 - e2).sqrt());
    let phi1 = mu
        + (3.0 * e1 / 2.0 - 27.0 * e1.powi(3) / 32.0) * (2.0 * mu).sin()
        + (21.0 * e1 * e1 / 16.0 - 55.0 * e1.powi(4) / 32.0) * (4.0 * mu).sin()
        + (151.0 * e1.powi(3) / 96.0) * (6.0 * mu).sin()
        + (1097.0 * e1.powi(4) / 512.0) * (8.0 * mu).sin();
    let (s, c, t) = (phi1.sin(), phi1.cos(), phi1.tan());
    let c1 = ep2 * c * c;
    let t1 = t * t;
    let n1 = a / (1.0 - e2 * s * s).sqrt();
    let r1 = a * (1.0 - e2) / (1.0 - e2 * s * s).powf(1.5);
    let d = x / (n1 * k0);
    let lat = phi1
        - (n1 * t / r1)
            * (d * d / 2.0
                - (5.0 + 3.0 * t1 + 10.0 * c1 - 4.0 * c1 * c1 - 9.0 * ep2) * d.powi(4) / 24.0
                + (61.0 + 90.0 * t1 + 298.0 * c1 + 45.0 * t1 * t1 - 252.0 * ep2 - 3.0 * c1 * c1)
                    * d.powi(6)
                    / 720.0);
    let lon0 = (zone - 1.0) * 6.0 - 180.0 + 3.0;
    let lon = lon0
        + ((d - (1.0 + 2.0 * t1 + c1) * d.powi(3) / 6.0
            + (5.0 - 2.0 * c1 + 28.0 * t1 - 3.0 * c1 * c1 + 8.0 * ep2 + 24.0 * t1 * t1)
                * d.powi(5)
                / 120.0)
            / c)
            .to_degrees();
    Some((lat.to_degrees(), lon))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utm_central_meridian_and_equator() {
        let (lat, lon) = utm_to_wgs84(31.0, 500_000.0, 0.0).unwrap();
        assert!(lat.abs() < 1e-9 && (lon - 3.0).abs() < 1e-9, "{lat} {lon}");
        // 999 274 m north on the central meridian is about 9.04 degrees.
        let (lat, lon) = utm_to_wgs84(31.0, 500_000.0, 999_274.0).unwrap();
        assert!(
            (lat - 9.04).abs() < 1e-3 && (lon - 3.0).abs() < 1e-9,
            "{lat}"
        );
        // East of the meridian: a larger longitude, same zone.
        let (_, lon) = utm_to_wgs84(31.0, 600_000.0, 4_800_000.0).unwrap();
        assert!(lon > 3.0 && lon < 6.0, "{lon}");
        assert_eq!(utm_to_wgs84(0.0, 500_000.0, 0.0), None);
        assert_eq!(utm_to_wgs84(61.0, 500_000.0, 0.0), None);
    }

    /// Checks `value` against the parts of JSON Schema [`LINK_SCHEMA`] uses: `type`
    /// (one or several), `enum`, `minimum`, `maximum`, `properties` (every key of the
    /// value described), `required`, `items`.
    fn conforms(schema: &serde_json::Value, value: &serde_json::Value, at: &str) {
        use serde_json::Value as J;
        if let Some(types) = schema.get("type") {
            let types: Vec<&str> = match types {
                J::String(t) => vec![t.as_str()],
                J::Array(ts) => ts.iter().filter_map(J::as_str).collect(),
                other => panic!("{at}: type {other}"),
            };
            let ok = types.iter().any(|t| match *t {
                "null" => value.is_null(),
                "integer" => value.is_i64() || value.is_u64(),
                "number" => value.is_number(),
                "string" => value.is_string(),
                "object" => value.is_object(),
                "array" => value.is_array(),
                other => panic!("{at}: type {other}"),
            });
            assert!(ok, "{at}: {value} is not {types:?}");
        }
        if let Some(values) = schema.get("enum").and_then(J::as_array) {
            assert!(values.contains(value), "{at}: {value} not in {values:?}");
        }
        if let Some(x) = value.as_f64() {
            let min = schema.get("minimum").and_then(J::as_f64);
            let max = schema.get("maximum").and_then(J::as_f64);
            assert!(min.is_none_or(|m| x >= m), "{at}: {x} below {min:?}");
            assert!(max.is_none_or(|m| x <= m), "{at}: {x} above {max:?}");
        }
        if let (Some(props), Some(object)) = (schema.get("properties"), value.as_object()) {
            for (key, v) in object {
                let sub = props
                    .get(key)
                    .unwrap_or_else(|| panic!("{at}: {key} not in the schema"));
                conforms(sub, v, &format!("{at}.{key}"));
            }
            for key in schema
                .get("required")
                .and_then(J::as_array)
                .into_iter()
                .flatten()
            {
                let key = key.as_str().unwrap();
                assert!(object.contains_key(key), "{at}: {key} required");
            }
        }
        if let (Some(items), Some(array)) = (schema.get("items"), value.as_array()) {
            for (i, v) in array.iter().enumerate() {
                conforms(items, v, &format!("{at}[{i}]"));
            }
        }
    }

    /// Every field of the link topic is in its schema, with the type the schema gives,
    /// with every figure known and with none.
    #[test]
    fn the_link_statistics_conform_to_their_schema() {
        use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};
        let schema: serde_json::Value = serde_json::from_str(LINK_SCHEMA).unwrap();
        let set =
            crate::set::RuntimeSet::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../messages.xml"))
                .unwrap();
        let mut m = Monitor::new(set, PprzV2::new().into());
        let frame = |id: u8, payload: &[u8]| {
            let mut buf = [0u8; 300];
            let meta = TxMeta::new(MsgHeader::new(7, 0, 1, id));
            let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
            buf[..n].to_vec()
        };
        // Heard, nothing more known.
        m.feed(0.0, &frame(2, &[0]), |_| {});
        let bare = link_json(
            m.aircraft_state(7).unwrap(),
            m.link_quality(7, 9.0).as_ref(),
            None,
            None,
        );
        conforms(&schema, &bare, "bare");
        assert_eq!(bare["state"], "stale");
        assert_eq!(bare["since_heard_s"], 9.0);
        for key in [
            "rssi_dbm",
            "ground_rssi_dbm",
            "loss_rate",
            "ap_mode",
            "uplink_lost_time",
        ] {
            assert!(bare[key].is_null(), "{key}: {bare}");
        }
        // Everything known.
        let report = |nb: u16| {
            let mut p = Vec::new();
            for v in [3u16, 1, nb, 100, 2] {
                p.extend(v.to_le_bytes());
            }
            p.push(0);
            frame(30, &p)
        };
        m.feed(1.0, &frame(28, &[62, 10]), |_| {});
        m.feed(1.0, &report(10), |_| {});
        m.feed(1.0, &frame(2, &[0]), |_| {});
        m.feed(2.0, &report(14), |_| {});
        let mut status = vec![0u8; 24];
        status[8] = 2;
        m.feed(2.0, &frame(231, &status), |_| {});
        let side = [LevelFigures {
            submitted: 3,
            sent: 2,
            shed: 1,
        }; 3];
        let full = link_json(
            m.aircraft_state(7).unwrap(),
            m.link_quality(7, 2.5).as_ref(),
            Some(side),
            Some(serde_json::json!({"uplink_lost_time": 3})),
        );
        conforms(&schema, &full, "full");
        assert_eq!(full["state"], "live");
        assert_eq!(full["rssi_dbm"], -62);
        assert_eq!(full["tx_power_db"], 10);
        assert_eq!(full["uplink_lost_time"], 3.0);
        assert_eq!(full["loss_rate"], 0.5);
        assert_eq!(full["ap_mode"], "HOME");
        assert!(full["ground_rssi_dbm"].is_null());
        // Not heard yet (an aircraft only addressed): stale, no figure.
        conforms(
            &schema,
            &link_json(m.aircraft_state(7).unwrap(), None, None, None),
            "none",
        );
    }

    /// With the settings files, the JSON of DL_VALUE names its setting, and its schema
    /// describes the key; an index beyond the files gets no key.
    #[test]
    fn dl_value_json_names_its_setting() {
        let set =
            crate::set::RuntimeSet::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../messages.xml"))
                .unwrap();
        let desc = set.find_by_name("telemetry", "DL_VALUE").unwrap();
        assert!(is_dl_value(desc));
        let table = SettingsTable::parse(&[(
            "s.xml",
            r#"<settings><dl_settings><dl_setting var="ins.gain" min="0" max="10"/></dl_settings></settings>"#,
        )])
        .unwrap();
        let schema: serde_json::Value =
            serde_json::from_str(&with_setting_key(&json::schema(desc))).unwrap();
        let json = |index: u8| {
            let mut payload = vec![index];
            payload.extend(2.5f32.to_le_bytes());
            let mut body = json::message(desc, &payload).unwrap();
            name_dl_value(&mut body, desc, &payload, Some(&table));
            serde_json::from_str::<serde_json::Value>(&body).unwrap()
        };
        let named = json(0);
        assert_eq!(named[SETTING_KEY], "ins.gain");
        assert_eq!(named["value"], 2.5);
        conforms(&schema, &named, "named");
        let beyond = json(4);
        assert!(beyond.get(SETTING_KEY).is_none(), "{beyond}");
        conforms(&schema, &beyond, "beyond");
    }

    #[test]
    fn gps_int_gives_a_fix_and_no_fix_gives_none() {
        let set = crate::set::RuntimeSet::parse(
            "m.xml",
            r#"<protocol><msg_class name="telemetry" id="1">
            <message name="GPS_INT" id="155">
              <field name="lat" type="int32"/><field name="lon" type="int32"/>
              <field name="hmsl" type="int32"/><field name="pacc" type="uint32"/>
              <field name="fix" type="uint8"/></message></msg_class></protocol>"#,
        )
        .unwrap();
        let d = set.find(1, 155).unwrap();
        let payload = |fix: u8| {
            let mut p = Vec::new();
            p.extend(434_629_172i32.to_le_bytes());
            p.extend(14_727_000i32.to_le_bytes());
            p.extend(152_300i32.to_le_bytes());
            p.extend(250u32.to_le_bytes());
            p.push(fix);
            p
        };
        let f = location(d, &payload(3)).unwrap();
        assert!((f.latitude - 43.462_917_2).abs() < 1e-9);
        assert!((f.longitude - 1.4727).abs() < 1e-9);
        assert!((f.altitude - 152.3).abs() < 1e-9);
        assert_eq!(f.accuracy, Some(2.5));
        assert_eq!(location(d, &payload(0)), None);
        let j: serde_json::Value = serde_json::from_str(&f.json(7, 1_500_000_001)).unwrap();
        assert_eq!(j["timestamp"]["sec"], 1);
        assert_eq!(j["timestamp"]["nsec"], 500_000_001);
        assert_eq!(j["frame_id"], "ac7");
        assert_eq!(j["position_covariance_type"], 2);
    }
}
