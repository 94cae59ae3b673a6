//! An interrupt-driven async driver for the nRF51's UART0 (modelled by QEMU's
//! `nrf51_soc.uart`), implementing `embedded_io_async`'s `Read` and `Write`.
//!
//! The UART sends one byte at a time and receives into a small FIFO (6 bytes in QEMU's
//! model). Both directions go through ring buffers (embassy-sync `Pipe`s) that the
//! interrupt handler fills and drains:
//!
//! ```text
//!   UartTx::write --> tx pipe --(pump: when the last byte left)--> TXD --> line
//!   line --> RXD --(RXDRDY interrupt, or after a read)--> rx pipe --> UartRx::read
//! ```
//!
//! * RX: while `EVENTS_RXDRDY` is set, the handler clears it, *then* reads `RXD` (a read
//!   that leaves bytes in the FIFO sets the event again; the other order would strand
//!   them) and moves the byte into the RX pipe, waking the reader. When the pipe is full
//!   the RXDRDY interrupt is disabled and the bytes stay in the FIFO (the interrupt is
//!   level-triggered: left enabled, it would fire forever); the reader drains them and
//!   enables it again after its next read. QEMU holds back further input while the FIFO
//!   is full, so nothing is lost; real hardware would overrun instead (the ERROR event,
//!   which the handler clears).
//! * TX: a write copies into the TX pipe and starts the pump, which writes the next byte
//!   to `TXD` when the previous one has left (`EVENTS_TXDRDY`; a software flag says a
//!   byte is on its way). Each TXDRDY interrupt pumps the next byte. `flush` waits until
//!   the pipe is empty and the last byte left. QEMU sets TXDRDY without raising the
//!   interrupt when its serial backend was full for a while; the board therefore also
//!   calls [`Instance::poll`] from its idle loop, which finds the event set.
//!
//! The pump and the RX drain run in critical sections (the handler's, or a task's), so the
//! tasks and the handler never race on the registers. Nothing here needs an atomic
//! read-modify-write: the state is plain cells in critical sections.

use core::cell::Cell;
use core::convert::Infallible;
use core::future::poll_fn;
use core::task::Poll;

use critical_section::{CriticalSection, Mutex};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::waitqueue::AtomicWaker;

/// The nRF51 UART registers used here (offsets from the block's base; all 32 bits wide).
#[derive(Debug, Clone, Copy)]
#[repr(usize)]
enum Reg {
    /// Write 1: start the receiver.
    TasksStartRx = 0x000,
    /// Write 1: start the transmitter.
    TasksStartTx = 0x008,
    /// A byte is in RXD (1); write 0 to clear.
    EventsRxdRdy = 0x108,
    /// The byte written to TXD has left (1); write 0 to clear.
    EventsTxdRdy = 0x11C,
    /// An error was detected (overrun, framing...); write 0 to clear.
    EventsError = 0x124,
    /// Write 1s: enable those interrupts.
    IntenSet = 0x304,
    /// Write 1s: disable those interrupts.
    IntenClr = 0x308,
    /// The error source bits; write 1s to clear them.
    ErrorSrc = 0x480,
    /// 4: enabled, 0: disabled.
    Enable = 0x500,
    /// The TXD pin number.
    PselTxd = 0x50C,
    /// The RXD pin number.
    PselRxd = 0x514,
    /// Read: the received byte (pops the FIFO).
    Rxd = 0x518,
    /// Write: the byte to send.
    Txd = 0x51C,
    /// The baud rate (fixed codes from the reference manual).
    BaudRate = 0x524,
    /// Bit 0 hardware flow control, bits 1-3 parity: 0 is 8N1 without flow control.
    Config = 0x56C,
}

const INT_RXDRDY: u32 = 1 << 2;
const INT_TXDRDY: u32 = 1 << 7;
const ENABLE: u32 = 4;

/// A baud rate, as the nRF51 UART's `BAUDRATE` register codes it (a table in the
/// reference manual, not a divider).
#[derive(Debug, Clone, Copy)]
pub struct Baud(u32);

impl Baud {
    /// 115200 baud.
    pub const B115200: Self = Self(0x01D7_E000);
}

/// An nRF51 UART register block.
///
/// Invariant: `base` is the address of an nRF51 UART's register block, mapped for the
/// whole program (so every [`Reg`] offset from it is a valid, aligned device register).
#[derive(Debug, Clone, Copy)]
struct Regs {
    base: usize,
}

