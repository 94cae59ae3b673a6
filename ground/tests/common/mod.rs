//! Test helpers shared by several test files of `pprz-ground` (each uses some of them).
#![allow(dead_code)]

use std::process::{Command, Output, Stdio};

use pprz_default::messages::telemetry::Gps;

/// The project's default message set.
pub const MESSAGES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../messages.xml");

/// The `pprz-monitor` binary, with no standard input.
pub fn monitor() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_pprz-monitor"));
    cmd.stdin(Stdio::null());
    cmd
}

/// Runs `cmd`: its exit code, standard output and standard error.
pub fn run(cmd: &mut Command) -> (Option<i32>, String, String) {
    let Output {
        status,
        stdout,
        stderr,
    } = cmd.output().expect("the monitor runs");
    (
        status.code(),
        String::from_utf8_lossy(&stdout).into_owned(),
        String::from_utf8_lossy(&stderr).into_owned(),
    )
}

/// A GPS message with a 3D fix in UTM zone 31 (values the tests check).
pub fn gps() -> Gps {
    Gps {
        mode: 3,
        utm_east: 37_712_345,
        utm_north: 482_112_000,
        alt: 152_300,
        utm_zone: 31,
        ..Gps::default()
    }
}
