//! The smallest firmware on an STM32F767: telemetry over one UART radio (USART6, PG14 TX,
//! PG9 RX, 57600 baud 8N1, PPRZ v2), answering the ground's PING, SETTING and
//! GET_SETTING, with the default message set.
//!
//! The one-link facade `Link` runs the writer, the reader and the services in one task;
//! any task sends with `LINK.send(&msg)`, which never blocks. An ATTITUDE goes down every
//! 100 ms. A failsafe task raises `GO_HOME` when the ground has been silent for 5 s
//! (`LINK.health()`).
//!
//! Clocks: embassy-stm32's defaults, the 16 MHz HSI as system clock (the UART needs
//! nothing faster; see `usb.rs` for 216 MHz from the HSE).

#![no_std]
#![no_main]

use core::sync::atomic::{AtomicBool, Ordering};
use embassy_executor::Spawner;
use embassy_stm32::peripherals::USART6;
use embassy_stm32::usart::{
    self, BufferedInterruptHandler, BufferedUart, BufferedUartRx, BufferedUartTx,
};
use embassy_time::{Duration, Ticker};
use panic_halt as _;
use pprz_default::messages::{Set, telemetry::Attitude};
use pprz_telemetry::{FrameArena, Health, HealthConfig, Link, LinkMutex};
use static_cell::ConstStaticCell;

embassy_stm32::bind_interrupts!(struct Irqs { USART6 => BufferedInterruptHandler<USART6>; });

/// Pending frames: about half a second of a saturated 57600-baud radio.
static ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
/// Aircraft 7; the ground is lost after 5 s of silence.
static LINK: Link<'static, Set> =
    Link::new(&ARENA, 7).health_config(HealthConfig::new().lost_after(Duration::from_secs(5)));
/// Set when the ground has been silent for 5 s: your autopilot flies home.
static GO_HOME: AtomicBool = AtomicBool::new(false);
/// The UART driver's ring buffers, 44 ms of 57600 baud each way.
static TX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
static RX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);

#[embassy_executor::task]
async fn radio(tx: BufferedUartTx<'static>, rx: BufferedUartRx<'static>) {
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

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(Default::default());
    let mut cfg = usart::Config::default();
    cfg.baudrate = 57_600;
    // USART6: PG9 RX, PG14 TX (AF8); D0 and D1 of a Nucleo-F767ZI's Arduino connector.
    let uart = BufferedUart::new(p.USART6, p.PG9, p.PG14, TX.take(), RX.take(), Irqs, cfg);
    let (tx, rx) = uart.expect("radio UART").split();
    spawner.spawn(radio(tx, rx).unwrap());
    spawner.spawn(attitude().unwrap());
    spawner.spawn(failsafe().unwrap());
}
