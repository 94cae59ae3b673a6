//! embassy-usb CDC-ACM as a telemetry/datalink device (feature `usb`).
//!
//! embassy-usb's `cdc_acm::Sender` writes one packet per `write` and waits for the
//! host as long as it takes; a telemetry writer needs more:
//!
//! * **Packetisation**: [`UsbTx::write`] sends the whole buffer as max-packet-size
//!   packets (a frame of up to 263 bytes is at most 5 packets at 64 bytes).
//! * **Zero-length packets**: a USB bulk transfer ends with a packet shorter than the
//!   max packet size. When a write ends exactly on a packet boundary, [`UsbTx`] sends a
//!   zero-length packet (ZLP) after it, so the host's read completes now instead of
//!   when the next frame arrives (counted in [`UsbStats::zlps`]).
//! * **No host, no wait**: when the host has not configured the device (cable
//!   unplugged, not enumerated) or has not opened the port (DTR low, checked when
//!   [`UsbConfig::require_dtr`] is set), a write fails at once with
//!   [`UsbError::NotConnected`]; when the host stops reading, a packet that is not
//!   taken within [`UsbConfig::write_timeout`] fails with [`UsbError::Timeout`]. Both
//!   are counted. The downlink writer counts the frame as a write error and goes on
//!   with the next one, so its queue keeps shedding by priority instead of stalling
//!   behind a closed port.
//! * **Reading**: [`UsbRx`] keeps a packet buffer (any `read` length works, as
//!   `embedded_io_async::Read` requires), skips zero-length packets, and while the
//!   device is not configured waits for the host instead of failing (a read error
//!   loop would only spin), counting each disconnection.
//!
//! The logic is written against two small traits, [`PacketSender`] and
//! [`PacketReceiver`], implemented for embassy-usb's CDC-ACM halves, so it is tested
//! on the host with a fake endpoint.
//!
//! # Construction on a board (STM32F405, USB OTG FS on PA11/PA12)
//!
//! The driver comes from `pprz_devices::stm32::f405::usb_otg_fs` (features `stm32f405`
//! and `usb`, compiled by CI), whose body is the embassy-stm32 call:
//!
//! ```ignore
//! use embassy_stm32::{bind_interrupts, peripherals, usb};
//! use pprz_devices::usb::{CdcPort, UsbConfig, UsbCounters};
//! use static_cell::{ConstStaticCell, StaticCell};
//!
//! bind_interrupts!(struct Irqs { OTG_FS => usb::InterruptHandler<peripherals::USB_OTG_FS>; });
//! static USB_COUNTERS: UsbCounters = UsbCounters::new();
//! static EP_OUT: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
//! static PORT: StaticCell<CdcPort> = StaticCell::new();
//!
//! // In main, with `p = embassy_stm32::init(config)` and a 48 MHz USB clock:
//! let mut usb_config = usb::Config::default();
//! usb_config.vbus_detection = true; // self-powered board: VBUS sensed on PA9
//! let driver = usb::Driver::new_fs(p.USB_OTG_FS, Irqs, p.PA12, p.PA11,
//!                                  EP_OUT.take(), usb_config);
//! let mut config = embassy_usb::Config::new(0x1209, 0x0001);
//! config.product = Some("Paparazzi telemetry");
//! let (usb, uplink, downlink) =
//!     pprz_devices::usb::cdc_acm(driver, config, PORT.init(CdcPort::new()), &USB_COUNTERS, UsbConfig::default());
//! spawner.spawn(usb_task(usb)?); // async fn usb_task(mut usb: UsbDevice<'static, Driver<..>>) { usb.run().await }
//! // `downlink` goes to a downlink writer task, `uplink` to a datalink Reader.
//! ```

use core::fmt;
use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

use embassy_time::{Duration, Instant, with_deadline};
use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State};
use embassy_usb::driver::{Driver, EndpointError};
use embassy_usb::{Builder, Config, UsbDevice};
use embedded_io_async::{ErrorKind, ErrorType, Read, Write};

use crate::{bump, len_u32};

/// The IN (device to host) side of a CDC-ACM interface, one packet at a time.
///
/// Implemented for embassy-usb's [`Sender`]; implement it for a test double.
#[allow(async_fn_in_trait)]
pub trait PacketSender {
    /// Largest packet of the endpoint.
    fn max_packet_size(&self) -> u16;
    /// Whether the host holds DTR (has the port open).
    fn dtr(&self) -> bool;
    /// Sends one packet (empty: a zero-length packet). `Disabled` while the host has
    /// not configured the device.
    async fn write_packet(&mut self, data: &[u8]) -> Result<(), EndpointError>;
}

