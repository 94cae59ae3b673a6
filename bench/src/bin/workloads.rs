//! Deterministic workloads of the telemetry stack, one named non-inlined function each,
//! for instruction counting with callgrind (see `BENCHMARKS.md`):
//!
//! ```text
//! cargo build --release -p pprz-bench --bin workloads
//! valgrind --tool=callgrind --toggle-collect='*workload_encode*' \
//!     target/release/workloads --mode encode
//! ```
//!
//! `bench/callgrind.sh` runs every mode that way and divides the totals. Each mode prints
//! its results and one `units <function> <count> <unit>` line that says what to divide
//! the function's instruction count by.
//!
//! Modes: `encode`, `parse` (`Decoder::feed_borrowed`), `parse-buffered` (`Decoder::feed`),
//! `downlink`, `arena-10`, `arena-50`, `arena-90`, `secure-seal`, `secure-open`, `arena` (the
//! three fill levels and the fill at the first failure), `overload`, `radio`, `all` (default).

use std::hint::black_box;
use std::process::ExitCode;

use pprz_bench::arena::{self, ChurnSummary, CostArena, FillState};
use pprz_bench::downlink::{self, Sink};
use pprz_bench::stream::{self, MESSAGES, ParseSummary};
use pprz_bench::{overload, radio, secure};
use pprz_secure::SecureChannel;
use pprz_telemetry::stats::DeviceStats;

/// Workload 1, measured: encode [`MESSAGES`] messages into `out`.
#[inline(never)]
fn workload_encode(count: usize, out: &mut [u8]) -> usize {
    stream::encode_stream(count, out).expect("the buffer holds the stream")
}

/// Workload 2, measured: parse and decode `stream`.
#[inline(never)]
fn workload_parse(stream: &[u8]) -> ParseSummary {
    stream::parse_stream(stream)
}

/// Workload 2 through `Decoder::feed` (every byte copied into the decoder), measured.
#[inline(never)]
fn workload_parse_buffered(stream: &[u8]) -> ParseSummary {
    stream::parse_stream_buffered(stream)
}

/// Workload 3, measured: `count` messages through the downlink to a sink.
#[inline(never)]
fn workload_downlink(
    downlink: &downlink::BenchDownlink<'_>,
    port: &mut pprz_telemetry::Port<'_>,
    count: usize,
    sink: &mut Sink,
) -> DeviceStats {
    downlink::run_downlink(downlink, port, count, sink)
}

/// Workload 5, measured: alloc/release steps at 10 % fill.
#[inline(never)]
fn workload_arena_10(state: &mut FillState<'_>) -> ChurnSummary {
    let summary = arena::churn(state);
    assert_eq!(summary.percent, 10);
    summary
}

/// Workload 5, measured: alloc/release steps at 50 % fill.
#[inline(never)]
fn workload_arena_50(state: &mut FillState<'_>) -> ChurnSummary {
    let summary = arena::churn(state);
    assert_eq!(summary.percent, 50);
    summary
}

/// Workload 5, measured: alloc/release steps at 90 % fill.
#[inline(never)]
fn workload_arena_90(state: &mut FillState<'_>) -> ChurnSummary {
    let summary = arena::churn(state);
    assert_eq!(summary.percent, 90);
    summary
}

/// Workload 8, measured: seal the plain frames on an installed session.
#[inline(never)]
fn workload_secure_seal(channel: &mut SecureChannel, frames: &mut [secure::SealedFrame]) -> usize {
    secure::seal_frames(channel, frames)
}

/// Workload 8, measured: open (verify, decrypt) the sealed frames on an installed session.
#[inline(never)]
fn workload_secure_open(
    channel: &mut SecureChannel,
    sealed: &[secure::SealedFrame],
) -> secure::OpenSummary {
    secure::open_frames(channel, sealed)
}

/// Workload 4 (figures come from the simulation, not from an instruction count).
#[inline(never)]
fn workload_overload() -> overload::OverloadReport {
    overload::run_overload()
}

fn run_encode() {
    let mut out = vec![0u8; stream::stream_len(MESSAGES)];
    let len = workload_encode(black_box(MESSAGES), black_box(&mut out));
    assert_eq!(len, out.len());
    println!("encode: {MESSAGES} messages (GPS/ATTITUDE alternating) -> {len} bytes of PPRZ v2");
    println!("units workload_encode {MESSAGES} message");
}

fn run_parse() {
    let stream = stream::make_stream(MESSAGES);
    let summary = workload_parse(black_box(&stream));
    assert_eq!(summary, stream::expected_summary(MESSAGES), "parse result");
    println!(
        "parse: {} bytes -> {} frames ({} GPS, {} ATTITUDE), digest {:016x}",
        stream.len(),
        summary.frames,
        summary.gps,
        summary.attitude,
        summary.digest
    );
    println!("units workload_parse {} byte", stream.len());
}

fn run_parse_buffered() {
    let stream = stream::make_stream(MESSAGES);
    let summary = workload_parse_buffered(black_box(&stream));
    assert_eq!(summary, stream::expected_summary(MESSAGES), "parse result");
    println!(
        "parse-buffered: {} bytes -> {} frames, same summary as `parse`",
        stream.len(),
        summary.frames
    );
    println!("units workload_parse_buffered {} byte", stream.len());
}

