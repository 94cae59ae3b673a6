//! Golden frames, byte for byte, through every public entry point; limits and
//! typed errors.

mod common;

use common::{Owned, all_transports, decode_chunked};
use pprz_transports::{
    AnyTransport, Control, Decoder, EncodeError, Encoder, Extra, Framing, LogInfo, MAX_FRAME_LEN,
    MsgHeader, PprzLog, PprzV1, PprzV2, RxError, TxMeta, TxStatus, WriteFrameError, XBee24,
    XBee868, XBeeInfo, write_frame,
};

/// The worked v2 example of `docs/wire-formats.md`: telemetry ALIVE (class 1, id 2) from
/// aircraft 7 to ground, md5sum = uint8[] [0, 1, 2]:
///   99 | LEN 0C | 07 00 01 02 | 03 00 01 02 | CK_A CK_B over 0C..02 = 1C C4
const V2_EXAMPLE: [u8; 12] = [
    0x99, 0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x1C, 0xC4,
];
/// The ALIVE fields: array count 3, then 0 1 2.
const FIELDS: [u8; 4] = [0x03, 0x00, 0x01, 0x02];
const META: TxMeta = TxMeta::new(MsgHeader::new(7, 0, 1, 2));

/// v1, same message: 99 | LEN = 2 + 2 + 4 + 2 = 0x0A | 07 02 | 03 00 01 02 | CK.
///   over 0A 07 02 03 00 01 02:  ck_a = 0A 11 13 16 16 17 19, ck_b = 0A 1B 2E 44 5A 71 8A
const V1_EXAMPLE: [u8; 10] = [0x99, 0x0A, 0x07, 0x02, 0x03, 0x00, 0x01, 0x02, 0x19, 0x8A];

/// XBee 802.15.4 TX16 to ground (0 -> 0x0100), frame id 0, options 0:
///   FRAME_DATA = 01 00 01 00 00 07 00 01 02 03 00 01 02 (LEN 13)
///   sum = 01+01+07+01+02+03+01+02 = 0x12, CK = FF - 12 = ED
const XBEE24_TX: [u8; 17] = [
    0x7E, 0x00, 0x0D, 0x01, 0x00, 0x01, 0x00, 0x00, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02,
    0xED,
];

/// XBee 802.15.4 RX16 from 0x0007, RSSI 0x28 (-40 dBm), options 0:
///   FRAME_DATA = 81 00 07 28 00 07 00 01 02 03 00 01 02
///   sum = 81+07+28+07+01+02+03+01+02 = 0xC0, CK = FF - C0 = 3F
const XBEE24_RX: [u8; 17] = [
    0x7E, 0x00, 0x0D, 0x81, 0x00, 0x07, 0x28, 0x00, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02,
    0x3F,
];

/// XBee 868 transmit request to ground (dest64 0x0000000000000100), 16-bit FF FE,
/// radius 0, options 0: LEN = 14 + 4 + 4 = 22
///   sum = 10+01+FF+FE+07+01+02+03+01+02 = 0x21E -> 1E, CK = FF - 1E = E1
const XBEE868_TX: [u8; 26] = [
    0x7E, 0x00, 0x16, 0x10, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0xFF, 0xFE, 0x00,
    0x00, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0xE1,
];

/// XBee 868 receive packet from 0x0013A20040A1B2C3, 16-bit FF FE, options 01:
///   LEN = 12 + 8 = 20
///   sum = 90+13+A2+40+A1+B2+C3+FF+FE+01+07+01+02+03+01+02 = 0x5A9 -> A9, CK = 56
const XBEE868_RX: [u8; 24] = [
    0x7E, 0x00, 0x14, 0x90, 0x00, 0x13, 0xA2, 0x00, 0x40, 0xA1, 0xB2, 0xC3, 0xFF, 0xFE, 0x01, 0x07,
    0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x56,
];

/// PPRZLOG, datalink source (1), t = 10 s = 100000 ticks = 0x000186A0 -> A0 86 01 00:
///   99 | LEN 08 | 01 | A0 86 01 00 | 07 00 01 02 03 00 01 02 | CK
///   CK = 08+01+A0+86+01+07+01+02+03+01+02 = 0x140 -> 40
const PPRZLOG: [u8; 16] = [
    0x99, 0x08, 0x01, 0xA0, 0x86, 0x01, 0x00, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x40,
];

fn check_alive(o: &Owned) {
    assert_eq!((o.source, o.class, o.msg_id), (7, 1, 2));
    assert_eq!(o.payload, FIELDS);
}