/// The OUT (host to device) side of a CDC-ACM interface, one packet at a time.
///
/// Implemented for embassy-usb's [`Receiver`]; implement it for a test double.
#[allow(async_fn_in_trait)]
pub trait PacketReceiver {
    /// Largest packet of the endpoint.
    fn max_packet_size(&self) -> u16;
    /// Receives one packet into `data` (at least max-packet-size bytes long).
    async fn read_packet(&mut self, data: &mut [u8]) -> Result<usize, EndpointError>;
    /// Waits until the host has configured the device.
    async fn wait_connection(&mut self);
}

impl<'d, D: Driver<'d>> PacketSender for Sender<'d, D> {
    fn max_packet_size(&self) -> u16 {
        Sender::max_packet_size(self)
    }

    fn dtr(&self) -> bool {
        Sender::dtr(self)
    }

    async fn write_packet(&mut self, data: &[u8]) -> Result<(), EndpointError> {
        Sender::write_packet(self, data).await
    }
}

impl<'d, D: Driver<'d>> PacketReceiver for Receiver<'d, D> {
    fn max_packet_size(&self) -> u16 {
        Receiver::max_packet_size(self)
    }

    async fn read_packet(&mut self, data: &mut [u8]) -> Result<usize, EndpointError> {
        Receiver::read_packet(self, data).await
    }

    async fn wait_connection(&mut self) {
        Receiver::wait_connection(self).await;
    }
}

/// Behaviour of a [`UsbTx`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UsbConfig {
    /// Longest wait for the host to take one packet; `None`: wait forever.
    pub write_timeout: Option<Duration>,
    /// Refuse writes while the host does not hold DTR (no program has the port open).
    /// Turn off for host software that never sets DTR.
    pub require_dtr: bool,
}

impl Default for UsbConfig {
    /// 50 ms per packet (the host polls bulk endpoints every millisecond when it reads),
    /// DTR required.
    fn default() -> Self {
        Self {
            write_timeout: Some(Duration::from_millis(50)),
            require_dtr: true,
        }
    }
}

/// Why a USB write failed (or a [`UsbRx`] could not be made).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum UsbError {
    /// The host has not configured the device, or (with
    /// [`UsbConfig::require_dtr`]) has not opened the port. Nothing was sent.
    NotConnected,
    /// The host did not take a packet within [`UsbConfig::write_timeout`].
    Timeout,
    /// The [`UsbRx`] packet buffer is smaller than the endpoint's max packet size.
    BufferTooSmall,
}

impl fmt::Display for UsbError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NotConnected => "USB host not connected",
            Self::Timeout => "USB host did not take the packet in time",
            Self::BufferTooSmall => "USB packet buffer smaller than the max packet size",
        })
    }
}

impl core::error::Error for UsbError {}

impl embedded_io_async::Error for UsbError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::NotConnected => ErrorKind::NotConnected,
            Self::Timeout => ErrorKind::TimedOut,
            Self::BufferTooSmall => ErrorKind::InvalidInput,
        }
    }
}

/// Shared counters of a USB device (both halves); `const fn new`, so they can be a
/// `static` any task reads. Each half updates its own counters only.
#[derive(Debug, Default)]
pub struct UsbCounters {
    bytes_written: AtomicU32,
    packets: AtomicU32,
    zlps: AtomicU32,
    not_connected: AtomicU32,
    timeouts: AtomicU32,
    bytes_read: AtomicU32,
    disconnects: AtomicU32,
}

/// A copy of [`UsbCounters`]. All counters wrap around.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UsbStats {
    /// Bytes the host took.
    pub bytes_written: u32,
    /// Non-empty packets sent.
    pub packets: u32,
    /// Zero-length packets sent.
    pub zlps: u32,
    /// Writes refused or cut short because the host was not connected.
    pub not_connected: u32,
    /// Packets the host did not take in time.
    pub timeouts: u32,
    /// Bytes received.
    pub bytes_read: u32,
    /// Times a read found the device not configured (and waited for the host).
    pub disconnects: u32,
}

impl UsbCounters {
    /// Zero counters.
    pub const fn new() -> Self {
        Self {
            bytes_written: AtomicU32::new(0),
            packets: AtomicU32::new(0),
            zlps: AtomicU32::new(0),
            not_connected: AtomicU32::new(0),
            timeouts: AtomicU32::new(0),
            bytes_read: AtomicU32::new(0),
            disconnects: AtomicU32::new(0),
        }
    }

    /// The current values.
    pub fn snapshot(&self) -> UsbStats {
        UsbStats {
            bytes_written: self.bytes_written.load(Relaxed),
            packets: self.packets.load(Relaxed),
            zlps: self.zlps.load(Relaxed),
            not_connected: self.not_connected.load(Relaxed),
            timeouts: self.timeouts.load(Relaxed),
            bytes_read: self.bytes_read.load(Relaxed),
            disconnects: self.disconnects.load(Relaxed),
        }
    }
}

