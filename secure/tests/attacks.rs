//! Attacks at the layer: each is rejected and counted, and nothing is applied (no frame
//! delivered, no counter or session changed).

mod common;

use common::*;
use pprz_secure::initiator::MSG3_RESENDS;
use pprz_secure::{
    HandshakeError, KeyExchange, KeyExchangeIds, KeyFile, KeyName, MsgType, Protection, Reject,
    ResponderState, SealError,
};

fn established() -> (Aircraft, Ground, TestRng) {
    let mut rng = TestRng::new(42);
    let mut air = Aircraft::new();
    let mut ground = Ground::new();
    establish(&mut air, &mut ground, 0, &mut rng);
    (air, ground, rng)
}

#[test]
fn forged_plaintext_setting() {
    let (mut air, _, mut rng) = established();
    // In the secure format, crypto byte 0xAA.
    assert_eq!(
        air.receive(&as_plaintext(&setting()), 0, &mut rng),
        Rx::Rejected(Reject::PlaintextNotAllowed)
    );
    // As an ordinary unsecured v2 frame (first DATA byte: the ground's id 0).
    assert_eq!(
        air.receive(&setting(), 0, &mut rng),
        Rx::Rejected(Reject::NotSecure)
    );
    let st = air.ch.stats();
    assert_eq!(
        (st.plaintext_not_allowed, st.not_secure, st.decrypted),
        (1, 1, 0)
    );
    // Before any session too.
    let mut fresh = Aircraft::new();
    assert_eq!(
        fresh.receive(&as_plaintext(&setting()), 0, &mut rng),
        Rx::Rejected(Reject::PlaintextNotAllowed)
    );
}

#[test]
fn replayed_frame() {
    let (mut air, mut ground, mut rng) = established();
    let wire = seal(&mut ground.ch, &setting()).unwrap();
    assert!(matches!(air.receive(&wire, 0, &mut rng), Rx::App(_, _)));
    assert_eq!(
        air.receive(&wire, 0, &mut rng),
        Rx::Rejected(Reject::Replayed)
    );
    // An older frame after a newer one.
    let old = seal(&mut ground.ch, &ping()).unwrap();
    let new = seal(&mut ground.ch, &ping()).unwrap();
    assert!(matches!(air.receive(&new, 0, &mut rng), Rx::App(_, _)));
    assert_eq!(
        air.receive(&old, 0, &mut rng),
        Rx::Rejected(Reject::Replayed)
    );
    assert_eq!(air.ch.stats().replayed, 2);
    assert_eq!(air.ch.last_rx_counter(), 3);
    // A frame of a previous session, after a new handshake: its tag does not verify.
    establish(&mut air, &mut ground, 2_000, &mut rng);
    assert_eq!(
        air.receive(&wire, 0, &mut rng),
        Rx::Rejected(Reject::BadTag)
    );
}

#[test]
fn every_modified_byte_is_rejected_and_nothing_changes() {
    let (mut air, mut ground, mut rng) = established();
    let wire = seal(&mut ground.ch, &setting()).unwrap();
    let data_len = wire.len() - 4;
    let mut reasons = std::collections::BTreeMap::new();
    for i in 0..data_len {
        for xor in [0x01, 0x80, 0xFF] {
            let bad = tamper(&wire, i, xor);
            let rx = air.receive(&bad, 0, &mut rng);
            let Rx::Rejected(reason) = rx else {
                panic!("byte {i} ^ {xor:#x} accepted: {rx:?}");
            };
            // What each part of the frame gives.
            let expected: &[Reject] = match i {
                0 => &[Reject::NotSecure, Reject::PlaintextNotAllowed],
                1..=4 => &[Reject::BadTag, Reject::Replayed], // counter
                5 => &[Reject::BadTag], // source (any is allowed, authenticated)
                6 => &[Reject::WrongAddress, Reject::BadTag], // destination
                _ => &[Reject::BadTag], // ciphertext, tag
            };
            assert!(
                expected.contains(&reason),
                "byte {i} ^ {xor:#x}: {reason:?}"
            );
            *reasons.entry(format!("{reason:?}")).or_insert(0) += 1;
            assert_eq!(air.ch.last_rx_counter(), 0, "state unchanged");
        }
    }
    let st = air.ch.stats();
    assert_eq!(st.decrypted, 0);
    assert_eq!(st.rejected() as usize, data_len * 3);
    assert!(st.bad_tag > 0 && st.wrong_address > 0 && st.not_secure > 0);
    // A counter moved up fails the tag and does not move the receiver's counter: the
    // genuine frame is still accepted.
    assert_eq!(
        air.receive(&tamper(&wire, 1, 0x80), 0, &mut rng),
        Rx::Rejected(Reject::BadTag)
    );
    assert_eq!(
        air.receive(&wire, 0, &mut rng),
        Rx::App(setting(), Protection::Encrypted { counter: 1 })
    );
    // Truncated frames: malformed (or a bad tag), never a panic.
    // (Below 4 bytes of DATA the PPRZ decoder drops them first; the channel copes.)
    let mut out = [0u8; 255];
    for n in 0..data_len {
        assert!(matches!(
            air.ch.open(&wire[2..2 + n], &mut out),
            Err(Reject::Malformed | Reject::BadTag | Reject::Replayed)
        ));
    }
}

