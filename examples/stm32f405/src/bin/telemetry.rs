//! The example aircraft on an STM32F405 autopilot ("Apogee"-class).
//!
//! * Telemetry radio on USART2 (PA2 TX, PA3 RX) at 57600 baud, PPRZ v2: downlink writer
//!   and datalink reader (PING, SETTING, GET_SETTING). With the cargo feature
//!   `flow-control` (on by default) the UART also uses hardware flow control, PA1 RTS and
//!   PA0 CTS: the modem's CTS holds our transmitter while its buffer is full, so frames
//!   wait in the downlink's priority queue instead of overflowing the modem. Built with
//!   `--no-default-features` (a radio without RTS/CTS wiring), the downlink paces the
//!   radio instead, with [`SIK_PACING`]. (USART1's only RTS/CTS pins, PA12/PA11, are the
//!   USB OTG FS data lines, hence USART2.)
//! * A second output: USB CDC-ACM (OTG FS, PA11/PA12), the same telemetry with the same
//!   priorities; unplugged, its writes fail fast and are counted.
//! * The application of `pprz-example-app`: simulated sensors and rotorcraft state,
//!   periodic telemetry from the project's `telemetry.xml`, settings.
//! * Persistent settings (the gain) in flash sectors 1 to 3 (`0x0800_4000..0x0801_0000`,
//!   three 16 KiB sectors; `memory.x` starts the code at sector 4), through
//!   embassy-stm32's async flash driver: loaded at start, stored when the ground sets
//!   setting 4 (the store flag) to 1.
//! * With the cargo feature `secure`, the radio is a secure PPRZ link (pprz-secure,
//!   `salty` backend): nothing but the key exchange until the ground completes the
//!   handshake, then every radio frame encrypted and authenticated; the handshake's
//!   ephemeral keys come from the hardware RNG; keys embedded at build time from the key
//!   file named by `PPRZ_SECURE_KEYS` (the published INSECURE test keys, with a build
//!   warning, without it). The USB output stays plain (a cable, not the air).

#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_stm32::flash::{self, Async, Bank1Region1, Flash};
use embassy_stm32::gpio::Pull;
use embassy_stm32::peripherals::{USART2, USB_OTG_FS};
use embassy_stm32::rcc::{
    AHBPrescaler, APBPrescaler, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv, PllSource, Sysclk,
};
use embassy_stm32::usart::{
    self, BufferedInterruptHandler, BufferedUart, BufferedUartRx, BufferedUartTx,
};
use embassy_stm32::{bind_interrupts, usb};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_usb::UsbDevice;
use panic_halt as _;
use pprz_devices::stm32::{UartErrorCounters, UartRx, f405};
use pprz_devices::usb::{CdcPort, CdcTx, UsbConfig, UsbCounters};
use pprz_example_app::{AC_ID, Config};
use pprz_settings::{PageCache, PersistentStore, StoreControl, buffer_len};
use pprz_telemetry::pprz_transports::{AnyTransport, PprzV2};
use pprz_telemetry::{Device, DeviceConfig, Downlink, FrameArena, Pacing, Port, run_writer};
use static_cell::{ConstStaticCell, StaticCell};

#[cfg(not(feature = "secure"))]
bind_interrupts!(struct Irqs {
    USART2 => BufferedInterruptHandler<USART2>;
    OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
    FLASH => flash::InterruptHandler;
});
#[cfg(feature = "secure")]
bind_interrupts!(struct Irqs {
    USART2 => BufferedInterruptHandler<USART2>;
    OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
    FLASH => flash::InterruptHandler;
    RNG => embassy_stm32::rng::InterruptHandler<embassy_stm32::peripherals::RNG>;
});

/// The radio's configuration: PPRZ v2, paced without flow control; with `secure`, room
/// for the secure overhead after every frame.
#[cfg(not(feature = "secure"))]
const RADIO: DeviceConfig = DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()));
#[cfg(feature = "secure")]
const RADIO: DeviceConfig = pprz_secure::link::SecureLink::<M>::DEVICE;

/// The radio's secure link (feature `secure`), shared by its writer, its reader and the
/// handshake.
#[cfg(feature = "secure")]
static SECURE: pprz_secure::link::SecureLink<M> = pprz_secure::link::SecureLink::aircraft(AC_ID);
/// The aircraft's keys (feature `secure`), embedded by build.rs.
#[cfg(feature = "secure")]
static KEYS: pprz_secure::KeyFile =
    pprz_secure::const_key_file!(include_str!(concat!(env!("OUT_DIR"), "/aircraft.keys")));

