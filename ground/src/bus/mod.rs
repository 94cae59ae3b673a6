//! The fleet bus: Zenoh sessions of the gateway and of the ground stations that use
//! it ([`keys`] gives the key layout).
//!
//! The gateway's session is a Zenoh peer listening on [`DEFAULT_LISTEN`]; a ground
//! station (`pprz-monitor --zenoh`, a script) opens a client session to it. Multicast
//! scouting is off unless asked for ([`BusConfig::multicast`]): nothing leaves the
//! machine unless an endpoint says so. Zenoh runs its own threads; the gateway's
//! loop publishes with blocking calls that return at once, and what Zenoh receives
//! (commands, settings queries) waits in a bounded queue for that loop
//! ([`Bus::next_request`]); beyond [`MAX_REQUESTS`] waiting, requests are dropped and
//! counted ([`Bus::flooded`]).
//!
//! What a session takes from the network is bounded: Zenoh drops a message longer than
//! [`MAX_MESSAGE`] before reassembling it, and a command or a settings query whose
//! payload is longer than [`MAX_PAYLOAD`] is not copied nor queued: it comes to the
//! loop as a [`Request::TooLarge`] (a query is answered with an error at once).
//!
//! ```no_run
//! use pprz_ground::bus::{Bus, BusConfig};
//! let mut bus = Bus::open(&BusConfig::client("tcp/127.0.0.1:7447")).unwrap();
//! bus.put("pprz/7/uplink/PING", "{}", None);
//! ```

pub mod keys;

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::query::{Query, Queryable};
use zenoh::{Config, Session};

/// Where the gateway listens by default.
pub const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7447";

/// Requests (commands, settings queries) waiting for the gateway's loop at most.
pub const MAX_REQUESTS: usize = 1024;

/// The longest payload of a command or a settings query taken: the longest JSON text
/// the gateway reads ([`crate::json::MAX_TEXT`]).
pub const MAX_PAYLOAD: usize = crate::json::MAX_TEXT;

/// The longest message a session receives (Zenoh's `transport/link/rx/max_message_size`,
/// 1 GiB by default): [`MAX_PAYLOAD`] with room for a key, an attachment and Zenoh's
/// headers. Zenoh drops longer messages as their fragments come, without closing the
/// session; shorter ones are not fragmented or are reassembled within this bound.
pub const MAX_MESSAGE: usize = MAX_PAYLOAD + 16 * 1024;

/// Bytes of its key kept for a request dropped for its size.
const MAX_KEY_KEPT: usize = 256;

/// Keys with a publisher of their own at most; further keys are put without one
/// (a little slower, never refused).
pub const MAX_PUBLISHERS: usize = 4096;

/// How a session joins the bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusConfig {
    /// A peer (the gateway: it serves clients and other peers) or a client (a ground
    /// station: it talks through the peer it connects to).
    pub peer: bool,
    /// Endpoints to listen on (e.g. `tcp/127.0.0.1:7447`).
    pub listen: Vec<String>,
    /// Endpoints to connect to (a `zenohd` router, another peer, the gateway).
    pub connect: Vec<String>,
    /// Multicast scouting (finds peers on the local network by multicast; off: only
    /// the endpoints given are used).
    pub multicast: bool,
}

impl BusConfig {
    /// The gateway's default: a peer listening on [`DEFAULT_LISTEN`], no scouting.
    pub fn gateway() -> Self {
        Self {
            peer: true,
            listen: vec![DEFAULT_LISTEN.to_owned()],
            connect: Vec::new(),
            multicast: false,
        }
    }

    /// A ground station's: a client of the gateway at `endpoint`.
    pub fn client(endpoint: &str) -> Self {
        Self {
            peer: false,
            listen: Vec::new(),
            connect: vec![endpoint.to_owned()],
            multicast: false,
        }
    }

