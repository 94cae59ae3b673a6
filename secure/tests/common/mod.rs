//! Shared by the integration tests: the known-answer vectors, deterministic RNGs, the
//! two ends of a link wired the way the telemetry stack and the ground tool use the
//! crate (reader -> channel -> handshake -> channel -> writer), frames as an attacker
//! forges them, and an in-memory radio for the Embassy aircraft.
#![allow(dead_code)]

use std::cell::RefCell;
use std::collections::HashMap;
use std::convert::Infallible;

use pprz_secure::rand_core::{CryptoRng, RngCore};
use pprz_secure::{
    Initiator, InitiatorEvent, KeyExchange, KeyExchangeIds, KeyFile, Opened, Policy, Protection,
    Reject, Responder, ResponderEvent, SealError, SecureChannel,
};
use pprz_test_support::rng::Rng;
use pprz_transports::{Framing, PprzV2};

/// The committed known-answer vectors (`secure/kat/vectors.txt`, made by
/// `secure/kat/generate.py`).
pub struct Vectors(HashMap<String, Vec<u8>>);

impl Vectors {
    pub fn load() -> Self {
        let text = include_str!("../../kat/vectors.txt");
        let mut map = HashMap::new();
        for line in text.lines() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let (name, value) = line.split_once('=').expect("name = hex");
            let value = value.trim();
            let bytes = (0..value.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&value[i..i + 2], 16).expect("hex"))
                .collect();
            assert!(map.insert(name.trim().to_string(), bytes).is_none());
        }
        Self(map)
    }

    pub fn bytes(&self, name: &str) -> Vec<u8> {
        self.0
            .get(name)
            .unwrap_or_else(|| panic!("no vector {name}"))
            .clone()
    }

    pub fn arr<const N: usize>(&self, name: &str) -> [u8; N] {
        self.bytes(name).try_into().expect("length")
    }

    pub fn u32(&self, name: &str) -> u32 {
        u32::from_be_bytes(self.arr(name))
    }
}

/// An RNG that returns the given bytes (a fixed ephemeral key), then zeros.
pub struct FixedRng(pub Vec<u8>);

impl RngCore for FixedRng {
    fn next_u32(&mut self) -> u32 {
        pprz_secure::rand_core::impls::next_u32_via_fill(self)
    }
    fn next_u64(&mut self) -> u64 {
        pprz_secure::rand_core::impls::next_u64_via_fill(self)
    }
    fn fill_bytes(&mut self, dst: &mut [u8]) {
        for b in dst {
            *b = if self.0.is_empty() {
                0
            } else {
                self.0.remove(0)
            };
        }
    }
}
impl CryptoRng for FixedRng {}

/// A deterministic stand-in for a hardware RNG (the workspace's seeded generator): fresh
/// keys every time, reproducible runs. Also the loss pattern of the lossy-link tests.
pub struct TestRng(Rng);

impl TestRng {
    pub const fn new(seed: u64) -> Self {
        Self(Rng::new(seed))
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }
}

impl RngCore for TestRng {
    fn next_u32(&mut self) -> u32 {
        self.next_u64() as u32
    }
    fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }
    fn fill_bytes(&mut self, dst: &mut [u8]) {
        pprz_secure::rand_core::impls::fill_bytes_via_next(self, dst)
    }
}
impl CryptoRng for TestRng {}

pub const AC_ID: u8 = 7;

pub fn test_keys() -> KeyFile {
    KeyFile::parse(pprz_secure::keys::INSECURE_TEST_KEY_FILE).unwrap()
}

/// A plain PPRZ v2 frame of `fields` from `src` to `dst`.
pub fn plain(src: u8, dst: u8, class: u8, id: u8, fields: &[u8]) -> Vec<u8> {
    let meta = pprz_transports::TxMeta::new(pprz_transports::MsgHeader::new(src, dst, class, id));
    let mut out = [0u8; 256];
    let n = pprz_transports::Encoder::encode(&PprzV2, &meta, fields, &mut out).unwrap();
    out[..n].to_vec()
}

/// PING (datalink 8) from the ground to the aircraft.
pub fn ping() -> Vec<u8> {
    plain(0, AC_ID, 2, 8, &[])
}

