//! Instruction counts of the telemetry stack on an emulated Cortex-M4:
//!
//! * workloads 1-3 of the host benchmarks (issue 16), the very same loops on the same
//!   inputs (`pprz-bench-common`): encoding 10 000 GPS/ATTITUDE messages into PPRZ v2
//!   frames, parsing that stream back, and sending them through the downlink (arena,
//!   priority queue, writer, a memory sink), polled without an executor, with the
//!   downlink's locks a Cortex-M critical section (`cortex-m`'s
//!   `critical-section-single-core`: an interrupt mask);
//! * the secure link's costs (issue 14): each handshake step of both ends and the
//!   per-frame seal and open of a frame with 40 bytes of message fields, with the firmware
//!   backend of `pprz-secure` (`salty`);
//! * the persistent settings' cost ([`settings`]): `pprz-settings` loading 100 persistent
//!   settings at boot, and storing them, over RAM flash of an STM32F405's geometry.
//!
//! Run under QEMU's `mps2-an386` with `-icount shift=0` (`run.sh`): QEMU then advances
//! its virtual clock by 1 ns per guest instruction, and the board's timers count that
//! clock at 25 MHz, so one timer tick is 40 instructions. The firmware first checks this
//! on a loop of known length (both timer 0 and SysTick), then measures each step on
//! timer 0 and prints one `result` line per figure on UART0, `done`, and stops QEMU
//! through semihosting.
//!
//! The ephemeral keys come from a fixed-seed ChaCha RNG: benchmark only, so the run is
//! the same every time (an aircraft uses its hardware RNG).

#![no_std]
#![no_main]

#[cfg(target_has_atomic = "32")]
mod basepri;
mod hw;
mod masked;
mod settings;
mod time_driver;

use core::fmt::Write;
use core::hint::black_box;

use cortex_m_rt::entry;
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, RawMutex, ThreadModeRawMutex};
use pprz_bench_common::downlink::BenchDownlink;
use pprz_bench_common::downlink::{self as dl_workload, Sink};
use pprz_bench_common::stream::{self, MESSAGES};
use pprz_secure::keys::INSECURE_TEST_KEY_FILE;
use pprz_secure::{
    Initiator, InitiatorEvent, KeyExchange, KeyFile, OVERHEAD, Policy, Responder, ResponderEvent,
    SecureChannel,
};
use pprz_telemetry::Port;
use pprz_telemetry::arena::ArenaStats;
use pprz_telemetry::stats::DeviceStats;
use pprz_transports::{Encoder, GROUND_ID, MsgHeader, PprzV2, TxMeta};
use rand_chacha::ChaCha20Rng;
use rand_chacha::rand_core::SeedableRng;

use hw::{SysTick, Timer, Uart};

/// Instructions per timer tick under `-icount shift=0`: 10^9 ns / 25 MHz.
const INSTRUCTIONS_PER_TICK: u32 = 1_000_000_000 / hw::SYSCLK_HZ;

/// The benchmark's RNG seed. BENCHMARK ONLY: a fixed seed makes every ephemeral key
/// predictable; never in an aircraft.
const BENCH_ONLY_SEED: [u8; 32] = [0x5E; 32];

/// Aircraft id.
const AC_ID: u8 = 7;
/// Frames sealed and opened (each figure is their average).
const FRAMES: usize = 100;
/// Bytes of message fields per frame.
const FIELDS_LEN: usize = 40;
/// Plain PPRZ v2 frame: 8 bytes of framing and header around the fields.
const PLAIN_LEN: usize = FIELDS_LEN + 8;
/// Sealed frame.
const SEALED_LEN: usize = PLAIN_LEN + OVERHEAD;
/// Handshakes measured (the steps of each are printed).
const ROUNDS: u64 = 2;

/// A frame buffer: a plain frame with room to seal it in place.
type FrameBuf = [u8; SEALED_LEN];

