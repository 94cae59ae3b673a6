//! Workloads 1 and 2 with the prototypes of `pprz_bench::proposals` (the optimisations
//! `BENCHMARKS.md` proposes to other crates), one named non-inlined function each, for
//! callgrind like the `workloads` binary:
//!
//! ```text
//! valgrind --tool=callgrind --toggle-collect='proposals::workload_encode_proposed' \
//!     target/release/proposals --mode encode-proposed
//! ```
//!
//! Modes: `encode-proposed` (proposed encoders and framing), `encode-framing-proposed`
//! (current generated encoders, proposed framing), `parse-proposed`, `all` (default). A separate binary, so the
//! prototypes cannot change how the code measured by `workloads` is inlined.

use std::hint::black_box;
use std::process::ExitCode;

use pprz_bench::proposals;
use pprz_bench::stream::{self, MESSAGES, ParseSummary};

/// Workload 1 with the prototypes, measured.
#[inline(never)]
fn workload_encode_proposed(count: usize, out: &mut [u8]) -> usize {
    proposals::encode_stream(count, out).expect("the buffer holds the stream")
}

/// Workload 1 with the current encoders and the proposed framing only, measured.
#[inline(never)]
fn workload_encode_framing_proposed(count: usize, out: &mut [u8]) -> usize {
    proposals::encode_stream_framing_only(count, out).expect("the buffer holds the stream")
}

/// Workload 2 with the prototypes, measured.
#[inline(never)]
fn workload_parse_proposed(stream: &[u8]) -> ParseSummary {
    proposals::parse_stream(stream)
}

fn run_encode() {
    let mut out = vec![0u8; stream::stream_len(MESSAGES)];
    let len = workload_encode_proposed(black_box(MESSAGES), black_box(&mut out));
    assert_eq!(out[..len], stream::make_stream(MESSAGES)[..], "same stream");
    println!("encode-proposed: {MESSAGES} messages -> {len} bytes, identical to `encode`");
    println!("units workload_encode_proposed {MESSAGES} message");
}

fn run_encode_framing() {
    let mut out = vec![0u8; stream::stream_len(MESSAGES)];
    let len = workload_encode_framing_proposed(black_box(MESSAGES), black_box(&mut out));
    assert_eq!(out[..len], stream::make_stream(MESSAGES)[..], "same stream");
    println!("encode-framing-proposed: {MESSAGES} messages -> {len} bytes, identical to `encode`");
    println!("units workload_encode_framing_proposed {MESSAGES} message");
}

fn run_parse() {
    let stream = stream::make_stream(MESSAGES);
    let summary = workload_parse_proposed(black_box(&stream));
    assert_eq!(summary, stream::expected_summary(MESSAGES), "parse result");
    println!(
        "parse-proposed: {} bytes -> {} frames, same summary as `parse`",
        stream.len(),
        summary.frames
    );
    println!("units workload_parse_proposed {} byte", stream.len());
}

const USAGE: &str =
    "usage: proposals [--mode encode-proposed|encode-framing-proposed|parse-proposed|all]";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mode = match args.as_slice() {
        [] => "all",
        [flag, mode] if flag == "--mode" => mode.as_str(),
        _ => {
            eprintln!("{USAGE}");
            return ExitCode::FAILURE;
        }
    };
    match mode {
        "encode-proposed" => run_encode(),
        "encode-framing-proposed" => run_encode_framing(),
        "parse-proposed" => run_parse(),
        "all" => {
            run_encode();
            run_encode_framing();
            run_parse();
        }
        other => {
            eprintln!("unknown mode {other:?}\n{USAGE}");
            return ExitCode::FAILURE;
        }
    }
    ExitCode::SUCCESS
}
