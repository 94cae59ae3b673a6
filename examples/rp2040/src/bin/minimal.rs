//! The smallest firmware on a Raspberry Pi Pico: telemetry over one UART radio (UART0,
//! GP0 TX / GP1 RX, 57600 baud, PPRZ v2), answering the ground's PING, SETTING and
//! GET_SETTING, with the default message set. The one-link facade `Link` runs the
//! writer, the reader and the services in one task; any task sends with
//! `LINK.send(&msg)`, which never blocks. A failsafe task raises `GO_HOME` when the
//! ground has been silent for 5 s (`LINK.health()`).
//!
//! The RP2040's Cortex-M0+ has no compare-and-swap: `GO_HOME` is only loaded and stored,
//! and every lock (the link's, the executor's) is embassy-rp's critical section.

#![no_std]
#![no_main]

use core::sync::atomic::{AtomicBool, Ordering};
use embassy_executor::Spawner;
use embassy_rp::peripherals::UART0;
use embassy_rp::uart::{
    self, BufferedInterruptHandler, BufferedUart, BufferedUartRx, BufferedUartTx,
};
use embassy_time::{Duration, Ticker};
use panic_halt as _;
use pprz_default::messages::{Set, telemetry::Attitude};
use pprz_telemetry::{FrameArena, Health, HealthConfig, Link, LinkMutex};
use static_cell::ConstStaticCell;

embassy_rp::bind_interrupts!(struct Irqs { UART0_IRQ => BufferedInterruptHandler<UART0>; });

static ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
/// Aircraft 7; the ground is lost after 5 s of silence.
static LINK: Link<'static, Set> =
    Link::new(&ARENA, 7).health_config(HealthConfig::new().lost_after(Duration::from_secs(5)));
/// Set when the ground has been silent for 5 s: your autopilot flies home.
static GO_HOME: AtomicBool = AtomicBool::new(false);
static TX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
static RX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);

#[embassy_executor::task]
async fn radio(tx: BufferedUartTx, rx: BufferedUartRx) {
    let Err(e) = LINK.run(tx, rx).await; // writer + reader + services, forever
    panic!("{e}");
}

#[embassy_executor::task]
async fn attitude() {
    let mut ticker = Ticker::every(Duration::from_millis(100));
    loop {
        ticker.next().await;
        // A message that cannot be queued is counted in LINK.stats(), by reason.
        let _ = LINK.send(&Attitude {
            phi: 0.1,
            psi: 0.0,
            theta: 0.0,
        });
    }
}

#[embassy_executor::task]
async fn failsafe() {
    LINK.health().wait_for(Health::Up).await; // not before the ground was heard once
    loop {
        LINK.health().wait_for(Health::Lost).await;
        GO_HOME.store(true, Ordering::Relaxed);
        LINK.health().wait_for(Health::Up).await;
    }
}

#[embassy_executor::main(
    executor = "embassy_rp::executor::Executor",
    entry = "cortex_m_rt::entry"
)]
async fn main(spawner: Spawner) {
    let p = embassy_rp::init(Default::default());
    let mut cfg = uart::Config::default();
    cfg.baudrate = 57_600;
    let uart = BufferedUart::new(p.UART0, p.PIN_0, p.PIN_1, Irqs, TX.take(), RX.take(), cfg);
    let (tx, rx) = uart.split();
    spawner.spawn(radio(tx, rx).unwrap());
    spawner.spawn(attitude().unwrap());
    spawner.spawn(failsafe().unwrap());
}