#[test]
fn v2_example_encode() {
    let mut out = [0u8; MAX_FRAME_LEN];
    let n = PprzV2::new().encode(&META, &FIELDS, &mut out).unwrap();
    assert_eq!(&out[..n], &V2_EXAMPLE);
}

#[test]
fn v2_example_encode_in_place() {
    let t = PprzV2::new();
    assert_eq!((t.header_len(), t.tail_len()), (6, 2));
    let mut frame = [0xEEu8; 12];
    frame[6..10].copy_from_slice(&FIELDS);
    assert_eq!(t.finish_frame(&META, &mut frame, 4), Ok(12));
    assert_eq!(frame, V2_EXAMPLE);
}

#[test]
fn v2_example_decode() {
    let mut d: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut input = &V2_EXAMPLE[..];
    let f = d.feed(&mut input).unwrap();
    assert_eq!(f.source(), 7);
    assert_eq!(f.destination(), Some(0));
    assert_eq!(f.class(), 1);
    assert_eq!(f.component(), 0);
    assert_eq!(f.msg_id(), 2);
    assert_eq!(f.payload(), &FIELDS);
    assert_eq!(f.data(), &V2_EXAMPLE[2..10]);
    assert_eq!(f.raw(), &V2_EXAMPLE);
    assert_eq!(f.header(), META.header);
    assert!(input.is_empty());
    assert_eq!(d.stats().frames, 1);
    assert_eq!(d.stats().errors(), 0);
}

#[test]
fn v2_example_write_frame() {
    let mut out = [0u8; 12];
    let mut w = &mut out[..];
    let n = embassy_futures::block_on(write_frame(&mut w, &PprzV2::new(), &META, &FIELDS));
    assert_eq!(n, Ok(12));
    assert_eq!(out, V2_EXAMPLE);
}

#[test]
fn golden_encodes() {
    let cases: [(AnyTransport, TxMeta, &[u8]); 5] = [
        (PprzV2::new().into(), META, &V2_EXAMPLE),
        (PprzV1::new(1).into(), META, &V1_EXAMPLE),
        (XBee24::new().into(), META, &XBEE24_TX),
        (XBee868::new().into(), META, &XBEE868_TX),
        (PprzLog::DATALINK.into(), META.at(100_000), &PPRZLOG),
    ];
    for (t, meta, golden) in cases {
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = t.encode(&meta, &FIELDS, &mut out).unwrap();
        assert_eq!(&out[..n], golden, "{t:?}");
        assert_eq!(t.frame_len(FIELDS.len()), Ok(golden.len()));
        assert_eq!(t.header_len() + FIELDS.len() + t.tail_len(), golden.len());
        // In place: fields first, then header and tail.
        let mut frame = [0u8; MAX_FRAME_LEN];
        t.payload_area(&mut frame)[..FIELDS.len()].copy_from_slice(&FIELDS);
        let n = t.finish_frame(&meta, &mut frame, FIELDS.len()).unwrap();
        assert_eq!(&frame[..n], golden, "{t:?} in place");
    }
}

#[test]
fn golden_decodes() {
    let v1 = decode_chunked::<MAX_FRAME_LEN>(PprzV1::new(1).into(), &V1_EXAMPLE, &[3]).0;
    check_alive(&v1[0]);
    assert_eq!(v1[0].destination, None);

    let rx = decode_chunked::<MAX_FRAME_LEN>(XBee24::new().into(), &XBEE24_RX, &[1]).0;
    check_alive(&rx[0]);
    assert_eq!(
        rx[0].extra,
        Extra::XBee(XBeeInfo {
            api_id: 0x81,
            address: 7,
            rssi: Some(0x28),
            options: 0
        })
    );
    let lo = decode_chunked::<MAX_FRAME_LEN>(XBee24::new().into(), &XBEE24_TX, &[5]).0;
    check_alive(&lo[0]);
    assert_eq!(lo[0].destination, Some(0));

    let rx = decode_chunked::<MAX_FRAME_LEN>(XBee868::new().into(), &XBEE868_RX, &[7]).0;
    check_alive(&rx[0]);
    assert_eq!(
        rx[0].extra,
        Extra::XBee(XBeeInfo {
            api_id: 0x90,
            address: 0x0013_A200_40A1_B2C3,
            rssi: None,
            options: 1
        })
    );
    let lo = decode_chunked::<MAX_FRAME_LEN>(XBee868::new().into(), &XBEE868_TX, &[2]).0;
    check_alive(&lo[0]);

    let log = decode_chunked::<MAX_FRAME_LEN>(PprzLog::TELEMETRY.into(), &PPRZLOG, &[4]).0;
    check_alive(&log[0]);
    assert_eq!(
        log[0].extra,
        Extra::Log(LogInfo {
            source: 1,
            timestamp: 100_000
        })
    );
}