/// Whether the radio UART uses hardware flow control (RTS/CTS): cargo feature
/// `flow-control`, on by default; build with `--no-default-features` for a radio whose
/// RTS/CTS lines are not wired.
const FLOW_CONTROL: bool = cfg!(feature = "flow-control");

/// The link budget of a SiK radio without flow control (57600 baud serial, `AIR_SPEED=64`).
/// Air rate: 64 kbit/s is 8000 B/s on the air, half of it with `ECC=1` (Golay coding
/// doubles every byte), less about a quarter for the radio's packet framing and its
/// time-division turns with the ground radio: 3000 B/s. On the low side on purpose: too
/// low only idles the link a little, too high fills the modem's serial buffer (1 to 2 KiB)
/// until it drops bytes. Budget: one longest PPRZ v2 frame (255 bytes) plus a margin may
/// wait in the UART driver and the modem, so an acknowledgement waits at most about two
/// frame times (170 ms). Measure the radio's real throughput with a saturating test and
/// adjust.
const SIK_PACING: Pacing = Pacing::new(3_000, 320);

/// The radio's pacing: none when the modem's CTS line pushes back, [`SIK_PACING`] when
/// nothing does.
const RADIO_PACING: Option<Pacing> = if FLOW_CONTROL { None } else { Some(SIK_PACING) };

/// Radio (0) and USB (1), 32 frames each at most.
type Dl = Downlink<'static, M, 2, 32>;
type UsbDriver = usb::Driver<'static, USB_OTG_FS>;

/// Pending frames of both devices: about 2 s of a saturated 57600-baud radio.
static ARENA: FrameArena<M, 8192> = FrameArena::new();
static DOWNLINK: Dl = Downlink::new(
    &ARENA,
    AC_ID,
    [
        RADIO.pacing(RADIO_PACING),
        DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())).depth(16),
    ],
);
static RADIO_ERRORS: UartErrorCounters = UartErrorCounters::new();
static UART_BUFFERS: StaticCell<([u8; 256], [u8; 256])> = StaticCell::new();
static USB_COUNTERS: UsbCounters = UsbCounters::new();
/// USB OUT endpoint buffer.
static USB_EP_OUT: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
/// The CDC-ACM port's descriptor and control buffers and class state.
static USB_PORT: StaticCell<CdcPort> = StaticCell::new();

/// The settings' flash: sectors 1 to 3, offsets within `bank1_region1` (sectors 0 to 3,
/// 16 KiB each, from `0x0800_0000`). Sector 0 holds the vector table; `memory.x` puts
/// everything else from sector 4 on.
const SETTINGS_SECTORS: core::ops::Range<u32> = 0x4000..0x1_0000;
/// The persistent settings' store: three 16 KiB sectors, room for 16 settings.
type Store = PersistentStore<Bank1Region1<'static, Async>, PageCache<3>, { buffer_len(16) }>;
static STORE: StaticCell<Store> = StaticCell::new();
/// The store flag's control. The example vehicle is simulated and has no motors, so it
/// accepts every request; an aircraft stores only with its motors killed
/// (`StoreControl::with_guard`): erasing a sector stalls the CPU for hundreds of
/// milliseconds, and the radio's interrupt-driven UART loses what arrives meanwhile.
static CONTROL: StoreControl<M> = StoreControl::new();

#[embassy_executor::task]
async fn radio_writer(mut port: Port<'static>, tx: BufferedUartTx<'static>) {
    #[cfg(not(feature = "secure"))]
    run_writer(&mut port, tx).await;
    #[cfg(feature = "secure")]
    pprz_telemetry::run_writer_with(&mut port, tx, &SECURE).await
}

#[embassy_executor::task]
async fn usb_writer(mut port: Port<'static>, tx: CdcTx<'static, 'static, UsbDriver>) {
    run_writer(&mut port, tx).await
}

#[embassy_executor::task]
async fn usb_device(mut device: UsbDevice<'static, UsbDriver>) {
    device.run().await
}

/// The application, its persistent settings in `store`.
#[cfg(not(feature = "secure"))]
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

