//! The door of the Foxglove server: a bounded number of clients, and bounded messages
//! from each.
//!
//! The `foxglove` SDK (0.30) accepts every connection on its own listener and reads
//! client messages with tungstenite's defaults (messages up to 64 MiB, frames up to
//! 16 MiB); it offers no setting for either. So the viewer listens itself, at the address
//! the user gives, and relays each accepted connection to the SDK's server, which listens
//! on a loopback port of its own:
//!
//! * at most `max_clients` connections at once: the next one is answered
//!   `503 Service Unavailable` and closed ([`GateCounts::refused`]);
//! * the client's HTTP request must be complete within [`HANDSHAKE_TIMEOUT`] and
//!   [`MAX_REQUEST_HEAD`] bytes, and each WebSocket message it sends (all its fragments)
//!   within [`MAX_CLIENT_MESSAGE`] bytes: the relay reads every frame header before
//!   passing the frame on, and closes the connection before the SDK sees a frame that
//!   would go over ([`GateCounts::closed`]).
//!
//! The server's side is relayed as it is. Each connection costs two threads with small
//! stacks and two buffers of [`RELAY_BUFFER`] bytes here, besides what the SDK keeps.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// Clients served at once by default.
pub const DEFAULT_MAX_CLIENTS: usize = 8;

/// The most clients that may be allowed at once.
pub const MAX_MAX_CLIENTS: usize = 256;

/// The longest WebSocket message a client may send, all fragments together, in bytes.
///
/// The server takes JSON requests only (no client publishing, no services), and the
/// largest it answers are, with 32 aircraft of the full PPRZLINK set (367 messages, so
/// 32 × 369 topics) and 256 settings each: `subscribe` to every topic (about 45 bytes
/// a topic: 530 kB), `getParameters` or `subscribeParameterUpdates` naming every
/// setting (about 25 bytes a name: 205 kB) and `setParameters` of every setting (about
/// 80 bytes each: 655 kB). 1 MiB holds each of them.
pub const MAX_CLIENT_MESSAGE: u64 = 1 << 20;

/// The longest HTTP request (the WebSocket handshake) a client may send, in bytes.
pub const MAX_REQUEST_HEAD: usize = 16 * 1024;

/// How long a client may take to send its HTTP request.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// Bytes of each relay buffer (two per connection).
pub const RELAY_BUFFER: usize = 16 * 1024;

/// Stack of each relay thread.
const RELAY_STACK: usize = 128 * 1024;

/// The answer to a client over the limit.
const REFUSAL: &[u8] = b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nConnection: close\r\nContent-Length: 36\r\n\r\ntoo many viewers connected: refused\n";

/// What the door turned away.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct GateCounts {
    /// Connections refused because `max_clients` were connected.
    pub refused: u64,
    /// Connections closed because a message or the HTTP request was over its bound, or
    /// the request was not complete in time.
    pub closed: u64,
}

/// Shared state of the door and its connections.
#[derive(Default)]
struct Shared {
    active: AtomicUsize,
    refused: AtomicU64,
    closed: AtomicU64,
    stop: AtomicBool,
}

/// A connection's place: freed when both its relay threads are done.
struct Place(Arc<Shared>);

impl Drop for Place {
    fn drop(&mut self) {
        self.0.active.fetch_sub(1, Ordering::SeqCst);
    }
}

/// The listener in front of the SDK's server.
pub(crate) struct Gate {
    shared: Arc<Shared>,
    addr: SocketAddr,
}

impl Gate {
    /// Listens at `listener`'s address and relays up to `max_clients` connections at
    /// once to `upstream` (the SDK's server).
    ///
    /// # Errors
    /// The thread that accepts could not start.
    pub(crate) fn start(
        listener: TcpListener,
        upstream: SocketAddr,
        max_clients: usize,
    ) -> io::Result<Self> {
        let addr = listener.local_addr()?;
        let shared = Arc::new(Shared::default());
        let s = shared.clone();
        std::thread::Builder::new()
            .name("foxglove-gate".into())
            .spawn(move || accept(&listener, upstream, max_clients, &s))?;
        Ok(Self { shared, addr })
    }

    /// What was turned away so far.
    pub(crate) fn counts(&self) -> GateCounts {
        GateCounts {
            refused: self.shared.refused.load(Ordering::Relaxed),
            closed: self.shared.closed.load(Ordering::Relaxed),
        }
    }

    /// Connections relayed now.
    #[cfg(test)]
    fn active(&self) -> usize {
        self.shared.active.load(Ordering::SeqCst)
    }
}

