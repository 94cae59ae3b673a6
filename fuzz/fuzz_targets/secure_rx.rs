//! Fuzz the secure receive path (pprz-secure): a byte stream through the PPRZ v2 decoder
//! into a secure channel, plaintext key exchanges into the handshake, as the reader and
//! the handshake task of each end do.
//!
//! Input layout: byte 0 selects the end and its state (bit 0: aircraft or ground; bit 1:
//! a session installed first, with the known-answer session keys, or none), the rest of
//! it and byte 1 seed the chunk sizes and the clock; the rest is the received stream.
//! The known-answer ephemeral keys are the RNG, and the ground has sent message 1, so
//! the seeds in `seeds/secure_rx` (known-answer frames) run whole handshakes and open
//! data frames.
//!
//! Checked: no panic; every frame the decoder yields is counted by the channel exactly
//! once (opened or rejected by reason); an opened frame is a valid plain PPRZ v2 frame
//! (at most 234 bytes if it was encrypted), whitelisted if it came in plaintext; accepted counters
//! increase strictly within a session; handshake refusals are counted; the responder
//! does at most one handshake's work per second of the fuzzer's clock.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use pprz_secure::rand_core::{CryptoRng, RngCore};
use pprz_secure::{
    DirectionKey, Initiator, InitiatorEvent, KeyExchange, KeyExchangeIds, KeyFile, Policy,
    Protection, Reject, Responder, ResponderEvent, SecureChannel, SessionKeys,
};
use pprz_transports::{Decoder, Framing, PprzV2};

const AC_ID: u8 = 7;

/// The known-answer vectors of pprz-secure.
struct Kat {
    a_eph: [u8; 32],
    b_eph: [u8; 32],
    ka: [u8; 32],
    sa: [u8; 12],
    kb: [u8; 32],
    sb: [u8; 12],
}

fn kat() -> &'static Kat {
    static KAT: OnceLock<Kat> = OnceLock::new();
    KAT.get_or_init(|| {
        let text = include_str!("../../secure/kat/vectors.txt");
        let get = |name: &str| -> Vec<u8> {
            let line = text
                .lines()
                .find(|l| l.split('=').next().map(str::trim) == Some(name))
                .expect(name);
            let hex = line.split('=').nth(1).unwrap().trim();
            (0..hex.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
                .collect()
        };
        Kat {
            a_eph: get("a_eph").try_into().unwrap(),
            b_eph: get("b_eph").try_into().unwrap(),
            ka: get("ka").try_into().unwrap(),
            sa: get("sa").try_into().unwrap(),
            kb: get("kb").try_into().unwrap(),
            sb: get("sb").try_into().unwrap(),
        }
    })
}

/// Returns the same 32 bytes for every key drawn.
struct Fixed([u8; 32]);

impl RngCore for Fixed {
    fn next_u32(&mut self) -> u32 {
        pprz_secure::rand_core::impls::next_u32_via_fill(self)
    }
    fn next_u64(&mut self) -> u64 {
        pprz_secure::rand_core::impls::next_u64_via_fill(self)
    }
    fn fill_bytes(&mut self, dst: &mut [u8]) {
        for (d, s) in dst.iter_mut().zip(self.0.iter().cycle()) {
            *d = *s;
        }
    }
}
impl CryptoRng for Fixed {}

enum Handshake {
    Aircraft(Box<Responder>),
    Ground(Box<Initiator>),
}

