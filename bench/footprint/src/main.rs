//! A minimal STM32F405 firmware that uses the telemetry stack the way a board example
//! does, so that the linker keeps what a real firmware keeps: periodic messages sent
//! through a `Downlink` (encoders, PPRZ v2 framing, frame arena, priority queue), the
//! device's writer task, and the datalink (reader task with the PPRZ v2 decoder,
//! subscriber registry, PING/SETTING/GET_SETTING services, DATALINK_REPORT).
//!
//! It is measured, not run: `bench/footprint.sh` builds it and sorts its symbols. The
//! UARTs are stand-ins (bytes go through `black_box`), the two tasks are polled in the
//! main loop with a no-op waker instead of an executor, and the time driver reads the
//! cycle counter, so nothing but the stack and a few dozen bytes of glue is linked.
//!
//! Every message is sent through the generic [`send`], so its monomorphised send path
//! is named after the message (`send::<..::Gps>`, with v0 symbol mangling) and the script
//! can tell per-message code from the stack's core.

#![no_std]
#![no_main]

use core::convert::Infallible;
use core::future::Future;
use core::hint::black_box;
use core::pin::{Pin, pin};
use core::task::{Context, Waker};

use cortex_m_rt::entry;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::Instant;
use panic_halt as _;
use pprz_default::messages::Set;
use pprz_default::messages::datalink::{Block, MoveWp};
use pprz_default::messages::telemetry::{
    Alive, Attitude, AutopilotVersion, DatalinkReport, DlValue, Energy, Gps, GpsInt, Ins, Payload,
    RotorcraftFp, RotorcraftStatus, UartErrors,
};
use pprz_messages::{Chars, Decode, Message, VarArray};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::registry::{Filter, Received};
use pprz_telemetry::services::{LinkReporter, Services};
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, run_writer};
use pprz_transports::AnyTransport;
use pprz_transports::PprzV2;
use static_cell::StaticCell;

const AC_ID: u8 = 7;
/// Queue capacity of the radio.
const QUEUE: usize = 16;
/// Subscriptions of the datalink registry.
const SUBSCRIPTIONS: usize = 8;
/// Entries of the settings table.
const SETTINGS: usize = 4;

type Dl = Downlink<'static, M, 1, QUEUE>;

/// Every pending frame of the radio: 2 KiB.
static ARENA: FrameArena<M, 2048> = FrameArena::new();
static DOWNLINK: Dl = Downlink::new(
    &ARENA,
    AC_ID,
    [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()))],
);
static SERVICES: Services<'static, Set, M, SETTINGS> = Services::new(AC_ID);
static DATALINK: Datalink<'static, M, SUBSCRIPTIONS> = Datalink::new(AC_ID);
/// The radio's reader: its PPRZ v2 decoder buffer is most of it.
static READER: StaticCell<Reader<'static, RxUart, PprzV2>> = StaticCell::new();

/// Sends one message (the monomorphised send path of each message is named after it).
#[cfg(not(feature = "encoders-only"))]
#[inline(never)]
fn send<Msg: Message>(downlink: &Dl, msg: &Msg) {
    // A drop is counted in the downlink statistics.
    let _ = black_box(downlink.send(msg));
}

/// With the `encoders-only` feature: only the generated encoder of each message, so its
/// size can be read off the symbol `encode::<Msg>` (plus a call and a return).
#[cfg(feature = "encoders-only")]
fn send<Msg: Message>(downlink: &Dl, msg: &Msg) {
    let _ = downlink;
    let mut buf = [0u8; 256];
    // The length is hidden from the compiler, as for a frame in the arena.
    black_box(encode(msg, black_box(&mut buf[..])));
}

/// The generated encoder of `Msg`, out of line.
#[cfg(feature = "encoders-only")]
#[inline(never)]
fn encode<Msg: Message>(msg: &Msg, buf: &mut [u8]) -> usize {
    msg.encode(buf).unwrap_or(0)
}

/// Polls a task once (out of line and named after the task's future, so its code is
/// attributed to the stack module it comes from).
#[inline(never)]
fn poll_task<F: Future>(task: Pin<&mut F>, cx: &mut Context<'_>) {
    let _ = task.poll(cx);
}

/// Handles one received message of type `Msg` (an application callback).
fn handle<Msg: for<'a> Decode<'a>>(rx: &Received<'_, '_>) {
    if let Ok(msg) = rx.decode::<Msg>() {
        black_box(&msg);
    }
}

fn input(t: u32) -> i32 {
    black_box(t) as i32
}

