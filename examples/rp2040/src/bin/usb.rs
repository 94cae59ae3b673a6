//! The one-link firmware of `minimal` over USB instead of a UART: the Pico's USB port is
//! a CDC-ACM serial port (`/dev/ttyACM0` on Linux) carrying PPRZ v2 telemetry, and the
//! ground's PING, SETTING and GET_SETTING are answered on it. The facade `Link` serves
//! one device, here the CDC-ACM class through the `pprz-devices` USB adapter: while the
//! host has not opened the port (DTR low) or the cable is out, writes fail at once and
//! are counted, so the queue keeps shedding by priority instead of stalling. A failsafe
//! task raises `GO_HOME` when the ground has been silent for 5 s.

#![no_std]
#![no_main]

use core::sync::atomic::{AtomicBool, Ordering};
use embassy_executor::Spawner;
use embassy_rp::peripherals::USB;
use embassy_rp::usb::{Driver, InterruptHandler};
use embassy_time::{Duration, Ticker};
use embassy_usb::UsbDevice;
use embassy_usb::class::cdc_acm::{CdcAcmClass, State};
use panic_halt as _;
use pprz_default::messages::{Set, telemetry::Attitude};
use pprz_devices::usb::{CdcRx, CdcTx, UsbConfig, UsbCounters};
use pprz_telemetry::{FrameArena, Health, HealthConfig, Link, LinkMutex};
use static_cell::{ConstStaticCell, StaticCell};

embassy_rp::bind_interrupts!(struct Irqs { USBCTRL_IRQ => InterruptHandler<USB>; });

type UsbDriver = Driver<'static, USB>;

static ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
/// Aircraft 7; the ground is lost after 5 s of silence.
static LINK: Link<'static, Set> =
    Link::new(&ARENA, 7).health_config(HealthConfig::new().lost_after(Duration::from_secs(5)));
/// Set when the ground has been silent for 5 s: your autopilot flies home.
static GO_HOME: AtomicBool = AtomicBool::new(false);
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
    let Err(e) = LINK.run(tx, rx).await; // writer + reader + services, forever
    panic!("{e}");
}

#[embassy_executor::task]
async fn attitude() {
    let mut ticker = Ticker::every(Duration::from_millis(100));
    loop {
        ticker.next().await;
        // A message that cannot be queued (or written) is counted in LINK.stats().
        let _ = LINK.send(&Attitude {
            phi: 0.1,
            psi: 0.0,
            theta: 0.0,
        });
    }
}

#[embassy_executor::task]
async fn failsafe() {
    LINK.health().wait_for(Health::Up).await; // not before the ground was heard once
    loop {
        LINK.health().wait_for(Health::Lost).await;
        GO_HOME.store(true, Ordering::Relaxed);
        LINK.health().wait_for(Health::Up).await;
    }
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
    spawner.spawn(attitude().unwrap());
    spawner.spawn(failsafe().unwrap());
}
