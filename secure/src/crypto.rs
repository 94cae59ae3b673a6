//! The public-key primitives and SHA-512, from one of two backends chosen by feature:
//!
//! * `dalek` (default): `x25519-dalek`, `ed25519-dalek` and RustCrypto's `sha2`: audited,
//!   fast on 64-bit hosts; about 29 KB of flash on a Cortex-M4 (with the rolled SHA-512).
//! * `salty`: `salty` (X25519, Ed25519 and its own SHA-512, with assembly field arithmetic
//!   on Cortex-M4): about 14 KB and faster on the aircraft, not audited. If both features
//!   are enabled, `salty` is used (a firmware opts into it; a crate elsewhere in the
//!   graph enabling the default must not undo that).
//!
//! ChaCha20-Poly1305 is RustCrypto's in both. Both backends give the same bytes (the
//! known-answer tests run on either, and a unit test compares them directly), and both
//! refuse the same keys and signatures: small-order or invalid public keys, and
//! non-canonical signature scalars.

use zeroize::Zeroizing;

#[cfg(not(any(feature = "dalek", feature = "salty")))]
compile_error!("pprz-secure needs a crypto backend: feature `dalek` (the default) or `salty`");

/// The backend in use: `"dalek"` or `"salty"`.
pub const BACKEND: &str = if cfg!(feature = "salty") {
    "salty"
} else {
    "dalek"
};

/// The group order `L` of Ed25519, little-endian: a signature's scalar must be below it.
const ORDER: [u8; 32] = [
    0xed, 0xd3, 0xf5, 0x5c, 0x1a, 0x63, 0x12, 0x58, 0xd6, 0x9c, 0xf7, 0xa2, 0xde, 0xf9, 0xde, 0x14,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x10,
];

/// Whether the little-endian scalar `s` is below `L` (signature scalars are public: a
/// plain comparison).
fn canonical_scalar(s: &[u8]) -> bool {
    for (a, l) in s.iter().rev().zip(ORDER.iter().rev()) {
        if a != l {
            return a < l;
        }
    }
    false
}

/// The y-coordinates (little-endian, sign bit cleared) of the small-order points of
/// Ed25519, canonical and not: 0, 1, the two of order 8, p - 1, p, p + 1.
#[cfg_attr(not(feature = "salty"), allow(dead_code))]
#[allow(clippy::indexing_slicing)] // evaluated at build time
const SMALL_ORDER_Y: [[u8; 32]; 7] = {
    let mut ys = [[0u8; 32]; 7];
    ys[1][0] = 1;
    ys[2] = [
        0x26, 0xe8, 0x95, 0x8f, 0xc2, 0xb2, 0x27, 0xb0, 0x45, 0xc3, 0xf4, 0x89, 0xf2, 0xef, 0x98,
        0xf0, 0xd5, 0xdf, 0xac, 0x05, 0xd3, 0xc6, 0x33, 0x39, 0xb1, 0x38, 0x02, 0x88, 0x6d, 0x53,
        0xfc, 0x05,
    ];
    ys[3] = [
        0xc7, 0x17, 0x6a, 0x70, 0x3d, 0x4d, 0xd8, 0x4f, 0xba, 0x3c, 0x0b, 0x76, 0x0d, 0x10, 0x67,
        0x0f, 0x2a, 0x20, 0x53, 0xfa, 0x2c, 0x39, 0xcc, 0xc6, 0x4e, 0xc7, 0xfd, 0x77, 0x92, 0xac,
        0x03, 0x7a,
    ];
    let mut i = 4;
    while i < 7 {
        let mut b = 0;
        while b < 31 {
            ys[i][b] = 0xff;
            b += 1;
        }
        ys[i][31] = 0x7f;
        i += 1;
    }
    ys[4][0] = 0xec; // p - 1
    ys[5][0] = 0xed; // p
    ys[6][0] = 0xee; // p + 1
    ys
};

/// Whether `key` encodes a point of small order (whatever its sign bit).
#[cfg_attr(not(feature = "salty"), allow(dead_code))]
fn small_order(key: &[u8; 32]) -> bool {
    let mut y = *key;
    y[31] &= 0x7f;
    SMALL_ORDER_Y.contains(&y)
}

#[cfg(feature = "salty")]
mod imp {
    use zeroize::Zeroizing;

