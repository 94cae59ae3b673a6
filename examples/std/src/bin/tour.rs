//! A tour of the message and transport layers on the host: the default message set,
//! typed encoding, PPRZ v2 framing in place, and incremental decoding of a noisy stream
//! with generic, unit-aware printing — what a ground tool does with any `messages.xml`.
//!
//! Run: `cargo run -p pprz-example-std --bin tour`

use pprz_default::messages::{MESSAGES, telemetry};
use pprz_messages::{Message, MessageDescriptor, VarArray, dynamic};
use pprz_transports::{
    Decoder, EncodeError, Encoder, MAX_FRAME_LEN, MsgHeader, PprzV2, TxMeta, XBee24,
};

/// Our aircraft id in this tour.
const AC_ID: u8 = 7;

/// Encodes `msg` directly into a frame of `transport` (no copy), to the ground.
fn frame<M: Message, T: Encoder>(transport: &T, msg: &M, out: &mut [u8]) -> Result<usize, String> {
    // Refuse what the transport cannot carry, with the transport's own error.
    transport
        .frame_len(msg.encoded_len())
        .map_err(|e| e.to_string())?;
    let n = msg
        .encode(transport.payload_area(out))
        .map_err(|e| e.to_string())?;
    let meta = TxMeta::new(MsgHeader::new(AC_ID, 0, M::CLASS_ID, M::ID));
    transport
        .finish_frame(&meta, out, n)
        .map_err(|e: EncodeError| e.to_string())
}

/// Prints one payload decoded generically: `NAME field=value unit ...`.
fn print_decoded(desc: &MessageDescriptor<'_>, payload: &[u8]) {
    print!("  {:<18}", desc.name);
    for item in dynamic::fields(desc, payload) {
        match item {
            Ok((field, value)) => {
                print!(" {}={value}", field.name);
                if let Some(label) = value.as_i64().and_then(|i| field.label(i)) {
                    print!("({label})");
                }
                match (field.alt_unit, field.alt_unit_coef, value.as_f64()) {
                    (Some(alt), Some(_), Some(raw)) => {
                        print!(" [{:.3} {alt}]", field.to_alt_unit(raw))
                    }
                    _ => {
                        if let Some(unit) = field.unit {
                            print!(" {unit}");
                        }
                    }
                }
            }
            Err(e) => print!(" <{e}>"),
        }
    }
    println!();
}

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn encode_and_show<M: Message>(msg: &M) {
    let mut buf = [0u8; 256];
    match msg.encode(&mut buf) {
        Ok(n) => {
            println!(
                "{} (class {}, id {}, priority {}): {} bytes: {}",
                M::NAME,
                M::CLASS_ID,
                M::ID,
                M::PRIORITY,
                n,
                hex(&buf[..n])
            );
            print_decoded(&M::DESCRIPTOR, &buf[..n]);
        }
        Err(e) => println!("{}: cannot encode: {e}", M::NAME),
    }
}

fn main() {
    list_messages();
    println!();
    encode_examples();
    println!();
    frame_examples();
    println!();
    decode_noisy_stream(&noisy_stream());
    println!();
    corrupt_payload();
}

/// The message set, one line a message.
fn list_messages() {
    println!("Default message set: {} messages", MESSAGES.len());
    println!(
        "{:<10} {:>3}  {:<20} {:>8}  fields",
        "class", "id", "name", "priority"
    );
    for m in MESSAGES.messages() {
        println!(
            "{:<10} {:>3}  {:<20} {:>8}  {}",
            m.class_name,
            m.id,
            m.name,
            m.priority,
            m.fields.len()
        );
    }
}

