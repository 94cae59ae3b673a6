//! Host adapters (feature `std`; the serial port also needs feature `serial`): UDP
//! socket, TCP stream, serial port, file, or any blocking `std::io` stream, as
//! `embedded_io_async` devices.
//!
//! # How they work on the Embassy std executor
//!
//! The Embassy std executor has no I/O reactor, so a device cannot wait on a socket.
//! Each adapter therefore runs **one background thread per direction** that does the
//! blocking I/O, and exchanges bytes with the async side through a bounded buffer
//! guarded by a `std::sync::Mutex`:
//!
//! ```text
//!  socket ──> [RX thread] ──> rx buffer ──> HostRx::read()    (wakes the reading task)
//!  socket <── [TX thread] <── tx buffer <── HostTx::write()   (wakes the writing task)
//! ```
//!
//! The threads wake the async tasks through their `Waker`s, so any executor works
//! (Embassy's std executor, `embassy_futures::block_on`, ...). No embassy-time driver
//! is needed.
//!
//! # Buffering and back-pressure
//!
//! * `write` copies into the TX buffer ([`HostConfig::tx_buffer`] bytes) and returns
//!   at once; it waits only while the buffer is full, so a slow peer slows the writer
//!   task down (and the telemetry queue behind it sheds by priority). `flush` waits
//!   until the TX thread has handed every byte to the OS (and, for streams, called
//!   `std::io::Write::flush`).
//! * The RX thread reads as soon as bytes arrive and waits while the RX buffer
//!   ([`HostConfig::rx_buffer`] bytes) is full; for TCP and serial ports this pushes
//!   back on the peer. A UDP datagram that does not fit is dropped and counted in
//!   [`HostStats::rx_dropped_datagrams`].
//!
//! # Datagrams (UDP)
//!
//! Each `write` call sends one datagram of at most [`HostConfig::max_datagram`] bytes
//! (the telemetry writer hands each frame to one `write`, so one frame per datagram).
//! Received datagrams are concatenated into the byte stream `read` returns (frames are
//! self-delimiting).
//!
//! # When the peer is gone
//!
//! * **TCP, serial, file**: end of input makes `read` return `Ok(0)` from then on
//!   (after the buffered bytes); a read error is returned as [`HostError::Io`] from then
//!   on. A failed write (peer reset, cable unplugged) is counted in
//!   [`HostStats::tx_errors`]; the bytes still buffered are dropped and counted in
//!   [`HostStats::tx_dropped_bytes`]; every later `write`/`flush` fails at once with
//!   the same [`HostError::Io`]: writes fail fast instead of blocking.
//! * **UDP** has no connection: a send error (for example `ConnectionRefused` after an
//!   ICMP "port unreachable" because nobody listens) is counted and the datagram is
//!   dropped; writes go on succeeding, as on a radio link.
//!
//! # Closing
//!
//! Dropping a [`HostTx`] lets its thread send what is buffered, then end (a TCP stream
//! is then shut down for writing). Dropping a [`HostRx`] ends its thread at the next
//! read (TCP: at once, by shutting the socket down for reading; UDP and serial: within
//! [`HostConfig::poll_interval`]). Await `flush` before dropping a [`HostTx`] when the
//! bytes must be out before the program exits.
//!
//! # Example: a ground link over UDP
//!
//! ```no_run
//! use pprz_devices::host::{HostConfig, HostDevice};
//!
//! # fn main() -> std::io::Result<()> {
//! // Aircraft side of a Paparazzi-style UDP link: send to 4242, receive on 4243.
//! let link = HostDevice::udp_bind("127.0.0.1:4243", "127.0.0.1:4242", HostConfig::default())?;
//! let (uplink, downlink) = link.split(); // for the datalink reader and the writer task
//! # let _ = (uplink, downlink);
//! # Ok(())
//! # }
//! ```

use std::boxed::Box;
use std::collections::VecDeque;
use std::fmt;
use std::fs::{File, OpenOptions};
use std::future::poll_fn;
use std::io;
use std::net::{Shutdown, TcpStream, ToSocketAddrs, UdpSocket};
use std::path::Path;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::task::{Poll, Waker};
use std::thread;
use std::time::Duration;
use std::vec;
use std::vec::Vec;

use embedded_io_async::{ErrorType, Read, Write};

