//! Known-answer tests: the committed vectors of `kat/generate.py` (Python `cryptography`,
//! an independent implementation) reproduced byte for byte: the long-term keys, the
//! three handshake messages on the wire, the session keys, and data frames in both
//! directions (including the skipped counter and the last counter).

mod common;

use common::*;
use pprz_secure::{
    Initiator, InitiatorEvent, KeyExchange, KeyExchangeIds, KeyName, Protection, Responder,
    ResponderEvent, SealError, SessionKeys,
};

fn assert_keys(keys: &SessionKeys, v: &Vectors, tx: (&str, &str), rx: (&str, &str)) {
    assert_eq!(keys.tx().key()[..], v.bytes(tx.0)[..], "{}", tx.0);
    assert_eq!(keys.tx().salt()[..], v.bytes(tx.1)[..], "{}", tx.1);
    assert_eq!(keys.rx().key()[..], v.bytes(rx.0)[..], "{}", rx.0);
    assert_eq!(keys.rx().salt()[..], v.bytes(rx.1)[..], "{}", rx.1);
}

fn kx_of(frame: &[u8]) -> KeyExchange {
    KeyExchange::parse(&frame[2..frame.len() - 2], &KeyExchangeIds::PPRZLINK)
        .unwrap()
        .expect("a key exchange")
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

macro_rules! assert_bytes {
    ($got:expr, $want:expr, $what:expr) => {
        assert_eq!(hex(&$got), hex(&$want), "{}", $what)
    };
}

#[test]
fn long_term_keys() {
    let v = Vectors::load();
    let f = test_keys();
    assert_eq!(
        f.get(KeyName::GcsPrivate).unwrap()[..],
        v.bytes("gcs_seed")[..]
    );
    assert_eq!(
        f.get(KeyName::UavPrivate).unwrap()[..],
        v.bytes("uav_seed")[..]
    );
    assert_eq!(
        f.aircraft().unwrap().public()[..],
        v.bytes("uav_public")[..]
    );
    assert_eq!(f.ground().unwrap().public()[..], v.bytes("gcs_public")[..]);
}

/// The whole exchange through both ends' channels and state machines, every wire byte
/// compared with the vectors.
#[test]
fn handshake_and_data_frames_byte_for_byte() {
    let v = Vectors::load();
    let keys = test_keys();
    let mut air = Aircraft::with_keys(&keys);
    let mut ground = Ground::with_keys(&keys);

    // Message 1: the ground's ephemeral key from its RNG.
    let mut a_rng = FixedRng(v.bytes("a_eph"));
    ground.poll(0, &mut a_rng);
    let msg1 = ground.out.remove(0);
    assert_bytes!(msg1, v.bytes("msg1_wire"), "message 1");

    // Message 2: the aircraft's ephemeral key from its RNG.
    let mut b_rng = FixedRng(v.bytes("b_eph"));
    assert_eq!(air.receive(&msg1, 0, &mut b_rng), Rx::Handshake(Ok(())));
    let msg2 = air.out.remove(0);
    assert_bytes!(msg2, v.bytes("msg2_wire"), "message 2");
    assert_eq!(
        kx_of(&open(&mut ground.ch, &msg2).unwrap().0).data()[..32],
        v.bytes("p_be")[..]
    );

    // Message 3, and the ground's session keys.
    let mut g = Initiator::new(AC_ID, keys.ground().unwrap());
    g.poll(0, &mut FixedRng(v.bytes("a_eph")));
    match g.handle(&kx_of(&open(&mut Ground::new().ch, &msg2).unwrap().0), 0) {
        Ok(InitiatorEvent::Established { keys, .. }) => {
            assert_keys(&keys, &v, ("ka", "sa"), ("kb", "sb"));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(ground.receive(&msg2, 0), Rx::Handshake(Ok(())));
    let msg3 = ground.out.remove(0);
    assert_bytes!(msg3, v.bytes("msg3_wire"), "message 3");

    // The aircraft's session keys.
    let mut r = Responder::new(AC_ID, keys.aircraft().unwrap());
    let mut fresh = Aircraft::new();
    r.handle(
        &kx_of(&open(&mut fresh.ch, &msg1).unwrap().0),
        0,
        &mut FixedRng(v.bytes("b_eph")),
    )
    .unwrap();
    match r.handle(
        &kx_of(&open(&mut fresh.ch, &msg3).unwrap().0),
        0,
        &mut FixedRng(vec![]),
    ) {
        Ok(ResponderEvent::Established(keys)) => {
            assert_keys(&keys, &v, ("kb", "sb"), ("ka", "sa"));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        air.receive(&msg3, 0, &mut FixedRng(vec![])),
        Rx::Handshake(Ok(()))
    );
    assert!(air.ch.has_session() && ground.ch.has_session());

    // Data frames, both directions.
    let up = |name: &str| {
        (
            v.bytes(&format!("{name}_plain")),
            v.bytes(&format!("{name}_wire")),
        )
    };
    for name in ["up1", "up2"] {
        let (plain, wire) = up(name);
        assert_bytes!(seal(&mut ground.ch, &plain).unwrap(), wire, name);
        let counter = v.u32(&format!("{name}_counter"));
        assert_eq!(
            air.receive(&wire, 0, &mut FixedRng(vec![])),
            Rx::App(plain, Protection::Encrypted { counter }),
            "{name}"
        );
    }
    for name in ["down1", "down2", "down3"] {
        let (plain, wire) = up(name);
        assert_bytes!(seal(&mut air.ch, &plain).unwrap(), wire, name);
        let counter = v.u32(&format!("{name}_counter"));
        assert_eq!(
            ground.receive(&wire, 0),
            Rx::App(plain, Protection::Encrypted { counter }),
            "{name}"
        );
    }
    // The biggest frame: 226 bytes of fields, 255 on the wire.
    assert_eq!(v.bytes("down3_wire").len(), 255);

    // The counter equal to BE32(salt[0..4]) is skipped.
    let reserved_b = v.u32("reserved_b");
    air.ch.advance_tx_counter(reserved_b);
    let (plain, wire) = up("down_skip");
    assert_bytes!(seal(&mut air.ch, &plain).unwrap(), wire, "down_skip");
    assert_eq!(v.u32("down_skip_counter"), reserved_b + 1);
    assert!(matches!(ground.receive(&wire, 0), Rx::App(p, _) if p == plain));
    let reserved_a = v.u32("reserved_a");
    ground.ch.advance_tx_counter(reserved_a);
    let (plain, wire) = up("up_skip");
    assert_bytes!(seal(&mut ground.ch, &plain).unwrap(), wire, "up_skip");
    assert!(matches!(air.receive(&wire, 0, &mut FixedRng(vec![])), Rx::App(p, _) if p == plain));

    // The last counter, then nothing: never a wrap.
    air.ch.advance_tx_counter(u32::MAX);
    let (plain, wire) = up("down_last");
    assert_bytes!(seal(&mut air.ch, &plain).unwrap(), wire, "down_last");
    assert_eq!(seal(&mut air.ch, &plain), Err(SealError::CounterExhausted));
    assert!(matches!(ground.receive(&wire, 0), Rx::App(p, _) if p == plain));
}

/// Paparazzi's ground leaves the `ac_id` field of KEY_EXCHANGE_GCS at 0: accepted, and
/// answered with the same message 2.
#[test]
fn reference_ground_message_1() {
    let v = Vectors::load();
    let mut air = Aircraft::new();
    let msg1 = v.bytes("msg1_ref_wire");
    assert_eq!(
        kx_of(&open(&mut Aircraft::new().ch, &msg1).unwrap().0).ac_id,
        Some(0)
    );
    assert_eq!(
        air.receive(&msg1, 0, &mut FixedRng(v.bytes("b_eph"))),
        Rx::Handshake(Ok(()))
    );
    assert_bytes!(air.out[0], v.bytes("msg2_wire"), "message 2");
    assert_eq!(
        air.receive(&v.bytes("msg3_wire"), 0, &mut FixedRng(vec![])),
        Rx::Handshake(Ok(()))
    );
    assert!(air.ch.has_session());
}
