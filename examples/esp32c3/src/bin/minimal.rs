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

use embassy_executor::Spawner;
use esp_hal::Async;
use esp_hal::timer::timg::TimerGroup;
use esp_hal::uart::{self, Uart, UartRx, UartTx};
use panic_halt as _;

esp_bootloader_esp_idf::esp_app_desc!();

#[embassy_executor::task]
async fn radio(tx: UartTx<'static, Async>, rx: UartRx<'static, Async>) {
    pprz_example_one_link::run(tx, rx).await // writer + reader + services, forever
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
    spawner.spawn(pprz_example_one_link::attitude().unwrap());
    spawner.spawn(pprz_example_one_link::failsafe().unwrap());
}