#[test]
fn handshake_signed_with_the_wrong_key() {
    let keys = test_keys();
    let mut other_rng = TestRng::new(77);
    let other = KeyFile::generate(&mut other_rng);
    // A ground whose key the aircraft does not trust (it knows the aircraft's public key).
    let impostor_keys = KeyFile::from_keys(
        None,
        other.get(KeyName::GcsPrivate).copied(),
        keys.get(KeyName::UavPublic).copied(),
        None,
    );
    let (mut air, _, mut rng) = established();
    let session_before = air.ch.stats().sessions;
    let mut impostor = Ground::with_keys(&impostor_keys);
    impostor.poll(5_000, &mut rng);
    for f in std::mem::take(&mut impostor.out) {
        air.receive(&f, 5_000, &mut rng);
    }
    for f in std::mem::take(&mut air.out) {
        impostor.receive(&f, 5_000); // the aircraft's signature is genuine: accepted
    }
    let sig = impostor.out.pop().unwrap();
    assert_eq!(
        air.receive(&sig, 5_000, &mut rng),
        Rx::Handshake(Err(HandshakeError::BadSignature))
    );
    assert_eq!(air.hs.stats().bad_signature, 1);
    assert_eq!(
        air.hs.state(),
        ResponderState::Established,
        "pending handshake dropped"
    );
    assert_eq!(air.ch.stats().sessions, session_before, "old session kept");
    // The same message again: no pending handshake, no second verification.
    assert_eq!(
        air.receive(&sig, 5_000, &mut rng),
        Rx::Handshake(Err(HandshakeError::Unexpected))
    );

    // An aircraft whose key the ground does not trust.
    let fake_air_keys = KeyFile::from_keys(
        keys.get(KeyName::GcsPublic).copied(),
        None,
        None,
        other.get(KeyName::UavPrivate).copied(),
    );
    let mut fake = Aircraft::with_keys(&fake_air_keys);
    let mut ground = Ground::new();
    ground.poll(0, &mut rng);
    for f in std::mem::take(&mut ground.out) {
        fake.receive(&f, 0, &mut rng);
    }
    let msg2 = fake.out.pop().unwrap();
    assert_eq!(
        ground.receive(&msg2, 0),
        Rx::Handshake(Err(HandshakeError::BadSignature))
    );
    assert!(!ground.ch.has_session());
    assert_eq!(ground.hs.stats().bad_signature, 1);
    assert_eq!(
        ground.hs.state(),
        pprz_secure::InitiatorState::WaitMsg2,
        "still waiting"
    );
}

/// Low-order points of Curve25519 (u-coordinates, little-endian), and non-canonical
/// encodings of some (u + p): all give an all-zero shared secret.
fn low_order_points() -> Vec<[u8; 32]> {
    let hex = [
        "0000000000000000000000000000000000000000000000000000000000000000",
        "0100000000000000000000000000000000000000000000000000000000000000",
        "e0eb7a7c3b41b8ae1656e3faf19fc46ada098deb9c32b1fd866205165f49b800",
        "5f9c95bca3508c24b1d0b1559c83ef5b04445cc4581c8e86d8224eddd09f1157",
        "ecffffffffffffffffffffffffffffffffffffffffffffffffffffffffffff7f",
        "edffffffffffffffffffffffffffffffffffffffffffffffffffffffffffff7f",
        "eeffffffffffffffffffffffffffffffffffffffffffffffffffffffffffff7f",
    ];
    hex.iter()
        .map(|h| {
            let v: Vec<u8> = (0..32)
                .map(|i| u8::from_str_radix(&h[2 * i..2 * i + 2], 16).unwrap())
                .collect();
            v.try_into().unwrap()
        })
        .collect()
}

