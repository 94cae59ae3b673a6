//! The example aircraft on an STM32H743 (a second board family: Cortex-M7, other clock
//! tree, other UARTs), to show that nothing in the stack is F4-specific.
//!
//! * Telemetry radio on USART2 (PD5 TX, PD6 RX) at 57600 baud, PPRZ v2: downlink writer
//!   and datalink reader.
//! * An on-board serial logger (an OpenLog-style recorder) on USART3 (PD8 TX, PD9 RX) at
//!   921600 baud with the PPRZLOG transport: the same messages, time-stamped, in the
//!   format Paparazzi's log tools read. Transport and device are run-time choices per
//!   downlink device.

#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_stm32::bind_interrupts;
use embassy_stm32::peripherals::{USART2, USART3};
use embassy_stm32::usart::{
    self, BufferedInterruptHandler, BufferedUart, BufferedUartRx, BufferedUartTx,
};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::Instant;
use panic_halt as _;
use pprz_devices::stm32::{UartErrorCounters, UartRx};
use pprz_example_app::{AC_ID, Config};
use pprz_telemetry::pprz_transports::{AnyTransport, PprzLog, PprzV2};
use pprz_telemetry::{Device, DeviceConfig, Downlink, FrameArena, Port, run_writer};
use static_cell::StaticCell;

bind_interrupts!(struct Irqs {
    USART2 => BufferedInterruptHandler<USART2>;
    USART3 => BufferedInterruptHandler<USART3>;
});

/// Radio (0) and log (1).
type Dl = Downlink<'static, M, 2, 32>;

static ARENA: FrameArena<M, 16384> = FrameArena::new();
static DOWNLINK: Dl = Downlink::new(
    &ARENA,
    AC_ID,
    [
        DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),
        DeviceConfig::new(AnyTransport::PprzLog(PprzLog::TELEMETRY)),
    ],
)
.with_clock(log_clock);
static RADIO_ERRORS: UartErrorCounters = UartErrorCounters::new();
static BUFFERS: StaticCell<[[u8; 256]; 4]> = StaticCell::new();

#[embassy_executor::task(pool_size = 2)]
async fn writer(mut port: Port<'static>, tx: BufferedUartTx<'static>) {
    run_writer(&mut port, tx).await
}

#[embassy_executor::task]
async fn aircraft(radio: Device<'static>, rx: UartRx<'static, BufferedUartRx<'static>>) {
    let Err(e) = pprz_example_app::run_aircraft(radio, rx, Config::default()).await;
    panic!("the aircraft application cannot start: {e}");
}

/// PPRZLOG time stamps: 100 µs ticks since boot.
fn log_clock() -> u32 {
    (Instant::now().as_micros() / 100) as u32
}

fn uart_config(baudrate: u32) -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = baudrate;
    config
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // Default clocks (64 MHz HSI) are plenty for the UARTs.
    let p = embassy_stm32::init(embassy_stm32::Config::default());
    let [radio_tx_buf, radio_rx_buf, log_tx_buf, log_rx_buf] = BUFFERS.init([[0; 256]; 4]);
    let radio = match BufferedUart::new(
        p.USART2,
        p.PD6,
        p.PD5,
        radio_tx_buf,
        radio_rx_buf,
        Irqs,
        uart_config(57_600),
    ) {
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
    spawner.spawn(writer(radio_port, radio_tx).unwrap());
    spawner.spawn(writer(log_port, log_tx).unwrap());
    spawner.spawn(aircraft(radio_device, UartRx::new(radio_rx, &RADIO_ERRORS)).unwrap());
}