fn run(input: &[u8]) {
    let Some((&mode, rest)) = input.split_first() else {
        return;
    };
    let Some((&seed, stream)) = rest.split_first() else {
        return;
    };
    let k = kat();
    let keys = KeyFile::parse(pprz_secure::keys::INSECURE_TEST_KEY_FILE).unwrap();
    let aircraft = mode & 1 == 0;
    let (mut channel, mut handshake, mut rng) = if aircraft {
        let ch = SecureChannel::new(Policy::aircraft(AC_ID));
        let r = Responder::new(AC_ID, keys.aircraft().unwrap());
        (ch, Handshake::Aircraft(Box::new(r)), Fixed(k.b_eph))
    } else {
        let ch = SecureChannel::new(Policy::ground(AC_ID));
        let mut i = Initiator::new(AC_ID, keys.ground().unwrap());
        assert!(i.poll(0, &mut Fixed(k.a_eph)).is_some(), "message 1");
        (ch, Handshake::Ground(Box::new(i)), Fixed(k.a_eph))
    };
    if mode & 2 != 0 {
        let (a, b) = (DirectionKey::new(k.ka, k.sa), DirectionKey::new(k.kb, k.sb));
        channel.install(if aircraft {
            SessionKeys::new(b, a)
        } else {
            SessionKeys::new(a, b)
        });
    }

    let mut decoder: Decoder<PprzV2, 255> = Decoder::new(PprzV2);
    let mut out = [0u8; 255];
    let mut frames = 0u32;
    let mut last_counter = 0u32;
    let mut sessions = channel.stats().sessions;
    let mut now: u64 = 0;
    let mut state = u32::from(seed) | (u32::from(mode) << 8);
    let mut input = stream;
    while !input.is_empty() {
        // Chunk sizes and clock steps from a small LCG seeded by the first bytes.
        state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        let n = 1 + (state >> 16) as usize % 64;
        let (chunk, tail) = input.split_at(n.min(input.len()));
        input = tail;
        now += u64::from((state >> 8) & 0x3FF);
        let mut bytes = chunk;
        while let Some(frame) = decoder.feed_borrowed(&mut bytes) {
            frames += 1;
            let before = channel.stats();
            let result = channel.open(frame.data(), &mut out);
            let after = channel.stats();
            if after.sessions != sessions {
                unreachable!("open never installs a session");
            }
            let opened = match result {
                Ok(opened) => opened,
                Err(reason) => {
                    assert_ne!(
                        reason,
                        Reject::BufferTooSmall,
                        "a 255-byte buffer is enough"
                    );
                    assert_eq!(after.rejected(), before.rejected() + 1);
                    continue;
                }
            };
            let plain = opened.frame();
            if opened.is_encrypted() {
                assert!(plain.len() <= 255 - pprz_secure::OVERHEAD);
            }
            let (view, len) = PprzV2
                .parse(plain)
                .expect("an opened frame is a PPRZ v2 frame");
            assert_eq!(len, plain.len());
            assert_eq!(view.data(), opened.data());
            match opened.protection() {
                Protection::Encrypted { counter } => {
                    assert!(counter > last_counter, "counters increase strictly");
                    assert_eq!(channel.last_rx_counter(), counter);
                    last_counter = counter;
                    assert_eq!(after.decrypted, before.decrypted + 1);
                }
                Protection::Plaintext => {
                    let h = opened.header();
                    assert!(channel
                        .policy()
                        .rx_plaintext
                        .iter()
                        .any(|m| m.class == h.class && m.id == h.msg_id));
                    assert_eq!(after.received_plaintext, before.received_plaintext + 1);
                }
            }
            let kx = match KeyExchange::parse(opened.data(), &KeyExchangeIds::PPRZLINK) {
                Ok(Some(kx)) => kx,
                Ok(None) | Err(_) => continue,
            };
            let keys = match &mut handshake {
                Handshake::Aircraft(r) => {
                    let started = r.stats().started;
                    let result = r.handle(&kx, now, &mut rng);
                    if r.stats().started != started {
                        assert!(result.is_ok());
                    }
                    match result {
                        Ok(ResponderEvent::Established(keys)) => Some(keys),
                        Ok(ResponderEvent::Reply(reply)) => {
                            let mut buf = [0u8; 255];
                            let n = reply.write_frame(&mut buf).expect("message 2 fits");
                            assert!(channel.seal_in_place(&mut buf, n).is_ok());
                            None
                        }
                        Err(_) => None,
                    }
                }
                Handshake::Ground(i) => match i.handle(&kx, now) {
                    Ok(InitiatorEvent::Established { keys, .. }) => Some(keys),
                    Ok(InitiatorEvent::Resend(_)) | Err(_) => None,
                },
            };
            if let Some(keys) = keys {
                channel.install(keys);
                sessions = channel.stats().sessions;
                last_counter = 0;
            }
        }
    }
    let s = channel.stats();
    assert_eq!(
        frames,
        s.decrypted + s.received_plaintext + s.rejected(),
        "every frame counted once"
    );
    if let Handshake::Aircraft(r) = &handshake {
        // One handshake's work per 1000 ms of the clock, at most.
        assert!(u64::from(r.stats().started) <= 1 + now / 1000);
    }
}

fuzz_target!(|data: &[u8]| run(data));
