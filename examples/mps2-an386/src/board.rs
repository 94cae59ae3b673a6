//! What the firmwares of this crate share: the MPS2 board's clock and UART0 with its
//! interrupts, the executor's pender and its WFI idle loop, the exception handlers, and
//! the application's link health. Each binary includes this module (`mod board;`), calls
//! [`init`] then [`run`], and runs the application with [`app_config`].

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
use crate::uart::{Instance, UartRx, UartTx};

/// The system (core and peripheral) clock of the MPS2 board.
pub const SYSCLK_HZ: u32 = 25_000_000;
/// The radio's baud rate.
pub const BAUD: u32 = 115_200;
/// UART0's register block.
const UART0_BASE: usize = 0x4000_4000;
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

/// Device-specific interrupts of the MPS2 AN385/AN386 images that this firmware uses.
#[derive(Debug, Clone, Copy)]
#[repr(u16)]
enum Irq {
    /// UART0 received a byte.
    Uart0Rx = 0,
    /// UART0's TX buffer emptied.
    Uart0Tx = 1,
}

// Safety: the numbers are the board's UART0 RX and TX interrupt lines (QEMU `mps2.c`,
// AN385/AN386: UART0 RX is IRQ 0, TX is RX + 1), valid device interrupts of its NVIC
// (32 of them).
unsafe impl InterruptNumber for Irq {
    fn number(self) -> u16 {
        self as u16
    }
}

/// UART0's driver.
type Uart0 = Instance<UART_RX_BUF, UART_TX_BUF>;
// Safety: 0x4000_4000 is UART0's register block on the MPS2 AN386 image (mapped for the
// whole program), and this `static` is the only code that accesses it.
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
/// executes as a no-op, so the guest would spin on a host core, and on a loaded host
/// QEMU would then fall behind with SysTick (coalescing its interrupts, so the guest
/// clock would lag). WFI halts the emulated core until an interrupt.
pub fn run(executor: &'static Executor) -> ! {
    loop {
        // Safety: `poll` is called only here, never reentrantly: the pender only sets a
        // flag.
        unsafe { executor.poll() };
        // With interrupts masked, a wake-up cannot slip in between the check and WFI;
        // WFI still returns when an interrupt becomes pending, which then runs.
        cortex_m::interrupt::free(|_| {
            if !WORK.swap(false, Ordering::AcqRel) {
                cortex_m::asm::wfi();
            }
        });
    }
}

/// UART0's receiving half (the uplink).
pub type Rx = UartRx<UART_RX_BUF, UART_TX_BUF>;
/// UART0's sending half (the telemetry).
pub type Tx = UartTx<UART_RX_BUF, UART_TX_BUF>;

/// Starts the board: SysTick time driver, UART0 with its interrupts; returns UART0's
/// halves and the executor. Panics if called twice.
pub fn init() -> (Rx, Tx, &'static Executor) {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals taken twice");
    };
    time_driver::init(core.SYST, SYSCLK_HZ);
    let Some((rx, tx)) = UART0.take(SYSCLK_HZ, BAUD) else {
        panic!("UART0 taken twice");
    };
    // Safety: unmasking can break a critical section only if it runs inside one; this
    // runs before the executor, with interrupts enabled. The handler (`DefaultHandler`)
    // uses only UART0's `Instance`, which is ready.
    unsafe {
        NVIC::unmask(Irq::Uart0Rx);
        NVIC::unmask(Irq::Uart0Tx);
    }
    (rx, tx, EXECUTOR.init(Executor::new(core::ptr::null_mut())))
}

#[exception]
fn SysTick() {
    time_driver::on_systick();
}

/// The device interrupts. Without a peripheral access crate for this board, cortex-m-rt
/// routes every device interrupt to the default handler, with its number.
///
/// # Safety
///
/// cortex-m-rt requires this handler to be `unsafe` because it would also serve the
/// non-maskable interrupt, which can preempt a critical section: it is never raised on
/// this board, and the handler panics on any exception but the UART's.
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if irqn == Irq::Uart0Rx as i16 || irqn == Irq::Uart0Tx as i16 {
        UART0.on_interrupt();
    } else {
        panic!("unexpected exception");
    }
}
