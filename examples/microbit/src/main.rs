//! The example aircraft on an emulated Cortex-M0 without compare-and-swap: QEMU's
//! `microbit` machine (BBC micro:bit, nRF51822, Cortex-M0 at 16 MHz), with the
//! nRF51822-QFAC's 32 KiB of RAM (`-global nrf51-soc.sram-size=32768`).
//!
//! It runs the same application as the host simulation, the STM32 boards and the
//! emulated Cortex-M4 (`pprz_example_app::run_aircraft`: simulated rotorcraft, periodic
//! telemetry of the project's `telemetry.xml`, datalink services answering PING and
//! SETTING, the link-loss failsafe) on the Embassy executor, with a tickless TIMER0 time
//! driver ([`time_driver`]) and an interrupt-driven driver for UART0 ([`uart`]), written
//! for the nRF51 without a HAL. UART0 is the radio: PPRZ v2 frames both ways, 115200 baud
//! (QEMU ignores the rate; its `-serial` backend carries the bytes, e.g. over loopback
//! TCP). Nothing persists: the micro:bit's flash is not kept in a file by QEMU. See
//! README.md for how to run it.
//!
//! The Cortex-M0 (ARMv6-M) has no atomic read-modify-write instructions. The libraries
//! and Embassy take critical sections instead; `static_cell` gets its compare-and-swap
//! from portable-atomic's critical-section fallback, which this crate enables.

#![no_std]
#![no_main]
#![deny(clippy::undocumented_unsafe_blocks)]

mod board;
mod time_driver;
mod uart;

use cortex_m_rt::entry;
use panic_halt as _;
use pprz_example_app::{AC_ID, M};
use pprz_telemetry::{Device, DeviceConfig, Downlink, FrameArena, Port, run_writer};
use pprz_transports::{AnyTransport, PprzV2};

/// The frames waiting for the radio.
static ARENA: FrameArena<M, 4096> = FrameArena::new();
static DOWNLINK: Downlink<'static, M, 1, 32> = Downlink::new(
    &ARENA,
    AC_ID,
    [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()))],
);

/// Sends the downlink's frames on UART0.
#[embassy_executor::task]
async fn radio_writer(mut port: Port<'static>, tx: board::Tx) {
    run_writer(&mut port, tx).await
}

/// The application, reading the uplink from UART0.
#[embassy_executor::task]
async fn aircraft(radio: Device<'static>, rx: board::Rx) {
    let Err(e) = pprz_example_app::run_aircraft(radio, rx, board::app_config()).await;
    panic!("the aircraft application cannot start: {e}");
}

#[entry]
fn main() -> ! {
    let (rx, tx, executor) = board::init();
    let Ok([radio]) = DOWNLINK.ports() else {
        panic!("the downlink's ports are taken once, here");
    };
    let radio_device = radio.device();
    let spawner = executor.spawner();
    spawner.spawn(radio_writer(radio, tx).expect("one radio writer"));
    spawner.spawn(aircraft(radio_device, rx).expect("one aircraft"));
    board::run(executor)
}