/// The periodic telemetry of the firmware: one function per message, as a scheduler
/// calls them.
static PERIODIC: [fn(&Dl, u32); 12] = [
    |dl, t| {
        send(
            dl,
            &Alive {
                md5sum: VarArray::new(&black_box([t as u8; 16])),
            },
        )
    },
    |dl, t| {
        send(
            dl,
            &RotorcraftStatus {
                link_imu_nb_err: t,
                frame_rate: input(t) as u8,
                ..Default::default()
            },
        )
    },
    |dl, t| {
        let v = input(t);
        send(
            dl,
            &RotorcraftFp {
                east: v,
                north: v + 1,
                up: v + 2,
                flight_time: t as u16,
                ..Default::default()
            },
        )
    },
    |dl, t| {
        let v = input(t) as f32;
        send(
            dl,
            &Attitude {
                phi: v,
                psi: v * 0.5,
                theta: -v,
            },
        )
    },
    |dl, t| {
        let v = input(t);
        send(
            dl,
            &Gps {
                mode: 3,
                utm_east: v,
                utm_north: v + 7,
                alt: v - 3,
                itow: t,
                ..Default::default()
            },
        )
    },
    |dl, t| {
        send(
            dl,
            &GpsInt {
                lat: input(t),
                lon: input(t + 1),
                tow: t,
                ..Default::default()
            },
        )
    },
    |dl, t| {
        send(
            dl,
            &Ins {
                ins_x: input(t),
                ins_z: input(t + 2),
                ..Default::default()
            },
        )
    },
    |dl, t| {
        send(
            dl,
            &Energy {
                voltage: input(t) as f32,
                ..Default::default()
            },
        )
    },
    |dl, t| {
        send(
            dl,
            &DlValue {
                index: t as u8,
                value: input(t) as f32,
            },
        )
    },
    |dl, t| {
        send(
            dl,
            &UartErrors {
                overrun_cnt: t as u16,
                ..Default::default()
            },
        )
    },
    |dl, t| {
        send(
            dl,
            &AutopilotVersion {
                version: t,
                desc: Chars::from_str("pprz-embassy"),
            },
        )
    },
    |dl, t| {
        let bytes = black_box([t as u8; 64]);
        send(
            dl,
            &Payload {
                values: VarArray::new(&bytes[..usize::from(t as u8 & 63)]),
            },
        )
    },
];

/// The radio's transmitter (a stand-in for a UART driver).
struct TxUart;

impl embedded_io_async::ErrorType for TxUart {
    type Error = Infallible;
}

impl embedded_io_async::Write for TxUart {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        black_box(buf);
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// The radio's receiver (a stand-in for a UART driver).
struct RxUart;

impl embedded_io_async::ErrorType for RxUart {
    type Error = Infallible;
}

impl embedded_io_async::Read for RxUart {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let n = black_box(buf.len());
        for b in buf.iter_mut().take(n) {
            *b = black_box(0x99);
        }
        Ok(n)
    }
}

/// Time from the cycle counter (enough for a footprint measurement).
struct Clock;

impl embassy_time_driver::Driver for Clock {
    fn now(&self) -> u64 {
        u64::from(cortex_m::peripheral::DWT::cycle_count())
    }

    fn schedule_wake(&self, _at: u64, waker: &Waker) {
        // The main loop polls every task anyway.
        waker.wake_by_ref();
    }
}

embassy_time_driver::time_driver_impl!(static CLOCK: Clock = Clock);

static GAIN: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

fn get_gain() -> f32 {
    f32::from_bits(GAIN.load(core::sync::atomic::Ordering::Relaxed))
}

fn set_gain(value: f32) {
    GAIN.store(value.to_bits(), core::sync::atomic::Ordering::Relaxed);
}

#[entry]
fn main() -> ! {
    let downlink: &'static Dl = &DOWNLINK;
    let datalink = &DATALINK;
    let set_up = SERVICES
        .settings()
        .add("gain", &get_gain, &set_gain)
        .is_ok()
        && SERVICES.subscribe(datalink.registry()).is_ok()
        && datalink
            .subscribe(Filter::message::<Block>(), &handle::<Block>)
            .is_ok()
        && datalink
            .subscribe(Filter::message::<MoveWp>(), &handle::<MoveWp>)
            .is_ok();
    // Kept (not asserted) so the measured firmware has no formatting code for it.
    black_box(set_up);
    let [mut port] = match downlink.ports() {
        Ok(ports) => ports,
        Err(_) => loop {
            cortex_m::asm::wfi();
        },
    };
    let device = port.device();
    let mut writer = pin!(run_writer(&mut port, TxUart));
    let reader = READER.init(Reader::new(RxUart, PprzV2::new(), device));
    let mut uplink = pin!(reader.run(datalink));
    let mut cx = Context::from_waker(Waker::noop());
    let mut reporter = LinkReporter::new();
    let mut tick = 0u32;
    loop {
        tick = tick.wrapping_add(1);
        let periodic = PERIODIC[black_box(tick as usize) % PERIODIC.len()];
        periodic(downlink, tick);
        if tick.is_multiple_of(600) {
            let report = reporter.report(
                Instant::now(),
                &datalink.stats(),
                &downlink.stats(0).unwrap_or_default(),
            );
            send(downlink, &DatalinkReport::from(report));
        }
        poll_task(writer.as_mut(), &mut cx);
        poll_task(uplink.as_mut(), &mut cx);
    }
}
