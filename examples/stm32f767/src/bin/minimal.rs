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

use embassy_executor::Spawner;
use embassy_stm32::peripherals::USART6;
use embassy_stm32::usart::{
    self, BufferedInterruptHandler, BufferedUart, BufferedUartRx, BufferedUartTx,
};
use panic_halt as _;
use static_cell::ConstStaticCell;

embassy_stm32::bind_interrupts!(struct Irqs { USART6 => BufferedInterruptHandler<USART6>; });

/// The UART driver's ring buffers, 44 ms of 57600 baud each way.
static TX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
static RX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);

#[embassy_executor::task]
async fn radio(tx: BufferedUartTx<'static>, rx: BufferedUartRx<'static>) {
    pprz_example_one_link::run(tx, rx).await // writer + reader + services, forever
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
    spawner.spawn(pprz_example_one_link::attitude().unwrap());
    spawner.spawn(pprz_example_one_link::failsafe().unwrap());
}