    pub(crate) fn sha512(parts: &[&[u8]]) -> Zeroizing<[u8; 64]> {
        let mut h = salty::Sha512::new();
        for p in parts {
            h.update(p);
        }
        Zeroizing::new(h.finalize())
    }

    pub(crate) fn x25519(k: &[u8; 32], u: &[u8; 32]) -> Zeroizing<[u8; 32]> {
        Zeroizing::new(salty::agreement::x25519(*k, *u))
    }

    /// salty's key pair; its secret part is zeroized on drop.
    pub(crate) struct SigningKey(salty::Keypair);

    impl SigningKey {
        pub(crate) fn from_seed(seed: &[u8; 32]) -> Self {
            Self(salty::Keypair::from(seed))
        }

        pub(crate) fn public(&self) -> [u8; 32] {
            self.0.public.to_bytes()
        }

        pub(crate) fn sign(&self, msg: &[u8]) -> [u8; 64] {
            self.0.sign(msg).to_bytes()
        }
    }

    pub(crate) struct VerifyingKey(salty::PublicKey);

    impl VerifyingKey {
        pub(crate) fn from_bytes(bytes: &[u8; 32]) -> Option<Self> {
            if super::small_order(bytes) {
                return None;
            }
            salty::PublicKey::try_from(bytes).ok().map(Self)
        }

        pub(crate) fn verify(&self, msg: &[u8], sig: &[u8; 64]) -> bool {
            let (r, s) = sig.split_at(32);
            let mut r_y = [0u8; 32];
            r_y.copy_from_slice(r);
            super::canonical_scalar(s)
                && !super::small_order(&r_y)
                && self.0.verify(msg, &salty::Signature::from(sig)).is_ok()
        }
    }
}

#[cfg(all(feature = "dalek", not(feature = "salty")))]
mod imp {
    use ed25519_dalek::ed25519::signature::Signer;
    use sha2::{Digest, Sha512};
    use zeroize::{Zeroize, Zeroizing};

    pub(crate) fn sha512(parts: &[&[u8]]) -> Zeroizing<[u8; 64]> {
        let mut h = Sha512::new();
        for p in parts {
            h.update(p);
        }
        let mut out = h.finalize();
        let mut digest = Zeroizing::new([0u8; 64]);
        digest.copy_from_slice(&out);
        out.as_mut_slice().zeroize();
        digest
    }

    pub(crate) fn x25519(k: &[u8; 32], u: &[u8; 32]) -> Zeroizing<[u8; 32]> {
        Zeroizing::new(x25519_dalek::x25519(*k, *u))
    }

    /// ed25519-dalek's signing key; zeroized on drop.
    pub(crate) struct SigningKey(ed25519_dalek::SigningKey);

    impl SigningKey {
        pub(crate) fn from_seed(seed: &[u8; 32]) -> Self {
            Self(ed25519_dalek::SigningKey::from_bytes(seed))
        }

        pub(crate) fn public(&self) -> [u8; 32] {
            self.0.verifying_key().to_bytes()
        }

        pub(crate) fn sign(&self, msg: &[u8]) -> [u8; 64] {
            self.0.sign(msg).to_bytes()
        }
    }

    pub(crate) struct VerifyingKey(ed25519_dalek::VerifyingKey);

    impl VerifyingKey {
        pub(crate) fn from_bytes(bytes: &[u8; 32]) -> Option<Self> {
            ed25519_dalek::VerifyingKey::from_bytes(bytes)
                .ok()
                .filter(|k| !k.is_weak())
                .map(Self)
        }

        pub(crate) fn verify(&self, msg: &[u8], sig: &[u8; 64]) -> bool {
            // verify_strict: canonical scalar, no small-order R or key.
            super::canonical_scalar(&sig[32..])
                && self
                    .0
                    .verify_strict(msg, &ed25519_dalek::Signature::from_bytes(sig))
                    .is_ok()
        }
    }
}

pub(crate) use imp::{SigningKey, VerifyingKey, sha512, x25519};

/// X25519's base point (u = 9).
pub(crate) const BASEPOINT: [u8; 32] = {
    let mut b = [0u8; 32];
    b[0] = 9;
    b
};

