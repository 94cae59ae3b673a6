//! Workload 1 with the prototype left in `pprz_bench::proposals` (fixed-offset message
//! encoders instead of the generated ones, framed by the real `PprzV2::finish_frame`),
//! one named non-inlined function, for callgrind like the `workloads` binary:
//!
//! ```text
//! valgrind --tool=callgrind --toggle-collect='proposals::workload_encode_proposed' \
//!     target/release/proposals --mode encode-proposed
//! ```
//!
//! Modes: `encode-proposed`, `all` (default, the same). A separate binary, so the
//! prototype cannot change how the code measured by `workloads` is inlined.

use std::hint::black_box;
use std::process::ExitCode;

use pprz_bench::proposals;
use pprz_bench::stream::{self, MESSAGES};

/// Workload 1 with the fixed-offset encoders, measured.
#[inline(never)]
fn workload_encode_proposed(count: usize, out: &mut [u8]) -> usize {
    proposals::encode_stream(count, out).expect("the buffer holds the stream")
}

fn run_encode() {
    let mut out = vec![0u8; stream::stream_len(MESSAGES)];
    let len = workload_encode_proposed(black_box(MESSAGES), black_box(&mut out));
    assert_eq!(out[..len], stream::make_stream(MESSAGES)[..], "same stream");
    println!("encode-proposed: {MESSAGES} messages -> {len} bytes, identical to `encode`");
    println!("units workload_encode_proposed {MESSAGES} message");
}

const USAGE: &str = "usage: proposals [--mode encode-proposed|all]";

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
        "encode-proposed" | "all" => run_encode(),
        other => {
            eprintln!("unknown mode {other:?}\n{USAGE}");
            return ExitCode::FAILURE;
        }
    }
    ExitCode::SUCCESS
}
