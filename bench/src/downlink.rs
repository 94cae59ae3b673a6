//! Workload 3: the downlink end to end. The workload is in
//! [`pprz_bench_common::downlink`] (`no_std`, shared with the Cortex-M4 firmware of
//! `bench/m4`), re-exported here.

pub use pprz_bench_common::downlink::*;
