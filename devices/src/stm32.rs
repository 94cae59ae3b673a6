//! embassy-stm32 UARTs as telemetry/datalink devices (feature `stm32`; the firmware
//! selects its chip with an `embassy-stm32/stm32...` feature, or uses this crate's
//! `stm32f405` feature).
//!
//! # What embassy-stm32 0.6 already provides
//!
//! Its UART drivers implement embedded-io-async 0.7 themselves, so they *are* devices
//! of this stack and need no adapter:
//!
//! | driver | `Read` | `Write` | notes |
//! |---|---|---|---|
//! | `usart::BufferedUart` and its halves `BufferedUartRx` / `BufferedUartTx` | yes | yes | interrupt driven, RAM ring buffers of your size |
//! | `usart::Uart<'_, Async>` / `UartTx<'_, Async>` | no | yes | DMA transmit |
//! | `usart::RingBufferedUartRx` (from `UartRx::into_ring_buffered`) | yes | no | DMA receive into a circular buffer |
//!
//! Plain `UartRx<'_, Async>` does not implement `Read`: with DMA, receive through
//! `into_ring_buffered`.
//!
//! What this module adds is [`UartRx`]: on a radio link noise, framing and parity
//! errors are normal (the frame checksums catch the damage) and an overrun only means
//! lost bytes, yet embassy returns each as a read error, and `RingBufferedUartRx` even
//! stops its DMA on one. A datalink reader that sees a read error pauses before reading
//! again, losing more bytes. [`UartRx`] counts each kind of line error in
//! [`UartErrorCounters`] and reads on at once (restarting the DMA), so only a
//! configuration error ([`Error::BufferTooLong`]) reaches the caller. Wrap the transmit
//! half in [`Counted`](crate::Counted) to count bytes and write errors too.
//!
//! # Construction on an STM32F405 board (radio on USART1: PB6 TX, PB7 RX, 57600 baud)
//!
//! These are the bodies of [`f405::usart1_buffered`] and [`f405::usart1_dma`]
//! (feature `stm32f405`), which CI compiles for `thumbv7em-none-eabihf`.
//!
//! Interrupt driven, buffered (simplest; one interrupt per byte):
//!
//! ```ignore
//! use embassy_stm32::{bind_interrupts, peripherals, usart};
//! use pprz_devices::stm32::{UartErrorCounters, UartRx};
//! use static_cell::StaticCell;
//!
//! bind_interrupts!(struct Irqs {
//!     USART1 => usart::BufferedInterruptHandler<peripherals::USART1>;
//! });
//! static RADIO_ERRORS: UartErrorCounters = UartErrorCounters::new();
//! static BUFFERS: StaticCell<([u8; 512], [u8; 256])> = StaticCell::new();
//!
//! let p = embassy_stm32::init(Default::default());
//! let (tx_buf, rx_buf) = BUFFERS.init(([0; 512], [0; 256]));
//! let mut config = usart::Config::default();
//! config.baudrate = 57_600;
//! let uart = usart::BufferedUart::new(p.USART1, p.PB7, p.PB6, tx_buf, rx_buf, Irqs, config)?;
//! let (tx, rx) = uart.split();
//! let rx = UartRx::new(rx, &RADIO_ERRORS);
//! // `tx` goes to the downlink writer task, `rx` to the datalink Reader task.
//! ```
//!
//! DMA (no per-byte interrupt; USART1 uses DMA2 stream 7 for TX and stream 2 for RX on
//! the F405):
//!
//! ```ignore
//! bind_interrupts!(struct Irqs {
//!     USART1 => usart::InterruptHandler<peripherals::USART1>;
//!     DMA2_STREAM7 => embassy_stm32::dma::InterruptHandler<peripherals::DMA2_CH7>;
//!     DMA2_STREAM2 => embassy_stm32::dma::InterruptHandler<peripherals::DMA2_CH2>;
//! });
//! static RING: StaticCell<[u8; 256]> = StaticCell::new();
//!
//! let uart = usart::Uart::new(p.USART1, p.PB7, p.PB6, p.DMA2_CH7, p.DMA2_CH2, Irqs, config)?;
//! let (tx, rx) = uart.split();
//! let rx = UartRx::new(rx.into_ring_buffered(RING.init([0; 256])), &RADIO_ERRORS);
//! ```
//!
//! (PB6/PB7 leave PA9 free: a self-powered board senses USB VBUS on PA9, see
//! [`f405::usb_otg_fs`].)
//!
//! Size the buffers for the worst pause of the reading task: at 57600 baud 5.76 bytes
//! arrive per millisecond, so a 256-byte ring covers 44 ms. The TX buffer only needs to
//! hold a frame or two: the downlink queue is the real buffer, and it sheds by priority.
//!
//! With hardware flow control (a modem that raises CTS when its buffer fills), build the
//! UART with `usart::BufferedUart::new_with_rtscts(peri, rx, tx, rts, cts, ...)` instead;
//! USART1's RTS/CTS pins on the F405 are the USB lines PA12/PA11, so the board examples
//! put the radio on USART2 (PA2 TX, PA3 RX, PA1 RTS, PA0 CTS; see their READMEs). Without
//! flow control, configure the downlink device's `Pacing` so frames wait in the priority
//! queue rather than in the modem.

