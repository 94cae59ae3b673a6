//! The `no_std` part of the benchmark workloads of the Paparazzi telemetry stack: their
//! fixed inputs and the loops that are measured, shared by the host benchmarks
//! (`pprz-bench`: callgrind on x86_64, divan) and the emulated Cortex-M4 firmware
//! (`bench/m4`), so both measure the same work on the same inputs.
//!
//! | module | workload | unit of the figure |
//! |--------|----------|--------------------|
//! | [`stream`] | 1. encode 10 000 GPS/ATTITUDE messages into PPRZ v2 frames | instructions per message |
//! | [`stream`] | 2. parse that byte stream and decode every message | instructions per byte |
//! | [`downlink`] | 3. send -> arena -> queue -> writer -> sink, polled without an executor | instructions per message |

#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

pub mod downlink;
pub mod stream;
