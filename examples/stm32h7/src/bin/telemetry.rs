//! The example aircraft on an STM32H743 (a second board family: Cortex-M7, other clock
//! tree, other UARTs), to show that nothing in the stack is F4-specific.
//!
//! * Telemetry radio on USART2 (PD5 TX, PD6 RX) at 57600 baud, PPRZ v2: downlink writer
//!   and datalink reader. With the cargo feature `flow-control` (on by default) the UART
//!   also uses hardware flow control, PD4 RTS and PD3 CTS: the modem's CTS holds our
//!   transmitter while its buffer is full, so frames wait in the downlink's priority
//!   queue instead of overflowing the modem. Built with `--no-default-features` (a radio
//!   without RTS/CTS wiring), the downlink paces the radio instead, with [`SIK_PACING`].
//! * An on-board serial logger (an OpenLog-style recorder) on USART3 (PD8 TX, PD9 RX) at
//!   921600 baud with the PPRZLOG transport: the same messages, time-stamped, in the
//!   format Paparazzi's log tools read. Transport and device are run-time choices per
//!   downlink device.
//! * Persistent settings (the gain) in the first two sectors of flash bank 2
//!   (`0x0810_0000..0x0814_0000`, 2 x 128 KiB; `memory.x` keeps the image in bank 1),
//!   through embassy-stm32's async flash driver: loaded at start, stored when the ground
//!   sets setting 4 (the store flag) to 1. See the README for the ECC caveat.

#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_stm32::bind_interrupts;
use embassy_stm32::flash::{self, Async, Bank2Region, Flash};
use embassy_stm32::gpio::Pull;
use embassy_stm32::peripherals::{USART2, USART3};
use embassy_stm32::usart::{
    self, BufferedInterruptHandler, BufferedUart, BufferedUartRx, BufferedUartTx,
};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::Instant;
use panic_halt as _;
use pprz_devices::stm32::{UartErrorCounters, UartRx};
use pprz_example_app::{AC_ID, Config};
use pprz_settings::{PageCache, PersistentStore, StoreControl, buffer_len};
use pprz_telemetry::pprz_transports::{AnyTransport, PprzLog, PprzV2};
use pprz_telemetry::{Device, DeviceConfig, Downlink, FrameArena, Pacing, Port, run_writer};
use static_cell::StaticCell;

bind_interrupts!(struct Irqs {
    USART2 => BufferedInterruptHandler<USART2>;
    USART3 => BufferedInterruptHandler<USART3>;
    FLASH => flash::InterruptHandler;
});

/// Whether the radio UART uses hardware flow control (RTS/CTS): cargo feature
/// `flow-control`, on by default; build with `--no-default-features` for a radio whose
/// RTS/CTS lines are not wired.
const FLOW_CONTROL: bool = cfg!(feature = "flow-control");

/// The link budget of a SiK radio without flow control (57600 baud serial, `AIR_SPEED=64`),
/// the same figures as the STM32F405 board's (see its `SIK_PACING`). Air rate: 64 kbit/s
/// is 8000 B/s on the air, half of it with `ECC=1` (Golay coding doubles every byte), less
/// about a quarter for the radio's packet framing and its time-division turns with the
/// ground radio: 3000 B/s, on the low side on purpose (too high fills the modem's serial
/// buffer until it drops bytes). Budget: one longest PPRZ v2 frame (255 bytes) plus a
/// margin, so an acknowledgement waits at most about two frame times (170 ms). Measure the
/// radio's real throughput with a saturating test and adjust.
const SIK_PACING: Pacing = Pacing::new(3_000, 320);

/// The radio's pacing: none when the modem's CTS line pushes back, [`SIK_PACING`] when
/// nothing does.
const RADIO_PACING: Option<Pacing> = if FLOW_CONTROL { None } else { Some(SIK_PACING) };

/// Radio (0) and log (1).
type Dl = Downlink<'static, M, 2, 32>;

static ARENA: FrameArena<M, 16384> = FrameArena::new();
static DOWNLINK: Dl = Downlink::new(
    &ARENA,
    AC_ID,
    [
        DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())).pacing(RADIO_PACING),
        DeviceConfig::new(AnyTransport::PprzLog(PprzLog::TELEMETRY)),
    ],
)
.with_clock(log_clock);
static RADIO_ERRORS: UartErrorCounters = UartErrorCounters::new();
static BUFFERS: StaticCell<[[u8; 256]; 4]> = StaticCell::new();

