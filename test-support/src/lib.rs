//! Test plumbing shared by the workspace's tests and build scripts. Not published: no
//! library crate depends on it except as a dev- or build-dependency of tests.
//!
//! [`reference`](mod@reference) locates the PPRZLINK reference data (`messages.xml`, `units.xml`,
//! telemetry configurations) that compatibility tests compare against, and decides
//! whether its absence (or that of any other precondition) skips a test or fails it.
//! [`rng`] is the deterministic generator of fixed-seed tests, fuzz targets and
//! benchmark workloads. [`chunked`] feeds a decoder its input in chunks. [`viewer_tools`] finds the independent
//! MCAP and Foxglove readers the viewer tests use. [`temp::TempFile`] is a file of a
//! test's own, removed when dropped. [`shown::assert_escaped`] checks what a tool printed
//! holds no control character.

#![forbid(unsafe_code)]

pub mod chunked;
pub mod reference;
pub mod rng;
pub mod shown;
pub mod temp;
pub mod viewer_tools;