/// Buffer sizes and timing of a host adapter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HostConfig {
    /// Bytes received but not yet read (at least 1).
    pub rx_buffer: usize,
    /// Bytes written but not yet sent (at least 1, and at least `max_datagram` for UDP).
    pub tx_buffer: usize,
    /// Largest UDP datagram sent; longer writes are split.
    pub max_datagram: usize,
    /// How often a thread blocked on a UDP socket or serial port checks that its
    /// half is still in use.
    pub poll_interval: Duration,
}

impl Default for HostConfig {
    /// 4 KiB buffers, 1472-byte datagrams (an Ethernet MTU), 50 ms poll interval.
    fn default() -> Self {
        Self {
            rx_buffer: 4096,
            tx_buffer: 4096,
            max_datagram: 1472,
            poll_interval: Duration::from_millis(50),
        }
    }
}

/// Why a host device operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum HostError {
    /// The operating system reported this error. It is sticky: the half fails the same
    /// way from then on.
    Io(io::ErrorKind),
    /// The half's I/O thread has ended (it could not be kept running).
    Closed,
}

impl fmt::Display for HostError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(kind) => write!(f, "host I/O error: {kind}"),
            Self::Closed => f.write_str("host I/O thread has ended"),
        }
    }
}

impl core::error::Error for HostError {}

impl embedded_io_async::Error for HostError {
    fn kind(&self) -> embedded_io_async::ErrorKind {
        match self {
            Self::Io(kind) => (*kind).into(),
            Self::Closed => embedded_io_async::ErrorKind::NotConnected,
        }
    }
}

/// Counters of a host device (both halves). They never wrap in practice (u64).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct HostStats {
    /// Bytes received from the OS.
    pub bytes_in: u64,
    /// Bytes handed to the OS.
    pub bytes_out: u64,
    /// UDP datagrams dropped because the RX buffer was full.
    pub rx_dropped_datagrams: u64,
    /// Receive errors (for UDP, each failed `recv`; for streams, the one that ended it).
    pub rx_errors: u64,
    /// Send errors (UDP: each dropped datagram; streams: the one failure that ended the
    /// stream) plus writes refused afterwards.
    pub tx_errors: u64,
    /// Written bytes dropped unsent because the stream failed.
    pub tx_dropped_bytes: u64,
}

/// How the end of input was reached.
#[derive(Clone, Copy, Debug)]
enum End {
    Eof,
    Error(io::ErrorKind),
}

type Hook = Box<dyn FnOnce() + Send>;

#[derive(Default)]
struct State {
    rx: VecDeque<u8>,
    rx_end: Option<End>,
    rx_waker: Option<Waker>,
    /// The `HostRx` was dropped.
    rx_closed: bool,
    tx: VecDeque<u8>,
    /// Datagram lengths in `tx` (UDP only).
    tx_datagrams: VecDeque<usize>,
    /// Bytes taken by the TX thread and not yet sent.
    tx_in_flight: usize,
    tx_error: Option<io::ErrorKind>,
    /// The TX thread has ended.
    tx_ended: bool,
    tx_waker: Option<Waker>,
    /// The `HostTx` was dropped.
    tx_closed: bool,
    stats: HostStats,
}

struct Shared {
    config: HostConfig,
    datagrams: bool,
    state: Mutex<State>,
    /// The RX thread waits here for room; the TX thread for data.
    rx_room: Condvar,
    tx_data: Condvar,
    /// Run when the `HostRx` is dropped (unblocks the RX thread).
    on_rx_close: Mutex<Option<Hook>>,
}

impl Shared {
    fn new(mut config: HostConfig, datagrams: bool) -> Arc<Self> {
        config.rx_buffer = config.rx_buffer.max(1);
        config.max_datagram = config.max_datagram.max(1);
        config.tx_buffer = config.tx_buffer.max(1);
        if datagrams {
            config.tx_buffer = config.tx_buffer.max(config.max_datagram);
        }
        Arc::new(Self {
            config,
            datagrams,
            state: Mutex::new(State::default()),
            rx_room: Condvar::new(),
            tx_data: Condvar::new(),
            on_rx_close: Mutex::new(None),
        })
    }

    /// Locks the state. A thread that panicked while holding the lock cannot leave it
    /// inconsistent (every update is a few field assignments), so poisoning is ignored.
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn wait<'a>(&self, cv: &Condvar, guard: MutexGuard<'a, State>) -> MutexGuard<'a, State> {
        cv.wait(guard).unwrap_or_else(|e| e.into_inner())
    }
}

