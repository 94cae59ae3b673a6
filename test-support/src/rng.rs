//! The deterministic generator of fixed-seed tests, fuzz targets and benchmark
//! workloads: the simulated link's own ([`pprz_devices::rng::SplitMix64`]), under the
//! name the tests use, so that one generator serves them all.

pub use pprz_devices::rng::SplitMix64 as Rng;