fn run_downlink() {
    let arena = <downlink::BenchArena>::new();
    let dl = downlink::new_downlink(&arena);
    let [mut port] = dl.ports().expect("a new downlink's ports");
    let mut sink = Sink::default();
    let stats = workload_downlink(&dl, &mut port, black_box(MESSAGES), &mut sink);
    assert_eq!(stats.sent as usize, MESSAGES, "{stats:?}");
    assert_eq!(arena.stats().live, 0);
    println!(
        "downlink: {MESSAGES} messages sent -> {} frames, {} bytes on the sink (queue high \
         water {}, arena high water {} B)",
        sink.writes,
        sink.bytes,
        stats.queue_high_water,
        arena.stats().high_water
    );
    println!("units workload_downlink {MESSAGES} message");
}

fn run_arena_level(percent: usize) {
    let arena = CostArena::new();
    let mut state = arena::prepare(&arena, percent, arena::SEED);
    let summary = match percent {
        10 => workload_arena_10(&mut state),
        50 => workload_arena_50(&mut state),
        _ => workload_arena_90(&mut state),
    };
    println!(
        "arena {percent} %: {} allocs, {} releases, {} failed allocs, mean fill {:.1} %, {} live",
        summary.allocs,
        summary.releases,
        summary.failures,
        summary.mean_fill * 100.0,
        state.live()
    );
    println!(
        "units workload_arena_{percent} {} operation",
        summary.operations()
    );
}

fn run_arena_fill() {
    let seed = 0x5EED;
    for f in [
        arena::fill_at_first_failure::<4096>(seed, 20_000),
        arena::fill_at_first_failure::<16384>(seed, 20_000),
    ] {
        println!(
            "arena {:>5} B: fill at first failure over {} rounds: used {:.1} % mean ({:.1} % \
             worst), payload {:.1} % mean ({:.1} % worst)",
            f.capacity,
            f.rounds,
            f.used_mean * 100.0,
            f.used_min * 100.0,
            f.payload_mean * 100.0,
            f.payload_min * 100.0
        );
    }
}

/// The sealed frames of workload 8 and the channel that opens them (sealed unmeasured
/// for `secure-open`).
fn secure_setup(measure_seal: bool) -> (SecureChannel, Vec<secure::SealedFrame>) {
    let (mut air, ground) = secure::session();
    let mut sealed = secure::frame_buffers(secure::FRAMES);
    let n = if measure_seal {
        workload_secure_seal(&mut air, black_box(&mut sealed))
    } else {
        secure::seal_frames(&mut air, &mut sealed)
    };
    assert_eq!(n, secure::FRAMES);
    assert_eq!(air.stats().encrypted as usize, secure::FRAMES);
    (ground, sealed)
}

fn run_secure_seal() {
    let (mut ground, sealed) = secure_setup(true);
    // Check (unmeasured): every sealed frame opens back to its plain frame.
    let summary = secure::open_frames(&mut ground, &sealed);
    assert_eq!(summary, secure::expected_open_summary(secure::FRAMES));
    println!(
        "secure-seal: {} frames of {} field bytes ({} -> {} bytes) sealed",
        secure::FRAMES,
        secure::FIELDS_LEN,
        secure::PLAIN_FRAME_LEN,
        secure::SEALED_FRAME_LEN
    );
    println!("units workload_secure_seal {} frame", secure::FRAMES);
}

fn run_secure_open() {
    let (mut ground, sealed) = secure_setup(false);
    let summary = workload_secure_open(&mut ground, black_box(&sealed));
    assert_eq!(summary, secure::expected_open_summary(secure::FRAMES));
    println!(
        "secure-open: {} frames of {} bytes opened ({} field bytes each), digest {:016x}",
        summary.opened,
        secure::SEALED_FRAME_LEN,
        secure::FIELDS_LEN,
        summary.digest
    );
    println!("units workload_secure_open {} frame", secure::FRAMES);
}

fn run_overload() {
    let report = workload_overload();
    print!("{}", overload::render(&report));
}

/// Workload 7: radios without back-pressure (figures from the simulation).
fn run_radio() {
    for report in radio::run_radio() {
        println!("{}", radio::render(&report));
    }
}

const USAGE: &str = "usage: workloads [--mode encode|parse|parse-buffered|downlink|arena-10|arena-50|arena-90|secure-seal|secure-open|arena|overload|radio|all]";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mode = match args.as_slice() {
        [] => "all",
        [flag, mode] if flag == "--mode" => mode.as_str(),
        [flag] if flag == "--help" || flag == "-h" => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        _ => {
            eprintln!("{USAGE}");
            return ExitCode::FAILURE;
        }
    };
    match mode {
        "encode" => run_encode(),
        "parse" => run_parse(),
        "parse-buffered" => run_parse_buffered(),
        "downlink" => run_downlink(),
        "arena-10" => run_arena_level(10),
        "arena-50" => run_arena_level(50),
        "arena-90" => run_arena_level(90),
        "secure-seal" => run_secure_seal(),
        "secure-open" => run_secure_open(),
        "arena" => {
            for p in [10, 50, 90] {
                run_arena_level(p);
            }
            run_arena_fill();
        }
        "overload" => run_overload(),
        "radio" => run_radio(),
        "all" => {
            run_encode();
            run_parse();
            run_parse_buffered();
            run_downlink();
            for p in [10, 50, 90] {
                run_arena_level(p);
            }
            run_arena_fill();
            run_secure_seal();
            run_secure_open();
            run_overload();
            run_radio();
        }
        other => {
            eprintln!("unknown mode {other:?}\n{USAGE}");
            return ExitCode::FAILURE;
        }
    }
    ExitCode::SUCCESS
}