/// X25519 of `k` (clamped) with the base point: the public key.
pub(crate) fn x25519_public(k: &[u8; 32]) -> [u8; 32] {
    *x25519(k, &BASEPOINT)
}

/// An all-zero 32-byte value, zeroized (for comparisons).
pub(crate) fn is_zero(x: &Zeroizing<[u8; 32]>) -> bool {
    crate::channel::ct_eq(x.as_slice(), &[0u8; 32])
}

#[cfg(test)]
mod tests {
    //! Both backends against each other and against the known-answer vectors, whichever
    //! one the crate is built with (salty and ed25519-dalek are dev-dependencies).
    extern crate std;
    use std::string::String;
    use std::vec::Vec;

    use super::*;

    fn vector(name: &str) -> Vec<u8> {
        let text = include_str!("../kat/vectors.txt");
        let line = text
            .lines()
            .find(|l| l.split('=').next().map(str::trim) == Some(name))
            .unwrap();
        let hex: String = line.split('=').nth(1).unwrap().trim().into();
        (0..hex.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
            .collect()
    }

    fn arr(name: &str) -> [u8; 32] {
        vector(name).try_into().unwrap()
    }

    #[test]
    fn backend_reproduces_the_vectors() {
        let (a, b) = (arr("a_eph"), arr("b_eph"));
        assert_eq!(x25519_public(&a), arr("p_ae"));
        assert_eq!(x25519_public(&b), arr("p_be"));
        assert_eq!(*x25519(&b, &arr("p_ae")), arr("z"));
        let h = sha512(&[&arr("z"), &[1]]);
        assert_eq!(h[..32], vector("kb")[..]);
        assert_eq!(h[32..44], vector("sb")[..]);
        let uav = SigningKey::from_seed(&arr("uav_seed"));
        assert_eq!(uav.public(), arr("uav_public"));
        let msg = [arr("p_be"), arr("p_ae")].concat();
        let sig = uav.sign(&msg);
        assert_eq!(sig[..], vector("sig_b")[..]);
        let v = VerifyingKey::from_bytes(&arr("uav_public")).unwrap();
        assert!(v.verify(&msg, &sig));
        assert!(!v.verify(&msg[1..], &sig));
    }

    #[test]
    fn salty_and_dalek_agree() {
        use ed25519_dalek::ed25519::signature::Signer;
        for i in 0..8u8 {
            let seed = [i.wrapping_mul(37).wrapping_add(1); 32];
            let k = [i.wrapping_mul(11).wrapping_add(3); 32];
            let u = x25519_dalek::x25519(seed, x25519_dalek::X25519_BASEPOINT_BYTES);
            assert_eq!(
                salty::agreement::x25519(k, u),
                x25519_dalek::x25519(k, u),
                "x25519"
            );
            let d = ed25519_dalek::SigningKey::from_bytes(&seed);
            let s = salty::Keypair::from(&seed);
            assert_eq!(s.public.to_bytes(), d.verifying_key().to_bytes());
            assert_eq!(s.sign(&u).to_bytes(), d.sign(&u).to_bytes());
        }
    }

    #[test]
    fn weak_keys_and_non_canonical_signatures() {
        // Every small-order encoding is refused, as ed25519-dalek's `is_weak` does.
        for y in SMALL_ORDER_Y {
            for sign in [0, 0x80] {
                let mut key = y;
                key[31] |= sign;
                assert!(VerifyingKey::from_bytes(&key).is_none(), "{key:02x?}");
                if let Ok(k) = ed25519_dalek::VerifyingKey::from_bytes(&key) {
                    assert!(k.is_weak(), "{key:02x?}");
                }
            }
        }
        // s + L verifies nowhere.
        let uav = SigningKey::from_seed(&arr("uav_seed"));
        let v = VerifyingKey::from_bytes(&uav.public()).unwrap();
        let mut sig = uav.sign(b"m");
        let mut carry = 0u16;
        for (b, l) in sig[32..].iter_mut().zip(ORDER) {
            let sum = u16::from(*b) + u16::from(l) + carry;
            *b = sum as u8;
            carry = sum >> 8;
        }
        assert!(!v.verify(b"m", &sig));
        assert!(canonical_scalar(&[0; 32]));
        assert!(!canonical_scalar(&ORDER));
        let mut below = ORDER;
        below[0] -= 1;
        assert!(canonical_scalar(&below));
    }
}
