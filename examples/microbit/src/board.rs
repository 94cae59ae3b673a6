//! The board: the nRF51's UART0 and TIMER0 with their interrupts, the executor's pender
//! and its WFI idle loop, the exception handlers, and the application's link health.
//! `main` calls [`init`] then [`run`], and runs the application with [`app_config`].
//!
//! Nothing here uses an atomic read-modify-write (the Cortex-M0 has none): the pender's
//! flag is a plain load and store, tested and cleared with interrupts masked.

use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m::interrupt::InterruptNumber;
use cortex_m::peripheral::NVIC;
use cortex_m_rt::exception;
use embassy_executor::raw::Executor;
use embassy_time::Duration;
use pprz_example_app::{Config, M};
use pprz_telemetry::health::{HealthConfig, LinkHealth};
use static_cell::StaticCell;

use crate::time_driver;
use crate::uart::{Baud, Instance, UartRx, UartTx};

/// UART0's register block.
const UART0_BASE: usize = 0x4000_2000;
/// The radio's baud rate.
const BAUD: Baud = Baud::B115200;
/// UART0's pins on the micro:bit (v1): P0.24 TXD and P0.25 RXD, to the interface chip's
/// USB serial port. QEMU ignores them.
const TXD_PIN: u8 = 24;
const RXD_PIN: u8 = 25;
/// UART0 buffers: received bytes (uplink) and bytes waiting to be sent (telemetry).
pub const UART_RX_BUF: usize = 256;
pub const UART_TX_BUF: usize = 512;

/// The link health the application's reader drives and its failsafe watches: Degraded
/// after 1 s without a frame from the ground, Lost (the vehicle flies home) after 2 s,
/// shorter than the application's default (5 s) so that the QEMU test of the failsafe
/// stays short. A ground that PINGs every second never lets it become Lost.
static HEALTH: LinkHealth<M> = LinkHealth::new(
    HealthConfig::new()
        .degraded_after(Duration::from_secs(1))
        .lost_after(Duration::from_secs(2)),
);

/// The application's configuration: the default, with [`HEALTH`] as its link health.
pub fn app_config() -> Config {
    Config {
        health: Some(&HEALTH),
        ..Config::default()
    }
}

/// The nRF51's device interrupts that this firmware uses (the number is the
/// peripheral's ID, bits 12 to 16 of its address).
#[derive(Debug, Clone, Copy)]
#[repr(u16)]
pub enum Irq {
    /// UART0 (0x4000_2000).
    Uart0 = 2,
    /// TIMER0 (0x4000_8000).
    Timer0 = 8,
}

// Safety: the numbers are the nRF51's UART0 and TIMER0 interrupt lines (the nRF51
// reference manual's peripheral IDs; QEMU `nrf51_soc.c` wires them the same way), valid
// device interrupts of its NVIC (32 of them).
unsafe impl InterruptNumber for Irq {
    fn number(self) -> u16 {
        self as u16
    }
}

/// UART0's driver.
type Uart0 = Instance<UART_RX_BUF, UART_TX_BUF>;
// Safety: 0x4000_2000 is UART0's register block on the nRF51 (mapped for the whole
// program), and this `static` is the only code that accesses it.
static UART0: Uart0 = unsafe { Instance::new(UART0_BASE) };
static EXECUTOR: StaticCell<Executor> = StaticCell::new();
/// Set when a task was woken (by a task or an interrupt handler) and the executor has
/// work; the idle loop sleeps only while it is clear.
static WORK: AtomicBool = AtomicBool::new(false);

/// The executor's pender, called by embassy-executor whenever a task is woken.
// Safety (of the attribute): embassy-executor's raw executor calls `__pender` with this
// signature, and this is its only definition (the crate's `executor-thread` and
// `executor-interrupt` features, which define one, are off).
#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    WORK.store(true, Ordering::Release);
}

/// Runs the executor forever, sleeping with WFI while no task is ready.
///
/// Not the thread-mode `Executor` of embassy-executor: it sleeps with WFE, which QEMU
/// executes as a no-op, so the guest would spin on a host core. WFI halts the emulated
/// core until an interrupt.
pub fn run(executor: &'static Executor) -> ! {
    loop {
        // Safety: `poll` is called only here, never reentrantly: the pender only sets a
        // flag.
        unsafe { executor.poll() };
        // With interrupts masked, a wake-up cannot slip in between the test and WFI; WFI
        // still returns when an interrupt becomes pending, which then runs. The test and
        // the clearing are a load and a store: no swap on this core, and none needed
        // with interrupts masked.
        cortex_m::interrupt::free(|_| {
            // A byte that left without its interrupt (see `uart`) wakes the writer here.
            UART0.poll();
            if WORK.load(Ordering::Acquire) {
                WORK.store(false, Ordering::Relaxed);
            } else {
                cortex_m::asm::wfi();
            }
        });
    }
}

/// UART0's receiving half (the uplink).
pub type Rx = UartRx<UART_RX_BUF, UART_TX_BUF>;
/// UART0's sending half (the telemetry).
pub type Tx = UartTx<UART_RX_BUF, UART_TX_BUF>;

/// Starts the board: TIMER0 time driver, UART0 with its interrupt; returns UART0's halves
/// and the executor. Panics if called twice.
pub fn init() -> (Rx, Tx, &'static Executor) {
    time_driver::init();
    let Some((rx, tx)) = UART0.take(BAUD, TXD_PIN, RXD_PIN) else {
        panic!("UART0 taken twice");
    };
    // Safety: unmasking can break a critical section only if it runs inside one; this
    // runs before the executor, with interrupts enabled. The handler (`DefaultHandler`)
    // uses only UART0's `Instance` and the time driver, which are ready.
    unsafe {
        NVIC::unmask(Irq::Timer0);
        NVIC::unmask(Irq::Uart0);
    }
    (rx, tx, EXECUTOR.init(Executor::new(core::ptr::null_mut())))
}

/// The device interrupts. Without a peripheral access crate for this chip, cortex-m-rt
/// routes every device interrupt to the default handler, with its number.
///
/// # Safety
///
/// cortex-m-rt requires this handler to be `unsafe` because it would also serve the
/// non-maskable interrupt, which can preempt a critical section: it is never raised on
/// this board, and the handler panics on any exception but UART0's and TIMER0's.
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if irqn == Irq::Uart0 as i16 {
        UART0.on_interrupt();
    } else if irqn == Irq::Timer0 as i16 {
        time_driver::on_interrupt();
    } else {
        panic!("unexpected exception");
    }
}