    /// The Zenoh configuration (messages received bounded by [`MAX_MESSAGE`]).
    ///
    /// # Errors
    /// An endpoint Zenoh refuses (its message).
    pub fn zenoh(&self) -> Result<Config, String> {
        let list = |v: &[String]| serde_json::Value::from(v.to_vec()).to_string();
        let mut c = Config::default();
        let mode = if self.peer { "\"peer\"" } else { "\"client\"" };
        let set = |c: &mut Config, k: &str, v: &str| {
            c.insert_json5(k, v)
                .map_err(|e| format!("zenoh configuration {k} = {v}: {e}"))
        };
        set(&mut c, "mode", mode)?;
        set(&mut c, "listen/endpoints", &list(&self.listen))?;
        set(&mut c, "connect/endpoints", &list(&self.connect))?;
        let multicast = if self.multicast { "true" } else { "false" };
        set(&mut c, "scouting/multicast/enabled", multicast)?;
        set(&mut c, "scouting/gossip/enabled", multicast)?;
        set(
            &mut c,
            "transport/link/rx/max_message_size",
            &MAX_MESSAGE.to_string(),
        )?;
        Ok(c)
    }
}

/// What the bus brought for the gateway's loop.
pub enum Request {
    /// A command put on `pprz/<ac_id>/uplink/<MESSAGE>`.
    Command {
        /// Its key.
        key: String,
        /// Its payload (JSON text, unchecked).
        payload: Vec<u8>,
    },
    /// A query on `pprz/<ac_id>/settings/<name>`, to answer with [`Query::reply`]; its
    /// payload, if any, is at most [`MAX_PAYLOAD`] bytes.
    Setting(Query),
    /// A command or a settings query whose payload is longer than [`MAX_PAYLOAD`]:
    /// dropped without being copied (the query already answered with an error).
    TooLarge {
        /// Its key (its first 256 bytes at most).
        key: String,
        /// The payload's length in bytes.
        len: usize,
    },
}

impl Request {
    /// The [`TooLarge`](Self::TooLarge) request for a payload of `len` bytes on `key`
    /// when it is longer than [`MAX_PAYLOAD`]; `None` when it may be taken.
    fn too_large(key: &str, len: usize) -> Option<Self> {
        (len > MAX_PAYLOAD).then(|| {
            let mut end = key.len().min(MAX_KEY_KEPT);
            while !key.is_char_boundary(end) {
                end -= 1;
            }
            Self::TooLarge {
                key: key[..end].to_owned(),
                len,
            }
        })
    }
}

/// A session on the bus (module doc).
pub struct Bus {
    session: Session,
    publishers: HashMap<String, Publisher<'static>>,
    requests: Option<Receiver<Request>>,
    flooded: Arc<AtomicU64>,
    put_errors: u64,
    _commands: Option<Subscriber<()>>,
    _settings: Option<Queryable<()>>,
    _schemas: Option<Queryable<()>>,
}

impl Bus {
    /// Opens a session.
    ///
    /// # Errors
    /// The configuration is refused, or an endpoint cannot be listened on or reached.
    pub fn open(config: &BusConfig) -> Result<Self, String> {
        let session = zenoh::open(config.zenoh()?)
            .wait()
            .map_err(|e| format!("zenoh: {e}"))?;
        Ok(Self {
            session,
            publishers: HashMap::new(),
            requests: None,
            flooded: Arc::new(AtomicU64::new(0)),
            put_errors: 0,
            _commands: None,
            _settings: None,
            _schemas: None,
        })
    }