fn wake(waker: Option<Waker>) {
    if let Some(w) = waker {
        w.wake();
    }
}

fn register(slot: &mut Option<Waker>, waker: &Waker) {
    match slot {
        Some(w) if w.will_wake(waker) => {}
        _ => *slot = Some(waker.clone()),
    }
}

fn retry(kind: io::ErrorKind) -> bool {
    matches!(
        kind,
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

/// The RX thread: blocking reads into the shared buffer until the half is dropped,
/// the input ends or (streams) fails.
fn rx_thread(shared: &Shared, mut recv: impl FnMut(&mut [u8]) -> io::Result<usize>) {
    let mut buf = vec![0u8; if shared.datagrams { 65_536 } else { 4096 }];
    loop {
        if shared.lock().rx_closed {
            return;
        }
        // More bytes than the buffer holds: a reader breaking the `io::Read` contract,
        // counted as a read error.
        let result = recv(&mut buf).and_then(|n| {
            if n <= buf.len() {
                Ok(n)
            } else {
                Err(io::ErrorKind::InvalidData.into())
            }
        });
        let mut s = shared.lock();
        match result {
            Ok(0) if !shared.datagrams => {
                s.rx_end = Some(End::Eof);
                let w = s.rx_waker.take();
                drop(s);
                return wake(w);
            }
            Ok(n) if shared.datagrams => {
                if shared.config.rx_buffer - s.rx.len() < n {
                    s.stats.rx_dropped_datagrams += 1;
                } else {
                    s.rx.extend(&buf[..n]);
                    s.stats.bytes_in += n as u64;
                    let w = s.rx_waker.take();
                    drop(s);
                    wake(w);
                }
            }
            Ok(n) => {
                let mut rest = &buf[..n];
                while !rest.is_empty() {
                    while s.rx.len() >= shared.config.rx_buffer && !s.rx_closed {
                        s = shared.wait(&shared.rx_room, s);
                    }
                    if s.rx_closed {
                        return;
                    }
                    let k = rest.len().min(shared.config.rx_buffer - s.rx.len());
                    s.rx.extend(&rest[..k]);
                    s.stats.bytes_in += k as u64;
                    rest = &rest[k..];
                    let w = s.rx_waker.take();
                    drop(s);
                    wake(w);
                    s = shared.lock();
                }
            }
            Err(e) if retry(e.kind()) => {}
            Err(_) if shared.datagrams => {
                // For example ConnectionRefused after an ICMP "port unreachable": the
                // socket stays usable. Pause so a persistent error cannot spin.
                s.stats.rx_errors += 1;
                drop(s);
                thread::sleep(shared.config.poll_interval);
            }
            Err(e) => {
                s.stats.rx_errors += 1;
                s.rx_end = Some(End::Error(e.kind()));
                let w = s.rx_waker.take();
                drop(s);
                return wake(w);
            }
        }
    }
}

/// The TX thread: sends what the async side buffered until the half is dropped and
/// everything is sent, or (streams) until a send fails.
fn tx_thread(
    shared: &Shared,
    mut send: impl FnMut(&[u8]) -> io::Result<usize>,
    mut flush: impl FnMut() -> io::Result<()>,
) {
    loop {
        let mut s = shared.lock();
        while s.tx.is_empty() && !s.tx_closed {
            s = shared.wait(&shared.tx_data, s);
        }
        if s.tx.is_empty() {
            s.tx_ended = true;
            return;
        }
        let n = match s.tx_datagrams.pop_front() {
            Some(n) if shared.datagrams => n,
            _ => s.tx.len(),
        };
        let chunk: Vec<u8> = s.tx.drain(..n).collect();
        s.tx_in_flight = n;
        drop(s);

        let result = if shared.datagrams {
            send(&chunk).map(drop)
        } else {
            write_stream(&chunk, &mut send).and_then(|()| flush())
        };

        let mut s = shared.lock();
        s.tx_in_flight = 0;
        let stream_failed = match result {
            Ok(()) => {
                s.stats.bytes_out += n as u64;
                false
            }
            Err(e) => {
                s.stats.tx_errors += 1;
                if !shared.datagrams {
                    s.tx_error = Some(e.kind());
                    s.stats.tx_dropped_bytes += (n + s.tx.len()) as u64;
                    s.tx.clear();
                    s.tx_ended = true;
                }
                !shared.datagrams
            }
        };
        let w = s.tx_waker.take();
        drop(s);
        wake(w);
        if stream_failed {
            return;
        }
    }
}

/// Writes all of `chunk`, retrying on timeouts (a serial port held by flow control).
fn write_stream(
    mut chunk: &[u8],
    send: &mut impl FnMut(&[u8]) -> io::Result<usize>,
) -> io::Result<()> {
    while !chunk.is_empty() {
        match send(chunk) {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            // More than it was given: a writer breaking the `io::Write` contract.
            Ok(n) => chunk = chunk.get(n..).ok_or(io::ErrorKind::InvalidData)?,
            Err(e) if retry(e.kind()) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

fn spawn(name: &str, f: impl FnOnce() + Send + 'static) -> io::Result<()> {
    thread::Builder::new().name(name.into()).spawn(f).map(drop)
}

/// The receiving half of a host device: [`Read`].
pub struct HostRx {
    shared: Arc<Shared>,
}

/// The sending half of a host device: [`Write`].
pub struct HostTx {
    shared: Arc<Shared>,
}

/// A bidirectional host device; [`split`](Self::split) it to give the halves to a
/// reader task and a writer task. See the [module docs](self).
pub struct HostDevice {
    /// The receiving half.
    pub rx: HostRx,
    /// The sending half.
    pub tx: HostTx,
}

impl HostRx {
    /// Reads `reader` on a background thread (a file to replay, a pipe, stdin).
    ///
    /// # Errors
    /// If the thread cannot be started.
    pub fn from_reader(
        reader: impl io::Read + Send + 'static,
        config: HostConfig,
    ) -> io::Result<Self> {
        Self::start(Shared::new(config, false), reader)
    }

    /// Reads the file at `path` (a recorded log to replay); `read` returns `Ok(0)` at
    /// its end.
    ///
    /// # Errors
    /// If the file cannot be opened or the thread cannot be started.
    pub fn open_file(path: impl AsRef<Path>, config: HostConfig) -> io::Result<Self> {
        Self::from_reader(File::open(path)?, config)
    }

    fn start(shared: Arc<Shared>, mut reader: impl io::Read + Send + 'static) -> io::Result<Self> {
        let thread_shared = shared.clone();
        spawn("pprz-host-rx", move || {
            rx_thread(&thread_shared, |buf| reader.read(buf));
        })?;
        Ok(Self { shared })
    }

    /// Counters of the device.
    pub fn stats(&self) -> HostStats {
        self.shared.lock().stats
    }
}

impl HostTx {
    /// Writes to `writer` on a background thread (a file, a pipe, stdout).
    ///
    /// # Errors
    /// If the thread cannot be started.
    pub fn from_writer(
        writer: impl io::Write + Send + 'static,
        config: HostConfig,
    ) -> io::Result<Self> {
        Self::start(Shared::new(config, false), writer, || {})
    }

    /// Creates (or truncates) the file at `path` and writes to it. `flush` returns once
    /// the bytes are handed to the operating system.
    ///
    /// # Errors
    /// If the file cannot be created or the thread cannot be started.
    pub fn create_file(path: impl AsRef<Path>, config: HostConfig) -> io::Result<Self> {
        Self::from_writer(File::create(path)?, config)
    }

    /// Opens (or creates) the file at `path` and appends to it.
    ///
    /// # Errors
    /// If the file cannot be opened or the thread cannot be started.
    pub fn append_file(path: impl AsRef<Path>, config: HostConfig) -> io::Result<Self> {
        let file = OpenOptions::new().create(true).append(true).open(path)?;
        Self::from_writer(file, config)
    }

    fn start(
        shared: Arc<Shared>,
        mut writer: impl io::Write + Send + 'static,
        on_end: impl FnOnce() + Send + 'static,
    ) -> io::Result<Self> {
        let thread_shared = shared.clone();
        spawn("pprz-host-tx", move || {
            let writer = std::cell::RefCell::new(&mut writer);
            tx_thread(
                &thread_shared,
                |buf| writer.borrow_mut().write(buf),
                || writer.borrow_mut().flush(),
            );
            on_end();
        })?;
        Ok(Self { shared })
    }

    /// Counters of the device.
    pub fn stats(&self) -> HostStats {
        self.shared.lock().stats
    }
}

impl HostDevice {
    /// Reads `reader` and writes `writer`, each on its own thread (a serial port and its
    /// clone, a child process's stdout and stdin, ...).
    ///
    /// # Errors
    /// If a thread cannot be started.
    pub fn from_stream(
        reader: impl io::Read + Send + 'static,
        writer: impl io::Write + Send + 'static,
        config: HostConfig,
    ) -> io::Result<Self> {
        let shared = Shared::new(config, false);
        let tx = HostTx::start(shared.clone(), writer, || {})?;
        let rx = HostRx::start(shared, reader)?;
        Ok(Self { rx, tx })
    }

    /// A TCP stream (Nagle's algorithm is turned off: frames are small and late frames
    /// are worse than small packets).
    ///
    /// # Errors
    /// If the stream cannot be cloned or configured, or a thread cannot be started.
    pub fn tcp(stream: TcpStream, config: HostConfig) -> io::Result<Self> {
        stream.set_nodelay(true)?;
        let shared = Shared::new(config, false);
        let on_close = stream.try_clone()?;
        *shared.on_rx_close.lock().unwrap_or_else(|e| e.into_inner()) =
            Some(Box::new(move || drop(on_close.shutdown(Shutdown::Read))));
        let writer = stream.try_clone()?;
        let on_end = stream.try_clone()?;
        let tx = HostTx::start(shared.clone(), writer, move || {
            drop(on_end.shutdown(Shutdown::Write));
        })?;
        let rx = HostRx::start(shared, stream)?;
        Ok(Self { rx, tx })
    }

    /// Connects a TCP stream to `addr`; see [`tcp`](Self::tcp).
    ///
    /// # Errors
    /// If the connection fails, or as [`tcp`](Self::tcp).
    pub fn tcp_connect(addr: impl ToSocketAddrs, config: HostConfig) -> io::Result<Self> {
        Self::tcp(TcpStream::connect(addr)?, config)
    }

    /// A UDP socket. If it is connected, it sends to and receives from its peer only;
    /// it must be connected (`UdpSocket::connect`) to send.
    ///
    /// # Errors
    /// If the socket cannot be cloned or configured, or a thread cannot be started.
    pub fn udp(socket: UdpSocket, config: HostConfig) -> io::Result<Self> {
        socket.set_read_timeout(Some(config.poll_interval.max(Duration::from_millis(1))))?;
        let shared = Shared::new(config, true);
        let sender = socket.try_clone()?;
        let tx_shared = shared.clone();
        spawn("pprz-host-udp-tx", move || {
            tx_thread(&tx_shared, |buf| sender.send(buf), || Ok(()));
        })?;
        let rx_shared = shared.clone();
        spawn("pprz-host-udp-rx", move || {
            rx_thread(&rx_shared, |buf| socket.recv(buf));
        })?;
        Ok(Self {
            rx: HostRx {
                shared: shared.clone(),
            },
            tx: HostTx { shared },
        })
    }

    /// Binds a UDP socket to `local` and connects it to `peer`; see [`udp`](Self::udp).
    ///
    /// # Errors
    /// If binding or connecting fails, or as [`udp`](Self::udp).
    pub fn udp_bind(
        local: impl ToSocketAddrs,
        peer: impl ToSocketAddrs,
        config: HostConfig,
    ) -> io::Result<Self> {
        let socket = UdpSocket::bind(local)?;
        socket.connect(peer)?;
        Self::udp(socket, config)
    }

    /// Opens the serial port at `path` (for example `/dev/ttyUSB0`) at `baud`, 8N1, no
    /// flow control; see [`serial_port`](Self::serial_port).
    ///
    /// # Errors
    /// If the port cannot be opened, or as [`serial_port`](Self::serial_port).
    #[cfg(feature = "serial")]
    pub fn serial(path: &str, baud: u32, config: HostConfig) -> io::Result<Self> {
        let port = serialport::new(path, baud)
            .timeout(config.poll_interval)
            .open()
            .map_err(io::Error::from)?;
        Self::serial_port(port, config)
    }

    /// An open serial port (its timeout is set to [`HostConfig::poll_interval`]). A
    /// write the port cannot take (flow control) waits, like a full UART.
    ///
    /// # Errors
    /// If the port cannot be cloned or configured, or a thread cannot be started.
    #[cfg(feature = "serial")]
    pub fn serial_port(
        mut port: Box<dyn serialport::SerialPort>,
        config: HostConfig,
    ) -> io::Result<Self> {
        port.set_timeout(config.poll_interval)
            .map_err(io::Error::from)?;
        let writer = port.try_clone().map_err(io::Error::from)?;
        Self::from_stream(port, writer, config)
    }

    /// The receiving and the sending half.
    pub fn split(self) -> (HostRx, HostTx) {
        (self.rx, self.tx)
    }

    /// Counters of the device.
    pub fn stats(&self) -> HostStats {
        self.rx.stats()
    }
}

impl Drop for HostRx {
    fn drop(&mut self) {
        let mut s = self.shared.lock();
        s.rx_closed = true;
        s.rx.clear();
        drop(s);
        self.shared.rx_room.notify_all();
        let hook = self
            .shared
            .on_rx_close
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        if let Some(hook) = hook {
            hook();
        }
    }
}

impl Drop for HostTx {
    fn drop(&mut self) {
        self.shared.lock().tx_closed = true;
        self.shared.tx_data.notify_all();
    }
}

impl ErrorType for HostRx {
    type Error = HostError;
}

impl ErrorType for HostTx {
    type Error = HostError;
}

impl ErrorType for HostDevice {
    type Error = HostError;
}

impl Read for HostRx {
    /// Waits until bytes are buffered, then returns as many as fit in `buf`. `Ok(0)`:
    /// end of input (stream closed by the peer, end of file).
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, HostError> {
        if buf.is_empty() {
            return Ok(0);
        }
        poll_fn(|cx| {
            let mut s = self.shared.lock();
            if !s.rx.is_empty() {
                let n = buf.len().min(s.rx.len());
                for (dst, src) in buf.iter_mut().zip(s.rx.drain(..n)) {
                    *dst = src;
                }
                drop(s);
                self.shared.rx_room.notify_all();
                return Poll::Ready(Ok(n));
            }
            match s.rx_end {
                Some(End::Eof) => Poll::Ready(Ok(0)),
                Some(End::Error(kind)) => Poll::Ready(Err(HostError::Io(kind))),
                None => {
                    register(&mut s.rx_waker, cx.waker());
                    Poll::Pending
                }
            }
        })
        .await
    }
}

impl HostTx {
    /// The sticky error, or `Closed` once the thread has ended; counts a refused call.
    fn refused(&self, s: &mut State) -> Option<HostError> {
        let error = match (s.tx_error, s.tx_ended) {
            (Some(kind), _) => HostError::Io(kind),
            (None, true) => HostError::Closed,
            (None, false) => return None,
        };
        s.stats.tx_errors += 1;
        Some(error)
    }
}

impl Write for HostTx {
    /// Copies bytes into the TX buffer, waiting only while it is full (UDP: one
    /// datagram of at most [`HostConfig::max_datagram`] bytes per call).
    async fn write(&mut self, buf: &[u8]) -> Result<usize, HostError> {
        if buf.is_empty() {
            return Ok(0);
        }
        let config = self.shared.config;
        poll_fn(|cx| {
            let mut s = self.shared.lock();
            if let Some(error) = self.refused(&mut s) {
                return Poll::Ready(Err(error));
            }
            let room = config.tx_buffer - s.tx.len();
            let n = if self.shared.datagrams {
                let n = buf.len().min(config.max_datagram);
                if room < n { 0 } else { n }
            } else {
                buf.len().min(room)
            };
            if n == 0 {
                register(&mut s.tx_waker, cx.waker());
                return Poll::Pending;
            }
            s.tx.extend(&buf[..n]);
            if self.shared.datagrams {
                s.tx_datagrams.push_back(n);
            }
            drop(s);
            self.shared.tx_data.notify_one();
            Poll::Ready(Ok(n))
        })
        .await
    }

    /// Waits until the TX thread has handed every written byte to the OS.
    async fn flush(&mut self) -> Result<(), HostError> {
        poll_fn(|cx| {
            let mut s = self.shared.lock();
            if s.tx.is_empty() && s.tx_in_flight == 0 && s.tx_error.is_none() {
                return Poll::Ready(Ok(()));
            }
            if let Some(error) = self.refused(&mut s) {
                return Poll::Ready(Err(error));
            }
            register(&mut s.tx_waker, cx.waker());
            Poll::Pending
        })
        .await
    }
}

impl Read for HostDevice {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, HostError> {
        self.rx.read(buf).await
    }
}

impl Write for HostDevice {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, HostError> {
        self.tx.write(buf).await
    }

    async fn flush(&mut self) -> Result<(), HostError> {
        self.tx.flush().await
    }
}