impl Regs {
    fn read(self, reg: Reg) -> u32 {
        // Safety: by the invariant of `Regs`, `base + reg` is an aligned, mapped 32-bit
        // device register; a volatile read of it has no effect on Rust-visible memory.
        unsafe { core::ptr::read_volatile((self.base + reg as usize) as *const u32) }
    }

    fn write(self, reg: Reg, value: u32) {
        // Safety: by the invariant of `Regs`, `base + reg` is an aligned, mapped 32-bit
        // device register; a volatile write to it has no effect on Rust-visible memory.
        unsafe { core::ptr::write_volatile((self.base + reg as usize) as *mut u32, value) }
    }
}

/// The driver's flags, read and written in critical sections only.
struct Flags {
    /// A byte was written to TXD and its TXDRDY event not handled yet.
    tx_busy: Cell<bool>,
    /// The RXDRDY interrupt is off because the RX pipe was full.
    rx_paused: Cell<bool>,
    /// The halves were handed out.
    taken: Cell<bool>,
}

/// Everything about one UART: its registers and the buffers and wakers the interrupt
/// handler shares with the tasks. Meant to be a `static`; `RX` and `TX` are the ring
/// buffer sizes in bytes.
///
/// The board calls [`Instance::on_interrupt`] from the UART's interrupt and enables it
/// in the NVIC after [`Instance::take`].
pub struct Instance<const RX: usize, const TX: usize> {
    regs: Regs,
    rx: Pipe<CriticalSectionRawMutex, RX>,
    tx: Pipe<CriticalSectionRawMutex, TX>,
    /// Woken when the TX pipe is empty and the UART has sent its last byte.
    tx_idle: AtomicWaker,
    flags: Mutex<Flags>,
}

impl<const RX: usize, const TX: usize> Instance<RX, TX> {
    /// The UART whose registers are at `base`.
    ///
    /// # Safety
    ///
    /// * `base` is the address of an nRF51 UART register block, mapped for the whole
    ///   program;
    /// * no other code accesses these registers (one `Instance` per UART).
    pub const unsafe fn new(base: usize) -> Self {
        Self {
            regs: Regs { base },
            rx: Pipe::new(),
            tx: Pipe::new(),
            tx_idle: AtomicWaker::new(),
            flags: Mutex::new(Flags {
                tx_busy: Cell::new(false),
                rx_paused: Cell::new(false),
                taken: Cell::new(false),
            }),
        }
    }

    /// Configures the UART (8N1, no flow control) for `baud` on pins `txd` and `rxd`,
    /// enables it with its RXDRDY and TXDRDY interrupts, starts both directions, and
    /// returns its two halves; `None` if it was taken already.
    pub fn take(
        &'static self,
        baud: Baud,
        txd: u8,
        rxd: u8,
    ) -> Option<(UartRx<RX, TX>, UartTx<RX, TX>)> {
        let first = critical_section::with(|cs| !self.flags.borrow(cs).taken.replace(true));
        if !first {
            return None;
        }
        let regs = self.regs;
        regs.write(Reg::Enable, 0);
        regs.write(Reg::PselTxd, u32::from(txd));
        regs.write(Reg::PselRxd, u32::from(rxd));
        regs.write(Reg::BaudRate, baud.0);
        regs.write(Reg::Config, 0);
        regs.write(Reg::Enable, ENABLE);
        regs.write(Reg::EventsRxdRdy, 0);
        regs.write(Reg::EventsTxdRdy, 0);
        regs.write(Reg::EventsError, 0);
        regs.write(Reg::IntenSet, INT_RXDRDY | INT_TXDRDY);
        regs.write(Reg::TasksStartRx, 1);
        regs.write(Reg::TasksStartTx, 1);
        Some((UartRx { uart: self }, UartTx { uart: self }))
    }

    /// The interrupt handler: takes the received bytes and sends the next one.
    pub fn on_interrupt(&self) {
        critical_section::with(|cs| {
            self.drain_rx(cs);
            self.pump_tx(cs);
        });
    }

