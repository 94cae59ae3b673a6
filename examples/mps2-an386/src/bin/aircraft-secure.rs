//! The example aircraft on the emulated Cortex-M4 with a **secure radio**: the same
//! application as `aircraft` (`src/main.rs`), its UART0 carrying Paparazzi's secure PPRZ
//! v2 link (pprz-secure, `salty` backend): nothing but the key exchange until a ground
//! completes the handshake, then every frame encrypted and authenticated both ways.
//!
//! Keys are embedded at build time by `build.rs`: the aircraft's part (`UAV_PRIVATE`,
//! `UAV_PUBLIC`, `GCS_PUBLIC`) of the key file named by `PPRZ_SECURE_KEYS`, or, without
//! it, of the repository's published **INSECURE test key set** (the build warns).
//!
//! **Not a source of randomness**: QEMU's `mps2-an386` has no hardware RNG, so the
//! handshake's ephemeral keys come from a ChaCha20 generator with a fixed seed: every run
//! of this emulated firmware makes the same keys. A real board seeds it from its
//! hardware RNG (the STM32's `Rng` implements `CryptoRng` itself).

#![no_std]
#![no_main]
#![deny(clippy::undocumented_unsafe_blocks)]

#[path = "../board.rs"]
mod board;
#[path = "../time_driver.rs"]
mod time_driver;
#[path = "../uart.rs"]
mod uart;

use cortex_m_rt::entry;
use panic_halt as _;
use pprz_example_app::{AC_ID, M};
use pprz_secure::link::SecureLink;
use pprz_secure::{KeyFile, Responder};
use pprz_telemetry::{Device, Downlink, FrameArena, Port, run_writer_with};
use rand_chacha::ChaCha20Rng;
use rand_chacha::rand_core::SeedableRng;

/// The aircraft's keys (see the crate docs).
static KEYS: KeyFile =
    pprz_secure::const_key_file!(include_str!(concat!(env!("OUT_DIR"), "/aircraft.keys")));
/// The frames waiting for the radio (each with room for the secure overhead).
static ARENA: FrameArena<M, 4096> = FrameArena::new();
static DOWNLINK: Downlink<'static, M, 1, 32> =
    Downlink::new(&ARENA, AC_ID, [SecureLink::<M>::DEVICE]);
/// The radio's secure link, shared by its writer, its reader and the handshake.
static SECURE: SecureLink<M> = SecureLink::aircraft(AC_ID);

/// Seals and sends the downlink's frames on UART0.
#[embassy_executor::task]
async fn radio_writer(mut port: Port<'static>, tx: board::Tx) {
    run_writer_with(&mut port, tx, &SECURE).await
}

/// The application, reading the uplink from UART0, and the handshake.
#[embassy_executor::task]
async fn aircraft(radio: Device<'static>, rx: board::Rx) {
    let keys = match KEYS.aircraft() {
        Ok(keys) => keys,
        Err(e) => panic!("the aircraft's keys: {e}"),
    };
    // Emulator only: a fixed seed (see the crate docs).
    let rng = ChaCha20Rng::from_seed(*b"emulator has no RNG: not secret!");
    let responder = Responder::new(AC_ID, keys);
    let Err(e) = pprz_example_app::run_secure_aircraft(
        radio,
        rx,
        board::app_config(),
        &SECURE,
        responder,
        rng,
    )
    .await;
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
