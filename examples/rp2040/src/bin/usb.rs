//! The one-link firmware of `minimal` over USB instead of a UART: the Pico's USB port is
//! a CDC-ACM serial port (`/dev/ttyACM0` on Linux) carrying PPRZ v2 telemetry, and the
//! ground's PING, SETTING and GET_SETTING are answered on it. The facade `Link` serves
//! one device, here the CDC-ACM class through the `pprz-devices` USB adapter: while the
//! host has not opened the port (DTR low) or the cable is out, writes fail at once and
//! are counted, so the queue keeps shedding by priority instead of stalling. A failsafe
//! task raises `GO_HOME` when the ground has been silent for 5 s.

#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_rp::peripherals::USB;
use embassy_rp::usb::{Driver, InterruptHandler};
use embassy_usb::UsbDevice;
use panic_halt as _;
use pprz_devices::usb::{CdcPort, CdcRx, CdcTx, UsbConfig, UsbCounters};
use static_cell::StaticCell;

embassy_rp::bind_interrupts!(struct Irqs { USBCTRL_IRQ => InterruptHandler<USB>; });

type UsbDriver = Driver<'static, USB>;

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

#[embassy_executor::main(
    executor = "embassy_rp::executor::Executor",
    entry = "cortex_m_rt::entry"
)]
async fn main(spawner: Spawner) {
    // The default configuration: the Pico's 12 MHz crystal, 125 MHz system clock, 48 MHz
    // USB clock from the USB PLL.
    let p = embassy_rp::init(Default::default());
    let driver = Driver::new(p.USB, Irqs);
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
