//! The one-link firmware of `minimal` over USB instead of a UART: the nRF52840's own USB
//! port (the DK's "nRF USB" connector) is a CDC-ACM serial port (`/dev/ttyACM0` on
//! Linux) carrying PPRZ v2 telemetry, and the ground's PING, SETTING and GET_SETTING are
//! answered on it. The facade `Link` serves one device, here the CDC-ACM class through
//! the `pprz-devices` USB adapter: while the host has not opened the port (DTR low) or
//! the cable is out, writes fail at once and are counted, so the queue keeps shedding by
//! priority instead of stalling. A failsafe task raises `GO_HOME` when the ground has
//! been silent for 5 s.
//!
//! VBUS: `HardwareVbusDetect`. The chip's POWER peripheral reports the cable (USB
//! detected, removed) and its USB regulator (power ready) as events, and the driver
//! powers the USB peripheral up and down on them, so unplugging and plugging again
//! works. `SoftwareVbusDetect` is for a firmware whose Bluetooth SoftDevice owns POWER
//! and must hand those events on by hand; this one has no SoftDevice.

#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_nrf::config::HfclkSource;
use embassy_nrf::peripherals::USBD;
use embassy_nrf::usb::vbus_detect::{self, HardwareVbusDetect};
use embassy_nrf::usb::{self, Driver};
use embassy_usb::UsbDevice;
use panic_halt as _;
use pprz_devices::usb::{CdcPort, CdcRx, CdcTx, UsbConfig, UsbCounters};
use static_cell::StaticCell;

embassy_nrf::bind_interrupts!(struct Irqs {
    USBD => usb::InterruptHandler<USBD>;
    CLOCK_POWER => vbus_detect::InterruptHandler;
});

type UsbDriver = Driver<'static, HardwareVbusDetect>;

static USB_COUNTERS: UsbCounters = UsbCounters::new();
/// The CDC-ACM port's descriptor and control buffers and class state.
static USB_PORT: StaticCell<CdcPort> = StaticCell::new();

#[embassy_executor::task]
async fn usb_device(mut device: UsbDevice<'static, UsbDriver>) {
    device.run().await
}

#[embassy_executor::task]
async fn link(tx: CdcTx<'static, 'static, UsbDriver>, rx: CdcRx<'static, 'static, UsbDriver>) {
    pprz_example_one_link::run(tx, rx).await // writer + reader + services, forever
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // The USB peripheral runs from the 32 MHz crystal (HFXO), not the internal oscillator.
    let mut config = embassy_nrf::config::Config::default();
    config.hfclk_source = HfclkSource::ExternalXtal;
    let p = embassy_nrf::init(config);
    let driver = Driver::new(p.USBD, Irqs, HardwareVbusDetect::new(Irqs));
    let mut config = embassy_usb::Config::new(0x1209, 0x0001);
    config.manufacturer = Some("pprz-embassy");
    config.product = Some("telemetry");
    let (device, rx, tx) = pprz_devices::usb::cdc_acm(
        driver,
        config,
        USB_PORT.init(CdcPort::new()),
        &USB_COUNTERS,
        UsbConfig::default(),
    );
    spawner.spawn(usb_device(device).unwrap());
    spawner.spawn(link(tx, rx).unwrap());
    spawner.spawn(pprz_example_one_link::attitude().unwrap());
    spawner.spawn(pprz_example_one_link::failsafe().unwrap());
}