#[entry]
fn main() -> ! {
    let mut out = Uart::init();
    #[allow(unused_mut)] // used on ARMv7-M only
    let mut cp = cortex_m::Peripherals::take().unwrap_or_else(|| fail("peripherals taken"));
    let timer = Timer::start();
    let systick = SysTick::start(cp.SYST);
    #[cfg(target_has_atomic = "32")]
    basepri::check(&mut cp.SCB);
    let _ = writeln!(
        out,
        "bench-m4: the telemetry stack and pprz-secure (salty) on mps2-an386, 1 tick = \
         {INSTRUCTIONS_PER_TICK} instructions under -icount shift=0"
    );
    if hw::cmdline_has("masked") {
        // The traced run (run.sh, second QEMU run): no timing, the instruction log counts.
        masked::run(&mut out);
        let _ = writeln!(out, "done");
        hw::exit(true)
    }
    calibrate(&mut out, &timer, &systick);
    workloads(&mut out, &timer);
    #[cfg(target_has_atomic = "32")]
    basepri::workload(&mut out, &timer);
    handshakes(&mut out, &timer);
    frames(&mut out, &timer);
    settings::settings(&mut out, &timer);
    let _ = writeln!(out, "done");
    hw::exit(true)
}

/// Prints `message` and stops QEMU with a failure status.
pub(crate) fn fail(message: &str) -> ! {
    let _ = writeln!(Uart::init(), "error: {message}");
    hw::exit(false)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    let _ = writeln!(Uart::init(), "panic: {info}");
    hw::exit(false)
}

/// `n` iterations of `subs; bne`: exactly `2 n` instructions (`n` >= 1).
#[inline(never)]
fn spin(n: u32) {
    // Safety: a register-only countdown loop; it touches no memory and no stack.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {n}, {n}, #1",
            "bne 2b",
            n = inout(reg) n => _,
            options(nomem, nostack),
        );
    }
}

/// Ticks of `clock` (counting down, wrapping at `mask`) taken by `f`, and its result.
#[inline(always)]
fn ticks<T>(now: impl Fn() -> u32, mask: u32, f: impl FnOnce() -> T) -> (T, u32) {
    let t0 = now();
    let result = f();
    let t1 = now();
    (result, t0.wrapping_sub(t1) & mask)
}

/// Checks the tick rate of both clocks on `spin` loops of known length: the difference
/// between a long and a short loop cancels the call and the clock reads.
fn calibrate(out: &mut Uart, timer: &Timer, systick: &SysTick) {
    const SHORT: u32 = 100_000;
    const LONG: u32 = 1_000_000;
    let instructions = 2 * u64::from(LONG - SHORT);
    let clocks: [(&str, &dyn Fn() -> u32, u32); 2] = [
        ("timer0", &|| timer.now(), u32::MAX),
        ("systick", &|| systick.now(), 0x00FF_FFFF),
    ];
    // Each measurement starts right after a tick, so that it counts whole ticks whatever
    // ran before it (otherwise the phase of the first tick can add one to either loop).
    let at_tick = |now: &dyn Fn() -> u32| {
        let t = now();
        while now() == t {}
    };
    for (name, now, mask) in clocks {
        at_tick(now);
        let ((), short) = ticks(now, mask, || spin(black_box(SHORT)));
        at_tick(now);
        let ((), long) = ticks(now, mask, || spin(black_box(LONG)));
        at_tick(now);
        let ((), empty) = ticks(now, mask, || ());
        let per_tick_milli = instructions * 1000 / u64::from(long - short).max(1);
        let _ = writeln!(
            out,
            "calibration {name}: spin({SHORT}) {short} ticks, spin({LONG}) {long} ticks: \
             {instructions} instructions in {} ticks = {}.{:03} instructions/tick; \
             empty measurement {empty} ticks",
            long - short,
            per_tick_milli / 1000,
            per_tick_milli % 1000,
        );
    }
}

/// Prints one figure, `result <name> <instructions> <count> <unit> <what>`:
/// `instructions` (from `ticks`) for `count` units of work.
pub(crate) fn result(out: &mut Uart, name: &str, ticks: u32, count: usize, unit: &str, what: &str) {
    let instructions = u64::from(ticks) * u64::from(INSTRUCTIONS_PER_TICK);
    let _ = writeln!(out, "result {name} {instructions} {count} {unit} {what}");
}

/// Bytes of the encoded stream of workloads 1 and 2.
pub(crate) const STREAM_LEN: usize = stream::stream_len(MESSAGES);

