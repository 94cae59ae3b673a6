//! The smallest firmware on an ESP32-C3: telemetry over one UART radio (UART1, GPIO4 TX,
//! GPIO5 RX, 57600 baud 8N1, PPRZ v2), answering the ground's PING, SETTING and
//! GET_SETTING, with the default message set.
//!
//! The one-link facade `Link` runs the writer, the reader and the services in one task;
//! any task sends with `LINK.send(&msg)`, which never blocks. An ATTITUDE goes down every
//! 100 ms. A failsafe task raises `GO_HOME` when the ground has been silent for 5 s
//! (`LINK.health()`).
//!
//! esp-hal's async UART halves implement embedded-io-async's `Read` and `Write` (feature
//! `unstable`), so they go to `LINK.run` as they are. The executor and the time driver
//! are esp-rtos's, started on timer group 0.

#![no_std]
#![no_main]

use core::sync::atomic::{AtomicBool, Ordering};
use embassy_executor::Spawner;
use embassy_time::{Duration, Ticker};
use esp_hal::Async;
use esp_hal::timer::timg::TimerGroup;
use esp_hal::uart::{self, Uart, UartRx, UartTx};
use panic_halt as _;
use pprz_default::messages::{Set, telemetry::Attitude};
use pprz_telemetry::{FrameArena, Health, HealthConfig, Link, LinkMutex};

esp_bootloader_esp_idf::esp_app_desc!();

/// Pending frames: about half a second of a saturated 57600-baud radio.
static ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
/// Aircraft 7; the ground is lost after 5 s of silence.
static LINK: Link<'static, Set> =
    Link::new(&ARENA, 7).health_config(HealthConfig::new().lost_after(Duration::from_secs(5)));
/// Set when the ground has been silent for 5 s: your autopilot flies home.
static GO_HOME: AtomicBool = AtomicBool::new(false);

#[embassy_executor::task]
async fn radio(tx: UartTx<'static, Async>, rx: UartRx<'static, Async>) {
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

#[esp_rtos::main]
async fn main(spawner: Spawner) {
    let p = esp_hal::init(esp_hal::Config::default());
    let timg0 = TimerGroup::new(p.TIMG0);
    esp_rtos::start(timg0.timer0, p.FROM_CPU_INTR0);

    // UART1 through the GPIO matrix: GPIO4 TX, GPIO5 RX (not UART0's GPIO21/GPIO20, where
    // the ROM bootloader prints at reset; not a strapping, flash or USB pin; the external
    // JTAG's MTMS and MTDI, free when debugging over USB).
    let cfg = uart::Config::default().with_baudrate(57_600);
    let uart = Uart::new(p.UART1, cfg).expect("radio UART");
    let (rx, tx) = uart.with_tx(p.GPIO4).with_rx(p.GPIO5).into_async().split();
    spawner.spawn(radio(tx, rx).unwrap());
    spawner.spawn(attitude().unwrap());
    spawner.spawn(failsafe().unwrap());
}