use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

pub use embassy_stm32::usart::Error;
use embedded_io_async::{ErrorType, Read};

use crate::counted::read_on_errors;
use crate::{bump, len_u32};

/// Counters of UART receive errors; `const fn new`, so they can be a `static` any
/// task reads (only the [`UartRx`] updates them).
#[derive(Debug, Default)]
pub struct UartErrorCounters {
    bytes: AtomicU32,
    framing: AtomicU32,
    noise: AtomicU32,
    overrun: AtomicU32,
    parity: AtomicU32,
}

/// A copy of [`UartErrorCounters`]. All counters wrap around.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UartErrorStats {
    /// Bytes received.
    pub bytes: u32,
    /// Framing errors (bad stop bit: wrong baud rate or noise).
    pub framing: u32,
    /// Noise detected on the line.
    pub noise: u32,
    /// Overruns: bytes lost because the buffer or DMA ring was full.
    pub overrun: u32,
    /// Parity errors.
    pub parity: u32,
}

impl UartErrorCounters {
    /// Zero counters.
    pub const fn new() -> Self {
        Self {
            bytes: AtomicU32::new(0),
            framing: AtomicU32::new(0),
            noise: AtomicU32::new(0),
            overrun: AtomicU32::new(0),
            parity: AtomicU32::new(0),
        }
    }

    /// The current values.
    pub fn snapshot(&self) -> UartErrorStats {
        UartErrorStats {
            bytes: self.bytes.load(Relaxed),
            framing: self.framing.load(Relaxed),
            noise: self.noise.load(Relaxed),
            overrun: self.overrun.load(Relaxed),
            parity: self.parity.load(Relaxed),
        }
    }
}

/// A UART receiver that counts line errors and reads on; see the [module docs](self).
pub struct UartRx<'c, R> {
    inner: R,
    counters: &'c UartErrorCounters,
}

impl<'c, R: Read<Error = Error>> UartRx<'c, R> {
    /// Wraps `BufferedUartRx`, `RingBufferedUartRx`, or any reader with embassy-stm32's
    /// UART error type.
    pub const fn new(inner: R, counters: &'c UartErrorCounters) -> Self {
        Self { inner, counters }
    }

    /// The counters.
    pub fn counters(&self) -> &'c UartErrorCounters {
        self.counters
    }

    /// The wrapped receiver.
    pub fn into_inner(self) -> R {
        self.inner
    }
}

impl<R: ErrorType<Error = Error>> ErrorType for UartRx<'_, R> {
    type Error = Error;
}

impl<R: Read<Error = Error>> Read for UartRx<'_, R> {
    /// Reads like the wrapped receiver; line errors are counted and reading goes on.
    ///
    /// # Errors
    /// Only [`Error::BufferTooLong`] (a DMA buffer too long for the controller).
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
        let c = self.counters;
        let n = read_on_errors(&mut self.inner, buf, |e| match e {
            Error::Framing => Some(&c.framing),
            Error::Noise => Some(&c.noise),
            Error::Overrun => Some(&c.overrun),
            Error::Parity => Some(&c.parity),
            _ => None,
        })
        .await?;
        bump(&c.bytes, len_u32(n));
        Ok(n)
    }
}

