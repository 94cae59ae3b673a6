//! A do-nothing STM32F405 firmware that links one part of the secure layer, selected by
//! features, so `measure.sh` can read each part's flash: the primitives alone as the
//! aircraft uses them (ChaCha20-Poly1305 both ways, SHA-512, X25519, Ed25519 signing and
//! verification; RustCrypto and dalek, or salty), and the whole aircraft side of
//! `pprz-secure` (channel, responder, key file). Inputs come from and results go to
//! `black_box`, so nothing is folded away. Measured, never run.

#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use panic_halt as _;

/// Bytes the optimiser cannot see through.
fn input<const N: usize>() -> [u8; N] {
    black_box([0x5A; N])
}

#[cfg(feature = "aead")]
fn aead() {
    use chacha20poly1305::aead::inout::InOutBuf;
    use chacha20poly1305::{AeadInOut, ChaCha20Poly1305, KeyInit};
    let cipher = ChaCha20Poly1305::new(&input::<32>().into());
    let nonce = input::<12>().into();
    let mut buf = input::<64>();
    let len = black_box(40);
    let tag = cipher.encrypt_inout_detached(&nonce, &input::<2>(), InOutBuf::from(&mut buf[..len]));
    black_box(&tag);
    let ok = cipher.decrypt_inout_detached(
        &nonce,
        &input::<2>(),
        InOutBuf::from(&mut buf[..len]),
        &input::<16>().into(),
    );
    black_box((ok.is_ok(), buf));
}

#[cfg(feature = "sha512")]
fn sha512() {
    use sha2::{Digest, Sha512};
    black_box(Sha512::digest(input::<33>()));
}

#[cfg(feature = "x25519")]
fn x25519() {
    black_box(x25519_dalek::x25519(input(), input()));
}

#[cfg(feature = "ed25519-sign")]
fn ed25519_sign() {
    use ed25519_dalek::ed25519::signature::Signer;
    let key = ed25519_dalek::SigningKey::from_bytes(&input());
    black_box(key.sign(&input::<64>()).to_bytes());
}

#[cfg(feature = "ed25519-verify")]
fn ed25519_verify() {
    if let Ok(key) = ed25519_dalek::VerifyingKey::from_bytes(&input()) {
        let sig = ed25519_dalek::Signature::from_bytes(&input());
        black_box(key.verify_strict(&input::<64>(), &sig).is_ok());
    }
}

#[cfg(feature = "salty-sha512")]
fn salty_sha512() {
    black_box(salty::Sha512::new().updated(&input::<33>()).finalize());
}

#[cfg(feature = "salty-x25519")]
fn salty_x25519() {
    black_box(salty::agreement::x25519(input(), input()));
}

#[cfg(feature = "salty-sign")]
fn salty_sign() {
    let key = salty::Keypair::from(&input::<32>());
    black_box(key.sign(&input::<64>()).to_bytes());
}

#[cfg(feature = "salty-verify")]
fn salty_verify() {
    if let Ok(key) = salty::PublicKey::try_from(&input::<32>()) {
        let sig = salty::Signature::from(&input::<64>());
        black_box(key.verify(&input::<64>(), &sig).is_ok());
    }
}

#[cfg(feature = "aircraft")]
fn aircraft() {
    use pprz_secure::rand_core::{CryptoRng, RngCore};
    use pprz_secure::{
        KeyExchange, KeyExchangeIds, KeyFile, Policy, Responder, ResponderEvent, SecureChannel,
    };

    /// Stands in for the hardware RNG.
    struct Rng;
    impl RngCore for Rng {
        fn next_u32(&mut self) -> u32 {
            black_box(7)
        }
        fn next_u64(&mut self) -> u64 {
            black_box(7)
        }
        fn fill_bytes(&mut self, dst: &mut [u8]) {
            for b in dst {
                *b = black_box(7);
            }
        }
    }
    impl CryptoRng for Rng {}

    static KEYS: KeyFile = KeyFile::from_raw(
        match pprz_secure::keys::parse_raw(pprz_secure::keys::INSECURE_TEST_KEY_FILE) {
            Ok(k) => k,
            Err(_) => panic!("test keys"),
        },
    );
    let Ok(keys) = black_box(&KEYS).aircraft() else {
        return;
    };
    let mut channel = SecureChannel::new(Policy::aircraft(7));
    let mut responder = Responder::new(7, keys);
    let mut out = [0u8; 255];
    // The reader: a frame's DATA, opened; a key exchange goes to the responder.
    let data = input::<64>();
    let opened = channel
        .open(&data[..black_box(40)], &mut out)
        .map(|o| o.data());
    if let Ok(data) = opened
        && let Ok(Some(kx)) = KeyExchange::parse(data, &KeyExchangeIds::PPRZLINK)
    {
        match responder.handle(&kx, black_box(1000), &mut Rng) {
            Ok(ResponderEvent::Established(keys)) => channel.install(keys),
            Ok(ResponderEvent::Reply(reply)) => {
                let mut buf = [0u8; 160];
                black_box(reply.write_frame(&mut buf));
                black_box(&buf);
            }
            Err(e) => {
                black_box(e);
            }
        }
    }
    // The writer: a frame sealed in place.
    let mut frame = input::<96>();
    black_box(channel.seal_in_place(&mut frame, black_box(40)).is_ok());
    black_box((&frame, channel.stats(), responder.stats()));
}

/// What every firmware links anyway (the telemetry stack copies and moves frames):
/// `memcpy`, `memmove` and `memset` of variable lengths, so they are not counted as the
/// secure layer's.
fn firmware_baseline() {
    let mut buf = input::<64>();
    let n = black_box(20);
    buf.copy_within(..n, black_box(3));
    let src = input::<64>();
    buf[..n].copy_from_slice(&src[..n]);
    buf[n..].fill(black_box(0));
    black_box(buf);
}

#[entry]
fn main() -> ! {
    firmware_baseline();
    #[cfg(feature = "aead")]
    aead();
    #[cfg(feature = "sha512")]
    sha512();
    #[cfg(feature = "x25519")]
    x25519();
    #[cfg(feature = "ed25519-sign")]
    ed25519_sign();
    #[cfg(feature = "ed25519-verify")]
    ed25519_verify();
    #[cfg(feature = "salty-sha512")]
    salty_sha512();
    #[cfg(feature = "salty-x25519")]
    salty_x25519();
    #[cfg(feature = "salty-sign")]
    salty_sign();
    #[cfg(feature = "salty-verify")]
    salty_verify();
    #[cfg(feature = "aircraft")]
    aircraft();
    loop {
        black_box(());
    }
}
