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
use embassy_usb::class::cdc_acm::{CdcAcmClass, State};
use panic_halt as _;
use pprz_devices::usb::{CdcRx, CdcTx, UsbConfig, UsbCounters};
use static_cell::{ConstStaticCell, StaticCell};

embassy_rp::bind_interrupts!(struct Irqs { USBCTRL_IRQ => InterruptHandler<USB>; });

type UsbDriver = Driver<'static, USB>;

static USB_COUNTERS: UsbCounters = UsbCounters::new();
/// USB buffers: configuration descriptor, BOS descriptor, control transfers (the RP2040's
/// endpoints have their own 4 KiB of USB RAM).
static USB_BUFFERS: ConstStaticCell<([u8; 256], [u8; 256], [u8; 64])> =
    ConstStaticCell::new(([0; 256], [0; 256], [0; 64]));
static CDC_STATE: StaticCell<State> = StaticCell::new();

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
    let (config_descriptor, bos_descriptor, control) = USB_BUFFERS.take();
    let mut builder = embassy_usb::Builder::new(
        driver,
        config,
        config_descriptor,
        bos_descriptor,
        &mut [],
        control,
    );
    let class = CdcAcmClass::new(&mut builder, CDC_STATE.init(State::new()), 64);
    let device = builder.build();
    let (rx, tx) =
        match pprz_devices::usb::split::<_, 64>(class, &USB_COUNTERS, UsbConfig::default()) {
            Ok(halves) => halves,
            Err(e) => panic!("USB CDC-ACM: {e}"),
        };
    spawner.spawn(usb_device(device).unwrap());
    spawner.spawn(link(tx, rx).unwrap());
    spawner.spawn(pprz_example_one_link::attitude().unwrap());
    spawner.spawn(pprz_example_one_link::failsafe().unwrap());
}
