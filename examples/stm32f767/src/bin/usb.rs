//! Telemetry over USB CDC-ACM on an STM32F767 (USB OTG FS: PA11 DM, PA12 DP, PA9 VBUS
//! sense), with the one-link facade `Link`: the ground's PING, SETTING and GET_SETTING
//! answered, an ATTITUDE every 100 ms, and a failsafe task that raises `GO_HOME` when
//! the ground has been silent for 5 s.
//!
//! The port appears on the host as `/dev/ttyACM0` (USB id 1209:0001). While the cable is
//! unplugged or the port closed, writes fail at once and are counted
//! (`pprz_devices::usb`), so the queue keeps shedding by priority instead of stalling.
//!
//! Clocks: 216 MHz from an 8 MHz HSE in bypass mode (the ST-LINK's MCO on a
//! Nucleo-F767ZI), 48 MHz for USB from the main PLL's Q output.

#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_stm32::peripherals::USB_OTG_FS;
use embassy_stm32::rcc::{
    AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv, PllSource,
    Sysclk, mux,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::{bind_interrupts, usb};
use embassy_usb::UsbDevice;
use panic_halt as _;
use pprz_devices::usb::{CdcPort, CdcRx, CdcTx, UsbConfig, UsbCounters};
use static_cell::{ConstStaticCell, StaticCell};

bind_interrupts!(struct Irqs { OTG_FS => usb::InterruptHandler<USB_OTG_FS>; });

type UsbDriver = usb::Driver<'static, USB_OTG_FS>;

static USB_COUNTERS: UsbCounters = UsbCounters::new();
/// USB OUT endpoint buffer.
static USB_EP_OUT: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
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

/// 216 MHz from the 8 MHz HSE, 48 MHz for USB. The Nucleo-F767ZI feeds the ST-LINK's
/// 8 MHz clock into OSC_IN (`HseMode::Bypass`); a board with a crystal there needs
/// `HseMode::Oscillator` and, for another frequency, another `prediv`. The HSI (1 %)
/// is not accurate enough for USB full speed.
fn clocks() -> embassy_stm32::Config {
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Bypass,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,   // 2 MHz PLL input
        mul: PllMul::MUL216,       // 432 MHz VCO
        divp: Some(PllPDiv::DIV2), // 216 MHz system clock
        divq: Some(PllQDiv::DIV9), // 48 MHz for USB
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV4; // 54 MHz
    config.rcc.apb2_pre = APBPrescaler::DIV2; // 108 MHz
    // The F7 picks the 48 MHz clock with a mux (PLL Q or PLLSAI P); the F4 has none.
    config.rcc.mux.clk48sel = mux::Clk48sel::PLL1_Q;
    config
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(clocks());

    // An autopilot is self-powered (its own battery), so it senses VBUS on PA9 to see
    // the cable come and go; the Nucleo-F767ZI wires PA9 to its user USB connector.
    let mut driver_config = usb::Config::default();
    driver_config.vbus_detection = true;
    let driver = usb::Driver::new_fs(
        p.USB_OTG_FS,
        Irqs,
        p.PA12,
        p.PA11,
        USB_EP_OUT.take(),
        driver_config,
    );
    let mut usb_config = embassy_usb::Config::new(0x1209, 0x0001);
    usb_config.manufacturer = Some("pprz-embassy");
    usb_config.product = Some("telemetry");
    let (device, rx, tx) = pprz_devices::usb::cdc_acm(
        driver,
        usb_config,
        USB_PORT.init(CdcPort::new()),
        &USB_COUNTERS,
        UsbConfig::default(),
    );

    spawner.spawn(usb_device(device).unwrap());
    spawner.spawn(link(tx, rx).unwrap());
    spawner.spawn(pprz_example_one_link::attitude().unwrap());
    spawner.spawn(pprz_example_one_link::failsafe().unwrap());
}