/// The settings' flash: the first two sectors of bank 2, offsets within `bank2_region`
/// (from `0x0810_0000`).
const SETTINGS_SECTORS: core::ops::Range<u32> = 0..0x4_0000;
/// The persistent settings' store: two 128 KiB sectors, room for 16 settings.
type Store = PersistentStore<Bank2Region<'static, Async>, PageCache<2>, { buffer_len(16) }>;
static STORE: StaticCell<Store> = StaticCell::new();
/// The store flag's control. The example vehicle is simulated and has no motors, so it
/// accepts every request; an aircraft stores only with its motors killed
/// (`StoreControl::with_guard`), the more so on the H7 (see the README: a cut during a
/// write can leave a word that faults when read).
static CONTROL: StoreControl<M> = StoreControl::new();

#[embassy_executor::task(pool_size = 2)]
async fn writer(mut port: Port<'static>, tx: BufferedUartTx<'static>) {
    run_writer(&mut port, tx).await
}

/// The application, its persistent settings in `store`.
#[embassy_executor::task]
async fn aircraft(
    radio: Device<'static>,
    rx: UartRx<'static, BufferedUartRx<'static>>,
    store: &'static mut Store,
) {
    let config = Config::default();
    let Err(e) =
        pprz_example_app::run_aircraft_with_store(radio, rx, config, store, &CONTROL).await;
    panic!("the aircraft application cannot start: {e}");
}

/// PPRZLOG time stamps: 100 µs ticks since boot.
fn log_clock() -> u32 {
    (Instant::now().as_micros() / 100) as u32
}

/// 8N1 at `baudrate`. CTS (used by the radio with flow control) has a pull-down, so an
/// unconnected or broken CTS line reads "clear to send": the radio then still works, only
/// without back-pressure, instead of falling silent.
fn uart_config(baudrate: u32) -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = baudrate;
    config.cts_pull = Pull::Down;
    config
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // Default clocks (64 MHz HSI) are plenty for the UARTs.
    let p = embassy_stm32::init(embassy_stm32::Config::default());
    let [radio_tx_buf, radio_rx_buf, log_tx_buf, log_rx_buf] = BUFFERS.init([[0; 256]; 4]);
    // Radio: with RTS (PD4) and CTS (PD3) under the `flow-control` feature.
    #[cfg(feature = "flow-control")]
    let radio = BufferedUart::new_with_rtscts(
        p.USART2,
        p.PD6,
        p.PD5,
        p.PD4,
        p.PD3,
        Irqs,
        radio_tx_buf,
        radio_rx_buf,
        uart_config(57_600),
    );
    #[cfg(not(feature = "flow-control"))]
    let radio = BufferedUart::new(
        p.USART2,
        p.PD6,
        p.PD5,
        radio_tx_buf,
        radio_rx_buf,
        Irqs,
        uart_config(57_600),
    );
    let radio = match radio {
        Ok(uart) => uart,
        Err(e) => panic!("radio UART: {e:?}"),
    };
    let log = match BufferedUart::new(
        p.USART3,
        p.PD9,
        p.PD8,
        log_tx_buf,
        log_rx_buf,
        Irqs,
        uart_config(921_600),
    ) {
        Ok(uart) => uart,
        Err(e) => panic!("log UART: {e:?}"),
    };
    let (radio_tx, radio_rx) = radio.split();
    let (log_tx, _log_rx) = log.split();
    let Ok([radio_port, log_port]) = DOWNLINK.ports() else {
        panic!("the downlink's ports are taken once, here");
    };
    let radio_device = radio_port.device();
    // The settings' flash: bank 2, its first two sectors.
    let region = Flash::new(p.FLASH, Irqs).into_regions().bank2_region;
    let store = match Store::with_page_cache(region, SETTINGS_SECTORS) {
        Ok(store) => STORE.init(store),
        Err(e) => panic!("settings flash: {e}"),
    };
    let radio_rx = UartRx::new(radio_rx, &RADIO_ERRORS);
    spawner.spawn(writer(radio_port, radio_tx).unwrap());
    spawner.spawn(writer(log_port, log_tx).unwrap());
    spawner.spawn(aircraft(radio_device, radio_rx, store).unwrap());
}
