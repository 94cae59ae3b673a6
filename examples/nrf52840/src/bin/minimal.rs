//! The smallest firmware on an nRF52840-DK: telemetry over one UART (UARTE0, P0.06 TX /
//! P0.08 RX, 57600 baud, PPRZ v2), answering the ground's PING, SETTING and GET_SETTING,
//! with the default message set. On the DK those two pins are the on-board J-Link's
//! virtual serial port, so the ground reaches the firmware over the debug USB cable
//! without a radio. The one-link facade `Link` runs the writer, the reader and the
//! services in one task; any task sends with `LINK.send(&msg)`, which never blocks. A
//! failsafe task raises `GO_HOME` when the ground has been silent for 5 s
//! (`LINK.health()`).

#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_nrf::buffered_uarte::{self, BufferedUarte, BufferedUarteRx, BufferedUarteTx};
use embassy_nrf::config::HfclkSource;
use embassy_nrf::peripherals::UARTE0;
use embassy_nrf::uarte::{self, Baudrate};
use panic_halt as _;
use static_cell::ConstStaticCell;

embassy_nrf::bind_interrupts!(struct Irqs {
    UARTE0 => buffered_uarte::InterruptHandler<UARTE0>;
});

static TX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
/// The receive buffer's length must be even (the driver receives into its two halves).
static RX: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);

#[embassy_executor::task]
async fn radio(tx: BufferedUarteTx<'static>, rx: BufferedUarteRx<'static>) {
    pprz_example_one_link::run(tx, rx).await // writer + reader + services, forever
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // The 32 MHz crystal: the UART's baud rate is derived from the high-frequency clock,
    // which the crystal keeps more exact than the internal oscillator.
    let mut config = embassy_nrf::config::Config::default();
    config.hfclk_source = HfclkSource::ExternalXtal;
    let p = embassy_nrf::init(config);
    let mut cfg = uarte::Config::default();
    cfg.baudrate = Baudrate::Baud57600;
    // TIMER0 counts the received bytes through two PPI channels (and a PPI group).
    let uart = BufferedUarte::new(
        p.UARTE0,
        p.TIMER0,
        p.PPI_CH0,
        p.PPI_CH1,
        p.PPI_GROUP0,
        p.P0_08, // RXD
        p.P0_06, // TXD
        Irqs,
        cfg,
        RX.take(),
        TX.take(),
    );
    let (rx, tx) = uart.split(); // receive half first, unlike embassy-stm32 and embassy-rp
    spawner.spawn(radio(tx, rx).unwrap());
    spawner.spawn(pprz_example_one_link::attitude().unwrap());
    spawner.spawn(pprz_example_one_link::failsafe().unwrap());
}