#[test]
fn xbee_addresses() {
    let mut out = [0u8; MAX_FRAME_LEN];
    for (dest, hi, lo) in [(0u8, 0x01, 0x00), (0xFF, 0xFF, 0xFF), (42, 0x00, 42)] {
        let meta = TxMeta::new(MsgHeader::new(7, dest, 1, 2));
        XBee24::new().encode(&meta, &[], &mut out).unwrap();
        assert_eq!(&out[5..7], &[hi, lo]);
        XBee868::new().encode(&meta, &[], &mut out).unwrap();
        assert_eq!(&out[5..13], &[0, 0, 0, 0, 0, 0, hi, lo]);
        assert_eq!(&out[13..15], &[0xFF, 0xFE]);
    }
}

#[test]
fn oversize_payload_is_a_typed_error() {
    let big = [0u8; 300];
    let expected_max = [249, 247, 96, 247, 251];
    for (t, max) in all_transports().into_iter().zip(expected_max) {
        assert_eq!(t.max_payload_len(), max, "{t:?}");
        let mut out = [0u8; 1024];
        assert!(
            t.encode(&META, &big[..max], &mut out).is_ok(),
            "{t:?} at max"
        );
        let err = EncodeError::PayloadTooLong { len: max + 1, max };
        assert_eq!(
            t.encode(&META, &big[..max + 1], &mut out),
            Err(err),
            "{t:?}"
        );
        assert_eq!(t.finish_frame(&META, &mut out, max + 1), Err(err));
        assert_eq!(t.frame_len(max + 1), Err(err));
        // Nothing is written when the frame is refused.
        let mut sink = [0u8; 1024];
        let mut w = &mut sink[..];
        let r = embassy_futures::block_on(write_frame(&mut w, &t, &META, &big[..max + 1]));
        assert_eq!(r, Err(WriteFrameError::Encode(err)));
        assert_eq!(w.len(), 1024);
        assert!(t.max_frame_len() <= MAX_FRAME_LEN);
    }
}

#[test]
fn small_buffer_is_a_typed_error() {
    for t in all_transports() {
        let need = t.frame_len(4).unwrap();
        let mut out = [0u8; 64];
        assert_eq!(
            t.encode(&META, &FIELDS, &mut out[..need - 1]),
            Err(EncodeError::BufferTooSmall {
                needed: need,
                available: need - 1
            })
        );
        assert!(t.payload_area(&mut out[..3]).is_empty());
    }
}

#[test]
fn invalid_header_is_a_typed_error() {
    let mut out = [0u8; 64];
    for bad in [
        MsgHeader::new(1, 2, 16, 3),
        MsgHeader::new(1, 2, 1, 3).with_component(16),
    ] {
        for t in all_transports() {
            let r = t.encode(&TxMeta::new(bad), &FIELDS, &mut out);
            if matches!(t, AnyTransport::PprzV1(_)) {
                assert!(r.is_ok(), "v1 does not carry class or component");
            } else {
                assert_eq!(r, Err(EncodeError::InvalidHeader), "{t:?}");
            }
        }
    }
}

#[test]
fn parse_errors() {
    let v2 = PprzV2::new();
    assert_eq!(v2.parse(&[]).unwrap_err(), RxError::Truncated);
    assert_eq!(v2.parse(&[0x12]).unwrap_err(), RxError::BadStart);
    assert_eq!(v2.parse(&V2_EXAMPLE[..11]).unwrap_err(), RxError::Truncated);
    assert_eq!(v2.parse(&[0x99, 0x07]).unwrap_err(), RxError::BadLength);
    let mut bad = V2_EXAMPLE;
    bad[4] ^= 0x10;
    assert_eq!(v2.parse(&bad).unwrap_err(), RxError::Checksum);
    // XBee length 0 and beyond the radio's limit.
    assert_eq!(
        XBee24::new().parse(&[0x7E, 0, 0, 0xFF]).unwrap_err(),
        RxError::BadLength
    );
    assert_eq!(
        XBee24::new().parse(&[0x7E, 0, 106]).unwrap_err(),
        RxError::BadLength
    );
    // A transmit status frame (0x89) is well formed but not a message: a control frame.
    let status = [0x7E, 0x00, 0x03, 0x89, 0x01, 0x00, 0x75];
    assert_eq!(
        XBee24::new().parse(&status).unwrap_err(),
        RxError::UnknownApiId(0x89)
    );
    assert_eq!(
        XBee24::new().parse_control(&status),
        Some((
            Control::TxStatus(TxStatus {
                frame_id: 1,
                delivered: true,
                status: 0,
                retries: 0
            }),
            7
        ))
    );
    // PPRZLOG DATA shorter than the message header.
    assert_eq!(
        PprzLog::TELEMETRY.parse(&[0x99, 3]).unwrap_err(),
        RxError::BadLength
    );
}