impl Drop for Gate {
    /// Stops accepting (the accepting thread is woken by a connection of its own).
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        let mut wake = self.addr;
        if wake.ip().is_unspecified() {
            wake.set_ip(match wake {
                SocketAddr::V4(_) => std::net::Ipv4Addr::LOCALHOST.into(),
                SocketAddr::V6(_) => std::net::Ipv6Addr::LOCALHOST.into(),
            });
        }
        let _ = TcpStream::connect_timeout(&wake, Duration::from_secs(1));
    }
}

/// Accepts connections until the gate is dropped.
fn accept(listener: &TcpListener, upstream: SocketAddr, max_clients: usize, shared: &Arc<Shared>) {
    loop {
        let accepted = listener.accept();
        if shared.stop.load(Ordering::SeqCst) {
            return;
        }
        let Ok((client, _)) = accepted else {
            // Out of file descriptors, say: not a busy loop.
            std::thread::sleep(Duration::from_millis(10));
            continue;
        };
        if shared.active.fetch_add(1, Ordering::SeqCst) >= max_clients {
            let place = Place(shared.clone());
            shared.refused.fetch_add(1, Ordering::Relaxed);
            refuse(client);
            drop(place);
            continue;
        }
        let place = Arc::new(Place(shared.clone()));
        // On failure the place is freed and the client closed.
        let _ = relay(client, upstream, &place);
    }
}

/// Answers 503 without waiting on the client, and closes.
fn refuse(mut client: TcpStream) {
    if client.set_nonblocking(true).is_ok() {
        let _ = client.write_all(REFUSAL);
    }
    let _ = client.shutdown(Shutdown::Both);
}

/// Connects to the SDK's server and starts the two relay threads of `client`.
fn relay(client: TcpStream, upstream: SocketAddr, place: &Arc<Place>) -> io::Result<()> {
    let server = TcpStream::connect_timeout(&upstream, Duration::from_secs(5))?;
    let _ = client.set_nodelay(true);
    let _ = server.set_nodelay(true);
    let (client_in, server_out) = (client.try_clone()?, server.try_clone()?);
    let p = place.clone();
    std::thread::Builder::new()
        .name("foxglove-in".into())
        .stack_size(RELAY_STACK)
        .spawn(move || {
            if let Err(Breach) = inbound(client_in, server_out) {
                p.0.closed.fetch_add(1, Ordering::Relaxed);
            }
        })?;
    let p = place.clone();
    let cleanup = client.try_clone()?;
    let spawned = std::thread::Builder::new()
        .name("foxglove-out".into())
        .stack_size(RELAY_STACK)
        .spawn(move || {
            outbound(server, client);
            drop(p);
        });
    if spawned.is_err() {
        // The inbound thread then ends.
        let _ = cleanup.shutdown(Shutdown::Both);
    }
    spawned.map(drop)
}

/// A client went over a bound: its connection is closed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Breach;

/// How the client's side of a connection ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    /// The client closed its side: the server's last words (its close frame) still go
    /// out.
    Closed,
    /// A read or write failed.
    Broken,
    /// The client went over a bound.
    Breach,
}

/// Relays the client's bytes to the server, checking each frame, until the client is
/// done or went over a bound (both sides are then closed).
fn inbound(mut client: TcpStream, mut server: TcpStream) -> Result<(), Breach> {
    let mut inspector = Inspector::new();
    let mut buf = vec![0u8; RELAY_BUFFER];
    let start = Instant::now();
    let end = loop {
        if inspector.in_head() {
            let left = HANDSHAKE_TIMEOUT.saturating_sub(start.elapsed());
            if left.is_zero() || client.set_read_timeout(Some(left)).is_err() {
                break End::Breach;
            }
        }
        let n = match client.read(&mut buf) {
            Ok(0) => break End::Closed,
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) if is_timeout(&e) && inspector.in_head() => break End::Breach,
            Err(_) => break End::Broken,
        };
        let was_head = inspector.in_head();
        if inspector.feed(&buf[..n]).is_err() {
            break End::Breach;
        }
        if was_head && !inspector.in_head() {
            // A viewer may send nothing for hours.
            let _ = client.set_read_timeout(None);
        }
        if server.write_all(&buf[..n]).is_err() {
            break End::Broken;
        }
    };
    if end == End::Closed {
        // The server then closes, and the outbound relay closes the client.
        let _ = server.shutdown(Shutdown::Write);
        return Ok(());
    }
    let _ = server.shutdown(Shutdown::Both);
    let _ = client.shutdown(Shutdown::Both);
    match end {
        End::Breach => Err(Breach),
        End::Closed | End::Broken => Ok(()),
    }
}

/// Whether a read error is its timeout.
fn is_timeout(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
    )
}

/// Relays the server's bytes to the client; closes both when either side is done.
fn outbound(mut server: TcpStream, mut client: TcpStream) {
    let _ = io::copy(&mut server, &mut client);
    let _ = client.shutdown(Shutdown::Both);
    let _ = server.shutdown(Shutdown::Both);
}

