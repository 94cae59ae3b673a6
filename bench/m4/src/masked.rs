//! The masked-interrupt run (`run.sh` passes `arg=masked`): the link's workloads on a few
//! messages each, between two marker calls, while QEMU logs every instruction it executes
//! (`-d in_asm,exec,nochain -accel tcg,one-insn-per-tb=on`). `masked.py` reads that log:
//! between the markers it counts the instructions executed with interrupts masked
//! (from a `cpsid i` that masks them to the `cpsie i` that unmasks them again: the
//! critical sections of `cortex-m`'s single-core implementation), the longest such
//! section, and their share of the workload.
//!
//! Before each region the firmware prints `region <name> <count> <unit> <what>` on
//! UART0, in the order of the regions, so the script can name them.

use core::fmt::Write;
use core::hint::black_box;

use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, RawMutex, ThreadModeRawMutex};
use pprz_bench_common::downlink::{self as dl_workload, BenchDownlink, Sink};
use pprz_bench_common::stream;
use pprz_telemetry::Port;
use pprz_telemetry::stats::DeviceStats;

use crate::hw::Uart;
use crate::{STREAM_LEN, fail};

/// Messages of each traced workload (enough for the queue and the arena to reach their
/// steady states; the trace of each instruction is a line of QEMU's log).
const TRACED: usize = 1_000;

/// Marks the start of a region: `masked.py` recognises the call by its symbol.
#[unsafe(no_mangle)]
#[inline(never)]
pub extern "C" fn bench_m4_region_begin() {
    cortex_m::asm::nop();
}

/// Marks the end of a region.
#[unsafe(no_mangle)]
#[inline(never)]
pub extern "C" fn bench_m4_region_end() {
    // Two instructions: a body of its own, so the linker does not fold the two markers
    // into one function.
    cortex_m::asm::nop();
    cortex_m::asm::nop();
}

/// Runs `f` as the region `name` of `count` `unit`s.
fn region<T>(
    out: &mut Uart,
    name: &str,
    count: usize,
    unit: &str,
    what: &str,
    f: impl FnOnce() -> T,
) -> T {
    let _ = writeln!(out, "region {name} {count} {unit} {what}");
    bench_m4_region_begin();
    let result = f();
    bench_m4_region_end();
    result
}

/// The traced workloads: encode, parse, the downlink (workload 3) and the flood.
pub fn run(out: &mut Uart) {
    let mut bytes = [0u8; STREAM_LEN];
    let len = region(
        out,
        "encode",
        TRACED,
        "message",
        "generated encoder + PPRZ v2 framing",
        || stream::encode_stream(black_box(TRACED), black_box(&mut bytes)),
    );
    let Ok(len) = len else { fail("encode") };
    let summary = region(
        out,
        "parse",
        len,
        "byte",
        "Decoder::feed_borrowed + generated decoder",
        || stream::parse_stream(black_box(&bytes[..len])),
    );
    if summary != stream::expected_summary(TRACED) {
        fail("parse");
    }
    let stats = traced_downlink::<CriticalSectionRawMutex>(
        out,
        "downlink",
        "send -> arena -> queue -> writer -> sink",
        dl_workload::run_downlink,
    );
    if stats.sent as usize != TRACED {
        fail("downlink");
    }
    let stats = traced_downlink::<ThreadModeRawMutex>(
        out,
        "thread",
        "the downlink with ThreadModeRawMutex",
        dl_workload::run_downlink,
    );
    if stats.sent as usize != TRACED {
        fail("downlink, thread mode");
    }
    #[cfg(target_has_atomic = "32")]
    {
        let stats = traced_downlink::<crate::basepri::Basepri>(
            out,
            "basepri",
            "the downlink with BasepriRawMutex",
            dl_workload::run_downlink,
        );
        if stats.sent as usize != TRACED {
            fail("downlink, BASEPRI");
        }
    }
    let stats = traced_downlink::<CriticalSectionRawMutex>(
        out,
        "flood",
        "bursts of 3 queues, 4 priorities: evictions and drops",
        dl_workload::run_downlink_flood,
    );
    if !stats.is_balanced() || stats.submitted as usize != TRACED {
        fail("flood");
    }
    let _ = writeln!(
        out,
        "flood: {} sent, {} evicted, {} dropped",
        stats.sent,
        stats.evicted.total(),
        stats.dropped.total()
    );
}

/// Runs `run` over [`TRACED`] messages on a new downlink whose locks are `M`, as the
/// region `name`: the device's statistics. Fails unless the arena is empty after it.
fn traced_downlink<M: RawMutex + Sync>(
    out: &mut Uart,
    name: &str,
    what: &str,
    run: impl FnOnce(&BenchDownlink<'_, M>, &mut Port<'_>, usize, &mut Sink) -> DeviceStats,
) -> DeviceStats {
    let arena = dl_workload::BenchArena::<M>::new();
    let downlink = dl_workload::new_downlink(&arena);
    let [mut port] = downlink.ports().unwrap_or_else(|_| fail("downlink ports"));
    let mut sink = Sink::default();
    let stats = region(out, name, TRACED, "message", what, || {
        run(&downlink, &mut port, black_box(TRACED), &mut sink)
    });
    if arena.stats().live != 0 {
        fail(name);
    }
    stats
}
