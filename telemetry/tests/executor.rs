//! The downlink as a firmware wires it (`const` statics, one writer task per device
//! taking the device's port), running on the Embassy std executor with embassy-time's mock driver: a busy
//! radio and an SD log, the Figure 27 trace of Jornet's design on the radio, and the log flushed per frame.
//!
//! The mock clock is advanced by a task of its own, so the run is deterministic. The test
//! thread only waits for the result (with a generous guard against a hang, not a timing
//! assertion).

use pprz_telemetry::SendOptions;
use std::convert::Infallible;
use std::sync::Mutex as StdMutex;
use std::sync::mpsc;

use embassy_executor::{Executor, Spawner};
use embassy_futures::yield_now;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::{Duration, MockDriver, Timer};
use pprz_default::messages::telemetry::DlValue;
use pprz_messages::Decode;
use pprz_telemetry::pprz_transports::{AnyTransport, Decoder, PprzLog, PprzLogDecoder, PprzV2};
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, Port, Targets, run_writer};
use static_cell::StaticCell;

type Dl = Downlink<'static, M, 2, 16>;

static ARENA: FrameArena<M, 2048> = FrameArena::new();
/// A radio and an SD log flushed after every frame: a plain `static` (`Downlink::new` is
/// a `const fn`).
static DOWNLINK: Dl = Downlink::new(
    &ARENA,
    7,
    [
        DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),
        DeviceConfig::new(AnyTransport::PprzLog(PprzLog::TELEMETRY)).flush(true),
    ],
);
static EXECUTOR: StaticCell<Executor> = StaticCell::new();
/// What reached the devices: frames of the radio, frames of the log, flushes.
struct Wire(Vec<Vec<u8>>, Vec<Vec<u8>>, u32);

static WIRE: StdMutex<Wire> = StdMutex::new(Wire(Vec::new(), Vec::new(), 0));

/// A device that takes `byte_us` microseconds per byte.
struct SlowDevice {
    index: usize,
    byte_us: u64,
}

impl embedded_io_async::ErrorType for SlowDevice {
    type Error = Infallible;
}

impl embedded_io_async::Write for SlowDevice {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        Timer::after(Duration::from_micros(self.byte_us * buf.len() as u64)).await;
        let mut wire = WIRE.lock().unwrap();
        let frames = if self.index == 0 {
            &mut wire.0
        } else {
            &mut wire.1
        };
        frames.push(buf.to_vec());
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        WIRE.lock().unwrap().2 += 1;
        Ok(())
    }
}

#[embassy_executor::task(pool_size = 2)]
async fn writer(mut port: Port<'static>, byte_us: u64) {
    let mut device = SlowDevice {
        index: port.device().index(),
        byte_us,
    };
    run_writer(&mut port, &mut device).await
}

#[embassy_executor::task]
async fn clock() {
    loop {
        MockDriver::get().advance(Duration::from_micros(50));
        yield_now().await;
    }
}

#[embassy_executor::task]
async fn app(spawner: Spawner, downlink: &'static Dl, done: mpsc::Sender<()>) {
    // The radio is busy with a first frame while four more arrive: priorities 0, 1, 0, 1.
    let mut ports = Some(downlink.ports().unwrap());
    // Sent through the copyable, type-erased handle, as application tasks would.
    let sender = downlink.sender();
    for (index, priority) in [(0u8, 9u8), (1, 0), (2, 1), (3, 0), (4, 1)] {
        sender
            .send_with(
                &DlValue { index, value: 0.0 },
                SendOptions::new().on(Targets::ALL).priority(priority),
            )
            .unwrap();
        if let Some([radio, log]) = ports.take() {
            assert_eq!((radio.device().index(), log.device().index()), (0, 1));
            spawner.spawn(writer(radio, 173).unwrap());
            spawner.spawn(writer(log, 10).unwrap());
            yield_now().await; // let the writers take the first frame
        }
    }
    while sender.stats(0).unwrap().sent < 5 || sender.stats(1).unwrap().sent < 5 {
        Timer::after(Duration::from_millis(1)).await;
    }
    let _ = done.send(());
}

#[test]
fn firmware_style_wiring_on_the_std_executor() {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let executor = EXECUTOR.init(Executor::new());
        executor.run(|spawner| {
            spawner.spawn(clock().unwrap());
            spawner.spawn(app(spawner, &DOWNLINK, tx).unwrap());
        })
    });
    rx.recv_timeout(std::time::Duration::from_secs(60))
        .expect("the firmware finished sending");

    let wire = WIRE.lock().unwrap();
    let radio: Vec<u8> = wire
        .0
        .iter()
        .map(|bytes| {
            let mut d: Decoder<PprzV2> = Decoder::new(PprzV2::new());
            let mut input = &bytes[..];
            DlValue::decode(d.feed(&mut input).unwrap().payload())
                .unwrap()
                .index
        })
        .collect();
    // Frame 0 was on the wire; then Figure 27's order: 2nd, 4th, 1st, 3rd.
    assert_eq!(radio, [0, 2, 4, 1, 3]);
    let log: Vec<u8> = wire
        .1
        .iter()
        .map(|bytes| {
            let mut d = PprzLogDecoder::new(PprzLog::TELEMETRY);
            let mut input = &bytes[..];
            DlValue::decode(d.feed(&mut input).unwrap().payload())
                .unwrap()
                .index
        })
        .collect();
    assert_eq!(log.len(), 5);
    assert_eq!(wire.2, 5, "the log is flushed after every frame");
    assert_eq!(ARENA.stats().live, 0, "every frame's memory came back");
    for d in 0..2 {
        let s = DOWNLINK.stats(d).unwrap();
        assert_eq!((s.submitted, s.sent, s.queued), (5, 5, 0), "device {d}");
        assert!(s.is_balanced(), "{s:?}");
    }
}