/// Where the inspector is in the client's byte stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// The HTTP request: bytes so far, and how many of `\r\n\r\n` were just seen.
    Head { bytes: usize, matched: usize },
    /// A frame header: its bytes so far.
    Header { have: usize },
    /// A frame's payload: bytes left.
    Payload { left: u64 },
}

/// Follows the client's side of a WebSocket connection (the HTTP request, then frames)
/// and tells when it goes over a bound.
#[derive(Debug)]
struct Inspector {
    phase: Phase,
    header: [u8; 14],
    /// Bytes of the data message being received (its fragments so far).
    message: u64,
}

impl Inspector {
    fn new() -> Self {
        Self {
            phase: Phase::Head {
                bytes: 0,
                matched: 0,
            },
            header: [0; 14],
            message: 0,
        }
    }

    /// Whether the HTTP request is still being received.
    fn in_head(&self) -> bool {
        matches!(self.phase, Phase::Head { .. })
    }

    /// Takes the next bytes of the client; `Err` once it went over a bound (the
    /// bytes must then not be passed on).
    fn feed(&mut self, mut bytes: &[u8]) -> Result<(), Breach> {
        while let Some((&b, rest)) = bytes.split_first() {
            match self.phase {
                Phase::Head { bytes: n, matched } => {
                    if n + 1 > MAX_REQUEST_HEAD {
                        return Err(Breach);
                    }
                    let matched = match (matched, b) {
                        (0 | 2, b'\r') => matched + 1,
                        (1 | 3, b'\n') => matched + 1,
                        (_, b'\r') => 1,
                        _ => 0,
                    };
                    self.phase = if matched == 4 {
                        Phase::Header { have: 0 }
                    } else {
                        Phase::Head {
                            bytes: n + 1,
                            matched,
                        }
                    };
                    bytes = rest;
                }
                Phase::Header { have } => {
                    self.header[have] = b;
                    let have = have + 1;
                    self.phase = if have == header_len(&self.header[..have]) {
                        self.frame(have)?
                    } else {
                        Phase::Header { have }
                    };
                    bytes = rest;
                }
                Phase::Payload { left } => {
                    let take = bytes.len().min(usize::try_from(left).unwrap_or(usize::MAX));
                    let left = left - take as u64;
                    self.phase = if left == 0 {
                        Phase::Header { have: 0 }
                    } else {
                        Phase::Payload { left }
                    };
                    bytes = &bytes[take..];
                }
            }
        }
        Ok(())
    }

    /// A complete frame header of `len` bytes: checks the frame's size and the
    /// message's, and gives the next phase.
    fn frame(&mut self, len: usize) -> Result<Phase, Breach> {
        let h = &self.header[..len];
        let opcode = h[0] & 0x0F;
        let size = match h[1] & 0x7F {
            126 => u64::from(u16::from_be_bytes([h[2], h[3]])),
            127 => u64::from_be_bytes(h[2..10].try_into().map_err(|_| Breach)?),
            n => u64::from(n),
        };
        let message = match opcode {
            // Continuation: one more fragment of the message.
            0 => self.message.saturating_add(size),
            // Control frames (close, ping, pong) are at most 125 bytes.
            8..=15 if size > 125 => return Err(Breach),
            8..=15 => self.message,
            // A text or binary message starts (or a reserved opcode: same bound).
            _ => size,
        };
        if message > MAX_CLIENT_MESSAGE {
            return Err(Breach);
        }
        self.message = message;
        Ok(if size == 0 {
            Phase::Header { have: 0 }
        } else {
            Phase::Payload { left: size }
        })
    }
}