/// SETTING (datalink 4): index 3 <- 1.5.
pub fn setting() -> Vec<u8> {
    let mut f = vec![3, AC_ID];
    f.extend_from_slice(&1.5f32.to_le_bytes());
    plain(0, AC_ID, 2, 4, &f)
}

/// ALIVE (telemetry 2) from the aircraft.
pub fn alive() -> Vec<u8> {
    plain(AC_ID, 0, 1, 2, &[3, 0, 1, 2])
}

/// PONG (telemetry 3) from the aircraft.
pub fn pong() -> Vec<u8> {
    plain(AC_ID, 0, 1, 3, &[])
}

/// Seals a plain frame for the wire, as the writer does (in a buffer with the overhead).
pub fn seal(ch: &mut SecureChannel, plain: &[u8]) -> Result<Vec<u8>, SealError> {
    let mut buf = [0u8; 256];
    buf[..plain.len()].copy_from_slice(plain);
    let sealed = ch.seal_in_place(&mut buf, plain.len())?;
    Ok(buf[..sealed.len].to_vec())
}

/// The DATA of a wire frame, checked by the PPRZ v2 framing as the decoder does.
pub fn data(wire: &[u8]) -> &[u8] {
    let (frame, n) = PprzV2.parse(wire).expect("a valid PPRZ frame");
    assert_eq!(n, wire.len());
    frame.data()
}

/// Opens a wire frame, as the reader does: the plain frame and how it came.
pub fn open(ch: &mut SecureChannel, wire: &[u8]) -> Result<(Vec<u8>, Protection), Reject> {
    let mut out = [0u8; 255];
    let opened: Opened<'_> = ch.open(data(wire), &mut out)?;
    // The plain frame is a valid PPRZ v2 frame.
    assert_eq!(
        PprzV2.parse(opened.frame()).unwrap().1,
        opened.frame().len()
    );
    Ok((opened.frame().to_vec(), opened.protection()))
}

/// What a received frame became.
#[derive(Debug, PartialEq)]
pub enum Rx {
    /// Delivered to the application (plain frame).
    App(Vec<u8>, Protection),
    /// Handled by the handshake.
    Handshake(Result<(), pprz_secure::HandshakeError>),
    /// Rejected by the channel.
    Rejected(Reject),
}

/// The aircraft: a channel and the responder, as the firmware wires them.
pub struct Aircraft {
    pub ch: SecureChannel,
    pub hs: Responder,
    /// Frames to write (sealed), in order.
    pub out: Vec<Vec<u8>>,
}

impl Aircraft {
    pub fn new() -> Self {
        Self::with_keys(&test_keys())
    }

    pub fn with_keys(keys: &KeyFile) -> Self {
        Self {
            ch: SecureChannel::new(Policy::aircraft(AC_ID)),
            hs: Responder::new(AC_ID, keys.aircraft().unwrap()),
            out: vec![],
        }
    }

    /// Queues a frame for the radio; `false` if the channel refused it (no session).
    pub fn send(&mut self, plain: &[u8]) -> Result<(), SealError> {
        let wire = seal(&mut self.ch, plain)?;
        self.out.push(wire);
        Ok(())
    }

    pub fn receive(&mut self, wire: &[u8], now_ms: u64, rng: &mut impl CryptoRng) -> Rx {
        let (frame, protection) = match open(&mut self.ch, wire) {
            Ok(x) => x,
            Err(e) => return Rx::Rejected(e),
        };
        let kx = KeyExchange::parse(&frame[2..frame.len() - 2], &KeyExchangeIds::PPRZLINK);
        match kx {
            Ok(Some(kx)) => Rx::Handshake(match self.hs.handle(&kx, now_ms, rng) {
                Ok(ResponderEvent::Reply(reply)) => {
                    let mut buf = [0u8; 256];
                    let n = reply.write_frame(&mut buf).unwrap();
                    self.send(&buf[..n]).unwrap();
                    Ok(())
                }
                Ok(ResponderEvent::Established(keys)) => {
                    self.ch.install(keys);
                    Ok(())
                }
                Err(e) => Err(e),
            }),
            Err(e) => Rx::Handshake(Err(e)),
            Ok(None) => Rx::App(frame, protection),
        }
    }
}