/// A few messages encoded and shown field by field.
fn encode_examples() {
    encode_and_show(&telemetry::Gps {
        mode: 3,
        utm_east: 37_712_345,
        utm_north: 482_112_000,
        course: 1_234,
        alt: 152_300,
        speed: 1_250,
        climb: -15,
        week: 2_345,
        itow: 345_600_000,
        utm_zone: 31,
        gps_nb_err: 0,
    });
    encode_and_show(&telemetry::Attitude {
        phi: 0.05,
        psi: 1.57,
        theta: -0.02,
    });
    encode_and_show(&telemetry::DlValue {
        index: 4,
        value: 2.5,
    });
    encode_and_show(&telemetry::Alive {
        md5sum: VarArray::new(&[0xDE, 0xAD, 0xBE, 0xEF]),
    });
    encode_and_show(&telemetry::RotorcraftStatus {
        ap_mode: telemetry::values::RotorcraftStatusApMode::Nav.raw(),
        ap_motors_on: 1,
        vsupply: 12.4,
        ..Default::default()
    });
}

/// Whole frames: the worked PPRZ v2 example, and a payload too long for XBee 802.15.4.
fn frame_examples() {
    let alive = telemetry::Alive {
        md5sum: VarArray::new(&[0, 1, 2]),
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    match frame(&PprzV2::new(), &alive, &mut buf) {
        Ok(len) => println!(
            "ALIVE in a PPRZ v2 frame (the worked example of docs/wire-formats.md): {}",
            hex(&buf[..len])
        ),
        Err(e) => println!("ALIVE: {e}"),
    }
    let big = [0u8; 120];
    let payload = telemetry::Payload {
        values: VarArray::new(&big),
    };
    match frame(&XBee24::default(), &payload, &mut buf) {
        Ok(len) => println!("PAYLOAD over XBee 802.15.4: {len} bytes"),
        Err(e) => println!("PAYLOAD of 121 field bytes over XBee 802.15.4 is refused: {e}"),
    }
}

/// A stream as a radio delivers it: frames mixed with noise.
fn noisy_stream() -> Vec<u8> {
    // It starts with a false start byte announcing a 5-byte frame whose checksum fails.
    let mut stream = vec![0x00, 0x99, 0x05, 0x13, 0x37, 0x00];
    let t = PprzV2::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for msg in [
        telemetry::AnyMessage::from(telemetry::Attitude {
            phi: 0.1,
            psi: -0.3,
            theta: 0.02,
        }),
        telemetry::AnyMessage::from(telemetry::DlValue {
            index: 2,
            value: 0.75,
        }),
        telemetry::AnyMessage::from(telemetry::Alive {
            md5sum: VarArray::new(&[0, 1, 2]),
        }),
    ] {
        let n = msg.encode(t.payload_area(&mut buf)).unwrap_or(0);
        let meta = TxMeta::new(MsgHeader::new(AC_ID, 0, 1, msg.id()));
        if let Ok(len) = t.finish_frame(&meta, &mut buf, n) {
            stream.extend_from_slice(&buf[..len]);
            stream.extend_from_slice(&[0x42, 0x00]); // noise between frames
        }
    }
    stream
}

/// Decodes `stream` read in odd-sized chunks.
fn decode_noisy_stream(stream: &[u8]) {
    println!("Decoding {} noisy bytes in chunks of 5:", stream.len());
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    for chunk in stream.chunks(5) {
        let mut input = chunk;
        while let Some(f) = decoder.feed(&mut input) {
            match MESSAGES.find(f.class(), f.msg_id()) {
                Some(desc) => print_decoded(desc, f.payload()),
                None => println!("  unknown message {}:{}", f.class(), f.msg_id()),
            }
        }
    }
    // End of stream: frames still held behind an incomplete false start come out here.
    while let Some(f) = decoder.flush() {
        if let Some(desc) = MESSAGES.find(f.class(), f.msg_id()) {
            print_decoded(desc, f.payload());
        }
    }
    let stats = decoder.stats();
    println!(
        "  frames {}, dropped bytes {}, checksum errors {}, length errors {}",
        stats.frames, stats.dropped_bytes, stats.checksum_errors, stats.length_errors
    );
}

/// A corrupt payload is an error, never a panic.
fn corrupt_payload() {
    println!("A corrupt payload is an error, never a panic:");
    let gps = MESSAGES.find(1, 8).map(|d| print_decoded(d, &[1, 2, 3]));
    if gps.is_none() {
        println!("  GPS is not in the set");
    }
}
