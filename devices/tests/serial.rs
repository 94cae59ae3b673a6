//! The serial port adapter against a real peer: the other end of a pseudo-terminal.

#![cfg(unix)]

mod common;

use std::io::{Read as _, Write as _};
use std::time::Duration;

use embedded_io_async::{Read, Write};
use pprz_devices::host::{HostConfig, HostDevice};
use serialport::{SerialPort, TTYPort};

#[test]
fn pty_both_ways() {
    let (mut peer, port) = TTYPort::pair().expect("a pseudo-terminal pair");
    // Raw mode on the peer side: bytes pass unchanged.
    peer.set_timeout(Duration::from_secs(5)).unwrap();
    let mut dev = HostDevice::serial_port(Box::new(port), HostConfig::default()).unwrap();

    // PPRZ v2 ALIVE frame (aircraft 7 to ground, md5sum [0, 1, 2]) out to the peer.
    let frame = [
        0x99, 0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x1C, 0xC4,
    ];
    common::block_on(async {
        dev.write_all(&frame).await.unwrap();
        dev.flush().await.unwrap();
    });
    let mut got = [0u8; 12];
    peer.read_exact(&mut got).unwrap();
    assert_eq!(got, frame);

    // And every byte value back (binary-safe: no line discipline in the way).
    let all: Vec<u8> = (0..=255).collect();
    peer.write_all(&all).unwrap();
    let mut back = vec![0u8; 256];
    common::block_on(dev.read_exact(&mut back)).unwrap();
    assert_eq!(back, all);
    let s = dev.stats();
    assert_eq!((s.bytes_out, s.bytes_in), (12, 256));
}
