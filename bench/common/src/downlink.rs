//! Workload 3: the downlink end to end on the host.
//!
//! `Downlink::send` (encode into arena memory, priority queue) -> `run_writer` (the
//! device's writer task) -> a [`Sink`] device that accepts every write at once, then the
//! frame's arena memory is released. The same message sequence as [`crate::stream`]
//! (GPS and ATTITUDE alternating), sent in batches of [`BATCH`] between which the
//! producer yields, so the writer drains the queue as a firmware's writer task would
//! between two scheduler ticks.
//!
//! Both futures are polled by `embassy_futures::block_on`, the smallest executor (one
//! thread, no timer, no system call; on a Cortex-M without an executor it polls the same
//! way), so the instruction count is deterministic. The arena's and the queue's lock is a
//! `CriticalSectionRawMutex` (the downlink's ports and type-erased handles need a mutex
//! that is `Sync`): on the host critical-section's `std` implementation (a process-wide
//! `std::sync::Mutex` plus a thread-local flag), on a Cortex-M an interrupt mask of a
//! few instructions (`cortex-m`'s `critical-section-single-core`), so the host figure
//! overstates that part (see `BENCHMARKS.md`).

use core::convert::Infallible;

use embassy_futures::select::{Either, select};
use embassy_futures::{block_on, yield_now};
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, RawMutex};
use pprz_telemetry::stats::DeviceStats;
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, Port, run_writer};
use pprz_transports::PprzV2;

use pprz_telemetry::SendOptions;

use crate::stream::{AC_ID, attitude, gps};

/// Bytes of the frame arena.
pub const ARENA_BYTES: usize = 4096;
/// Queue capacity of the device.
pub const QUEUE: usize = 16;
/// Messages sent between two yields of the producer.
pub const BATCH: usize = 8;
/// Messages sent between two yields of the producer in the flood: three queues' worth,
/// so every burst fills the queue and then evicts or drops.
pub const FLOOD_BATCH: usize = 3 * QUEUE;

/// The arena of the workload (with the mutex `M` of its downlink).
pub type BenchArena<M = CriticalSectionRawMutex> = FrameArena<M, ARENA_BYTES>;
/// The downlink of the workload: one PPRZ v2 device, its locks `M` (a critical section
/// by default).
pub type BenchDownlink<'a, M = CriticalSectionRawMutex> = Downlink<'a, M, 1, QUEUE>;

/// A device that accepts every write at once, counting frames and bytes and folding the
/// bytes into a digest (so the writes cannot be optimised away).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Sink {
    /// Writes (one per frame: the writer uses `write_all`, which this device completes in
    /// one `write`).
    pub writes: u32,
    /// Bytes written.
    pub bytes: u64,
    /// Sum of the bytes written (wrapping).
    pub digest: u32,
}

impl embedded_io_async::ErrorType for Sink {
    type Error = Infallible;
}

impl embedded_io_async::Write for Sink {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.writes += 1;
        self.bytes += buf.len() as u64;
        // First and last byte only: a UART driver copies the frame to DMA; the point is
        // the stack's cost, not the device's.
        if let (Some(&a), Some(&b)) = (buf.first(), buf.last()) {
            self.digest = self.digest.wrapping_add(u32::from(a) + u32::from(b));
        }
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// A downlink for the workload over `arena`.
pub fn new_downlink<M: RawMutex + Sync>(arena: &BenchArena<M>) -> BenchDownlink<'_, M> {
    Downlink::new(arena, AC_ID, [DeviceConfig::new(PprzV2::new().into())])
}

/// Workload 3: sends `count` messages through `downlink` to `sink`, written through
/// `port` (the downlink's port); returns the device's statistics once every message has
/// been written.
pub fn run_downlink<M: RawMutex + Sync>(
    downlink: &BenchDownlink<'_, M>,
    port: &mut Port<'_>,
    count: usize,
    sink: &mut Sink,
) -> DeviceStats {
    drive(downlink, port, count, BATCH, sink, |_| SendOptions::new())
}

/// The flood: `count` messages as in [`run_downlink`], in bursts of [`FLOOD_BATCH`] (three
/// times the queue) at priorities cycling through 0, 64, 128 and 192, so each burst fills
/// the queue, evicts less important frames and drops the rest (all counted by reason in
/// the returned statistics). The send path's worst cases: eviction, refusal, the arena's
/// release of an evicted frame.
pub fn run_downlink_flood<M: RawMutex + Sync>(
    downlink: &BenchDownlink<'_, M>,
    port: &mut Port<'_>,
    count: usize,
    sink: &mut Sink,
) -> DeviceStats {
    drive(downlink, port, count, FLOOD_BATCH, sink, |i| {
        SendOptions::new().priority((i % 4) as u8 * 64)
    })
}

/// Sends `count` messages (GPS and ATTITUDE alternating) with `options(i)`, `batch` between
/// two yields, while the writer drains to `sink`; the device's statistics at the end.
fn drive<M: RawMutex + Sync>(
    downlink: &BenchDownlink<'_, M>,
    port: &mut Port<'_>,
    count: usize,
    batch: usize,
    sink: &mut Sink,
    options: impl Fn(usize) -> SendOptions,
) -> DeviceStats {
    let producer = async {
        let mut i = 0;
        while i < count {
            let end = (i + batch).min(count);
            while i < end {
                let index = i as u32;
                // A drop is counted in the device statistics, which the caller checks.
                let _ = if i % 2 == 0 {
                    downlink.send_with(&gps(index), options(i))
                } else {
                    downlink.send_with(&attitude(index), options(i))
                };
                i += 1;
            }
            // The writer drains the queue before the producer runs again.
            yield_now().await;
        }
    };
    let writer = run_writer(port, sink);
    match block_on(select(producer, writer)) {
        Either::First(()) => {}
        Either::Second(never) => never,
    }
    downlink.stats(0).unwrap_or_default()
}