/// Compile-checked construction of the STM32F405 board wiring documented in the
/// [module docs](self) (feature `stm32f405`).
#[cfg(feature = "stm32f405")]
pub mod f405 {
    use embassy_stm32::Peri;
    use embassy_stm32::interrupt::typelevel::{
        Binding, DMA2_STREAM2, DMA2_STREAM7, OTG_FS, USART1,
    };
    use embassy_stm32::mode::Async;
    use embassy_stm32::usart::{
        self, BufferedInterruptHandler, BufferedUart, ConfigError, RingBufferedUartRx, Uart, UartTx,
    };
    use embassy_stm32::{peripherals, usb};

    /// The USB OTG FS device driver on PA11 (DM) / PA12 (DP), for embassy-usb (and the
    /// CDC-ACM adapter of feature `usb`). A self-powered board (an autopilot on its own
    /// battery) must sense VBUS, wired to PA9: `vbus_detection = true`; a bus-powered
    /// one may pass `false`. Needs a 48 MHz USB clock in the RCC configuration and the
    /// binding `OTG_FS => usb::InterruptHandler<peripherals::USB_OTG_FS>`.
    pub fn usb_otg_fs<'d>(
        otg: Peri<'d, peripherals::USB_OTG_FS>,
        irqs: impl Binding<OTG_FS, usb::InterruptHandler<peripherals::USB_OTG_FS>> + 'd,
        dp: Peri<'d, peripherals::PA12>,
        dm: Peri<'d, peripherals::PA11>,
        ep_out_buffer: &'d mut [u8],
        vbus_detection: bool,
    ) -> usb::Driver<'d, peripherals::USB_OTG_FS> {
        let mut config = usb::Config::default();
        config.vbus_detection = vbus_detection;
        usb::Driver::new_fs(otg, irqs, dp, dm, ep_out_buffer, config)
    }

    fn config(baudrate: u32) -> usart::Config {
        let mut config = usart::Config::default();
        config.baudrate = baudrate;
        config
    }

    /// USART1 on PB7 (RX) / PB6 (TX), 8N1 at `baudrate`, interrupt driven with the
    /// given RAM buffers. Split the result into its `Read` and `Write` halves.
    ///
    /// # Errors
    /// If the baud rate cannot be reached from the peripheral clock.
    pub fn usart1_buffered<'d>(
        usart1: Peri<'d, peripherals::USART1>,
        rx: Peri<'d, peripherals::PB7>,
        tx: Peri<'d, peripherals::PB6>,
        irqs: impl Binding<USART1, BufferedInterruptHandler<peripherals::USART1>> + 'd,
        tx_buffer: &'d mut [u8],
        rx_buffer: &'d mut [u8],
        baudrate: u32,
    ) -> Result<BufferedUart<'d>, ConfigError> {
        BufferedUart::new(usart1, rx, tx, tx_buffer, rx_buffer, irqs, config(baudrate))
    }

    /// USART1 on PB7 (RX) / PB6 (TX), 8N1 at `baudrate`, with DMA2 stream 7 (TX) and
    /// stream 2 (RX) receiving into the circular `rx_ring`.
    ///
    /// # Errors
    /// If the baud rate cannot be reached from the peripheral clock.
    // One argument per peripheral, as embassy's own constructor.
    #[allow(clippy::too_many_arguments)]
    pub fn usart1_dma<'d>(
        usart1: Peri<'d, peripherals::USART1>,
        rx: Peri<'d, peripherals::PB7>,
        tx: Peri<'d, peripherals::PB6>,
        tx_dma: Peri<'d, peripherals::DMA2_CH7>,
        rx_dma: Peri<'d, peripherals::DMA2_CH2>,
        irqs: impl Binding<USART1, usart::InterruptHandler<peripherals::USART1>>
        + Binding<DMA2_STREAM7, embassy_stm32::dma::InterruptHandler<peripherals::DMA2_CH7>>
        + Binding<DMA2_STREAM2, embassy_stm32::dma::InterruptHandler<peripherals::DMA2_CH2>>
        + 'd,
        rx_ring: &'d mut [u8],
        baudrate: u32,
    ) -> Result<(UartTx<'d, Async>, RingBufferedUartRx<'d>), ConfigError> {
        let uart = Uart::new(usart1, rx, tx, tx_dma, rx_dma, irqs, config(baudrate))?;
        let (tx, rx) = uart.split();
        Ok((tx, rx.into_ring_buffered(rx_ring)))
    }
}