    /// Sends the next byte if the last one left without an interrupt (QEMU sets TXDRDY
    /// without raising the interrupt when its backend was full). Cheap: one register read
    /// when nothing is pending.
    pub fn poll(&self) {
        critical_section::with(|cs| {
            if self.regs.read(Reg::EventsTxdRdy) != 0 {
                self.pump_tx(cs);
            }
        });
    }

    /// Moves the received bytes into the RX pipe while it has room; pauses the RXDRDY
    /// interrupt when it is full, resumes it when it has room again.
    fn drain_rx(&self, cs: CriticalSection<'_>) {
        let regs = self.regs;
        if regs.read(Reg::EventsError) != 0 {
            // Overrun or framing error: the byte is lost; clear and go on.
            regs.write(Reg::EventsError, 0);
            regs.write(Reg::ErrorSrc, regs.read(Reg::ErrorSrc));
        }
        let flags = self.flags.borrow(cs);
        loop {
            if regs.read(Reg::EventsRxdRdy) == 0 {
                if flags.rx_paused.replace(false) {
                    regs.write(Reg::IntenSet, INT_RXDRDY);
                }
                break;
            }
            if self.rx.is_full() {
                if !flags.rx_paused.replace(true) {
                    regs.write(Reg::IntenClr, INT_RXDRDY);
                }
                break;
            }
            // Clear first: reading RXD sets the event again if more bytes wait.
            regs.write(Reg::EventsRxdRdy, 0);
            let byte = regs.read(Reg::Rxd) as u8;
            // Room was checked above and only this function writes the RX pipe.
            let _ = self.rx.try_write(&[byte]);
        }
    }

    /// Sends the next byte from the TX pipe if the UART has sent the previous one; wakes
    /// `flush` when everything is sent.
    fn pump_tx(&self, cs: CriticalSection<'_>) {
        let regs = self.regs;
        let busy = &self.flags.borrow(cs).tx_busy;
        if regs.read(Reg::EventsTxdRdy) != 0 {
            regs.write(Reg::EventsTxdRdy, 0);
            busy.set(false);
        }
        if busy.get() {
            return;
        }
        let mut byte = [0u8];
        if let Ok(1) = self.tx.try_read(&mut byte) {
            regs.write(Reg::Txd, u32::from(byte[0]));
            busy.set(true);
        } else {
            self.tx_idle.wake();
        }
    }

    fn tx_idle(&self, cs: CriticalSection<'_>) -> bool {
        self.pump_tx(cs);
        self.tx.is_empty() && !self.flags.borrow(cs).tx_busy.get()
    }
}

/// The receiving half of a UART.
pub struct UartRx<const RX: usize, const TX: usize> {
    uart: &'static Instance<RX, TX>,
}

/// The transmitting half of a UART.
pub struct UartTx<const RX: usize, const TX: usize> {
    uart: &'static Instance<RX, TX>,
}

impl<const RX: usize, const TX: usize> embedded_io_async::ErrorType for UartRx<RX, TX> {
    type Error = Infallible;
}

impl<const RX: usize, const TX: usize> embedded_io_async::ErrorType for UartTx<RX, TX> {
    type Error = Infallible;
}

impl<const RX: usize, const TX: usize> embedded_io_async::Read for UartRx<RX, TX> {
    /// Waits for at least one byte. Cancel-safe: a dropped read loses nothing.
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        if buf.is_empty() {
            return Ok(0);
        }
        let n = self.uart.rx.read(buf).await;
        // The pipe has room again: take the bytes the handler had to leave in the FIFO.
        critical_section::with(|cs| self.uart.drain_rx(cs));
        Ok(n)
    }
}

impl<const RX: usize, const TX: usize> embedded_io_async::Write for UartTx<RX, TX> {
    /// Waits for room in the TX buffer, then queues as much of `buf` as fits.
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        if buf.is_empty() {
            return Ok(0);
        }
        let n = self.uart.tx.write(buf).await;
        critical_section::with(|cs| self.uart.pump_tx(cs));
        Ok(n)
    }

    /// Waits until every queued byte has left the UART.
    async fn flush(&mut self) -> Result<(), Infallible> {
        poll_fn(|cx| {
            self.uart.tx_idle.register(cx.waker());
            if critical_section::with(|cs| self.uart.tx_idle(cs)) {
                Poll::Ready(Ok(()))
            } else {
                Poll::Pending
            }
        })
        .await
    }
}