    /// The same session taking commands ([`keys::UPLINK_ALL`]) and settings queries
    /// ([`keys::SETTINGS_ALL`]) for [`next_request`](Self::next_request).
    ///
    /// # Errors
    /// Zenoh refused a declaration.
    pub fn serving(mut self) -> Result<Self, String> {
        let (tx, rx) = sync_channel::<Request>(MAX_REQUESTS);
        let (tx2, flooded, flooded2) = (tx.clone(), self.flooded.clone(), self.flooded.clone());
        let commands = self
            .session
            .declare_subscriber(keys::UPLINK_ALL)
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let request =
                    Request::too_large(key, sample.payload().len()).unwrap_or_else(|| {
                        Request::Command {
                            key: key.to_owned(),
                            payload: sample.payload().to_bytes().into_owned(),
                        }
                    });
                queue(&tx, request, &flooded);
            })
            .wait()
            .map_err(|e| format!("zenoh: {e}"))?;
        let settings = self
            .session
            .declare_queryable(keys::SETTINGS_ALL)
            .callback(move |query| {
                let len = query.payload().map_or(0, ZBytes::len);
                let request = match Request::too_large(query.key_expr().as_str(), len) {
                    Some(refused) => {
                        let why = too_large_message(len);
                        let _ = query.reply_err(why).wait();
                        refused
                    }
                    None => Request::Setting(query),
                };
                queue(&tx2, request, &flooded2);
            })
            .wait()
            .map_err(|e| format!("zenoh: {e}"))?;
        self.requests = Some(rx);
        self._commands = Some(commands);
        self._settings = Some(settings);
        Ok(self)
    }

    /// The same session answering schema queries on `pprz/schema/<class>/<MESSAGE>`
    /// ([`keys::SCHEMAS_ALL`]) with the JSON Schema of each message of `set` the query's
    /// key expression names (`pprz/schema/**`: every message): the schemas of the
    /// messages' JSON, as the viewer publishes them. Answered on Zenoh's own threads.
    ///
    /// # Errors
    /// Zenoh refused the declaration.
    pub fn serving_schemas(mut self, set: crate::set::RuntimeSet) -> Result<Self, String> {
        let messages: Vec<(
            zenoh::key_expr::KeyExpr<'static>,
            &'static pprz_messages::MessageDescriptor<'static>,
        )> = set
            .set()
            .messages()
            .iter()
            .filter_map(|d| {
                let key = keys::schema(d.class_name, d.name);
                Some((zenoh::key_expr::KeyExpr::try_from(key).ok()?, d))
            })
            .collect();
        let queryable = self
            .session
            .declare_queryable(keys::SCHEMAS_ALL)
            .callback(move |query| {
                for (key, desc) in &messages {
                    if query.key_expr().intersects(key) {
                        let _ = query.reply(key.clone(), crate::json::schema(desc)).wait();
                    }
                }
            })
            .wait()
            .map_err(|e| format!("zenoh: {e}"))?;
        self._schemas = Some(queryable);
        Ok(self)
    }

    /// The next request waiting, if any.
    pub fn next_request(&self) -> Option<Request> {
        self.requests.as_ref()?.try_recv().ok()
    }

    /// Requests dropped because [`MAX_REQUESTS`] were waiting.
    pub fn flooded(&self) -> u64 {
        self.flooded.load(Ordering::Relaxed)
    }

    /// Puts that Zenoh refused (counted, not retried).
    pub fn put_errors(&self) -> u64 {
        self.put_errors
    }

    /// Publishes `payload` on `key` (a publisher is declared for it the first time, up
    /// to [`MAX_PUBLISHERS`]), with an attachment. Under congestion Zenoh drops the
    /// sample; a put it refuses is counted ([`put_errors`](Self::put_errors)).
    pub fn put(&mut self, key: &str, payload: impl Into<ZBytes>, attachment: Option<Vec<u8>>) {
        if !self.publishers.contains_key(key)
            && self.publishers.len() < MAX_PUBLISHERS
            && let Ok(p) = self.session.declare_publisher(key.to_owned()).wait()
        {
            self.publishers.insert(key.to_owned(), p);
        }
        let result = match self.publishers.get(key) {
            Some(p) => p.put(payload).attachment(attachment).wait(),
            None => self
                .session
                .put(key.to_owned(), payload)
                .attachment(attachment)
                .wait(),
        };
        if result.is_err() {
            self.put_errors += 1;
        }
    }

    /// Declares the liveliness token `key` (it vanishes when dropped, or when this
    /// session ends, even by a crash); `None` if Zenoh refused it.
    pub fn token(&self, key: &str) -> Option<zenoh::liveliness::LivelinessToken> {
        self.session
            .liveliness()
            .declare_token(key.to_owned())
            .wait()
            .ok()
    }

    /// The Zenoh session (to subscribe, query...).
    pub fn session(&self) -> &Session {
        &self.session
    }
}

/// Why a payload of `len` bytes is refused.
pub fn too_large_message(len: usize) -> String {
    format!("{len} bytes of payload: at most {MAX_PAYLOAD}")
}

/// Queues a request for the loop, or counts it when the queue is full (or gone).
fn queue(tx: &SyncSender<Request>, request: Request, flooded: &AtomicU64) {
    if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) = tx.try_send(request) {
        flooded.fetch_add(1, Ordering::Relaxed);
    }
}
