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

use embassy_executor::Spawner;
use embassy_rp::peripherals::UART0;
use embassy_rp::uart::{
    self, BufferedInterruptHandler, BufferedUart, BufferedUartRx, BufferedUartTx,
};
use panic_halt as _;
use static_cell::ConstStaticCell;

embassy_rp::bind_interrupts!(struct Irqs { UART0_IRQ => BufferedInterruptHandler<UART0>; });

static TX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
static RX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);

#[embassy_executor::task]
async fn radio(tx: BufferedUartTx, rx: BufferedUartRx) {
    pprz_example_one_link::run(tx, rx).await // writer + reader + services, forever
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
    spawner.spawn(pprz_example_one_link::attitude().unwrap());
    spawner.spawn(pprz_example_one_link::failsafe().unwrap());
}