/// The ground: a channel and the initiator, as the ground tool wires them.
pub struct Ground {
    pub ch: SecureChannel,
    pub hs: Initiator,
    pub out: Vec<Vec<u8>>,
}

impl Ground {
    pub fn new() -> Self {
        Self::with_keys(&test_keys())
    }

    pub fn with_keys(keys: &KeyFile) -> Self {
        Self {
            ch: SecureChannel::new(Policy::ground(AC_ID)),
            hs: Initiator::new(AC_ID, keys.ground().unwrap()),
            out: vec![],
        }
    }

    pub fn send(&mut self, plain: &[u8]) -> Result<(), SealError> {
        let wire = seal(&mut self.ch, plain)?;
        self.out.push(wire);
        Ok(())
    }

    fn send_kx(&mut self, kx: &KeyExchange) {
        let mut buf = [0u8; 256];
        let n = kx.write_frame(&mut buf).unwrap();
        self.send(&buf[..n]).unwrap();
    }

    /// The ground tool's periodic step.
    pub fn poll(&mut self, now_ms: u64, rng: &mut impl CryptoRng) {
        if self.ch.needs_rekey() {
            self.hs.restart();
        }
        if let Some(kx) = self.hs.poll(now_ms, rng) {
            self.send_kx(&kx);
        }
    }

    pub fn receive(&mut self, wire: &[u8], now_ms: u64) -> Rx {
        let (frame, protection) = match open(&mut self.ch, wire) {
            Ok(x) => x,
            Err(e) => return Rx::Rejected(e),
        };
        if let Protection::Encrypted { .. } = protection {
            self.hs.confirm(now_ms);
        }
        let kx = KeyExchange::parse(&frame[2..frame.len() - 2], &KeyExchangeIds::PPRZLINK);
        match kx {
            Ok(Some(kx)) => Rx::Handshake(match self.hs.handle(&kx, now_ms) {
                Ok(InitiatorEvent::Established { keys, reply }) => {
                    self.ch.install(keys);
                    self.send_kx(&reply);
                    Ok(())
                }
                Ok(InitiatorEvent::Resend(reply)) => {
                    self.send_kx(&reply);
                    Ok(())
                }
                Err(e) => Err(e),
            }),
            Err(e) => Rx::Handshake(Err(e)),
            Ok(None) => Rx::App(frame, protection),
        }
    }
}

/// Runs a complete handshake over a perfect link at `now_ms`; both ends up.
pub fn establish(air: &mut Aircraft, ground: &mut Ground, now_ms: u64, rng: &mut TestRng) {
    ground.hs.restart();
    ground.poll(now_ms, rng);
    for _ in 0..3 {
        for f in std::mem::take(&mut ground.out) {
            air.receive(&f, now_ms, rng);
        }
        for f in std::mem::take(&mut air.out) {
            ground.receive(&f, now_ms);
        }
    }
    assert!(air.ch.has_session() && ground.ch.has_session());
    assert_eq!(air.hs.state(), pprz_secure::ResponderState::Established);
}

/// A plaintext (0xAA) frame of a plain v2 frame, as an attacker would forge it.
pub fn as_plaintext(plain: &[u8]) -> Vec<u8> {
    let mut data = vec![0xAA];
    data.extend_from_slice(&plain[2..plain.len() - 2]);
    frame(&data)
}

/// A PPRZ frame around `data` (valid checksum).
pub fn frame(data: &[u8]) -> Vec<u8> {
    let mut f = vec![0x99, (data.len() + 4) as u8];
    f.extend_from_slice(data);
    let (a, b) = pprz_transports::checksum::pprz(&f[1..]);
    f.extend_from_slice(&[a, b]);
    f
}

/// The same wire frame with DATA byte `i` changed by `xor`, checksum fixed.
pub fn tamper(wire: &[u8], i: usize, xor: u8) -> Vec<u8> {
    let mut data = wire[2..wire.len() - 2].to_vec();
    data[i] ^= xor;
    frame(&data)
}

/// The radio's downlink: bytes the aircraft's writer wrote.
pub struct Wire<'a>(pub &'a RefCell<Vec<u8>>);

impl embedded_io_async::ErrorType for Wire<'_> {
    type Error = Infallible;
}

impl embedded_io_async::Write for Wire<'_> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.0.borrow_mut().extend_from_slice(buf);
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}
