//! Test helpers shared by several test files (each file uses some of them).
#![allow(dead_code)]

pub mod frames;
pub mod roundtrip;
pub mod sim;
