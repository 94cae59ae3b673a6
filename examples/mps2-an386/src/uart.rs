//! An interrupt-driven async driver for the ARM CMSDK APB UART (the UARTs of the MPS2
//! boards, modelled by QEMU's `cmsdk-apb-uart`), implementing `embedded_io_async`'s
//! `Read` and `Write`.
//!
//! The UART holds one byte in each direction. Both directions go through ring buffers
//! (embassy-sync `Pipe`s) that the interrupt handler fills and drains:
//!
//! ```text
//!   UartTx::write --> tx pipe --(pump: while TX not full)--> DATA --> line
//!   line --> DATA --(RX interrupt, or after a read)--> rx pipe --> UartRx::read
//! ```
//!
//! * RX: the RX interrupt moves the received byte into the RX pipe and wakes the
//!   reader. When the pipe is full the byte is left in the UART (RX stays "full") and
//!   the reader picks it up after its next read; QEMU then holds back further input
//!   (its model accepts a byte only while RX is empty), so nothing is lost. Real
//!   hardware would overrun instead (the byte is lost; the overrun flag is cleared).
//! * TX: a write copies into the TX pipe and starts the pump, which feeds `DATA` while
//!   the UART's TX buffer is not full; each TX interrupt (TX buffer emptied) pumps the
//!   next byte. `flush` waits until the pipe is empty and the last byte left.
//!
//! The pump and the RX drain run with interrupts masked (in the handler, or in a
//! critical section from a task), so the task and the handler never race on `DATA`.

use core::convert::Infallible;
use core::future::poll_fn;
use core::sync::atomic::{AtomicBool, Ordering};
use core::task::Poll;

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::waitqueue::AtomicWaker;

/// The CMSDK APB UART registers (offsets from the block's base; all 32 bits wide).
#[derive(Debug, Clone, Copy)]
#[repr(usize)]
enum Reg {
    /// Read: the received byte (clears RX full). Write: the byte to send.
    Data = 0x00,
    /// Bit 0 TX buffer full, bit 1 RX buffer full, bits 2/3 TX/RX overrun (write 1 to clear).
    State = 0x04,
    /// Bit 0 TX enable, bit 1 RX enable, bits 2/3 TX/RX interrupt enable.
    Ctrl = 0x08,
    /// Read: interrupt status; write: clear (bit 0 TX, bit 1 RX, bits 2/3 overruns).
    IntStatus = 0x0C,
    /// Baud rate divider: the UART clock divided by the baud rate (16 at least).
    BaudDiv = 0x10,
}

const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const STATE_RX_OVERRUN: u32 = 1 << 3;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;
const CTRL_TX_INT_EN: u32 = 1 << 2;
const CTRL_RX_INT_EN: u32 = 1 << 3;
const INT_TX: u32 = 1 << 0;
const INT_RX: u32 = 1 << 1;

/// A CMSDK APB UART register block.
///
/// Invariant: `base` is the address of a CMSDK APB UART's register block, mapped for the
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

/// Everything about one UART: its registers and the buffers and wakers the interrupt
/// handler shares with the tasks. Meant to be a `static`; `RX` and `TX` are the ring
/// buffer sizes in bytes.
///
/// The board calls [`Instance::on_interrupt`] from the UART's RX and TX interrupts and
/// enables them in the NVIC after [`Instance::take`].
pub struct Instance<const RX: usize, const TX: usize> {
    regs: Regs,
    rx: Pipe<CriticalSectionRawMutex, RX>,
    tx: Pipe<CriticalSectionRawMutex, TX>,
    /// Woken when the TX pipe is empty and the UART has sent its last byte.
    tx_idle: AtomicWaker,
    taken: AtomicBool,
}

impl<const RX: usize, const TX: usize> Instance<RX, TX> {
    /// The UART whose registers are at `base`.
    ///
    /// # Safety
    ///
    /// * `base` is the address of a CMSDK APB UART register block, mapped for the whole
    ///   program;
    /// * no other code accesses these registers (one `Instance` per UART).
    pub const unsafe fn new(base: usize) -> Self {
        Self {
            regs: Regs { base },
            rx: Pipe::new(),
            tx: Pipe::new(),
            tx_idle: AtomicWaker::new(),
            taken: AtomicBool::new(false),
        }
    }

    /// Configures the UART for `baud` from a `clock_hz` UART clock (8N1 is fixed in the
    /// CMSDK UART), enables it with its TX and RX interrupts, and returns its two halves;
    /// `None` if it was taken already.
    pub fn take(
        &'static self,
        clock_hz: u32,
        baud: u32,
    ) -> Option<(UartRx<RX, TX>, UartTx<RX, TX>)> {
        if self.taken.swap(true, Ordering::AcqRel) {
            return None;
        }
        let regs = self.regs;
        regs.write(Reg::Ctrl, 0);
        regs.write(Reg::BaudDiv, (clock_hz / baud.max(1)).max(16));
        regs.write(Reg::IntStatus, INT_TX | INT_RX);
        regs.write(
            Reg::Ctrl,
            CTRL_TX_EN | CTRL_RX_EN | CTRL_TX_INT_EN | CTRL_RX_INT_EN,
        );
        Some((UartRx { uart: self }, UartTx { uart: self }))
    }

    /// The interrupt handler, for both the RX and the TX interrupt of this UART.
    pub fn on_interrupt(&self) {
        // Clear first: a byte that arrives (or leaves) while we work sets it again.
        self.regs.write(Reg::IntStatus, INT_TX | INT_RX);
        critical_section::with(|_| {
            self.drain_rx();
            self.pump_tx();
        });
    }

    /// Moves the received byte, if any, into the RX pipe while it has room. Call with
    /// interrupts masked.
    fn drain_rx(&self) {
        loop {
            let state = self.regs.read(Reg::State);
            if state & STATE_RX_OVERRUN != 0 {
                self.regs.write(Reg::State, STATE_RX_OVERRUN);
            }
            if state & STATE_RX_FULL == 0 || self.rx.is_full() {
                break;
            }
            let byte = self.regs.read(Reg::Data) as u8;
            // Room was checked above and only this function writes the RX pipe.
            let _ = self.rx.try_write(&[byte]);
        }
    }

    /// Feeds the UART from the TX pipe while its TX buffer has room; wakes `flush` when
    /// everything is sent. Call with interrupts masked.
    fn pump_tx(&self) {
        while self.regs.read(Reg::State) & STATE_TX_FULL == 0 {
            let mut byte = [0u8];
            if let Ok(1) = self.tx.try_read(&mut byte) {
                self.regs.write(Reg::Data, u32::from(byte[0]));
            } else {
                self.tx_idle.wake();
                break;
            }
        }
    }

    fn tx_idle(&self) -> bool {
        self.tx.is_empty() && self.regs.read(Reg::State) & STATE_TX_FULL == 0
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
        // The pipe has room again: take the byte the handler had to leave in the UART.
        critical_section::with(|_| self.uart.drain_rx());
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
        critical_section::with(|_| self.uart.pump_tx());
        Ok(n)
    }

    /// Waits until every queued byte has left the UART.
    async fn flush(&mut self) -> Result<(), Infallible> {
        poll_fn(|cx| {
            self.uart.tx_idle.register(cx.waker());
            if critical_section::with(|_| self.uart.tx_idle()) {
                Poll::Ready(Ok(()))
            } else {
                Poll::Pending
            }
        })
        .await
    }
}