/// The reading half over embassy-usb's CDC-ACM [`Receiver`].
pub type CdcRx<'c, 'd, D, const N: usize = 64> = UsbRx<'c, Receiver<'d, D>, N>;

/// The writing half over embassy-usb's CDC-ACM [`Sender`].
pub type CdcTx<'c, 'd, D> = UsbTx<'c, Sender<'d, D>>;

/// Splits an embassy-usb CDC-ACM class into a datalink reader half and a telemetry
/// writer half. `N` is the receive packet buffer (64 for a full-speed device).
///
/// # Errors
/// [`UsbError::BufferTooSmall`] if `N` is below the class's max packet size.
pub fn split<'d, 'c, D: Driver<'d>, const N: usize>(
    class: CdcAcmClass<'d, D>,
    counters: &'c UsbCounters,
    config: UsbConfig,
) -> Result<(CdcRx<'c, 'd, D, N>, CdcTx<'c, 'd, D>), UsbError> {
    let (sender, receiver) = class.split();
    Ok((
        UsbRx::new(receiver, counters)?,
        UsbTx::new(sender, counters, config),
    ))
}

/// Packet size of the CDC-ACM interface [`cdc_acm`] builds: the largest bulk packet of a
/// full-speed device, and [`CdcRx`]'s default buffer.
pub const FULL_SPEED_PACKET: u16 = 64;

/// What the USB stack borrows from a [`cdc_acm`] port for as long as the device runs:
/// the configuration and BOS descriptor buffers (256 bytes each), the control transfer
/// buffer (64 bytes) and embassy-usb's CDC-ACM class state. Keep it in a `static`
/// (`static_cell::StaticCell`: the class state is not `Send`, so `ConstStaticCell` does
/// not take it).
pub struct CdcPort<'d> {
    config_descriptor: [u8; 256],
    bos_descriptor: [u8; 256],
    control: [u8; 64],
    state: State<'d>,
}

impl CdcPort<'_> {
    /// Zeroed buffers and a new class state.
    pub const fn new() -> Self {
        Self {
            config_descriptor: [0; 256],
            bos_descriptor: [0; 256],
            control: [0; 64],
            state: State::new(),
        }
    }
}

impl Default for CdcPort<'_> {
    fn default() -> Self {
        Self::new()
    }
}

/// A USB device with one CDC-ACM interface (full speed, [`FULL_SPEED_PACKET`]-byte
/// packets) on `driver`, named by `config` (vendor and product ids, strings), split as
/// [`split`] does. Returns the device, which a task must run (`UsbDevice::run`), the
/// reading half for a datalink reader and the writing half for a downlink writer; both
/// count into `counters` and write as `usb` says.
pub fn cdc_acm<'d, 'c, D: Driver<'d>>(
    driver: D,
    config: Config<'d>,
    port: &'d mut CdcPort<'d>,
    counters: &'c UsbCounters,
    usb: UsbConfig,
) -> (UsbDevice<'d, D>, CdcRx<'c, 'd, D>, CdcTx<'c, 'd, D>) {
    let CdcPort {
        config_descriptor,
        bos_descriptor,
        control,
        state,
    } = port;
    let mut builder = Builder::new(
        driver,
        config,
        config_descriptor,
        bos_descriptor,
        &mut [],
        control,
    );
    let class = CdcAcmClass::new(&mut builder, state, FULL_SPEED_PACKET);
    let device = builder.build();
    let (sender, receiver) = class.split();
    // The class's packet size is the buffer's size: the check in `UsbRx::new` cannot fail.
    let rx = UsbRx::unchecked(receiver, counters);
    (device, rx, UsbTx::new(sender, counters, usb))
}

/// The writing half: packetisation, zero-length packets, fail-fast; see the
/// [module docs](self).
pub struct UsbTx<'c, S> {
    sender: S,
    counters: &'c UsbCounters,
    config: UsbConfig,
}

impl<'c, S: PacketSender> UsbTx<'c, S> {
    /// Wraps a packet sender.
    pub const fn new(sender: S, counters: &'c UsbCounters, config: UsbConfig) -> Self {
        Self {
            sender,
            counters,
            config,
        }
    }

