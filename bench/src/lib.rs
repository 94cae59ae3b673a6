//! Benchmarks and deterministic workloads of the Paparazzi telemetry stack (issue 8).
//!
//! Every workload runs fixed inputs (fixed seeds, fixed message sequences), so its
//! instruction count is the same on every run and every machine of one architecture:
//!
//! | module | workload | unit of the figure |
//! |--------|----------|--------------------|
//! | [`stream`] | 1. encode 10 000 GPS/ATTITUDE messages into PPRZ v2 frames | instructions per message |
//! | [`stream`] | 2. parse that byte stream and decode every message | instructions per byte |
//! | [`downlink`] | 3. send -> arena -> queue -> writer -> sink, polled on the host | instructions per message |
//! | [`overload`] | 4. a 57 600-baud link overloaded 10x for 60 s of mock time, against a FIFO | latencies, shedding, utilisation |
//! | [`arena`] | 5. alloc + release at 10/50/90 % fill, fill at the first failure | instructions per operation (an allocation or a release), fill |
//! | [`secure`] | 8. seal and open 10 000 40-byte-field frames of the secure link | instructions per frame |
//!
//! The `workloads` binary (`src/bin/workloads.rs`) runs each workload inside one named,
//! non-inlined function (`workload_encode`, `workload_parse`, ...) so that callgrind's
//! `--toggle-collect` counts exactly that work; the wall-clock benchmarks in
//! `benches/stack.rs` (divan) reuse the same functions. `BENCHMARKS.md` at the root of
//! the repository has the commands and the latest figures; footprint (workload 6) is
//! measured by `bench/footprint.sh` on the `bench/footprint` firmware.
//!
//! Workloads 1-3 live in `pprz-bench-common` (`bench/common`, `no_std`), re-exported by
//! [`stream`] and [`downlink`]: the Cortex-M4 firmware of `bench/m4` runs the very same
//! loops on the same inputs under QEMU.

#![warn(missing_docs)]

pub mod arena;
pub mod downlink;
pub mod overload;
pub mod radio;
pub use pprz_test_support::rng;
pub mod secure;
pub mod sim;
pub mod stream;
