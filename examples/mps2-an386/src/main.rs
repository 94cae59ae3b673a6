//! The example aircraft on an emulated Cortex-M4: QEMU's `mps2-an386` machine (ARM MPS2
//! board with the AN386 Cortex-M4 FPGA image, 25 MHz).
//!
//! It runs the same application as the host simulation and the STM32 boards
//! (`pprz_example_app::run_aircraft`: simulated rotorcraft, periodic telemetry of the
//! project's `telemetry.xml`, datalink services answering PING and SETTING) on the
//! Embassy executor, with a SysTick time driver ([`time_driver`]) and an
//! interrupt-driven driver for the CMSDK UART ([`uart`]). UART0 is the radio: PPRZ v2
//! frames both ways, 115200 baud (QEMU ignores the rate; its `-serial` backend carries
//! the bytes, e.g. over loopback TCP). The persistent settings (the gain) are kept in
//! the PSRAM ([`settings_flash`]), which QEMU can keep in a file. See README.md for how
//! to run it.

#![no_std]
#![no_main]
#![deny(clippy::undocumented_unsafe_blocks)]

mod board;
mod settings_flash;
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

/// The application, reading the uplink from UART0, its persistent settings in `store`.
#[embassy_executor::task]
async fn aircraft(
    radio: Device<'static>,
    rx: board::Rx,
    store: &'static mut settings_flash::Store,
) {
    let config = board::app_config();
    let control = &settings_flash::CONTROL;
    let Err(e) = pprz_example_app::run_aircraft_with_store(radio, rx, config, store, control).await;
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
    let store = settings_flash::store();
    spawner.spawn(aircraft(radio_device, rx, store).expect("one aircraft"));
    board::run(executor)
}