    /// The counters.
    pub fn counters(&self) -> &'c UsbCounters {
        self.counters
    }

    /// The packet sender.
    pub fn inner(&self) -> &S {
        &self.sender
    }

    /// Whether a write would be attempted now (configured check aside: that one is
    /// known only when a packet is sent).
    pub fn host_ready(&self) -> bool {
        !self.config.require_dtr || self.sender.dtr()
    }

    async fn send(&mut self, packet: &[u8]) -> Result<(), UsbError> {
        let result = match self.config.write_timeout {
            Some(timeout) => {
                // Saturating: a timeout too long to add to the clock never expires.
                let at = Instant::now().saturating_add(timeout);
                with_deadline(at, self.sender.write_packet(packet))
                    .await
                    .map_err(|_| UsbError::Timeout)
            }
            None => Ok(self.sender.write_packet(packet).await),
        };
        match result {
            Ok(Ok(())) => {
                if packet.is_empty() {
                    bump(&self.counters.zlps, 1);
                } else {
                    bump(&self.counters.packets, 1);
                    bump(&self.counters.bytes_written, len_u32(packet.len()));
                }
                Ok(())
            }
            // BufferOverflow cannot happen (packets are at most max-packet-size long);
            // treat it like a disabled endpoint rather than panic.
            Ok(Err(EndpointError::Disabled | EndpointError::BufferOverflow)) => {
                bump(&self.counters.not_connected, 1);
                Err(UsbError::NotConnected)
            }
            Err(e) => {
                bump(&self.counters.timeouts, 1);
                Err(e)
            }
        }
    }
}

impl<S> ErrorType for UsbTx<'_, S> {
    type Error = UsbError;
}

impl<S: PacketSender> Write for UsbTx<'_, S> {
    /// Sends all of `buf` as max-packet-size packets, then a zero-length packet if the
    /// last one was full. Fails at once, sending nothing, when the host is not there.
    /// If the host goes away in the middle, returns the bytes sent so far (the next
    /// call reports the error).
    async fn write(&mut self, buf: &[u8]) -> Result<usize, UsbError> {
        if buf.is_empty() {
            return Ok(0);
        }
        if !self.host_ready() {
            bump(&self.counters.not_connected, 1);
            return Err(UsbError::NotConnected);
        }
        let mps = usize::from(self.sender.max_packet_size().max(1));
        let mut sent = 0;
        for packet in buf.chunks(mps) {
            match self.send(packet).await {
                Ok(()) => sent += packet.len(),
                Err(e) if sent == 0 => return Err(e),
                Err(_) => return Ok(sent),
            }
        }
        if buf.len().is_multiple_of(mps) {
            // The data went out; a failed ZLP only delays the host's read and is
            // counted, the next write reports a lasting problem.
            let _ = self.send(&[]).await;
        }
        Ok(sent)
    }

    /// Nothing to do: `write` hands every packet to the USB peripheral.
    async fn flush(&mut self) -> Result<(), UsbError> {
        Ok(())
    }
}

/// The reading half: any read length, zero-length packets skipped, waits for the
/// host while it is away; see the [module docs](self).
pub struct UsbRx<'c, R, const N: usize = 64> {
    receiver: R,
    counters: &'c UsbCounters,
    /// Invariant: `start <= end <= N`; `buf[start..end]` is not read yet.
    buf: [u8; N],
    start: usize,
    end: usize,
}

impl<'c, R: PacketReceiver, const N: usize> UsbRx<'c, R, N> {
    /// Wraps a packet receiver.
    ///
    /// # Errors
    /// [`UsbError::BufferTooSmall`] if `N` is below the endpoint's max packet size.
    pub fn new(receiver: R, counters: &'c UsbCounters) -> Result<Self, UsbError> {
        if usize::from(receiver.max_packet_size()) > N {
            return Err(UsbError::BufferTooSmall);
        }
        Ok(Self::unchecked(receiver, counters))
    }

    /// [`new`](Self::new) for a receiver whose max packet size is known to fit `N`.
    fn unchecked(receiver: R, counters: &'c UsbCounters) -> Self {
        Self {
            receiver,
            counters,
            buf: [0; N],
            start: 0,
            end: 0,
        }
    }

    /// The counters.
    pub fn counters(&self) -> &'c UsbCounters {
        self.counters
    }
}

impl<R, const N: usize> ErrorType for UsbRx<'_, R, N> {
    type Error = UsbError;
}

impl<R: PacketReceiver, const N: usize> Read for UsbRx<'_, R, N> {
    /// Returns buffered bytes, or waits for the next non-empty packet (and, while the
    /// host has not configured the device, for the host). Never fails.
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, UsbError> {
        if buf.is_empty() {
            return Ok(0);
        }
        while self.start == self.end {
            match self.receiver.read_packet(&mut self.buf).await {
                Ok(n) => {
                    self.start = 0;
                    self.end = n.min(N);
                    bump(&self.counters.bytes_read, len_u32(self.end));
                }
                Err(_) => {
                    bump(&self.counters.disconnects, 1);
                    self.receiver.wait_connection().await;
                }
            }
        }
        let n = buf.len().min(self.end - self.start);
        buf[..n].copy_from_slice(&self.buf[self.start..self.start + n]);
        self.start += n;
        Ok(n)
    }
}
