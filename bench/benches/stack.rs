//! Wall-clock benchmarks of the telemetry stack (divan): the workloads of `pprz_bench`
//! with their fixed inputs. Machines are noisy; the deterministic figures are the
//! instruction counts of the `workloads` binary under callgrind (`BENCHMARKS.md`).
//!
//! `cargo bench -p pprz-bench` runs them; CI only builds them
//! (`cargo bench -p pprz-bench --no-run`).

use std::hint::black_box;

use divan::counter::{BytesCount, ItemsCount};
use divan::{Bencher, Divan};
use pprz_bench::arena::{self, CostArena};
use pprz_bench::downlink::{self, Sink};
use pprz_bench::stream::{self, MESSAGES};

fn main() {
    Divan::from_args().main();
}

/// Workload 1: 10 000 GPS/ATTITUDE messages encoded and framed (PPRZ v2).
#[divan::bench]
fn encode(bencher: Bencher<'_, '_>) {
    let mut out = vec![0u8; stream::stream_len(MESSAGES)];
    bencher
        .counter(ItemsCount::new(MESSAGES))
        .bench_local(|| stream::encode_stream(black_box(MESSAGES), black_box(&mut out)));
}

/// Workload 2: that stream decoded and every message decoded.
#[divan::bench]
fn parse(bencher: Bencher<'_, '_>) {
    let bytes = stream::make_stream(MESSAGES);
    bencher
        .counter(BytesCount::new(bytes.len()))
        .bench_local(|| stream::parse_stream(black_box(&bytes)));
}

/// Workload 2 through `Decoder::feed` (every byte copied into the decoder's buffer).
#[divan::bench]
fn parse_buffered(bencher: Bencher<'_, '_>) {
    let bytes = stream::make_stream(MESSAGES);
    bencher
        .counter(BytesCount::new(bytes.len()))
        .bench_local(|| stream::parse_stream_buffered(black_box(&bytes)));
}

/// Workload 3: 10 000 messages through send, arena, queue and writer to a sink.
#[divan::bench]
fn downlink(bencher: Bencher<'_, '_>) {
    let arena = <downlink::BenchArena>::new();
    let dl = downlink::new_downlink(&arena);
    let [mut port] = dl.ports().expect("a new downlink's ports");
    let mut sink = Sink::default();
    bencher
        .counter(ItemsCount::new(MESSAGES))
        .bench_local(|| downlink::run_downlink(&dl, &mut port, black_box(MESSAGES), &mut sink));
}

/// Workload 5: allocation and release steps at 10, 50 and 90 % fill.
#[divan::bench(args = [10, 50, 90])]
fn arena(bencher: Bencher<'_, '_>, percent: usize) {
    let memory = CostArena::new();
    let mut state = arena::prepare(&memory, percent, arena::SEED);
    bencher
        .counter(ItemsCount::new(arena::OPS))
        .bench_local(|| arena::churn(&mut state));
}