/// The application on the secure radio, its handshake's keys from the hardware RNG, its
/// persistent settings in `store`.
#[cfg(feature = "secure")]
#[embassy_executor::task]
async fn aircraft(
    radio: Device<'static>,
    rx: UartRx<'static, BufferedUartRx<'static>>,
    rng: embassy_stm32::rng::Rng<'static, embassy_stm32::peripherals::RNG>,
    store: &'static mut Store,
) {
    let keys = match KEYS.aircraft() {
        Ok(keys) => keys,
        Err(e) => panic!("the aircraft's keys: {e}"),
    };
    let responder = pprz_secure::Responder::new(AC_ID, keys);
    let Err(e) = pprz_example_app::run_secure_aircraft_with_store(
        radio,
        rx,
        Config::default(),
        &SECURE,
        responder,
        rng,
        store,
        &CONTROL,
    )
    .await;
    panic!("the aircraft application cannot start: {e}");
}

/// The radio UART's settings: 57600 baud 8N1. CTS has a pull-down, so with flow control
/// an unconnected (or broken) CTS line reads "clear to send": the radio then still works,
/// only without back-pressure, instead of falling silent.
fn radio_config() -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = 57_600;
    config.cts_pull = Pull::Down;
    config
}

/// 168 MHz from the 16 MHz HSI, 48 MHz for USB.
fn clocks() -> embassy_stm32::Config {
    let mut config = embassy_stm32::Config::default();
    config.rcc.hsi = true;
    config.rcc.pll_src = PllSource::HSI;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV8,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2), // 168 MHz system clock
        divq: Some(PllQDiv::DIV7), // 48 MHz USB clock
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV4;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(clocks());

    // Radio: USART2, interrupt driven, 256-byte buffers (44 ms of 57600 baud each way);
    // with RTS (PA1) and CTS (PA0) under the `flow-control` feature.
    let (tx_buf, rx_buf) = UART_BUFFERS.init(([0; 256], [0; 256]));
    #[cfg(feature = "flow-control")]
    let uart = BufferedUart::new_with_rtscts(
        p.USART2,
        p.PA3,
        p.PA2,
        p.PA1,
        p.PA0,
        Irqs,
        tx_buf,
        rx_buf,
        radio_config(),
    );
    #[cfg(not(feature = "flow-control"))]
    let uart = BufferedUart::new(p.USART2, p.PA3, p.PA2, tx_buf, rx_buf, Irqs, radio_config());
    let uart = match uart {
        Ok(uart) => uart,
        Err(e) => panic!("radio UART: {e:?}"),
    };
    let (radio_tx, radio_rx) = uart.split();
    let radio_rx = UartRx::new(radio_rx, &RADIO_ERRORS);

    // USB CDC-ACM: a second telemetry output.
    let driver = f405::usb_otg_fs(p.USB_OTG_FS, Irqs, p.PA12, p.PA11, USB_EP_OUT.take(), true);
    let mut usb_config = embassy_usb::Config::new(0x1209, 0x0001);
    usb_config.manufacturer = Some("pprz-embassy");
    usb_config.product = Some("telemetry");
    let (device, _usb_rx, usb_tx) = pprz_devices::usb::cdc_acm(
        driver,
        usb_config,
        USB_PORT.init(CdcPort::new()),
        &USB_COUNTERS,
        UsbConfig::default(),
    );

    // The settings' flash: bank 1's first region (sectors 0 to 3), sectors 1 to 3 of it.
    let region = Flash::new(p.FLASH, Irqs).into_regions().bank1_region1;
    let store = match Store::with_page_cache(region, SETTINGS_SECTORS) {
        Ok(store) => STORE.init(store),
        Err(e) => panic!("settings flash: {e}"),
    };

    let Ok([radio, usb]) = DOWNLINK.ports() else {
        panic!("the downlink's ports are taken once, here");
    };
    let radio_device = radio.device();
    spawner.spawn(usb_device(device).unwrap());
    spawner.spawn(radio_writer(radio, radio_tx).unwrap());
    spawner.spawn(usb_writer(usb, usb_tx).unwrap());
    #[cfg(not(feature = "secure"))]
    spawner.spawn(aircraft(radio_device, radio_rx, store).unwrap());
    #[cfg(feature = "secure")]
    spawner.spawn(
        aircraft(
            radio_device,
            radio_rx,
            embassy_stm32::rng::Rng::new(p.RNG, Irqs),
            store,
        )
        .unwrap(),
    );
}