/// Workloads 1-3 of the host benchmarks (`BENCHMARKS.md`, sections 1-3), each checked
/// against its expected result after the measurement, as on the host.
fn workloads(out: &mut Uart, timer: &Timer) {
    let now = || timer.now();
    // 1. Encode: generated encoder + PPRZ v2 framing, frame after frame.
    let mut bytes = [0u8; STREAM_LEN];
    let (len, t_encode) = ticks(now, u32::MAX, || {
        stream::encode_stream(black_box(MESSAGES), black_box(&mut bytes))
    });
    if len != Ok(STREAM_LEN) {
        fail("encode");
    }
    // 2. Parse: `Decoder::feed_borrowed` (the reader's path) and the generated decoder.
    let (summary, t_parse) = ticks(now, u32::MAX, || stream::parse_stream(black_box(&bytes)));
    if summary != stream::expected_summary(MESSAGES) {
        fail("parse");
    }
    // 3. Downlink: send -> arena -> queue -> writer -> sink.
    let (stats, sink, arena, t_downlink) =
        timed_downlink::<CriticalSectionRawMutex>(timer, |d, p, n, s| {
            dl_workload::run_downlink(d, p, n, s)
        });
    if stats.sent as usize != MESSAGES || sink.bytes as usize != STREAM_LEN || arena.live != 0 {
        fail("downlink");
    }
    // The flood: bursts of three queues at four priorities (evictions and drops).
    let (flood, _, flood_arena, t_flood) =
        timed_downlink::<CriticalSectionRawMutex>(timer, |d, p, n, s| {
            dl_workload::run_downlink_flood(d, p, n, s)
        });
    if !flood.is_balanced() || flood.submitted as usize != MESSAGES || flood_arena.live != 0 {
        fail("flood");
    }
    // The downlink again, its locks a thread-mode mutex: nothing masked.
    let (thread, thread_sink, thread_arena, t_thread) =
        timed_downlink::<ThreadModeRawMutex>(timer, |d, p, n, s| {
            dl_workload::run_downlink(d, p, n, s)
        });
    if thread.sent as usize != MESSAGES
        || thread_sink.bytes as usize != STREAM_LEN
        || thread_arena.live != 0
    {
        fail("downlink, thread mode");
    }
    let _ = writeln!(
        out,
        "workloads: {MESSAGES} messages (GPS/ATTITUDE alternating), {STREAM_LEN} bytes of \
         PPRZ v2; downlink queue high water {}, arena high water {} B",
        stats.queue_high_water, arena.high_water
    );
    let _ = writeln!(
        out,
        "flood: {} sent, {} evicted, {} dropped",
        flood.sent,
        flood.evicted.total(),
        flood.dropped.total()
    );
    result(
        out,
        "encode",
        t_encode,
        MESSAGES,
        "message",
        "generated encoder + PPRZ v2 framing (workload 1)",
    );
    result(
        out,
        "parse",
        t_parse,
        STREAM_LEN,
        "byte",
        "Decoder::feed_borrowed + generated decoder (workload 2)",
    );
    result(
        out,
        "downlink",
        t_downlink,
        MESSAGES,
        "message",
        "send -> arena -> queue -> writer -> sink (workload 3)",
    );
    result(
        out,
        "downlink-thread",
        t_thread,
        MESSAGES,
        "message",
        "the same with ThreadModeRawMutex (thread-mode senders only; nothing masked)",
    );
    result(
        out,
        "flood",
        t_flood,
        MESSAGES,
        "message",
        "the same, in bursts of 3 queues at 4 priorities: evictions and drops",
    );
}

/// Runs `run` on a new downlink whose locks are `M` over [`MESSAGES`] messages: the
/// device's statistics, the sink, the arena's statistics after it, and the ticks it took.
pub(crate) fn timed_downlink<M: RawMutex + Sync>(
    timer: &Timer,
    run: impl FnOnce(&BenchDownlink<'_, M>, &mut Port<'_>, usize, &mut Sink) -> DeviceStats,
) -> (DeviceStats, Sink, ArenaStats, u32) {
    let arena = dl_workload::BenchArena::<M>::new();
    let downlink = dl_workload::new_downlink(&arena);
    let [mut port] = downlink.ports().unwrap_or_else(|_| fail("downlink ports"));
    let mut sink = Sink::default();
    let (stats, t) = ticks(
        || timer.now(),
        u32::MAX,
        || run(&downlink, &mut port, black_box(MESSAGES), &mut sink),
    );
    (stats, sink, arena.stats(), t)
}