#[test]
fn all_zero_and_low_order_ephemeral_keys() {
    let (mut air, mut ground, mut rng) = established();
    let ids = KeyExchangeIds::PPRZLINK;
    let mut now = 10_000;
    for p in low_order_points() {
        now += 1_000; // past the rate limit: the work is done, and refused
        let msg1 = KeyExchange::parse(
            &[&[0, AC_ID, 2, 159, AC_ID, 0, 32][..], &p[..]].concat(),
            &ids,
        )
        .unwrap()
        .unwrap();
        assert_eq!(
            air.hs.handle(&msg1, now, &mut rng).unwrap_err(),
            HandshakeError::BadKey,
            "{p:02x?}"
        );
    }
    assert_eq!(air.hs.stats().bad_key, 7);
    assert_eq!(air.hs.state(), ResponderState::Established);
    assert!(air.out.is_empty(), "no answer");

    // The ground refuses a low-order P_BE the same way.
    ground.hs.restart();
    ground.poll(now, &mut rng);
    for p in low_order_points() {
        let mut data = p.to_vec();
        data.extend_from_slice(&[0; 80]);
        let msg2 = KeyExchange::parse(&[&[AC_ID, 0, 1, 239, 1, 112][..], &data[..]].concat(), &ids)
            .unwrap()
            .unwrap();
        assert_eq!(
            ground.hs.handle(&msg2, now).unwrap_err(),
            HandshakeError::BadKey
        );
    }
    assert_eq!(ground.hs.stats().bad_key, 7);
}

