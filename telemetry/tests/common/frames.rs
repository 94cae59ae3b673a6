//! PPRZ v2 frames as the ground sends them (built with the transport's encoder) and as
//! the aircraft must answer (built by hand, so replies are checked byte for byte against
//! an independent computation).

use pprz_messages::Message;
use pprz_telemetry::pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};

/// A PPRZ v2 frame of `msg` from `source` to `dest`, encoded by the transport.
pub fn v2_frame<Msg: Message>(msg: &Msg, source: u8, dest: u8) -> Vec<u8> {
    let mut fields = [0u8; 256];
    let n = msg.encode(&mut fields).unwrap();
    let mut out = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(source, dest, Msg::CLASS_ID, Msg::ID));
    let len = PprzV2::new().encode(&meta, &fields[..n], &mut out).unwrap();
    out[..len].to_vec()
}

/// A PPRZ v2 frame from the ground (id 0) to `dest`.
pub fn uplink_frame<Msg: Message>(msg: &Msg, dest: u8) -> Vec<u8> {
    v2_frame(msg, 0, dest)
}

/// PONG (telemetry class 1, id 3, no fields) of aircraft 7 to the ground, by hand.
pub const PONG_7: [u8; 8] = [0x99, 0x08, 0x07, 0x00, 0x01, 0x03, 0x13, 0x49];

/// The PING (datalink class 2, id 8) of the ground to aircraft 7, by hand.
pub const PING_7: [u8; 8] = [0x99, 0x08, 0x00, 0x07, 0x02, 0x08, 0x19, 0x49];

/// DL_VALUE(index, value) (telemetry class 1, id 31) of aircraft `ac_id` to the ground,
/// by hand: STX, length, source, destination, class, id, fields, Fletcher checksum of
/// everything after STX.
pub fn dl_value_frame(ac_id: u8, index: u8, value: f32) -> Vec<u8> {
    let mut v = vec![0x99, 0x0D, ac_id, 0x00, 0x01, 31, index];
    v.extend_from_slice(&value.to_le_bytes());
    let (mut a, mut b) = (0u8, 0u8);
    for byte in &v[1..] {
        a = a.wrapping_add(*byte);
        b = b.wrapping_add(a);
    }
    v.extend_from_slice(&[a, b]);
    v
}

/// The ground's service requests to aircraft 7 that the datalink and `Link` tests send, in
/// order: PING; SETTING(0, 1.5); GET_SETTING(1) broadcast; SETTING for aircraft 9;
/// SETTING of index 5 (no such setting); PING addressed to aircraft 9.
pub fn service_requests() -> Vec<Vec<u8>> {
    use pprz_default::messages::datalink::{GetSetting, Ping, Setting};
    const AC_ID: u8 = 7;
    vec![
        PING_7.to_vec(),
        uplink_frame(
            &Setting {
                index: 0,
                ac_id: AC_ID,
                value: 1.5,
            },
            AC_ID,
        ),
        uplink_frame(
            &GetSetting {
                index: 1,
                ac_id: AC_ID,
            },
            0xFF,
        ), // broadcast
        uplink_frame(
            &Setting {
                index: 0,
                ac_id: 9,
                value: 9.0,
            },
            AC_ID,
        ), // other aircraft id
        uplink_frame(
            &Setting {
                index: 5,
                ac_id: AC_ID,
                value: 9.0,
            },
            AC_ID,
        ), // no such setting
        uplink_frame(&Ping, 9), // addressed to aircraft 9
    ]
}