/// `ROUNDS` complete handshakes between an initiator and a responder, each step
/// measured. Messages go from one state machine to the other directly (their framing
/// through the channel is per-frame work, measured by [`frames`]).
fn handshakes(out: &mut Uart, timer: &Timer) {
    let keys = KeyFile::parse(INSECURE_TEST_KEY_FILE).unwrap_or_else(|_| fail("key file"));
    let air_keys = keys.aircraft().unwrap_or_else(|_| fail("aircraft keys"));
    let ground_keys = keys.ground().unwrap_or_else(|_| fail("ground keys"));
    let mut rng = ChaCha20Rng::from_seed(BENCH_ONLY_SEED);
    let mut responder = Responder::new(AC_ID, air_keys);
    let mut initiator = Initiator::new(AC_ID, ground_keys);
    let now = || timer.now();
    for round in 0..ROUNDS {
        // Past the responder's rate limit (one handshake per second).
        let now_ms = round * 10_000;
        initiator.restart();
        let (msg1, t1) = ticks(now, u32::MAX, || initiator.poll(now_ms, &mut rng));
        let msg1: KeyExchange = msg1.unwrap_or_else(|| fail("message 1"));
        let (ev, t2) = ticks(now, u32::MAX, || {
            responder.handle(black_box(&msg1), now_ms, &mut rng)
        });
        let Ok(ResponderEvent::Reply(msg2)) = ev else {
            fail("message 2")
        };
        let (ev, t3) = ticks(now, u32::MAX, || initiator.handle(black_box(&msg2), now_ms));
        let Ok(InitiatorEvent::Established { keys: _, reply }) = ev else {
            fail("message 3")
        };
        let (ev, t4) = ticks(now, u32::MAX, || {
            responder.handle(black_box(&reply), now_ms, &mut rng)
        });
        let Ok(ResponderEvent::Established(_)) = ev else {
            fail("session")
        };
        let _ = writeln!(out, "handshake {}", round + 1);
        result(
            out,
            "initiator-msg1",
            t1,
            1,
            "handshake",
            "ground: ephemeral key (X25519 base point) -> message 1",
        );
        result(
            out,
            "responder-msg1",
            t2,
            1,
            "handshake",
            "aircraft: message 1 -> message 2 (2 X25519, Ed25519 sign)",
        );
        result(
            out,
            "initiator-msg2",
            t3,
            1,
            "handshake",
            "ground: message 2 -> message 3 (X25519, Ed25519 verify + sign)",
        );
        result(
            out,
            "responder-msg3",
            t4,
            1,
            "handshake",
            "aircraft: message 3 -> session (Ed25519 verify)",
        );
    }
}

/// The plain frame `i` from `src` to `dst`, class `class`, with [`FIELDS_LEN`] bytes of
/// fields that vary with `i`, in a buffer with room to seal it.
fn plain_frame(i: usize, (src, dst, class, id): (u8, u8, u8, u8)) -> FrameBuf {
    let mut fields = [0u8; FIELDS_LEN];
    fields[0] = (FIELDS_LEN - 1) as u8;
    for (k, v) in fields[1..].iter_mut().enumerate() {
        *v = (i * 31 + k * 7) as u8;
    }
    let meta = TxMeta::new(MsgHeader::new(src, dst, class, id));
    let mut buf = [0u8; SEALED_LEN];
    match PprzV2.encode(&meta, &fields, &mut buf) {
        Ok(PLAIN_LEN) => buf,
        _ => fail("plain frame"),
    }
}

/// Telemetry PAYLOAD (id 114) from the aircraft to the ground.
const DOWN: (u8, u8, u8, u8) = (AC_ID, GROUND_ID, 1, 114);
/// A datalink message (class 2, id 114) from the ground to the aircraft.
const UP: (u8, u8, u8, u8) = (GROUND_ID, AC_ID, 2, 114);