#[test]
fn msg1_flood_keeps_the_session_and_the_telemetry() {
    let (mut air, mut ground, mut rng) = established();
    let ids = KeyExchangeIds::PPRZLINK;
    let mut flood_rng = TestRng::new(999);
    let start = air.hs.stats();
    let mut now = 1_000;
    // 100 fresh P_AE per second for 10 s, each a random (valid) point.
    for i in 0..1_000u64 {
        now = 1_000 + i * 10;
        let mut p = [0u8; 32];
        pprz_secure::rand_core::RngCore::fill_bytes(&mut flood_rng, &mut p);
        let msg1 = KeyExchange::parse(&[&[0, AC_ID, 2, 159, 0, 0, 32][..], &p[..]].concat(), &ids)
            .unwrap()
            .unwrap();
        let wire = {
            let mut buf = [0u8; 64];
            let n = msg1.write_frame(&mut buf).unwrap();
            as_plaintext(&buf[..n])
        };
        let _ = air.receive(&wire, now, &mut rng);
        // The aircraft keeps sending telemetry the ground decrypts, and answers PING.
        if i % 10 == 0 {
            air.send(&alive()).unwrap();
            let ping = seal(&mut ground.ch, &ping()).unwrap();
            assert!(matches!(air.receive(&ping, now, &mut rng), Rx::App(_, _)));
        }
    }
    let st = air.hs.stats();
    let work = st.started - start.started;
    assert!(
        work <= 11,
        "at most one handshake's work per second: {work}"
    );
    assert_eq!(st.rate_limited - start.rate_limited, 1_000 - work);
    assert_eq!(air.ch.stats().sessions, 1, "session kept");
    let replies = air.out.iter().filter(|f| f[2] == 0xAA).count() as u32;
    assert_eq!(replies, work, "one message 2 per handshake worked on");
    for f in std::mem::take(&mut air.out) {
        match ground.receive(&f, now) {
            Rx::App(p, Protection::Encrypted { .. }) => assert_eq!(p, alive()),
            // The flood's messages 2 are not for this ground's handshake: refused.
            Rx::Handshake(Err(HandshakeError::Unexpected)) => {}
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(ground.ch.stats().decrypted, 100);
    // After the flood, the genuine ground can still re-key.
    establish(&mut air, &mut ground, now + 1_000, &mut rng);
    assert_eq!(air.ch.stats().sessions, 2);
}

#[test]
fn counter_near_2_pow_32_stops_and_rekeys() {
    let (mut air, mut ground, mut rng) = established();
    air.ch.advance_tx_counter(u32::MAX - 2);
    assert_eq!(air.ch.counter_space_left(), 3);
    let mut counters = vec![];
    for _ in 0..5 {
        match seal(&mut air.ch, &alive()) {
            Ok(wire) => {
                counters.push(u32::from_be_bytes(wire[3..7].try_into().unwrap()));
                assert!(matches!(ground.receive(&wire, 0), Rx::App(_, _)));
            }
            Err(e) => assert_eq!(e, SealError::CounterExhausted),
        }
    }
    assert_eq!(counters, [u32::MAX - 2, u32::MAX - 1, u32::MAX]);
    assert_eq!(air.ch.stats().counter_exhausted, 2);
    assert_eq!(air.ch.counter_space_left(), 0);
    // The ground sees the peer's counter near the end and re-keys.
    assert!(ground.ch.needs_rekey());
    ground.poll(3_000, &mut rng);
    for f in std::mem::take(&mut ground.out) {
        air.receive(&f, 3_000, &mut rng);
    }
    for f in std::mem::take(&mut air.out) {
        ground.receive(&f, 3_000);
    }
    for f in std::mem::take(&mut ground.out) {
        air.receive(&f, 3_000, &mut rng);
    }
    assert_eq!(air.ch.stats().sessions, 2);
    let wire = seal(&mut air.ch, &alive()).unwrap();
    assert_eq!(
        &wire[3..7],
        &[0, 0, 0, 1],
        "counters start again under new keys"
    );
    assert!(matches!(ground.receive(&wire, 3_000), Rx::App(_, _)));
}

#[test]
fn handshake_not_for_us() {
    let (mut air, _, mut rng) = established();
    let ids = KeyExchangeIds::PPRZLINK;
    let kx = |dst: u8, ac: u8| {
        KeyExchange::parse(
            &[&[0, dst, 2, 159, ac, 0, 32][..], &[9u8; 32][..]].concat(),
            &ids,
        )
        .unwrap()
        .unwrap()
    };
    // Another aircraft's destination, or its id in the ac_id field.
    for (dst, ac) in [(8, 0), (8, 8), (AC_ID, 8), (0xFF, 8)] {
        assert_eq!(
            air.hs.handle(&kx(dst, ac), 10_000, &mut rng).unwrap_err(),
            HandshakeError::WrongAddress
        );
    }
    // Broadcast with ac_id 0 or ours is for us.
    assert!(air.hs.handle(&kx(0xFF, AC_ID), 10_000, &mut rng).is_ok());
    assert_eq!(air.hs.stats().wrong_address, 4);
    // A message 2 or the aircraft's own message type sent to it: unexpected.
    let mut m = kx(AC_ID, 0);
    m.msg_type = MsgType::PBe;
    assert_eq!(
        air.hs.handle(&m, 20_000, &mut rng).unwrap_err(),
        HandshakeError::Unexpected
    );
    // A frame for another aircraft never reaches the handshake.
    let mut buf = [0u8; 64];
    let n = kx(8, 0).write_frame(&mut buf).unwrap();
    assert_eq!(
        air.receive(&as_plaintext(&buf[..n]), 0, &mut rng),
        Rx::Rejected(Reject::WrongAddress)
    );
}

/// A captured message 2 replayed 200 times: the initiator answers with message 3 at
/// most `MSG3_RESENDS` times while the aircraft is unconfirmed, never once it is
/// confirmed; every copy not answered and every forged message 2 is refused and counted.
#[test]
fn replayed_message_2_is_answered_at_most_msg3_resends_times() {
    let mut rng = TestRng::new(42);
    let (mut air, mut ground) = (Aircraft::new(), Ground::new());
    ground.poll(0, &mut rng);
    for f in std::mem::take(&mut ground.out) {
        air.receive(&f, 0, &mut rng);
    }
    let msg2 = std::mem::take(&mut air.out);
    assert_eq!(msg2.len(), 1);
    let msg2 = msg2.into_iter().next().unwrap();
    assert_eq!(ground.receive(&msg2, 0), Rx::Handshake(Ok(())));
    for f in std::mem::take(&mut ground.out) {
        air.receive(&f, 0, &mut rng);
    }
    assert!(air.ch.has_session() && ground.ch.has_session());
    let replay = |ground: &mut Ground, now_ms| {
        let mut sent = 0;
        for _ in 0..200 {
            let _ = ground.receive(&msg2, now_ms);
            sent += std::mem::take(&mut ground.out).len();
        }
        sent
    };
    let sent = replay(&mut ground, 10);
    assert!(sent <= usize::from(MSG3_RESENDS), "{sent} messages 3");
    air.send(&alive()).unwrap();
    for f in std::mem::take(&mut air.out) {
        assert!(matches!(ground.receive(&f, 20), Rx::App(_, _)));
    }
    assert_eq!(ground.hs.state(), pprz_secure::InitiatorState::Confirmed);
    assert_eq!(replay(&mut ground, 30), 0, "confirmed: no message 3");
    // Forged: the aircraft's key changed, or the sealed signature.
    for i in [10, 40, 100] {
        assert_eq!(
            ground.receive(&tamper(&msg2, i, 0x10), 40),
            Rx::Handshake(Err(HandshakeError::Unexpected))
        );
    }
    assert!(ground.out.is_empty());
    let st = ground.hs.stats();
    assert_eq!(st.duplicate, 400 - sent as u32, "{st:?}");
    assert_eq!(st.unexpected, 3, "{st:?}");
    assert_eq!(st.refused(), 403 - sent as u32, "{st:?}");
    assert_eq!((st.started, st.completed), (1, 1), "{st:?}");
    assert_eq!(ground.hs.state(), pprz_secure::InitiatorState::Confirmed);
}