#[test]
fn decoder_counts_error_kinds() {
    let mut stream = Vec::new();
    let mut bad = V2_EXAMPLE;
    bad[11] ^= 1;
    stream.extend_from_slice(&bad); // checksum error
    stream.extend_from_slice(&[0x99, 0x02]); // impossible length
    stream.extend_from_slice(&V2_EXAMPLE);
    let (frames, s) = decode_chunked::<MAX_FRAME_LEN>(PprzV2::new().into(), &stream, &[1]);
    assert_eq!(frames.len(), 1);
    assert_eq!(s.frames, 1);
    assert_eq!(s.checksum_errors, 1);
    assert_eq!(s.length_errors, 1);

    // A modem status (0x8A: `8A 00`, hardware reset) is well formed but not carried; a
    // transmit status (0x89) is a control frame, neither an error nor a message.
    let modem_status = [0x7E, 0x00, 0x02, 0x8A, 0x00, 0x75];
    let tx_status = [0x7E, 0x00, 0x03, 0x89, 0x01, 0x00, 0x75];
    let mut stream = modem_status.to_vec();
    stream.extend_from_slice(&tx_status);
    stream.extend_from_slice(&XBEE24_RX);
    let (frames, s) = decode_chunked::<MAX_FRAME_LEN>(XBee24::new().into(), &stream, &[3]);
    assert_eq!(frames.len(), 1);
    assert_eq!(s.unknown_api, 1);
    assert_eq!((s.control_frames, s.control_bytes), (1, 7));
    assert_eq!(s.dropped_bytes, 6);

    let (frames, s) = decode_chunked::<32>(PprzV2::new().into(), &[0x99, 200, 1, 2], &[4]);
    assert!(frames.is_empty());
    assert_eq!(s.too_long, 1);
}

/// A writer that takes at most `step` bytes per call, then refuses (`Ok(0)`) once
/// `limit` bytes are written.
struct Trickle {
    out: Vec<u8>,
    step: usize,
    limit: usize,
}

impl embedded_io_async::ErrorType for Trickle {
    type Error = core::convert::Infallible;
}

impl embedded_io_async::Write for Trickle {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let n = buf
            .len()
            .min(self.step)
            .min(self.limit.saturating_sub(self.out.len()));
        self.out.extend_from_slice(&buf[..n]);
        Ok(n)
    }

    async fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

#[test]
fn write_frame_handles_short_writes() {
    for t in all_transports() {
        let mut w = Trickle {
            out: Vec::new(),
            step: 3,
            limit: usize::MAX,
        };
        let meta = META.at(100_000);
        let n = embassy_futures::block_on(write_frame(&mut w, &t, &meta, &FIELDS)).unwrap();
        assert_eq!(w.out, common::encode(&t, &meta, &FIELDS));
        assert_eq!(n, w.out.len());

        let mut full = Trickle {
            out: Vec::new(),
            step: 3,
            limit: 5,
        };
        let r = embassy_futures::block_on(write_frame(&mut full, &t, &meta, &FIELDS));
        assert_eq!(r, Err(WriteFrameError::WriteZero));
    }
}

/// A writer that claims to have written more bytes than it was given.
struct Boaster;

impl embedded_io_async::ErrorType for Boaster {
    type Error = core::convert::Infallible;
}

impl embedded_io_async::Write for Boaster {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        Ok(buf.len() + 1)
    }

    async fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

#[test]
fn write_frame_refuses_a_writer_that_reports_too_many_bytes() {
    for t in all_transports() {
        let r = embassy_futures::block_on(write_frame(&mut Boaster, &t, &META, &FIELDS));
        assert_eq!(r, Err(WriteFrameError::Overrun));
    }
}