/// The length of a frame header whose first `have.len()` bytes are `have`: 2 until the
/// second byte is known, then with the extended length and the mask.
fn header_len(have: &[u8]) -> usize {
    let Some(&second) = have.get(1) else {
        return 2;
    };
    let extended = match second & 0x7F {
        126 => 2,
        127 => 8,
        _ => 0,
    };
    let mask = if second & 0x80 != 0 { 4 } else { 0 };
    2 + extended + mask
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A masked client frame header for `size` payload bytes.
    fn header(fin: bool, opcode: u8, size: u64) -> Vec<u8> {
        let mut h = vec![if fin { 0x80 } else { 0 } | opcode];
        match size {
            0..=125 => h.push(0x80 | size as u8),
            126..=0xFFFF => {
                h.push(0x80 | 126);
                h.extend((size as u16).to_be_bytes());
            }
            _ => {
                h.push(0x80 | 127);
                h.extend(size.to_be_bytes());
            }
        }
        h.extend([1, 2, 3, 4]);
        h
    }

    fn open() -> Inspector {
        let mut i = Inspector::new();
        i.feed(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
        assert!(!i.in_head());
        i
    }

    #[test]
    fn messages_up_to_the_bound_pass_in_any_pieces() {
        let mut stream = Vec::new();
        stream.extend(header(false, 1, 3));
        stream.extend(b"abc");
        // A ping between the fragments does not count.
        stream.extend(header(true, 9, 2));
        stream.extend(b"hi");
        stream.extend(header(true, 0, MAX_CLIENT_MESSAGE - 3));
        let mut i = open();
        for piece in stream.chunks(3) {
            i.feed(piece).unwrap();
        }
        i.feed(&vec![0; (MAX_CLIENT_MESSAGE - 3) as usize]).unwrap();
        // The next message starts from zero.
        i.feed(&header(true, 2, MAX_CLIENT_MESSAGE)).unwrap();
        assert_eq!(
            i.phase,
            Phase::Payload {
                left: MAX_CLIENT_MESSAGE
            }
        );
    }

    #[test]
    fn a_message_over_the_bound_is_refused_at_the_header_that_goes_over() {
        let mut i = open();
        i.feed(&header(true, 1, MAX_CLIENT_MESSAGE + 1))
            .unwrap_err();
        let mut i = open();
        i.feed(&header(false, 1, 1 << 19)).unwrap();
        i.feed(&vec![0; 1 << 19]).unwrap();
        i.feed(&header(false, 0, 1 << 19)).unwrap();
        i.feed(&vec![0; 1 << 19]).unwrap();
        assert_eq!(i.feed(&header(false, 0, 1)), Err(Breach));
        let mut i = open();
        assert_eq!(i.feed(&header(true, 0, u64::MAX)), Err(Breach));
        let mut i = open();
        assert_eq!(i.feed(&header(true, 9, 126)), Err(Breach));
    }

    #[test]
    fn an_http_request_over_its_bound_is_refused() {
        let mut i = Inspector::new();
        i.feed(&[b'a'; MAX_REQUEST_HEAD]).unwrap();
        assert_eq!(i.feed(b"\r"), Err(Breach));
        let mut i = Inspector::new();
        i.feed(b"GET / HTTP/1.1\r\n\r\r\n\r\n").unwrap();
        assert!(!i.in_head());
    }

    /// The bound holds the largest requests the server answers.
    #[test]
    fn the_largest_requests_fit() {
        let topics: Vec<_> = (0..32 * 369u64)
            .map(|i| serde_json::json!({"id": u32::MAX - i as u32, "channelId": 1_000_000 + i}))
            .collect();
        let subscribe = serde_json::json!({"op": "subscribe", "subscriptions": topics});
        let names: Vec<String> = (0..32u32)
            .flat_map(|ac| (0..256).map(move |i| format!("/ac/{}/settings/{i}", 224 + ac)))
            .collect();
        let get = serde_json::json!({"op": "getParameters", "parameterNames": names, "id": "x".repeat(64)});
        let set: Vec<_> = names
            .iter()
            .map(|n| serde_json::json!({"name": n, "value": -1.234_567_890_123_456_7e-300, "type": "float64"}))
            .collect();
        let set =
            serde_json::json!({"op": "setParameters", "parameters": set, "id": "x".repeat(64)});
        for request in [subscribe, get, set] {
            let len = request.to_string().len() as u64;
            assert!(len <= MAX_CLIENT_MESSAGE, "{len}");
        }
    }

    /// A client that sends nothing: holds its place until it is closed.
    fn connect(addr: SocketAddr) -> TcpStream {
        let s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        s
    }

    #[test]
    fn the_client_over_the_limit_is_refused_and_a_place_freed_is_taken_again() {
        // The "server": accepts the relayed connections, closes each when its client
        // has closed, as the SDK's does.
        let upstream = TcpListener::bind("127.0.0.1:0").unwrap();
        let up = upstream.local_addr().unwrap();
        let held = std::thread::spawn(move || {
            for _ in 0..3 {
                let (mut s, _) = upstream.accept().unwrap();
                std::thread::spawn(move || io::copy(&mut s, &mut io::sink()));
            }
            3
        });
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let gate = Gate::start(listener, up, 2).unwrap();
        let a = connect(gate.addr);
        let _b = connect(gate.addr);
        let mut c = connect(gate.addr);
        let mut answer = String::new();
        c.read_to_string(&mut answer).unwrap();
        assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
        assert_eq!(gate.counts().refused, 1);
        drop(a);
        // Bounded by count: the place is freed once both relay threads are done.
        let mut d = None;
        for _ in 0..200 {
            if gate.active() < 2 {
                d = Some(connect(gate.addr));
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        assert!(d.is_some(), "the place of the client that left is freed");
        assert_eq!(held.join().unwrap(), 3);
        assert_eq!(gate.counts().refused, 1);
    }
}
