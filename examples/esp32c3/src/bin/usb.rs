//! Telemetry over the ESP32-C3's built-in USB Serial/JTAG port (GPIO18 D-, GPIO19 D+),
//! with the one-link facade `Link`: the ground's PING, SETTING and GET_SETTING answered,
//! an ATTITUDE every 100 ms, and a failsafe task that raises `GO_HOME` when the ground
//! has been silent for 5 s.
//!
//! The port is a fixed-function CDC-ACM device (USB id 303a:1001, `/dev/ttyACM0` on the
//! host), the same one espflash flashes through; no USB stack runs on the chip. esp-hal's
//! async driver implements embedded-io-async's `Read` and `Write` (feature `unstable`).
//! Its transmitter waits until the host has taken every 64-byte packet, which with no
//! host (cable unplugged, port never opened) is forever: [`FailFast`] ends such a write
//! after [`WRITE_TIMEOUT`], so the link's writer counts the frame as lost and its queue
//! keeps shedding by priority instead of holding stale frames behind a stalled one.

#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_time::{Duration, with_timeout};
use embedded_io_async::{ErrorKind, ErrorType, Write};
use esp_hal::Async;
use esp_hal::timer::timg::TimerGroup;
use esp_hal::usb::usb_serial_jtag::{UsbSerialJtag, UsbSerialJtagRx, UsbSerialJtagTx};
use panic_halt as _;

esp_bootloader_esp_idf::esp_app_desc!();

/// How long a write may wait for the host. A host with the port open polls the endpoint
/// every millisecond, so a frame (at most five 64-byte packets) goes in a few
/// milliseconds; past this, the host is taken to be absent.
const WRITE_TIMEOUT: Duration = Duration::from_millis(50);

/// The USB Serial/JTAG transmitter with a deadline on every write and flush.
///
/// A write that times out may leave the start of its frame in the peripheral's 64-byte
/// FIFO; the host receives it before the next frame, and the ground's decoder drops the
/// broken frame by its checksum.
struct FailFast(UsbSerialJtagTx<'static, Async>);

/// The one error, `TimedOut`: the host did not take a packet within [`WRITE_TIMEOUT`].
impl ErrorType for FailFast {
    type Error = ErrorKind;
}

impl Write for FailFast {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, ErrorKind> {
        match with_timeout(WRITE_TIMEOUT, Write::write(&mut self.0, buf)).await {
            Ok(Ok(n)) => Ok(n),
            Ok(Err(never)) => match never {},
            Err(_) => Err(ErrorKind::TimedOut),
        }
    }

    async fn flush(&mut self) -> Result<(), ErrorKind> {
        match with_timeout(WRITE_TIMEOUT, Write::flush(&mut self.0)).await {
            Ok(Ok(())) => Ok(()),
            Ok(Err(never)) => match never {},
            Err(_) => Err(ErrorKind::TimedOut),
        }
    }
}

#[embassy_executor::task]
async fn link(tx: FailFast, rx: UsbSerialJtagRx<'static, Async>) {
    pprz_example_one_link::run(tx, rx).await // writer + reader + services, forever
}

#[esp_rtos::main]
async fn main(spawner: Spawner) {
    let p = esp_hal::init(esp_hal::Config::default());
    let timg0 = TimerGroup::new(p.TIMG0);
    esp_rtos::start(timg0.timer0, p.FROM_CPU_INTR0);

    let (rx, tx) = UsbSerialJtag::new(p.USB_DEVICE).into_async().split();
    spawner.spawn(link(FailFast(tx), rx).unwrap());
    spawner.spawn(pprz_example_one_link::attitude().unwrap());
    spawner.spawn(pprz_example_one_link::failsafe().unwrap());
}