/// The aircraft's per-frame work under an installed session: sealing [`FRAMES`]
/// telemetry frames in place, and opening [`FRAMES`] datalink frames (their `DATA`, as
/// the PPRZ decoder hands it out). Each is checked against the other end afterwards.
fn frames(out: &mut Uart, timer: &Timer) {
    let keys = KeyFile::parse(INSECURE_TEST_KEY_FILE).unwrap_or_else(|_| fail("key file"));
    let mut rng = ChaCha20Rng::from_seed(BENCH_ONLY_SEED);
    let mut responder = Responder::new(
        AC_ID,
        keys.aircraft().unwrap_or_else(|_| fail("aircraft keys")),
    );
    let mut initiator =
        Initiator::new(AC_ID, keys.ground().unwrap_or_else(|_| fail("ground keys")));
    let mut air = SecureChannel::new(Policy::aircraft(AC_ID));
    let mut ground = SecureChannel::new(Policy::ground(AC_ID));
    let msg1 = initiator
        .poll(0, &mut rng)
        .unwrap_or_else(|| fail("message 1"));
    let Ok(ResponderEvent::Reply(msg2)) = responder.handle(&msg1, 0, &mut rng) else {
        fail("message 2")
    };
    let Ok(InitiatorEvent::Established { keys, reply }) = initiator.handle(&msg2, 0) else {
        fail("message 3")
    };
    ground.install(keys);
    let Ok(ResponderEvent::Established(keys)) = responder.handle(&reply, 0, &mut rng) else {
        fail("session")
    };
    air.install(keys);

    let now = || timer.now();
    // Seal, as the aircraft's writer does when it takes a frame for the wire.
    let mut down: [FrameBuf; FRAMES] = core::array::from_fn(|i| plain_frame(i, DOWN));
    let (sealed, t_seal) = ticks(now, u32::MAX, || {
        let mut sealed = 0;
        for buf in black_box(&mut down).iter_mut() {
            if matches!(air.seal_in_place(buf, PLAIN_LEN), Ok(s) if s.len == SEALED_LEN) {
                sealed += 1;
            }
        }
        sealed
    });
    // Check: the ground opens every one back to its plain frame.
    let mut plain = [0u8; 255];
    for (i, buf) in down.iter().enumerate() {
        let back = ground.open(&buf[2..SEALED_LEN - 2], &mut plain);
        if sealed != FRAMES || !back.is_ok_and(|o| o.frame() == &plain_frame(i, DOWN)[..PLAIN_LEN])
        {
            fail("sealed frames do not open back");
        }
    }

    // Open, as the aircraft's reader does with each frame the decoder hands out.
    let mut up: [FrameBuf; FRAMES] = core::array::from_fn(|i| plain_frame(i, UP));
    for buf in up.iter_mut() {
        if ground.seal_in_place(buf, PLAIN_LEN).map(|s| s.len) != Ok(SEALED_LEN) {
            fail("uplink seal");
        }
    }
    let mut opened = [[0u8; 64]; FRAMES];
    let (ok, t_open) = ticks(now, u32::MAX, || {
        let mut ok = 0;
        for (buf, o) in black_box(&up).iter().zip(opened.iter_mut()) {
            if air.open(&buf[2..SEALED_LEN - 2], o).is_ok() {
                ok += 1;
            }
        }
        ok
    });
    for (i, o) in opened.iter().enumerate() {
        if ok != FRAMES || o[..PLAIN_LEN] != plain_frame(i, UP)[..PLAIN_LEN] {
            fail("opened frames differ");
        }
    }
    let _ = writeln!(
        out,
        "frames: {FRAMES} of {FIELDS_LEN} field bytes ({PLAIN_LEN} -> {SEALED_LEN} bytes), totals"
    );
    result(
        out,
        "seal",
        t_seal,
        FRAMES,
        "frame",
        "aircraft: seal_in_place, 48 -> 69 bytes",
    );
    result(
        out,
        "open",
        t_open,
        FRAMES,
        "frame",
        "aircraft: open, 65 bytes of DATA -> 48-byte frame",
    );
}
